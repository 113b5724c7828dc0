"""Plots of a run folder: `dem plot RUN_DIR [--fits]` (or python3 -m demkit.plots).

Writes RUN_DIR/plots/*.png and *.svg:
  deviatoric_<quantity>.png   s_dev, F_dev, p_star, C against eps_d, one line per (mode, nu)
  isotropic.png               p_star and C against nu on the loading/unloading cycle
  path_<name>_<nu>.png        loading paths ([paths]): s_dev with the signed stress ratio, F_dev,
                              eps_v (dilatancy) and the servo error against the accumulated eps_d
  fit_<mode>_<nu>.png         (--fits) curves with their fitted law and residuals
  fit_parameters.png          (--fits) x_max and beta against nu with error bars
"""
import argparse
import glob
import math
import json
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from demkit.curves import read_curve, CurveError  # noqa: E402

NAME_RE = re.compile(r"([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv$")
LABELS = {"s_dev": r"$s_\mathrm{dev} = \sigma_\mathrm{dev}/p$", "F_dev": r"$F_\mathrm{dev}$",
          "p_star": r"$p^* = 2\langle r\rangle p/k$", "C": "coordination number C"}


def deviatoric_curves(run):
    out = []
    for f in sorted(glob.glob(os.path.join(run, "deviatoric", "*.csv"))):
        m = NAME_RE.search(os.path.basename(f))
        if m:
            out.append((m.group(1), float(m.group(2)), read_curve(f)))
    return out


def save(fig, stem):
    fig.savefig(stem + ".png", dpi=120)
    fig.savefig(stem + ".svg")
    plt.close(fig)


def is_path(c):
    return "control_error_rel" in c


def plot_path(mode, nu, c, outdir):
    """One loading path: s_dev (and the signed ratio (sigma_xx - sigma_zz)/p), F_dev, eps_v and
    the servo's relative error against the eps_d accumulated along the path, stages shaded."""
    x = c["eps_d_accumulated"]
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.8))
    stages = list(c["stage"]) if "stage" in c else []
    bounds = [i for i in range(1, len(stages)) if stages[i] != stages[i - 1]]
    axes[0].plot(x, c["s_dev"], "-", label=LABELS["s_dev"])
    axes[0].plot(x, (c["sigma_xx_Pa"] - c["sigma_zz_Pa"]) / c["p_Pa"], "--", label=r"$(\sigma_{xx}-\sigma_{zz})/p$")
    axes[0].axhline(0, color="0.6", lw=0.8)
    axes[1].plot(x, c["F_dev"], "-")
    axes[2].plot(x, c["eps_v"], "-")
    err = np.nan_to_num(c["control_error_rel"])
    if np.any(err > 0):
        axes[3].semilogy(x, np.maximum(err, 1e-6), "-")
    else:
        axes[3].text(0.5, 0.5, "strain controlled:\nno servo", ha="center", va="center", transform=axes[3].transAxes)
    for ax, lab in zip(axes, [None, LABELS["F_dev"], r"volumetric strain $\varepsilon_v$ (dilatancy: > 0)",
                              "servo error |target - measured| / target"]):
        for b in bounds:
            ax.axvline(x[b], color="0.7", lw=0.8, ls=":")
        ax.set_xlabel(r"accumulated $\varepsilon_d$")
        if lab:
            ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"path {mode} from ν = {nu:.3f}" + (f" (stages: {', '.join(dict.fromkeys(stages))})" if stages else ""),
                 fontsize=9)
    fig.tight_layout()
    stem = os.path.join(outdir, f"path_{mode}_phi{nu:.3f}")
    save(fig, stem)
    return stem + ".png"


def plot_deviatoric(run, outdir):
    curves = deviatoric_curves(run)
    written = [plot_path(mode, nu, c, outdir) for mode, nu, c in curves if is_path(c)]
    curves = [cv for cv in curves if not is_path(cv[2])]
    if not curves:
        return written
    if not curves:
        return []
    nus = sorted({c[1] for c in curves})
    cmap = plt.get_cmap("viridis")
    for q in ("s_dev", "F_dev", "p_star", "C"):
        fig, ax = plt.subplots(figsize=(6, 4.2))
        for mode, nu, c in curves:
            color = cmap(nus.index(nu) / max(1, len(nus) - 1))
            ax.plot(c["eps_d"], c[q], ("-" if mode == "D2" else "--"), color=color, lw=1.3,
                    label=f"{mode} ν={nu:.3f}")
        ax.set_xlabel(r"deviatoric strain $\varepsilon_d$")
        ax.set_ylabel(LABELS[q])
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        stem = os.path.join(outdir, f"deviatoric_{q}")
        save(fig, stem)
        written.append(stem + ".png")
    return written


def prep_stages(run):
    """The preparation stages of a run folder in the order they ran (manifest.json), else by name."""
    try:
        with open(os.path.join(run, "manifest.json")) as f:
            outputs = json.load(f)["outputs"]
        names = [os.path.splitext(os.path.basename(o["file"]))[0] for o in outputs if o["file"].startswith("prep")]
    except (OSError, ValueError, KeyError):
        names = sorted(os.path.splitext(f)[0] for f in os.listdir(os.path.join(run, "prep")))
    return [n for n in names if os.path.exists(os.path.join(run, "prep", n + ".csv"))]


def plot_isotropic(run, outdir):
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    any_data = False
    for name in prep_stages(run):
        c = read_curve(os.path.join(run, "prep", name + ".csv"))
        # Loading and unloading stages; not relaxations (constant nu) nor the compression of the
        # random placement (a gas below nu = 0.5).
        if len(c["nu"]) < 2 or c["nu"][0] < 0.5 or np.ptp(c["nu"]) < 1e-6:
            continue
        style = "-" if c["nu"][-1] > c["nu"][0] else "--"
        any_data = True
        axes[0].semilogy(c["nu"], np.maximum(c["p_star"], 1e-9), style, label=name)
        axes[1].plot(c["nu"], c["C"], style, label=name + " C")
        axes[1].plot(c["nu"], c["C_nonrattler"], style, alpha=0.6, label=name + " C*")
    if not any_data:
        plt.close(fig)
        return []
    axes[0].set_xlabel("volume fraction ν"); axes[0].set_ylabel(LABELS["p_star"])
    axes[1].set_xlabel("volume fraction ν"); axes[1].set_ylabel("coordination number")
    for a in axes:
        a.grid(alpha=0.3); a.legend(fontsize=8)
    fig.tight_layout()
    stem = os.path.join(outdir, "isotropic")
    save(fig, stem)
    return [stem + ".png"]


def law(x0, xm, beta, e):
    return xm - (xm - x0) * np.exp(-beta * e)


def plot_fits(run, outdir):
    table = os.path.join(run, "fit", "parameters.csv")
    if not os.path.exists(table):
        return []
    import csv
    with open(table, newline="") as fh:
        rows = list(csv.DictReader(fh))
    curves = {(m, round(nu, 4)): c for m, nu, c in deviatoric_curves(run)}
    written = []
    for (mode, nu), c in sorted(curves.items()):
        fig, axes = plt.subplots(2, 2, figsize=(9, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        for k, q in enumerate(("s_dev", "F_dev")):
            r = [r for r in rows if r["mode"] == mode and abs(float(r["nu"]) - nu) < 1e-6 and r["quantity"] == q]
            e, y = c["eps_d"], c[q]
            axes[0, k].plot(e, y, ".", ms=3, color="0.4", label="DEM")
            if r and r[0]["x0"] != "nan":
                p = [float(r[0][n]) for n in ("x0", "x_max", "beta")]
                axes[0, k].plot(e, law(*p, e), "r-", label=f"fit: $x_0$={p[0]:.3g}, $x_{{max}}$={p[1]:.3g}, β={p[2]:.3g}")
                axes[1, k].plot(e, y - law(*p, e), ".", ms=3)
            axes[0, k].set_ylabel(LABELS[q]); axes[0, k].legend(fontsize=7); axes[0, k].grid(alpha=0.3)
            axes[1, k].axhline(0, color="k", lw=0.5); axes[1, k].set_ylabel("residual")
            axes[1, k].set_xlabel(r"$\varepsilon_d$")
        fig.suptitle(f"{mode}, ν = {nu:.3f}")
        fig.tight_layout()
        stem = os.path.join(outdir, f"fit_{mode}_phi{nu:.3f}")
        save(fig, stem)
        written.append(stem + ".png")
    # parameters against nu
    fig, axes = plt.subplots(2, 2, figsize=(9, 6))
    for k, q in enumerate(("s_dev", "F_dev")):
        for j, (par, se) in enumerate((("x_max", "se_x_max"), ("beta", "se_beta"))):
            ax = axes[j, k]
            for mode, marker in (("D2", "o"), ("D3", "s")):
                sel = [r for r in rows if r["mode"] == mode and r["quantity"] == q and r[par] != "nan"]
                if not sel:
                    continue
                nu = [float(r["nu"]) for r in sel]
                v = [float(r[par]) for r in sel]
                err = [float(r[se]) if r[se] != "nan" else 0.0 for r in sel]
                ax.errorbar(nu, v, yerr=err, fmt=marker, capsize=3, label=mode)
            ax.set_xlabel("ν"); ax.set_ylabel(f"{par} of {q}"); ax.grid(alpha=0.3); ax.legend(fontsize=8)
    fig.tight_layout()
    stem = os.path.join(outdir, "fit_parameters")
    save(fig, stem)
    written.append(stem + ".png")
    return written


def main(argv=None):
    ap = argparse.ArgumentParser(prog="dem plot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir")
    ap.add_argument("--fits", action="store_true", help="also plot the fits of RUN_DIR/fit")
    a = ap.parse_args(argv)
    if not os.path.isdir(a.run_dir):
        print(f"dem plot: {a.run_dir} is not a folder", file=sys.stderr)
        return 1
    outdir = os.path.join(a.run_dir, "plots")
    os.makedirs(outdir, exist_ok=True)
    try:
        written = plot_deviatoric(a.run_dir, outdir) + plot_isotropic(a.run_dir, outdir)
        if a.fits:
            written += plot_fits(a.run_dir, outdir)
    except CurveError as e:
        print(f"dem plot: {e}", file=sys.stderr)
        return 1
    print(f"dem plot: {len(written)} figures in {outdir}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
