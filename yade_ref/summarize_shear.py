"""Simple-shear cross-check (data/yade_shear/): plateaus and shear-specific differences that
`dem compare` does not check (the shear stress ratio -sigma_xz/p and the non-coaxiality angles
between the major stress / major fabric and the most compressive stretching), for ours (dt,
dt x 1.001, and the dt-perturbed runs in floor/) and YADE; and a plot of them.
Run: /usr/bin/python3 yade_ref/summarize_shear.py [DIR]
"""
import glob
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from demkit.curves import read_curve  # noqa: E402

D = sys.argv[1] if len(sys.argv) > 1 else "data/yade_shear"
CURVES = [("ours dt", "ours_SS_xz_dt0.02.csv"), ("ours dt x 1.001", "ours_SS_xz_dt0.02002.csv"),
          ("YADE", "yade_SS_xz_phi0.740.csv")]
PLATEAU = 0.15           # plateau = mean over rows with eps_d >= 0.15 (as docs/simple_shear.md)


def tau(c):
    return -c["sigma_xz_Pa"] / c["p_Pa"]           # compression positive: sigma_xz < 0 under v_x = 2 r z


curves = [(name, read_curve(os.path.join(D, f))) for name, f in CURVES]
members = [curves[0][1], curves[1][1]] + [read_curve(f) for f in sorted(glob.glob(os.path.join(D, "floor", "*.csv")))]
print(f"plateau (eps_d >= {PLATEAU}) means")
print(f"{'curve':18s} {'p [GPa]':>8s} {'s_dev':>7s} {'F_dev':>7s} {'C':>6s} {'-s_xz/p':>8s} {'ang s-D':>8s} {'ang F-D':>8s}")
for name, c in curves:
    m = c["eps_d"] >= PLATEAU
    print(f"{name:18s} {c['p_Pa'][m].mean() / 1e9:8.4f} {c['s_dev'][m].mean():7.4f} {c['F_dev'][m].mean():7.4f} "
          f"{c['C'][m].mean():6.3f} {tau(c)[m].mean():8.4f} {c['angle_sigma_D_deg'][m].mean():8.2f} "
          f"{c['angle_F_D_deg'][m].mean():8.2f}")


def plateau_row(c):
    m = c["eps_d"] >= PLATEAU
    return [c["p_Pa"][m].mean() / 1e9, c["s_dev"][m].mean(), c["F_dev"][m].mean(), c["C"][m].mean(), tau(c)[m].mean(),
            c["angle_sigma_D_deg"][m].mean(), c["angle_F_D_deg"][m].mean()]


rows = np.array([plateau_row(c) for c in members])
print(f"{'ours, ' + str(len(members)) + ' runs: mean':18s} " + " ".join(f"{v:{w}.{d}f}" for v, (w, d) in
      zip(rows.mean(0), [(8, 4), (7, 4), (7, 4), (6, 3), (8, 4), (8, 2), (8, 2)])))
print(f"{'ours: SD':18s} " + " ".join(f"{v:{w}.{d}f}" for v, (w, d) in
      zip(rows.std(0, ddof=1), [(8, 4), (7, 4), (7, 4), (6, 3), (8, 4), (8, 2), (8, 2)])))
yrow = np.array(plateau_row(curves[2][1]))
print(f"{'YADE - mean, in SD':18s} " + " ".join(f"{v:{w}.2f}" for v, w in
      zip((yrow - rows.mean(0)) / rows.std(0, ddof=1), [8, 7, 7, 6, 8, 8, 8])))

ref = curves[0][1]
grid = np.linspace(0, min(c["eps_d"].max() for _, c in curves), 200)
print("\ndifferences to 'ours dt' on a common eps_d grid (200 points): max |d|, RMS")
for name, c in curves[1:]:
    for q, f in (("-sigma_xz/p", tau), ("angle_sigma_D_deg", lambda x: x["angle_sigma_D_deg"])):
        d = np.interp(grid, c["eps_d"], f(c)) - np.interp(grid, ref["eps_d"], f(ref))
        print(f"  {name:16s} {q:18s} max {np.abs(d).max():.4f}  rms {np.sqrt(np.mean(d * d)):.4f}")

import matplotlib  # noqa: E402
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharex=True)
for c in members[2:]:
    for ax, y in zip(axes, [tau(c), c["angle_sigma_D_deg"], c["angle_F_D_deg"]]):
        ax.plot(c["eps_d"], y, "-", color="0.8", lw=0.6)
for (name, c), style in zip(curves, ["-", ":", "--"]):
    axes[0].plot(c["eps_d"], tau(c), style, label=name)
    axes[1].plot(c["eps_d"], c["angle_sigma_D_deg"], style, label=name)
    axes[2].plot(c["eps_d"], c["angle_F_D_deg"], style, label=name)
for ax, lab in zip(axes, [r"$-\sigma_{xz}/p$", r"angle $\sigma$–D [°]", "angle F–D [°]"]):
    ax.set_ylabel(lab)
    ax.set_xlabel(r"$\varepsilon_d$")
    ax.grid(alpha=0.3)
axes[0].legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(D, "shear_stress_angles.png"), dpi=120)
fig.savefig(os.path.join(D, "shear_stress_angles.svg"))
