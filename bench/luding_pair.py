#!/usr/bin/python3
"""Two spheres under Luding's elasto-plastic adhesive law, run through our engine (demtk):

  loop        a prescribed overlap history (loading, unloading, reloading, beyond delta*,
              pull-off to separation): the force the engine's pair loop computes at each step;
  impacts     head-on collisions over a range of impact speeds: the restitution coefficient
              (0 when the pair sticks).

Writes OUT/ours_loop.csv, OUT/ours_impacts.csv and OUT/scene.toml (default OUT:
data/yade_luding), and with --figures the two figures of docs/contact_models.md
(docs/luding_loop.{png,svg}, docs/luding_restitution.{png,svg}) against the closed forms of
demkit/luding.py. YADE's side: yade_ref/luding_pair.py (the same pair, LudingMat).

    PYTHONPATH=build/python /usr/bin/python3 bench/luding_pair.py [--out DIR] [--figures]
"""
import argparse
import math
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from demkit.luding import Luding  # noqa: E402

R = 0.5e-3          # sphere radius [m]
RHO = 2000.0        # [kg/m^3]
K1, KP = 1e8, 5e8   # [N/m]
BOX = 20e-3         # periodic box [m]
# The loop: phi_f = 0.05 (delta* = 6 % of r, large enough to see), kc = k1/2; the overlap goes
# through these fractions of delta* (straight segments at a constant rate).
LOOP_PHI, LOOP_KC = 0.05, 0.5 * K1
LOOP_STOPS = [0.0, 0.35, 0.12, 0.7, 0.3, 1.3, 0.0]
LOOP_STEPS_PER_DSTAR = 2000
# The impacts: phi_f = 0.001 (delta* = 0.1 % of r: reached at ~9 m/s), four adhesions.
IMPACT_PHI = 0.001
IMPACT_KC = [0.0, 0.1 * K1, 1.0 * K1, 5.0 * K1]
IMPACT_V = [0.01, 0.03, 0.1, 0.3, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0, 60.0, 100.0]


def scene(kc, phi_f, damping=0.0):
    import demtk
    return demtk.load_scene(set={
        "particles.radius_min_m": R, "particles.radius_max_m": R, "particles.density_kg_m3": RHO,
        "contact.normal": "luding", "contact.stiffness_N_m": K1, "contact.luding_kp_N_m": KP,
        "contact.luding_kc_N_m": kc, "contact.luding_plasticity_depth": phi_f,
        "contact.damping_kg_s": damping, "contact.background_damping_kg_s": 0.0, "integration.threads": 1})


def law(kc, phi_f):
    return Luding(K1, KP, kc, phi_f, R * R / (2 * R))


def reduced_mass():
    m = 4 / 3 * math.pi * R ** 3 * RHO
    return m / 2


def pair_state(gap, masses):
    import demtk
    x0 = 5e-3
    pos = np.array([[x0, 10e-3, 10e-3], [x0 + 2 * R + gap, 10e-3, 10e-3]])
    return demtk.State.from_arrays(pos, np.array([R, R]), np.array([BOX, BOX, BOX]), masses=np.array(masses))


def run_loop(sc, stops, steps_per_dstar):
    """Prescribed overlap: both spheres of 1e20 kg (the forces do not move them), relative speed
    set per segment. Returns (step, delta [m], f_n [N]) after each step, in contact only."""
    import demtk
    L = law(sc["contact"]["luding_kc_N_m"], sc["contact"]["luding_plasticity_depth"])
    ds, dt = L.delta_star, sc.dt
    u = ds / (steps_per_dstar * dt)                       # overlap rate [m/s]
    st = pair_state(0.0, [1e20, 1e20])
    eng = demtk.Engine(sc, st)
    rows, step = [], 0
    for a, b in zip(stops[:-1], stops[1:]):
        n = int(round(abs(b - a) * steps_per_dstar))
        sign = 1.0 if b > a else -1.0                    # +: approach
        for _ in range(n):
            by_id = np.argsort(st.ids)
            v = np.zeros((2, 3))
            v[by_id[0], 0], v[by_id[1], 0] = 0.5 * sign * u, -0.5 * sign * u
            st.set_velocities(v)
            eng.step(1, keep_last_good=False)
            step += 1
            c = eng.contacts()
            if len(c["overlap"]):
                rows.append((step, float(c["overlap"][0]), float(c["force_normal"][0])))
    return rows


def run_impact(sc, v, max_contact_times=100):
    """Head-on impact at relative speed v [m/s]: e = |v_rel after| / v, or 0 if the spheres are
    still together after max_contact_times contact durations (sticking)."""
    import demtk
    m = 4 / 3 * math.pi * R ** 3 * RHO
    gap = 20 * sc.dt * v                                  # contact after ~20 steps
    st = pair_state(gap, [m, m])
    v0 = np.zeros((2, 3))
    v0[0, 0], v0[1, 0] = 0.5 * v, -0.5 * v
    st.set_velocities(v0)
    eng = demtk.Engine(sc, st)
    touched, limit = False, int(max_contact_times * sc.t_c / sc.dt) + 100
    for _ in range(limit):
        eng.step(1, keep_last_good=False)
        n = len(eng.contacts()["overlap"])
        if n and not touched:
            touched = True
        if touched and not n:
            eng.step(5, keep_last_good=False)
            by_id = np.argsort(st.ids)
            vel = np.array(st.velocities)
            return abs(vel[by_id[1], 0] - vel[by_id[0], 0]) / v
    if not touched:
        raise RuntimeError(f"the spheres never touched at v = {v} m/s")
    return 0.0


def write_csv(path, header, rows):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(",".join(header) + "\n")
        for r in rows:
            fh.write(",".join(repr(float(x)) if not isinstance(x, int) else str(x) for x in r) + "\n")
    os.replace(tmp, path)


def read_csv(path):
    """A numeric CSV with a header as an array, or None if absent."""
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2) if os.path.isfile(path) else None


def figures(out, loop_rows, impact_rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from demkit import figures as F
    L = law(LOOP_KC, LOOP_PHI)
    ds, scale = L.delta_star, K1 * L.delta_star
    d = np.array([r[1] for r in loop_rows])
    f = np.array([r[2] for r in loop_rows])
    closed = np.array([x[0] for x in L.path(d)])
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.plot(d / ds, closed / scale, "-", color="0.6", lw=3, label="piecewise closed form (demkit/luding.py)")
    ax.plot(d[::25] / ds, f[::25] / scale, ".", ms=3, color="C0", label="our engine, two spheres (every 25th step)")
    yade = read_csv(os.path.join(out, "yade_loop.csv"))
    if yade is not None:
        ax.plot(yade[12::25, 1] / ds, yade[12::25, 2] / scale, "x", ms=3, mew=0.6, color="C4",
                label="YADE LudingMat, the same loop (every 25th step)")
    xx = np.linspace(0, 1.45, 10)
    ax.plot(xx, xx, ":", color="C1", lw=1, label=r"$k_1\delta$ (virgin loading)")
    ax.plot(xx, -LOOP_KC / K1 * xx, ":", color="C3", lw=1, label=r"$-k_c\delta$ (adhesive limit)")
    ax.plot(xx, KP / K1 * (xx - L.delta0_limit / ds), ":", color="C2", lw=1, label=r"$k_p(\delta-\phi_f 2a_{12})$ (limit branch)")
    ax.set_ylim(-0.6, 1.9)
    ax.set_xlabel(r"overlap $\delta/\delta^*$")
    ax.set_ylabel(r"normal force $f/(k_1\delta^*)$")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_title(rf"Luding's law: $k_p = 5k_1$, $k_c = k_1/2$, $\phi_f = {LOOP_PHI}$, $\delta^* = {ds * 1e6:.1f}$ µm", fontsize=9)
    err = np.max(np.abs(f - closed)) / scale
    ax.text(0.02, 0.97, f"max |engine - closed form| = {err:.1e} k1 δ*", transform=ax.transAxes, va="top", fontsize=8)
    F.legend_if_any(ax, fontsize=7, loc="upper left", bbox_to_anchor=(0.0, 0.93))
    fig.tight_layout()
    F.save(fig, os.path.join(REPO, "docs", "luding_loop"), run=out)

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    mr = reduced_mass()
    vv = np.logspace(-2, 2, 600)
    for k, kc in enumerate(IMPACT_KC):
        Lk = law(kc, IMPACT_PHI)
        ax.plot(vv, [Lk.restitution(mr, v) for v in vv], "-", color=f"C{k}", lw=1.2,
                label=rf"closed form, $k_c/k_1 = {kc / K1:g}$")
        pts = [(r[1], r[2]) for r in impact_rows if r[0] == kc]
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o", mfc="none", color=f"C{k}", ms=5)
    ax.plot([], [], "o", mfc="none", color="k", label="our engine (e = 0: the pair sticks)")
    yade = read_csv(os.path.join(out, "yade_impacts.csv"))
    if yade is not None:
        ax.plot(yade[:, 1], yade[:, 2], "+", color="k", ms=4, mew=0.6, label="YADE LudingMat")
    vstar = math.sqrt(K1 / mr) * law(0, IMPACT_PHI).delta_star
    ax.axvline(vstar, color="0.5", ls="--", lw=0.8)
    ax.text(vstar * 1.05, 0.03, r"$\delta_\mathrm{max}=\delta^*$", fontsize=8, color="0.4")
    ax.set_xscale("log")
    ax.set_xlabel("impact speed v [m/s]")
    ax.set_ylabel("restitution coefficient e")
    ax.set_ylim(-0.03, 1.03)
    ax.set_title(rf"head-on impacts, $r$ = 0.5 mm, $k_p = 5k_1$, $\phi_f = {IMPACT_PHI}$, no dashpot", fontsize=9)
    F.legend_if_any(ax, fontsize=7, loc="lower left")
    fig.tight_layout()
    F.save(fig, os.path.join(REPO, "docs", "luding_restitution"), run=out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--out", default=os.path.join(REPO, "data", "yade_luding"))
    ap.add_argument("--figures", action="store_true")
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    sc = scene(LOOP_KC, LOOP_PHI)
    tmp = os.path.join(a.out, "scene.toml.tmp")
    with open(tmp, "w") as fh:
        fh.write(sc.toml)
    os.replace(tmp, os.path.join(a.out, "scene.toml"))
    loop = run_loop(sc, LOOP_STOPS, LOOP_STEPS_PER_DSTAR)
    write_csv(os.path.join(a.out, "ours_loop.csv"), ["step", "delta_m", "fn_N"], loop)
    impacts = []
    for kc in IMPACT_KC:
        s = scene(kc, IMPACT_PHI)
        for v in IMPACT_V:
            impacts.append((kc, v, run_impact(s, v)))
    write_csv(os.path.join(a.out, "ours_impacts.csv"), ["kc_N_m", "v_m_s", "restitution"], impacts)
    print(f"dt loop {sc.dt:.6g} s, dt impacts {scene(0, IMPACT_PHI).dt:.6g} s")
    if a.figures:
        figures(a.out, loop, impacts)
    return 0


if __name__ == "__main__":
    sys.exit(main())
