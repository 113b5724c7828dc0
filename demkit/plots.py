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
import json
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from demkit import rounding  # noqa: E402
from demkit.curves import read_curve, CurveError  # noqa: E402
from demkit.figures import fit_label, legend_if_any, plot_parameters, read_rows, save, usable  # noqa: E402

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


def is_path(c):
    return "control_error_rel" in c


def held_constant(v, scale=1.0):
    """True when v varies by no more than round-off (relative to scale)."""
    v = np.asarray(v, dtype=float)
    return v.size == 0 or not np.all(np.isfinite(v)) or np.ptp(v) <= 1e-9 * max(scale, np.max(np.abs(v)), 1e-300)


def shear_plane(c):
    """('xz', 'zz') for a curve sheared in xz (its largest off-diagonal log strain), None for none."""
    best = None
    for ij, n in (("xy", "yy"), ("xz", "zz"), ("yz", "zz")):
        col = c.get(f"eps_{ij}")
        if col is not None and f"sigma_{ij}_Pa" in c and np.size(col) and np.nanmax(np.abs(col)) > 1e-6:
            if best is None or np.nanmax(np.abs(col)) > np.nanmax(np.abs(c[f"eps_{best[0]}"])):
                best = (ij, n)
    return best


def plot_path(mode, nu, c, outdir, run=None):
    """One loading path, 2 x 2 (one journal column wide at 7 in): s_dev (and the signed ratio
    (sigma_xx - sigma_zz)/p), F_dev, eps_v and the servo's relative error against the eps_d
    accumulated along the path, stages marked. A quantity held constant (eps_v at constant
    volume, the servo error of a strain-controlled path) gets no panel: the title says so."""
    x = c["eps_d_accumulated"]
    stages = list(c["stage"]) if "stage" in c else []
    bounds = [i for i in range(1, len(stages)) if stages[i] != stages[i - 1]]
    err = np.nan_to_num(c["control_error_rel"])
    panels = [("s", None), ("F", LABELS["F_dev"])]
    notes = []
    if held_constant(c["eps_v"], 1.0):
        notes.append(r"$\varepsilon_v$ = 0 (constant volume)")
    else:
        panels.append(("v", r"volumetric strain $\varepsilon_v$ (dilatancy > 0)"))
    if np.any(err > 0):
        panels.append(("e", "servo error |target − measured| / target"))
    else:
        notes.append("strain controlled (no servo)")
    ncols = 2
    nrows = (len(panels) + 1) // 2
    fig, axes = plt.subplots(nrows, ncols, figsize=(7, 2.9 * nrows), squeeze=False, sharex=True)
    for ax, (kind, lab) in zip(axes.flat, panels):
        if kind == "s":
            ax.plot(x, c["s_dev"], "-", lw=1.2, label=r"$s_\mathrm{dev}$")
            shear = shear_plane(c)
            if shear:   # simple shear: the friction-like ratio tau / sigma_n of the sheared plane
                ij, n = shear
                ax.plot(x, c[f"sigma_{ij}_Pa"] / c[f"sigma_{n}_Pa"], "--", lw=1.0,
                        label=rf"$\tau_{{{ij}}}/\sigma_{{{n}}}$")
            else:
                ax.plot(x, (c["sigma_xx_Pa"] - c["sigma_zz_Pa"]) / c["p_Pa"], "--", lw=1.0,
                        label=r"$(\sigma_{xx}-\sigma_{zz})/p$")
            ax.axhline(0, color="0.6", lw=0.8)
            ax.set_ylabel("stress ratio", fontsize=9)
            ax.legend(fontsize=7)
        elif kind == "F":
            ax.plot(x, c["F_dev"], "-", lw=1.2)
        elif kind == "v":
            ax.plot(x, c["eps_v"], "-", lw=1.2)
        else:
            ax.semilogy(x, np.maximum(err, 1e-6), "-", lw=1.0)
        for b in bounds:
            ax.axvline(x[b], color="0.7", lw=0.8, ls=":")
        if lab:
            ax.set_ylabel(lab, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(r"accumulated $\varepsilon_d$")
    if len(panels) % 2:
        axes.flat[len(panels) - 2].set_xlabel(r"accumulated $\varepsilon_d$")
        axes.flat[len(panels) - 2].xaxis.set_tick_params(labelbottom=True)
    title = f"path {mode} from ν = {nu:.3f}"
    if stages:
        title += f"; stages (dotted): {', '.join(dict.fromkeys(stages))}"
    if notes:
        title += "\n" + "; ".join(notes)
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    stem = os.path.join(outdir, f"path_{mode}_phi{nu:.3f}")
    save(fig, stem, run)
    return stem + ".png"


def plot_deviatoric(run, outdir):
    curves = deviatoric_curves(run)
    written = [plot_path(mode, nu, c, outdir, run) for mode, nu, c in curves if is_path(c)]
    curves = [cv for cv in curves if not is_path(cv[2])]
    if not curves:
        return written
    if not curves:
        return []
    nus = sorted({c[1] for c in curves})
    cmap = plt.get_cmap("viridis")
    modes = sorted({c[0] for c in curves})
    for q in ("s_dev", "F_dev", "p_star", "C"):
        # one panel per mode, side by side (D2 | D3), sharing y
        fig, axes = plt.subplots(1, len(modes), figsize=(4.2 * len(modes) + 0.6, 3.8), sharey=True, squeeze=False)
        for ax, mode in zip(axes[0], modes):
            for m, nu, c in curves:
                if m != mode:
                    continue
                color = cmap(0.85 * nus.index(nu) / max(1, len(nus) - 1))
                ax.plot(c["eps_d"], c[q], "-", color=color, lw=1.2, label=f"ν = {nu:.3f}")
            ax.set_title(mode, fontsize=10)
            ax.set_xlabel(r"deviatoric strain $\varepsilon_d$")
            ax.grid(alpha=0.3)
            legend_if_any(ax, fontsize=7)
        axes[0, 0].set_ylabel(LABELS[q])
        fig.tight_layout()
        stem = os.path.join(outdir, f"deviatoric_{q}")
        save(fig, stem, run)
        written.append(stem + ".png")
    return written


def prep_stages(run):
    """The preparation stages of a run folder in the order they ran (manifest.json), else by name."""
    try:
        with open(os.path.join(run, "manifest.json")) as f:
            outputs = json.load(f)["outputs"]
        names = [os.path.splitext(os.path.basename(o["file"]))[0] for o in outputs if o["file"].startswith("prep")]
    except (OSError, ValueError, KeyError):
        prep = os.path.join(run, "prep")
        names = sorted(os.path.splitext(f)[0] for f in os.listdir(prep)) if os.path.isdir(prep) else []
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
    save(fig, stem, run)
    return [stem + ".png"]


def paren(v, se):
    """A value rounded to its standard error, 0.197(2): the rule of every table (demkit.rounding)."""
    return rounding.paren(v, se)


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
                se = [float(r[0]["se_" + n]) for n in ("x0", "x_max", "beta")]
                axes[0, k].plot(e, law(*p, e), "-" if usable(r[0]) else ":", color="r" if usable(r[0]) else "0.5",
                                label=fit_label(r[0], f"fit: $x_0$ = {paren(p[0], se[0])}, "
                                                      f"$x_\\mathrm{{max}}$ = {paren(p[1], se[1])}, "
                                                      f"$\\beta$ = {paren(p[2], se[2])}"))
                axes[1, k].plot(e, y - law(*p, e), ".", ms=3)
                axes[1, k].axhline(0, color="k", lw=0.5); axes[1, k].set_ylabel("residual")
                axes[1, k].set_xlabel(r"$\varepsilon_d$")
            else:   # nothing to show below: no residual panel
                axes[1, k].set_visible(False)
                axes[0, k].set_title("not fitted (the reason: fit/parameters.md)", fontsize=8)
                axes[0, k].set_xlabel(r"$\varepsilon_d$")
                axes[0, k].xaxis.set_tick_params(labelbottom=True)
            axes[0, k].set_ylabel(LABELS[q]); axes[0, k].legend(fontsize=7); axes[0, k].grid(alpha=0.3)
        fig.suptitle(f"{mode}, ν = {nu:.3f}")
        fig.tight_layout()
        stem = os.path.join(outdir, f"fit_{mode}_phi{nu:.3f}")
        save(fig, stem, run)
        written.append(stem + ".png")
    # parameters against nu, with the nu-laws
    laws = read_rows(os.path.join(run, "fit", "nu_laws.csv"))

    def interval(r, par):
        v, se = float(r[par]), float(r["se_" + par])
        return (v - 1.96 * se, v + 1.96 * se) if np.isfinite(se) else (v, v)
    written += plot_parameters(outdir, rows, laws, run, interval, "±1.96 standard errors of each curve's fit")
    return written


def main(argv=None):
    ap = argparse.ArgumentParser(prog="dem plot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", help="a `dem run` folder (deviatoric/, prep/; figures go to RUN_DIR/plots)")
    ap.add_argument("--fits", action="store_true", help="also plot the fits of RUN_DIR/fit (`dem fit` writes them)")
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
