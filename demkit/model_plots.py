"""Plots of `dem model` results (docs/model.md):

  model_<quantity>.png/.svg   p_star, s_dev, F_dev against eps_d: DEM ensemble mean and 95 % band
                              (shaded) and the model (fitted mode solid, predicted modes dashed)
                              for every nu, one panel per mode
  model_paths.png/.svg        the model-only paths (undrained cyclic shear, isobaric D2)
  model_path_<name>.png/.svg  DEM path ensembles (reversal, isobaric, cyclic, triaxial; curves/paths/) against
                              the model: p* (eps_v where p was held), s_dev and F_dev signed along
                              the first loading direction, against the accumulated eps_d

    python3 -m demkit.model_plots OUT_DIR
"""
import glob
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from demkit.curves import read_curve  # noqa: E402
from demkit.plots import LABELS, save as save_fig  # noqa: E402

def save(fig, stem):
    save_fig(fig, stem, os.path.dirname(os.path.dirname(stem)))   # DIR/model/x: provenance of DIR
    return [stem + ".png", stem + ".svg"]


NAME_RE = re.compile(r"([A-Za-z0-9]+)_phi([0-9.]+)\.csv$")


def model_curves(out):
    curves = []
    for f in sorted(glob.glob(os.path.join(out, "curves", "*_phi*.csv"))):
        m = NAME_RE.search(os.path.basename(f))
        if m and m.group(1) not in ("cyclic", "isobaric"):
            curves.append((m.group(1), float(m.group(2)), read_curve(f)))
    return curves


def plot_quantities(out, curves):
    modes = sorted({mode for mode, _, _ in curves})
    nus = sorted({nu for _, nu, _ in curves})
    cmap = plt.get_cmap("viridis")
    written = []
    for q in ("p_star", "s_dev", "F_dev"):
        fig, axes = plt.subplots(1, len(modes), figsize=(5.2 * len(modes), 4.2), squeeze=False, sharey=True)
        for ax, mode in zip(axes[0], modes):
            for m, nu, c in curves:
                if m != mode:
                    continue
                color = cmap(0.85 * nus.index(nu) / max(1, len(nus) - 1))
                ax.fill_between(c["eps_d"], c[q + "_lo95"], c[q + "_hi95"], color=color, alpha=0.25, lw=0)
                ax.plot(c["eps_d"], c[q + "_mean"], color=color, lw=0.8, alpha=0.7)
                ax.plot(c["eps_d"], c[q + "_model"], "-" if mode == "D2" else "--", color=color, lw=1.6,
                        label=f"ν={nu:.3f}")
            ax.set_title(f"{mode}: DEM mean + 95 % band (thin, shaded), model (thick"
                         f"{'' if mode == 'D2' else ', predicted'})", fontsize=8)
            ax.set_xlabel(r"deviatoric strain $\varepsilon_d$")
            ax.grid(alpha=0.3)
        axes[0][0].set_ylabel(LABELS.get(q, q))
        axes[0][-1].legend(fontsize=7)
        written += save(fig, os.path.join(out, f"model_{q}"))
    return written


def plot_paths(out):
    files = sorted(glob.glob(os.path.join(out, "curves", "cyclic_phi*.csv")))
    if not files:
        return []
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    cmap = plt.get_cmap("viridis")
    for i, f in enumerate(files):
        c = read_curve(f)
        nu = float(NAME_RE.search(os.path.basename(f)).group(2))
        color = cmap(0.85 * i / max(1, len(files) - 1))
        axes[0].plot(c["eps_d"], c["s_dev"], color=color, lw=1.2, label=f"ν={nu:.3f}")
        axes[1].plot(c["eps_d_accumulated"], c["p_star"] / c["p_star"][0], color=color, lw=1.2)
        iso = read_curve(f.replace("cyclic_", "isobaric_"))
        axes[2].plot(iso["eps_d"], iso["eps_vol"], color=color, lw=1.2)
    axes[0].set_xlabel(r"$\varepsilon_d$ (signed)")
    axes[0].set_ylabel(r"$s_{dev}$ (signed)")
    axes[0].set_title("model: undrained cyclic shear", fontsize=9)
    axes[1].set_xlabel(r"accumulated $\varepsilon_d$")
    axes[1].set_ylabel(r"$p/p_0$")
    axes[1].set_title("model: pressure along the cycles", fontsize=9)
    axes[2].set_xlabel(r"$\varepsilon_d$")
    axes[2].set_ylabel(r"$\varepsilon_{vol}$ = tr E (extension > 0)")
    axes[2].set_title("model: isobaric D2 (dilatancy > 0)", fontsize=9)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return save(fig, os.path.join(out, "model_paths"))


def plot_dem_paths(out):
    files = sorted(glob.glob(os.path.join(out, "curves", "paths", "*_phi*.csv")))
    groups = {}
    for f in files:
        m = re.search(r"([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv$", os.path.basename(f))
        if m:
            groups.setdefault(m.group(1), []).append((float(m.group(2)), f))
    written = []
    cmap = plt.get_cmap("viridis")
    for name, items in sorted(groups.items()):
        items.sort()
        first = read_curve(items[0][1])
        isobaric = max(first["isobaric"]) > 0.5
        triaxial = max(first["isobaric"]) > 1.5   # 2: constant side stress, p* and eps_v both free
        qs = (("eps_v" if isobaric else "p_star", r"$\varepsilon_v$ (extension > 0: dilatancy)" if isobaric else "p*"),
              ("s_dev", r"$s_{dev}$ signed"), ("F_dev", r"$F_{dev}$ signed"))
        if triaxial:   # p* over its start value: the rise is a few % of p*, the packings differ by 7x in p*
            qs = (("p_star", "p*/p*(0)"),) + qs
        fig, axes = plt.subplots(1, len(qs), figsize=(5 * len(qs), 4.2))
        for i, (nu, f) in enumerate(items):
            c = read_curve(f)
            with open(f) as fh:
                role = "fitted" if "(fitted)" in fh.readline() else "predicted"
            color = cmap(0.85 * i / max(1, len(items) - 1))
            x = c["eps_d_accumulated"]
            for ax, (q, label) in zip(axes, qs):
                sc = 1.0 / c["p_star_mean"][0] if triaxial and q == "p_star" else 1.0
                ax.fill_between(x, sc * c[q + "_lo95"], sc * c[q + "_hi95"], color=color, alpha=0.25, lw=0)
                ax.plot(x, sc * c[q + "_mean"], color=color, lw=0.8, alpha=0.7)
                ax.plot(x, sc * c[q + "_model"], "-" if role == "fitted" else "--", color=color, lw=1.6,
                        label=f"ν={nu:.3f} ({role})")
                ax.set_ylabel(label)
        for ax in axes:
            ax.set_xlabel(r"accumulated $\varepsilon_d$")
            ax.grid(alpha=0.3)
            if not isobaric:
                ax.axhline(0, color="k", lw=0.4)
        axes[0].set_title(f"{name}: DEM mean + 95 % band (thin, shaded), model (thick)", fontsize=9)
        axes[-1].legend(fontsize=7)
        fig.tight_layout()
        written += save(fig, os.path.join(out, f"model_path_{name}"))
    return written


def main(argv):
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    out = argv[0]
    curves = model_curves(out)
    if not curves:
        print(f"model_plots: no model curves under {out}/curves", file=sys.stderr)
        return 1
    written = plot_quantities(out, curves) + plot_paths(out) + plot_dem_paths(out)
    print(f"model_plots: {len(written)} files written to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
