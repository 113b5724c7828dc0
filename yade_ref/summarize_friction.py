#!/usr/bin/env python3
"""Tabulates data/yade_friction: YADE against our chaos floor for the frictional packing (D2 at constant
volume, constant side stress), as docs/yade.md's method: the floor is the spread of our own runs with dt
perturbed (ours_*_dt0.04.csv and perturbed_*.csv), `dem compare`'s distances between every ordered pair of
them, and YADE's distance to each of them; plateaus (mean over the second half of the common eps_d range)
of ours' ensemble (mean, SD) against YADE's, and z = (YADE - mean) / SD.

    /usr/bin/python3 yade_ref/summarize_friction.py    -> data/yade_friction/summary.md, overlay_*.png
    /usr/bin/python3 yade_ref/summarize_friction.py --dir data/yade_hm    (Hertz-Mindlin, data/yade_hm/run.sh)
"""
import argparse
import glob
import itertools
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from demkit.atomic import write_atomic  # noqa: E402
from demkit.compare import compare, overlay  # noqa: E402
from demkit.curves import read_curve  # noqa: E402

REF = os.path.join(ROOT, "data", "yade_friction")
INTRO = {
    "yade_friction": ("Frictional cross-check with YADE",
                      "mu = 0.5, k_t = 2/7 k, no dashpots (YADE: FrictMat + Law2_ScGeom_FrictPhys_CundallStrack), "
                      "gamma_b = 0, leapfrog in both codes, dt = t_c/25, rate 1e-4/t_c."),
    "yade_hm": ("Hertz-Mindlin cross-check with YADE",
                "Hertz normal law and the incremental Mindlin tangential law (ours: contact.normal = \"hertz\", "
                "contact.tangential = \"mindlin_force\"; YADE: FrictMat + Ip2_FrictMat_FrictMat_MindlinPhys + "
                "Law2_ScGeom_MindlinPhys_Mindlin), E = 1.82e11 Pa, nu = 0.3, mu = 0.5, no dashpots (e = 1, en = 1), "
                "gamma_b = 0, leapfrog in both codes, dt = T_R/25 (the Rayleigh time of the 0.5 mm sphere), rate 1e-4/T_R."),
}
MEASURES = [("p_Pa", "max_rel", "p, max rel"), ("s_dev", "rms_rel", "s_dev, RMS / plateau"),
            ("F_dev", "rms_rel", "F_dev, RMS / plateau"), ("C", "rms_abs", "C, RMS"), ("eps_v", "rms_abs", "eps_v, RMS"),
            ("sliding_fraction", "rms_abs", "sliding fraction, RMS")]
PLATEAUS = ["p_Pa", "s_dev", "F_dev", "C", "sliding_fraction", "eps_v", "E_rot_J", "omega_mean_rad_s", "E_t_J",
            "W_friction_J", "sigma_antisym_rel", "E_kin_J"]


def distances(a, b):
    res, grid = compare(a, b)
    ya = np.interp(grid, a["eps_d"], a["sliding_fraction"])
    yb = np.interp(grid, b["eps_d"], b["sliding_fraction"])
    res["sliding_fraction"] = {"rms_abs": float(np.sqrt(np.mean((yb - ya) ** 2)))}
    return res


def plateaus(curves, lo, hi):
    """Mean over the second half of [lo, hi] (W_friction, eps_v: the value at hi)."""
    grid = np.linspace(lo, hi, 200)
    out = []
    for c in curves:
        row = {}
        for q in PLATEAUS:
            y = np.interp(grid, c["eps_d"], c[q])
            row[q] = float(y[-1]) if q in ("W_friction_J", "eps_v") else float(np.mean(y[grid >= 0.5 * (lo + hi)]))
        out.append(row)
    return out


def section(mode, label):
    yf = os.path.join(REF, f"yade_{mode}_phi0.700.csv")
    of = os.path.join(REF, f"ours_{mode}_dt0.04.csv")
    pert = sorted(glob.glob(os.path.join(REF, f"perturbed_{mode}_dt*.csv")))
    if not (os.path.exists(yf) and os.path.exists(of)):
        return [f"({label}: not generated)"]
    yade = read_curve(yf)
    ours = [read_curve(f) for f in [of] + pert]
    n = len(ours)
    lines = [f"## {label}", "",
             f"First row (the packing as loaded, at rest): E_pot ours {ours[0]['E_pot_J'][0]:.10g} J, YADE {yade['E_pot_J'][0]:.10g} J; "
             f"p ours {ours[0]['p_Pa'][0]:.10g} Pa, YADE {yade['p_Pa'][0]:.10g} Pa "
             f"(rel {yade['p_Pa'][0] / ours[0]['p_Pa'][0] - 1:.1e}); C {ours[0]['C'][0]:.4g} / {yade['C'][0]:.4g}.", "",
             f"Distances (`dem compare`'s measures): {n} runs of ours (dt = t_c/25 and {n - 1} perturbed by -0.2 ... +0.5 %), "
             f"{n * (n - 1)} ordered pairs; YADE against each of the {n}. Rank: the fraction of ours-ours distances below "
             "YADE's median distance (0.5: YADE is a typical member; 1: beyond every pair of ours).", "",
             "| measure | ours-ours median | 90 % | max | ours-YADE median | max | rank |", "|---|---|---|---|---|---|---|"]
    floor = {q: [] for q, _, _ in MEASURES}
    vs = {q: [] for q, _, _ in MEASURES}
    for i, j in itertools.permutations(range(n), 2):
        r = distances(ours[i], ours[j])
        for q, k, _ in MEASURES:
            floor[q].append(r[q][k])
    for o in ours:
        r = distances(o, yade)
        for q, k, _ in MEASURES:
            vs[q].append(r[q][k])
    for q, k, name in MEASURES:
        f, y = np.array(floor[q]), np.array(vs[q])
        lines.append(f"| {name} | {np.median(f):.3g} | {np.percentile(f, 90):.3g} | {f.max():.3g} | {np.median(y):.3g} | "
                     f"{y.max():.3g} | {(f < np.median(y)).mean():.2f} |")
    lo = max(c["eps_d"].min() for c in ours + [yade])
    hi = min(c["eps_d"].max() for c in ours + [yade])
    po = plateaus(ours, lo, hi)
    py = plateaus([yade], lo, hi)[0]
    lines += ["", f"Plateaus: mean over eps_d in [{0.5 * (lo + hi):.3f}, {hi:.3f}] (eps_v and W_friction: the value at eps_d = {hi:.3f}); "
              f"ours: mean and SD of the {n} runs.", "",
              "| quantity | ours mean | ours SD | YADE | (YADE - mean) / SD |", "|---|---|---|---|---|"]
    for q in PLATEAUS:
        v = np.array([r[q] for r in po])
        m, sd = v.mean(), v.std(ddof=1)
        z = (py[q] - m) / sd if sd > 1e-12 * max(abs(m), 1e-12) and abs(sd) > 1e-15 and np.isfinite(py[q]) else float("nan")
        lines.append(f"| {q} | {m:.5g} | {sd:.2g} | {py[q]:.5g} | {z:+.1f} |")
    overlay(ours[0], yade, ["ours", "YADE"], os.path.join(REF, f"overlay_{mode}.png"))
    return lines + [""]


def main():
    global REF
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dir", default=REF, help="the folder of curves (data/yade_friction or data/yade_hm)")
    REF = os.path.abspath(ap.parse_args().dir)
    name = os.path.basename(REF.rstrip("/"))
    if name not in INTRO:
        sys.exit(f"summarize_friction.py: --dir must be one of data/{', data/'.join(INTRO)} (got {REF})")
    title, physics = INTRO[name]
    cmd = "" if name == "yade_friction" else f" --dir data/{name}"
    lines = [f"# {title}: summary", "",
             f"Generated by `/usr/bin/python3 yade_ref/summarize_friction.py{cmd}` from the curves in this folder "
             "(COMMANDS.txt / run.sh). Packing: `data/yade_friction/packing_phi0.700.txt`, N = 1000, prepared by ours "
             "with friction (mu = 0.5, Cundall-Strack), at rest. " + physics, ""]
    lines += section("D2", "D2 at constant volume, to eps_d = 0.2")
    lines += section("triax", "Constant side stress (sigma_xx = sigma_yy = p0), eps_zz to -0.10")
    write_atomic(os.path.join(REF, "summary.md"), "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
