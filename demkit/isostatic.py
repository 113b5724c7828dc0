"""Is a jammed packing isostatic? Coordination of relaxed (static) packings near jamming, read from
checkpoints with demtk, rattlers removed by a rule that fits the contact law, and extrapolated to
zero pressure.

    PYTHONPATH=build/python /usr/bin/python3 -m demkit.isostatic --out data/isostatic runs/iso/s1 runs/iso/s2 ...

Each RUN is a `dem run` folder of a scene whose preparation stops the unloading near jamming and
relaxes at constant volume there (`data/scenes/isostatic_probe.toml`): every
`prep/after_relax_*.ckpt` is a static packing (E_kin < 1e-10 E_pot). For each: p*, C over all
particles, and C_nr over the non-rattlers, counting only contacts that carry force (f_n > 0).
Rattlers are removed recursively: fewer than d + 1 = 4 such contacts without friction (a sphere
needs four non-coplanar normal forces for force balance), fewer than 2 with friction (two
contacts can balance force and torque when the chord between them lies in both friction cones;
one never can). Isostaticity: C_nr -> 2d = 6 (frictionless) and towards d + 1 = 4 as mu grows,
as p -> 0. C*_nr is the intercept of C_nr = C* + a sqrt(p*) fitted over the packings with
p* < P_MAX, with its standard error from the fit and, over runs, the spread between packings.
"""
import argparse
import glob
import json
import math
import os
import sys

import numpy as np

P_MAX = 0.01
P_MIN = 1e-7   # below: unjammed (the gas's kinetic pressure)


def rattler_mask(n, i, j, min_contacts):
    """True for rattlers: particles with fewer than min_contacts contacts, removed recursively
    (removing one lowers its neighbours' counts)."""
    alive = np.ones(n, bool)
    while True:
        keep = alive[i] & alive[j]
        z = np.bincount(i[keep], minlength=n) + np.bincount(j[keep], minlength=n)
        drop = alive & (z < min_contacts)
        if not drop.any():
            return ~alive
        alive &= ~drop


def coordination(n, i, j, min_contacts):
    """(C over all particles, C over non-rattlers, rattler fraction) of contacts (i, j)."""
    ratt = rattler_mask(n, i, j, min_contacts)
    keep = ~ratt[i] & ~ratt[j]
    n_nr = n - ratt.sum()
    return 2.0 * len(i) / n, (2.0 * keep.sum() / n_nr if n_nr else 0.0), ratt.mean()


def measure_checkpoint(path):
    import demtk
    ck = demtk.read_checkpoint(path)
    scene = demtk.load_scene(demtk.Scene.from_toml(ck.scene_toml))
    eng = demtk.Engine(scene, ck.state)
    c = eng.contacts()
    m = eng.measure()
    carry = c["force_normal"] > 0
    i, j = c["row_i"][carry], c["row_j"][carry]
    n = ck.state.count
    mu = float(scene.to_dict().get("contact", {}).get("friction", 0.0))
    rule = 2 if mu > 0 else 4
    C, C_nr, ratt = coordination(n, i, j, rule)
    C4 = coordination(n, i, j, 4)[1]
    return {"checkpoint": path, "mu": mu, "nu": m["nu"], "p_star": m["p_star"], "C": C, "C_nr": C_nr,
            "rattler_fraction": ratt, "rule_min_contacts": rule, "C_nr_rule4": C4,
            "E_kin_over_E_pot": m["E_kin_J"] / m["E_pot_J"] if m["E_pot_J"] > 0 else math.inf}


def extrapolate(points, key="C_nr"):
    """(C*, se) of C = C* + a sqrt(p*) over the points with P_MIN < p* < P_MAX."""
    pts = [p for p in points if P_MIN < p["p_star"] < P_MAX and p[key] > 0]
    if len(pts) < 3:
        return math.nan, math.nan
    x = np.sqrt([p["p_star"] for p in pts])
    y = np.array([p[key] for p in pts])
    A = np.vstack([np.ones_like(x), x]).T
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = len(y) - 2
    s2 = float(np.sum((y - A @ coef) ** 2)) / dof if dof > 0 else math.nan
    cov = s2 * np.linalg.inv(A.T @ A)
    return float(coef[0]), float(math.sqrt(cov[0, 0]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="dem run folders with prep/after_relax_*.ckpt")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    per_run = {}
    for run in a.runs:
        cks = sorted(glob.glob(os.path.join(run, "prep", "after_relax_*.ckpt")))
        if not cks:
            sys.exit(f"isostatic: {run} has no prep/after_relax_*.ckpt: run a scene like data/scenes/isostatic_probe.toml")
        per_run[run] = [measure_checkpoint(c) for c in cks]
    os.makedirs(a.out, exist_ok=True)
    summary = []
    for run, pts in per_run.items():
        c_nr, se_nr = extrapolate(pts)
        c_all, se_all = extrapolate(pts, "C")
        summary.append({"run": run, "mu": pts[0]["mu"], "C_star_nr": c_nr, "se_C_star_nr": se_nr,
                        "C_star": c_all, "se_C_star": se_all, "points": pts})
    pooled = {}
    for mu in sorted({s["mu"] for s in summary}):
        stars = np.array([s["C_star_nr"] for s in summary if s["mu"] == mu and math.isfinite(s["C_star_nr"])])
        pooled[f"{mu:g}"] = {"mean": float(stars.mean()) if len(stars) else math.nan,
                             "se_between_packings": float(stars.std(ddof=1) / math.sqrt(len(stars)))
                             if len(stars) > 1 else math.nan, "packings": int(len(stars))}
    tmp = os.path.join(a.out, "isostatic.json.part")
    with open(tmp, "w") as fh:
        json.dump({"runs": summary, "C_star_nr": pooled, "p_star_max": P_MAX},
                  fh, indent=1, default=lambda v: None)
    os.replace(tmp, os.path.join(a.out, "isostatic.json"))
    lines = ["| run | mu | nu | p* | C | C_nr | rattlers | E_kin/E_pot |", "|---|---|---|---|---|---|---|---|"]
    for s in summary:
        for p in s["points"]:
            lines.append(f"| {os.path.basename(s['run'])} | {p['mu']:g} | {p['nu']:.4f} | {p['p_star']:.2e} | {p['C']:.3f} | "
                         f"{p['C_nr']:.3f} | {p['rattler_fraction']:.3f} | {p['E_kin_over_E_pot']:.1e} |")
    lines += ["", "| run | mu | C*_nr (p -> 0) | C* (all particles) |", "|---|---|---|---|"]
    for s in summary:
        lines.append(f"| {os.path.basename(s['run'])} | {s['mu']:g} | {s['C_star_nr']:.3f} ± {s['se_C_star_nr']:.3f} | "
                     f"{s['C_star']:.3f} ± {s['se_C_star']:.3f} |")
    lines += ["", "| mu | packings | C*_nr (mean ± SE between packings) | isostatic limit |", "|---|---|---|---|"]
    for mu, v in pooled.items():
        lines.append(f"| {mu} | {v['packings']} | {v['mean']:.3f} ± {v['se_between_packings']:.3f} | "
                     f"{'6 (2d)' if float(mu) == 0 else 'between 6 and 4 (d + 1, mu -> inf)'} |")
    tmp = os.path.join(a.out, "isostatic.md.part")
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    os.replace(tmp, os.path.join(a.out, "isostatic.md"))
    print("\n".join(lines[-2 - len(pooled):]), file=sys.stderr)


if __name__ == "__main__":
    main()
