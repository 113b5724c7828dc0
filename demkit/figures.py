"""What every figure of demkit shares: typeset names and units, the provenance written into each
PNG and SVG (scene hash, toolkit version), the check that no panel is drawn empty, and the
parameters-against-nu figure (with the fitted nu-laws and their bands).
"""
import csv
import functools
import hashlib
import os
import re
import subprocess
import sys

import numpy as np

from demkit.atomic import write_figure

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Curve columns and fit parameters as a paper prints them (dimensionless unless a unit is given).
SYMBOL = {"s_dev": r"s_\mathrm{dev}", "F_dev": r"F_\mathrm{dev}", "p_star": r"p^*", "C": r"C",
          "eps_v": r"\varepsilon_v", "eps_d": r"\varepsilon_d"}
PARAMETER = {"x_max": r"x_\mathrm{max}", "beta": r"\beta", "x0": r"x_0", "initial_slope": r"\mathrm{d}x/\mathrm{d}\varepsilon_d|_0"}


def parameter_label(par, quantity):
    """'$x_\\mathrm{max}$ of $s_\\mathrm{dev}$' -> the saturation level of s_dev, as a paper writes it."""
    q = SYMBOL.get(quantity, quantity.replace("_", r"\_"))
    names = {"x_max": rf"${q}^\mathrm{{max}}$ (saturation level)", "beta": rf"$\beta$ of ${q}$ (rate of approach)",
             "x0": rf"${q}^0$ (initial value)"}
    return names.get(par, rf"${PARAMETER.get(par, par)}$ of ${q}$")


def toolkit_version():
    """'dem-toolkit 0.2.0 (git 1a2b3c4)': the CMake project version and, in a git checkout, the commit."""
    version = "unknown"
    try:
        with open(os.path.join(REPO, "CMakeLists.txt")) as fh:
            m = re.search(r"project\(\s*\w+\s+VERSION\s+([0-9.]+)", fh.read())
            version = m.group(1) if m else version
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "-C", REPO, "rev-parse", "--short=10", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        commit = ""
    return f"dem-toolkit {version}" + (f" (git {commit})" if commit else "")


def scene_hash(run):
    """sha256 (first 16 hex digits) of RUN/scene.toml, the resolved scene (of a sweep folder:
    its sweep.json, which names every row); None without one."""
    if not run:
        return None
    path = os.path.join(run, "scene.toml")
    if not os.path.isfile(path):
        path = os.path.join(run, "sweep.json")
    if not os.path.isfile(path):
        return None
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()[:16]


def physics_hash(run):
    """The `# physics: HASH` of the first curve found in the run folder (None if none)."""
    if not run:
        return None
    import glob
    for d in [os.path.join(run, "deviatoric"), os.path.join(run, "prep")] + \
            sorted(glob.glob(os.path.join(run, "members", "*", "deviatoric"))):
        if not os.path.isdir(d):
            continue
        for f in sorted(os.listdir(d)):
            if f.endswith(".csv"):
                with open(os.path.join(d, f)) as fh:
                    for ln in fh:
                        if not ln.startswith("#"):
                            break
                        if ln.startswith("# physics: "):
                            return ln.split()[2]
    return None


def provenance(run):
    """{'version', 'scene', 'physics'} of a run folder, for the figures' metadata: once per folder
    and version of its scene file in a process (git and the file reads are not paid per figure)."""
    stamp = None
    for name in ("scene.toml", "sweep.json"):
        try:
            st = os.stat(os.path.join(run, name)) if run else None
            stamp = (name, st.st_mtime_ns, st.st_size) if st else None
            break
        except OSError:
            continue
    return _provenance(run, stamp)


@functools.lru_cache(maxsize=64)
def _provenance(run, stamp):
    return {"version": toolkit_version(), "scene": scene_hash(run), "physics": physics_hash(run)}


def empty_axes(fig):
    """The visible axes of fig that show no data (no line, marker, band, bar or image)."""
    out = []
    for ax in fig.axes:
        if not ax.get_visible() or ax.get_label() == "<colorbar>":
            continue
        if not (ax.lines or ax.collections or ax.containers or ax.images or ax.patches):
            out.append(ax)
    return out


SAVED = []   # {stem, empty, axes, title} of every figure saved in this process (tests read it)


def save(fig, stem, run=None, dpi=150):
    """stem.png and stem.svg with the provenance in their metadata: PNG text chunks Software
    (toolkit version), Source (scene sha256 and physics hash), Title; SVG Dublin Core Creator,
    Source, Title."""
    p = provenance(os.path.abspath(run) if run else None)
    source = f"scene sha256:{p['scene'] or 'none'}; physics {p['physics'] or 'none'}"
    title = os.path.basename(stem)
    SAVED.append({"stem": stem, "empty": len(empty_axes(fig)), "title": fig._suptitle.get_text() if fig._suptitle else "",
                  "axes": sum(1 for ax in fig.axes if ax.get_visible())})
    write_figure(fig, stem, dpi=dpi, metadata={
        "png": {"Software": p["version"], "Source": source, "Title": title},
        "svg": {"Creator": p["version"], "Source": source, "Title": title, "Date": None}})


def legend_if_any(ax, **kw):
    """A legend only when something is labelled (no matplotlib warning, no empty box)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(**kw)


def read_rows(path):
    if not os.path.exists(path):
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _num(r, k):
    try:
        return float(r.get(k, "nan"))
    except (TypeError, ValueError):
        return float("nan")


def usable(row):
    """The fit tables' one rule for a usable fit (demfit::unusable_reason, written as the `usable`
    column of fit/parameters.csv; README, "Errors"): True when the row's numbers are determined by
    the data. A table written before that column: finite standard errors of x_max and beta."""
    u = (row.get("usable") or "").strip()
    if u in ("yes", "no"):
        return u == "yes"
    return bool(np.isfinite(_num(row, "se_x_max")) and np.isfinite(_num(row, "se_beta")))


def not_usable_because(row):
    """The reason printed beside a fit that is not usable ("" for a usable one)."""
    if usable(row):
        return ""
    return (row.get("not_usable_because") or "").strip() or "no finite standard error of x_max or beta"


def fit_label(row, text):
    """The legend of a fitted law: its numbers when usable, else only why it is not."""
    return text if usable(row) else f"fit not usable: {not_usable_because(row)}"


def plot_parameters(outdir, rows, laws, run, interval, note=""):
    """x_max and beta of s_dev and F_dev against nu, one panel each that has data at two or more
    volume fractions (the others are left out, and the figure says so), with the fitted nu-laws
    a + b (nu - nu_ref) of fit/nu_laws.csv and their 95 % bands. interval(row, par) -> (lo, hi)."""
    import matplotlib.pyplot as plt
    panels, left_out = [], []
    for q in ("s_dev", "F_dev"):
        for par in ("x_max", "beta"):
            sel = [r for r in rows if r["quantity"] == q and np.isfinite(_num(r, par))]
            if len({r["nu"] for r in sel}) >= 2:
                panels.append((q, par, sel))
            else:
                left_out.append(parameter_label(par, q).split(" (")[0])
    if not panels:
        print("dem plot: note: parameters against nu not drawn: fitted at fewer than two volume fractions "
              "(the values are in fit/parameters.md)", file=sys.stderr, flush=True)
        return []
    ncols = 2 if len(panels) > 1 else 1
    nrows = (len(panels) + 1) // 2 if ncols == 2 else 1
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.4 * nrows), squeeze=False)
    colours = {"D2": "#1f77b4", "D3": "#d62728"}
    undetermined = False
    for ax, (q, par, sel) in zip(axes.flat, panels):
        # A fit that is not usable (the tables' rule, `usable`): a hollow marker without its bar, so it
        # does not set the scale of the panel and is not drawn as a result.
        allv = np.array([_num(r, par) for r in sel])
        span = np.ptp(allv) if np.ptp(allv) > 0 else max(abs(np.mean(allv)), 1e-12)
        shown = []
        for mode, marker, dx in (("D2", "o", -0.0008), ("D3", "s", 0.0008)):
            ms = [r for r in sel if r["mode"] == mode]
            if not ms:
                continue
            nu = np.array([_num(r, "nu") for r in ms])
            v = np.array([_num(r, par) for r in ms])
            lohi = np.array([interval(r, par) for r in ms], dtype=float)
            ok = np.array([usable(r) for r in ms]) & np.isfinite(lohi).all(axis=1)
            colour = colours.get(mode, "k")
            err = [np.nan_to_num(v - lohi[:, 0]), np.nan_to_num(lohi[:, 1] - v)]
            if np.any(ok):
                ax.errorbar(nu[ok] + dx, v[ok], yerr=[err[0][ok], err[1][ok]], fmt=marker, ms=4, capsize=2.5,
                            color=colour, label=mode)
            if np.any(~ok):
                undetermined = True
                ax.plot(nu[~ok] + dx, v[~ok], marker, ms=5, mfc="white", color=colour,
                        label=f"{mode}, not usable")
            shown += list(v) + list(lohi[ok].ravel())
            law = [lw for lw in laws if lw["mode"] == mode and lw["quantity"] == q and lw["parameter"] == par]
            if law:
                lw = law[0]
                a, b, sa, sb, ref = (_num(lw, k) for k in ("a", "b", "se_a", "se_b", "nu_ref"))
                g = np.linspace(nu.min(), nu.max(), 50)
                y = a + b * (g - ref)
                band = 1.96 * np.sqrt(sa ** 2 + ((g - ref) * sb) ** 2)
                ax.plot(g, y, "-", lw=1, color=colour, alpha=0.8)
                if np.all(np.isfinite(band)) and np.all(band <= 4 * span):
                    ax.fill_between(g, y - band, y + band, color=colour, alpha=0.12, lw=0)
        shown = np.array([y for y in shown if np.isfinite(y)])
        if shown.size:
            pad = 0.08 * max(np.ptp(shown), 1e-12)
            ax.set_ylim(shown.min() - pad, shown.max() + pad)
        ax.set_xlabel(r"volume fraction $\nu$")
        ax.set_ylabel(parameter_label(par, q))
        ax.grid(alpha=0.3)
        legend_if_any(ax, fontsize=8)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    text = "bars: " + note + "; lines: linear ν-laws (fit/nu_laws.csv) with 95 % bands"
    if undetermined:
        text += "\nhollow: fit not usable (no result; the reason beside it in fit/parameters.md, column not_usable_because)"
    if left_out:
        text += "\nnot drawn (fitted at fewer than two ν): " + ", ".join(left_out)
    fig.suptitle(text, fontsize=8)
    fig.tight_layout()
    stem = os.path.join(outdir, "fit_parameters")
    save(fig, stem, run)
    return [stem + ".png"]
