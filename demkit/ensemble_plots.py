"""Plots of an ensemble folder (written by `dem fit DIR` after `dem ensemble`):

  plots/ensemble_<quantity>.png/.svg   mean curve and 95 % band of every (mode, nu): s_dev, F_dev, p_star, C
  plots/fit_<mode>_phiX.XXX.png/.svg   s_dev and F_dev: mean, band, members (thin) and the fitted law
  plots/fit_parameters.png/.svg        x_max and beta against nu with their 95 % intervals
  plots/isotropic.png/.svg             p_star and C* on the unloading branch of every member

    python3 -m demkit.ensemble_plots DIR
"""
import glob
import os
import re
import sys
import time

T_START = time.time()   # before matplotlib's import: the plots' time printed at the end includes it

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from demkit.curves import read_curve  # noqa: E402
from demkit.figures import fit_label, legend_if_any, plot_parameters as parameters_figure, read_rows, save  # noqa: E402
from demkit.figures import usable  # noqa: E402
from demkit.plots import LABELS, law, paren  # noqa: E402

NAME_RE = re.compile(r"([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv$")


def ensemble_curves(run):
    out = []
    for f in sorted(glob.glob(os.path.join(run, "ensemble", "*_phi*.csv"))):
        m = NAME_RE.search(os.path.basename(f))
        if m:
            out.append((m.group(1), float(m.group(2)), read_curve(f)))
    return out


def plot_bands(run, outdir, curves, qs=("s_dev", "F_dev", "p_star", "C")):
    """Mean and 95 % band of every (mode, nu), one panel per mode side by side (D2 | D3), sharing y."""
    nus = sorted({nu for _, nu, _ in curves})
    modes = sorted({mode for mode, _, _ in curves})
    cmap = plt.get_cmap("viridis")
    written = []
    for q in qs:
        fig, axes = plt.subplots(1, len(modes), figsize=(4.2 * len(modes) + 0.6, 3.8), sharey=True, squeeze=False)
        for ax, mode in zip(axes[0], modes):
            for m, nu, c in curves:
                if m != mode:
                    continue
                color = cmap(0.85 * nus.index(nu) / max(1, len(nus) - 1))   # stop before viridis' pale yellow
                ax.fill_between(c["eps_d"], c[q + "_lo95"], c[q + "_hi95"], color=color, alpha=0.25, lw=0)
                ax.plot(c["eps_d"], c[q + "_mean"], "-", color=color, lw=1.3, label=f"ν = {nu:.3f}")
            ax.set_title(mode, fontsize=10)
            ax.set_xlabel(r"deviatoric strain $\varepsilon_d$")
            ax.grid(alpha=0.3)
            legend_if_any(ax, fontsize=7)
        axes[0, 0].set_ylabel(LABELS[q])
        k = int(curves[0][2]["n_packings"][0])
        fig.suptitle(f"mean of {k} packings with its 95 % confidence band", fontsize=9)
        fig.tight_layout()
        stem = os.path.join(outdir, f"ensemble_{q}")
        save(fig, stem, run)
        written.append(stem + ".png")
    return written


def member_curve(run, member, mode, nu):
    f = os.path.join(run, "members", member, "deviatoric", f"{mode}_phi{nu:.3f}.csv")
    return read_curve(f) if os.path.exists(f) else None


def peak_law(x0, x_cs, beta, A, gamma, e):
    """The peak-and-soften law (fit/include/demfit/peak.hpp, docs/model_selection.md)."""
    e = np.asarray(e, dtype=float)
    return x_cs - (x_cs - x0) * np.exp(-beta * e) + A * (np.exp(-gamma * e) - np.exp(-beta * e))


def plot_peak_law(ax, e, row):
    """The chosen peak law of a fit-table row, its peak and critical state."""
    p = [float(row[n]) for n in ("pk_x0", "pk_x_cs", "pk_beta", "pk_A", "pk_gamma")]
    cs = (f"$x_\\mathrm{{cs}}$ = {paren(p[1], float(row['se_pk_x_cs']))}" if row.get("x_crit", "nan") != "nan"
          else "critical state beyond the data")
    label = f"peak law ({row['model']}, chosen, p = {float(row['selection_p']):.1g}): {cs}"
    if row.get("x_peak", "nan") != "nan":
        label += (f", peak {paren(float(row['x_peak']), float(row['se_x_peak']))} at "
                  f"{paren(float(row['eps_peak']), float(row['se_eps_peak']))}")
        ax.plot([float(row["eps_peak"])], [float(row["x_peak"])], "kv", ms=5)
    ax.plot(e, peak_law(*p, e), "k-", lw=1.2, label=label)


def plot_fit_cells(run, outdir, curves, rows):
    members = sorted(os.path.basename(d) for d in glob.glob(os.path.join(run, "members", "m*")))
    written = []
    for mode, nu, c in curves:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        mcs = [mc for mc in (member_curve(run, m, mode, nu) for m in members) if mc is not None]   # read once per cell
        for ax, q in zip(axes, ("s_dev", "F_dev")):
            for mc in mcs:
                ax.plot(mc["eps_d"], mc[q], "-", color="0.75", lw=0.6)
            e = c["eps_d"]
            ax.fill_between(e, c[q + "_lo95"], c[q + "_hi95"], color="C0", alpha=0.3, lw=0, label="95 % band of the mean")
            ax.plot(e, c[q + "_mean"], "C0-", lw=1.2, label=f"mean of {int(c['n_packings'][0])} packings (members grey)")
            r = [r for r in rows if r["mode"] == mode and abs(float(r["nu"]) - nu) < 1e-6 and r["quantity"] == q]
            if r and r[0]["x_max"] != "nan":
                p = [float(r[0][n]) for n in ("x0", "x_max", "beta")]
                ax.plot(e, law(*p, e), "--" if usable(r[0]) else ":", color="r" if usable(r[0]) else "0.5", lw=1.2,
                        label=fit_label(r[0], f"fit: $x_\\mathrm{{max}}$ = {paren(p[1], float(r[0]['se_x_max']))}, "
                                              f"$\\beta$ = {paren(p[2], float(r[0]['se_beta']))} (jackknife SE)"))
            if r and r[0].get("model") in ("peak", "two-rate"):
                plot_peak_law(ax, e, r[0])
            ax.set_xlabel(r"$\varepsilon_d$"); ax.set_ylabel(LABELS[q]); ax.grid(alpha=0.3)
            # the peak law's long label: smaller, and where the curves leave room (below the rise)
            peak = bool(r) and r[0].get("model") in ("peak", "two-rate")
            ax.legend(fontsize=5.5 if peak else 7, loc="lower right" if peak else "best")
        fig.suptitle(f"{mode}, ν = {nu:.3f}")
        fig.tight_layout()
        stem = os.path.join(outdir, f"fit_{mode}_phi{nu:.3f}")
        save(fig, stem, run)
        written.append(stem + ".png")
    return written


def plot_parameters(outdir, rows, run=None):
    if not rows:
        return []
    laws = read_rows(os.path.join(run, "fit", "nu_laws.csv")) if run else []

    def interval(r, par):
        return float(r[par + "_lo95"]), float(r[par + "_hi95"])
    return parameters_figure(outdir, rows, laws, run, interval,
                             "95 % intervals between packings (fit to the ensemble mean)")


def plot_isotropic(run, outdir):
    files = sorted(glob.glob(os.path.join(run, "members", "m*", "prep", "cycle_unloading.csv")))
    if not files:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for f in files:
        c = read_curve(f)
        axes[0].semilogy(c["nu"], np.maximum(c["p_star"], 1e-9), "-", lw=0.8)
        axes[1].plot(c["nu"], c["C_nonrattler"], "-", lw=0.8)
    axes[0].set_xlabel("volume fraction ν"); axes[0].set_ylabel(LABELS["p_star"])
    axes[1].set_xlabel("volume fraction ν"); axes[1].set_ylabel("C* (without rattlers)")
    fig.suptitle(f"unloading branch of {len(files)} packings", fontsize=9)
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    stem = os.path.join(outdir, "isotropic")
    save(fig, stem, run)
    return [stem + ".png"]


def call(job):
    f, args = job
    return f(*args)


def run_jobs(jobs, workers=None):
    """Every figure's function, on two processes where there are two cores (forked after the
    imports: matplotlib is imported once); the written files in the order of the jobs."""
    workers = min(2, os.cpu_count() or 1, len(jobs)) if workers is None else workers
    if workers < 2:
        return [call(j) for j in jobs]
    import multiprocessing
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        return pool.map(call, jobs, chunksize=1)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1 or not os.path.isdir(argv[0]):
        print("usage: python3 -m demkit.ensemble_plots ENSEMBLE_DIR", file=sys.stderr)
        return 2
    run = argv[0]
    outdir = os.path.join(run, "plots")
    os.makedirs(outdir, exist_ok=True)
    curves = ensemble_curves(run)
    rows = read_rows(os.path.join(run, "fit", "parameters.csv"))
    jobs = [(plot_bands, (run, outdir, curves, (q,))) for q in ("s_dev", "F_dev", "p_star", "C") if curves]
    jobs += [(plot_fit_cells, (run, outdir, [c], rows)) for c in curves]
    jobs += [(plot_parameters, (outdir, rows, run)), (plot_isotropic, (run, outdir))]
    written = [f for w in run_jobs(jobs) for f in w]
    # demkit.task reads the seconds into the reduce's status (plots_s, the run's breakdown)
    print(f"dem plot: {len(written)} figures in {outdir} ({time.time() - T_START:.2f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
