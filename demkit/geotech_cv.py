"""Constant-volume D2 and D3 at the friction study's pressure, with the intermediate stress (issue 31,
thirteenth round; docs/geotech.md, "The constant-volume tests' Lode parameter and critical state").

The friction study's constant-volume D2/D3 (data/friction_n1000) end at eps_d = 0.3 on the laboratory
critical-state line in volume and pressure, but their stress ratios are not the drained tests'; their
curves carry no intermediate stress. These runs settle why: D2 and D3 at constant volume from the loose
p* = 5e-2 preparations of data/geotech (nu = 0.69, the friction study's densest state; at mu = 0 the
frictionless one, nu = 0.75), to eps_d = 1.0, with the full stress tensor.

    /usr/bin/python3 -m demkit.geotech_cv run --out runs/cv --preps runs/geotech_vhi [--mu 0.1 0.3 0.5 1]
        one `dem mode` per (mu, packing, mode) from the iso_vhi checkpoints under PREPS (`demkit.geotech run
        --levels iso_vhi` makes them; those missing are prepared the same way first), in demkit.geotech's layout
        ROOT/mu_MU/PREP/iso_vhi/CV_D2/mSEED.csv;
    /usr/bin/python3 -m demkit.geotech_cv analyse runs/cv --out data/geotech/constant_volume [--store]
        the stress ratio q/p, the Lode parameter b and p* over three strain windows (the friction study's
        0.25-0.30, 0.55-0.60, 0.90-1.00) with 95 % intervals over packings, demkit.geotech's critical-state
        flags over the last 0.2, and the drained constant-p tests at the same pressure (data/geotech's
        summary.csv) read at the measured b, beside the b that a Matsuoka-Nakai or Lade-Duncan surface
        through the drained TC_p gives for a plane-strain flow normal to it in the deviatoric plane.
"""

import argparse
import glob
import math
import os
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import optimize

from demkit import geotech as gt
from demkit.atomic import write_atomic, write_figure
from demkit.curves import read_curve

MODES = ("D2", "D3")
EPS_END = 1.0
WINDOWS = ((0.25, 0.30), (0.55, 0.60), (0.90, 1.00))
LEVEL = gt.HIGH_LEVEL
DRAINED = ("TC_p", "TT_b025", "TT_b050", "TT_b075", "TE_p")   # the constant-p family, b = 0 ... 1


def prep_of(mu):
    """The preparation the runs start from: the loose one (own mu), at mu = 0 the only one (demkit.geotech)."""
    return "dense" if float(mu) == 0 else "loose"


def run_one(args, mu, seed, mode):
    prep = prep_of(mu)
    d = gt.prep_dir(args.preps, prep, mu, seed, LEVEL)
    ckpt = sorted(glob.glob(os.path.join(d, "checkpoints", f"{LEVEL}_phi*.ckpt")))
    if len(ckpt) != 1:
        return f"no single {LEVEL} checkpoint for {prep} mu={mu} m{seed} under {args.preps} (its preparation " \
               f"failed: {d}.log)"
    out = os.path.join(args.out, f"mu_{mu}", prep, LEVEL, f"CV_{mode}", f"m{seed}.csv")
    if os.path.exists(out):
        return "ok (kept)"
    os.makedirs(os.path.dirname(out), exist_ok=True)
    path = f'[{{ rate = "{mode}", until = {{ eps_d = {EPS_END} }} }}]'
    rc = gt.run_cmd([args.dem, "mode", "--scene", args.scene, "--packing", ckpt[0], "--mode", f"CV_{mode}",
                     "--out", out, "--set", f"paths.CV_{mode}={path}", "--set", f"contact.friction={mu}",
                     "--threads", "1", "--quiet"], out[:-4] + ".log")
    return "ok" if rc == 0 else f"failed ({rc})"


def run(args):
    seeds = range(args.first_seed, args.first_seed + args.packings)
    preps = [(prep_of(mu), mu, s) for mu in args.mu for s in seeds]
    jobs = [(mu, s, m) for mu in args.mu for s in seeds for m in MODES]
    with ThreadPoolExecutor(args.jobs) as pool:
        # the iso_vhi preparations first, where missing (demkit.geotech's, so that `demkit.geotech run --levels
        # iso_vhi` and these runs share them)
        for (p, mu, s), rc in zip(preps, pool.map(lambda a: gt.prepare(args.dem, args.scene, args.preps, *a, own=LEVEL),
                                                  preps)):
            if rc:
                print(f"preparation {p} mu={mu} m{s} {LEVEL} failed ({rc})", file=sys.stderr)
        failed = 0
        for job, msg in zip(jobs, pool.map(lambda a: run_one(args, *a), jobs)):
            print(f"mu={job[0]} m{job[1]} CV_{job[2]}: {msg}", flush=True)
            failed += not msg.startswith("ok")
    if failed:
        print(f"demkit.geotech_cv: {failed} of {len(jobs)} runs failed (their .log beside the curve, or the "
              f"preparation's under {args.preps})", file=sys.stderr)
    return 1 if failed else 0


FABRIC = ("F_xx", "F_yy", "F_zz", "F_xy", "F_xz", "F_yz")


def fabric_b(c, k):
    """The Lode parameter (F_2 - F_3)/(F_1 - F_3) of the fabric tensor averaged over rows k (NaN without it)."""
    if not all(n in c for n in FABRIC):
        return math.nan
    t = np.zeros((3, 3))
    for (i, j), n in zip(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)), FABRIC):
        t[i, j] = t[j, i] = np.mean(c[n][k])
    f = np.sort(np.linalg.eigvalsh(t))[::-1]
    return float((f[1] - f[2]) / (f[0] - f[2]))


def window_values(c):
    """q/p, b, p* and the fabric's b of one curve, each averaged over every WINDOWS row range (NaN where it is not
    reached)."""
    x = c["eps_d"]
    s = gt.principal_stresses(c)
    series = {"q_over_p": c["sigma_dev_Pa"] / c["p_Pa"], "b": gt.b_value(s[:, 0], s[:, 1], s[:, 2]),
              "p_star": c["p_star"]}
    out = {}
    for lo, hi in WINDOWS:
        k = (x >= lo - 1e-9) & (x <= hi + 1e-9)
        for name, y in series.items():
            out[(name, lo)] = float(np.mean(y[k])) if k.any() else math.nan
        out[("b_F", lo)] = fabric_b(c, k) if k.any() else math.nan
    return out


def plane_strain_b(name, sin_phi_tc):
    """The b at which the deviatoric normal of the surface `name` (MN or LD) through triaxial compression at
    Mohr-Coulomb friction sin_phi_tc has no intermediate component: plane strain under a flow normal to the
    surface in the deviatoric plane (SANISAND's direction n). The Python twin of the model's
    plane_strain_lode_b (fit/include/demfit/model.hpp), written independently for the DEM tables."""
    const = gt.constant_from_sin_phi(name, sin_phi_tc)

    def intermediate(b):
        sp = gt.predicted_sin_phi(name, const, b)
        sig = np.array(gt.principal_from_ratio((1 + sp) / (1 - sp), b), float)
        g = np.array([(gt.criterion(name, *(sig + h)) - gt.criterion(name, *(sig - h))) / 2e-7
                      for h in np.eye(3) * 1e-7])
        return g[1] - g.mean()
    return float(optimize.brentq(intermediate, 1e-3, 1 - 1e-3, xtol=1e-10))


def q_over_p(sin_phi, b):
    """q/p of principal stresses at Mohr-Coulomb friction sin_phi and intermediate ratio b."""
    s1, s2, s3 = gt.principal_from_ratio((1 + sin_phi) / (1 - sin_phi), b)
    q = math.sqrt(((s1 - s2) ** 2 + (s2 - s3) ** 2 + (s3 - s1) ** 2) / 2)
    return q / ((s1 + s2 + s3) / 3)


def drained_family(summary_csv, mu):
    """The iso_vhi constant-p tests (prep_of(mu)) of data/geotech's summary.csv at mu: (target b, q/p_cs, its
    interval) sorted by b. The target, not the measured b_cs: the servo holds b within 0.01-0.04 of it (TC_p's
    0.02-0.04 is the noise of a ratio of small stress differences), and a CV D3 at b = 0.03 is then still read."""
    rows = [r for r in _summary_rows(summary_csv, mu) if r["test"] in DRAINED]
    return sorted((gt.test_b(r["test"]), float(r["q_over_p_cs"]), float(r["q_over_p_cs_ci95"])) for r in rows)


def drained_at(family, b):
    """q/p_cs and its interval of the drained family, linear in the measured b between its neighbours."""
    bs = [f[0] for f in family]
    if not family or not bs[0] <= b <= bs[-1]:
        return math.nan, math.nan
    return float(np.interp(b, bs, [f[1] for f in family])), float(np.interp(b, bs, [f[2] for f in family]))


def table_rows(results, summary_csv):
    rows = []
    for (mu, _, _, test), res in sorted(results.items()):
        members, summ = res["members"], res["summary"]
        fam = drained_family(summary_csv, mu)
        tc = {r["test"]: r for r in _summary_rows(summary_csv, mu)}.get("TC_p")
        row = {"mu": mu, "test": test, "K": summ["K"], "critical_state": summ["critical_state"],
               "volume_stationary": summ["volume_stationary"], "stress_stationary": summ["stress_stationary"]}
        for lo, hi in WINDOWS:
            for name in ("q_over_p", "b", "p_star", "b_F"):
                m, h, _ = gt.mean_ci([v["windows"][(name, lo)] for v in members])
                row[f"{name}_{lo:.2f}_{hi:.2f}"], row[f"{name}_{lo:.2f}_{hi:.2f}_ci95"] = m, h
        # the fall from the friction study's window to the end, packing by packing (paired)
        m, h, _ = gt.mean_ci([v["windows"][("q_over_p", WINDOWS[0][0])] - v["windows"][("q_over_p", WINDOWS[-1][0])]
                              for v in members])
        row["q_over_p_fall"], row["q_over_p_fall_ci95"] = m, h
        b_end = row[f"b_{WINDOWS[-1][0]:.2f}_{WINDOWS[-1][1]:.2f}"]
        row["drained_q_over_p_at_b"], row["drained_q_over_p_at_b_ci95"] = drained_at(fam, b_end)
        for name in ("MN", "LD"):
            row[f"b_plane_strain_{name}"] = plane_strain_b(name, math.sin(math.radians(float(tc["phi_cs_deg"])))) \
                if tc and test == "CV_D2" else math.nan
        rows.append(row)
    return rows


def _summary_rows(summary_csv, mu):
    import csv
    with open(summary_csv) as fh:
        return [r for r in csv.DictReader(fh) if r["mu"] == mu and r["prep"] == prep_of(mu) and r["level"] == LEVEL]


def analyse(root, out, summary_csv, plots=True):
    groups = gt.collect(root)
    if not groups:
        raise SystemExit(f"demkit.geotech_cv: no curves under {root}/mu_*/PREP/{LEVEL}/CV_*/m*.csv (run first)")
    results = gt.analyse_groups(groups)
    for res in results.values():
        for v in res["members"]:
            v["windows"] = window_values(read_curve(v["path"]))
    os.makedirs(out, exist_ok=True)
    rows = table_rows(results, summary_csv)
    gt.write_dict_rows(os.path.join(out, "constant_volume.csv"), rows)
    write_atomic(os.path.join(out, "constant_volume.md"), report(rows))
    if plots:
        plot(results, out)
    return rows


def report(rows):
    w0, w1 = WINDOWS[0], WINDOWS[-1]
    k0, k1 = f"{w0[0]:.2f}_{w0[1]:.2f}", f"{w1[0]:.2f}_{w1[1]:.2f}"
    lines = ["<!-- demkit.geotech_cv analyse: constant-volume D2/D3 from the p* = 5e-2 preparations (loose; mu = 0 the frictionless one); means over "
             "packings with 95 % Student-t intervals; fall: q/p at the first window minus the last, per packing; drained: "
             "data/geotech's constant-p tests at the same level and preparation, linear in their target b, read at the "
             "measured b; b_ps: the plane-strain b of a surface through TC_p's phi_cs with the flow normal to it in the "
             "deviatoric plane; b_F: the fabric tensor's Lode parameter -->",
             f"| mu | test | K | q/p at eps_d {w0[0]}-{w0[1]} | q/p at {w1[0]}-{w1[1]} | fall | drained q/p_cs at that b | "
             f"b at {w0[0]}-{w0[1]} | b at {w1[0]}-{w1[1]} | b_ps MN | b_ps LD | b_F at {w1[0]}-{w1[1]} | "
             f"p* at {w1[0]}-{w1[1]} | critical state |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mu']} | {r['test']} | {r['K']} | {gt.pm(r['q_over_p_' + k0], r['q_over_p_' + k0 + '_ci95'], 3)} | "
                     f"{gt.pm(r['q_over_p_' + k1], r['q_over_p_' + k1 + '_ci95'], 3)} | "
                     f"{gt.pm(r['q_over_p_fall'], r['q_over_p_fall_ci95'], 3)} | "
                     f"{gt.pm(r['drained_q_over_p_at_b'], r['drained_q_over_p_at_b_ci95'], 3)} | "
                     f"{gt.pm(r['b_' + k0], r['b_' + k0 + '_ci95'], 3)} | {gt.pm(r['b_' + k1], r['b_' + k1 + '_ci95'], 3)} | "
                     f"{_num(r['b_plane_strain_MN'])} | {_num(r['b_plane_strain_LD'])} | "
                     f"{gt.pm(r['b_F_' + k1], r['b_F_' + k1 + '_ci95'], 3)} | "
                     f"{gt.pm(r['p_star_' + k1], r['p_star_' + k1 + '_ci95'], 4)} | {r['critical_state']} |")
    return "\n".join(lines) + "\n"


def _num(v):
    return f"{v:.3f}" if math.isfinite(v) else "not determined"


def plot(results, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    mus = sorted({k[0] for k in results}, key=float)
    fig, axes = plt.subplots(2, len(mus), figsize=(3.2 * len(mus), 5.6), sharex=True, squeeze=False)
    for j, mu in enumerate(mus):
        for (m, _, _, test), res in sorted(results.items()):
            if m != mu:
                continue
            curves = [read_curve(v["path"]) for v in res["members"]]
            x = np.linspace(0, EPS_END, 201)
            s = [gt.principal_stresses(c) for c in curves]
            q = np.array([np.interp(x, c["eps_d"], c["sigma_dev_Pa"] / c["p_Pa"]) for c in curves])
            b = np.array([np.interp(x, c["eps_d"], gt.b_value(si[:, 0], si[:, 1], si[:, 2])) for c, si in zip(curves, s)])
            for ax, y in ((axes[0, j], q), (axes[1, j], b)):
                mean, half = y.mean(0), gt.stats.t.ppf(0.975, len(y) - 1) * y.std(0, ddof=1) / math.sqrt(len(y))
                ax.plot(x, mean, label=test)
                ax.fill_between(x, mean - half, mean + half, alpha=0.3)
        axes[0, j].set_title(f"mu = {mu}")
        axes[1, j].set_xlabel("eps_d [-]")
    axes[0, 0].set_ylabel("q/p [-]")
    axes[1, 0].set_ylabel("b = (s2 - s3)/(s1 - s3) [-]")
    axes[0, 0].legend()
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "constant_volume"), exts=("png",))


def store(root, out):
    for key, paths in gt.collect(root).items():
        for p in paths:
            gt.trim_curve(p, os.path.join(out, "curves", f"mu_{key[0]}", *key[1:], os.path.basename(p)),
                          gt.TRIM + FABRIC)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="demkit.geotech_cv", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="constant-volume D2/D3 from the iso_vhi preparations")
    r.add_argument("--out", required=True)
    r.add_argument("--preps", required=True, help="a demkit.geotech run folder with (or for) the iso_vhi preparations")
    r.add_argument("--scene", default="data/scenes/geotech.toml")
    r.add_argument("--dem", default="build/dem")
    r.add_argument("--mu", nargs="+", default=["0", "0.1", "0.3", "0.5", "1"])
    r.add_argument("--packings", type=int, default=8)
    r.add_argument("--first-seed", type=int, default=1)
    r.add_argument("--jobs", type=int, default=2)
    a = sub.add_parser("analyse", help="the tables and the figure")
    a.add_argument("root")
    a.add_argument("--out", required=True)
    a.add_argument("--summary", default="data/geotech/summary.csv", help="data/geotech's drained tests")
    a.add_argument("--store", action="store_true", help="also copy trimmed curves to OUT/curves")
    a.add_argument("--no-plots", action="store_true")
    args = ap.parse_args(argv)
    if args.cmd == "run":
        sys.exit(run(args))
    analyse(args.root, args.out, args.summary, plots=not args.no_plots)
    if args.store:
        store(args.root, args.out)


if __name__ == "__main__":
    main()
