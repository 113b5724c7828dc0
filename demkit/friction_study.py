"""The study across the friction coefficient (issue 24): one ensemble folder per mu (`dem ensemble`
of the same scene with `--set contact.friction=MU`) -> one table and the figures of every quantity
against mu, each a mean over the packings with its standard error and 95 % interval (Student's t
with K - 1 degrees of freedom), computed per packing and then averaged (model-free: no fit).

    /usr/bin/python3 -m demkit.friction_study --out data/friction_n1000 runs/friction_mu0 runs/friction_mu0.5 ...

Per packing:
- isotropic unloading branch (prep/cycle_unloading.csv): nu_J and the coordination at jamming
  C_star (all particles) and C_star_nr (rattlers removed), extrapolated from the solid samples
  (`jamming`), and nu_bracket, the sample spacing there;
- D2 / D3 at constant volume (deviatoric/MODE_phiX.csv): the peak of s_dev and its strain, the
  critical-state level (mean over eps_d in [0.25, 0.30]) of s_dev and F_dev, s_peak - s_cs;
- isobaric D2 (deviatoric/isobaric_D2_phiX.csv): the dilatancy d eps_vol / d eps_d with
  eps_vol = tr E = 3 eps_v (positive: dilation) at its maximum (slope over a 0.03 strain window) and late (eps_d in [0.15, 0.30]),
  the critical-state volume fraction nu_cs (mean nu over [0.25, 0.30]) and stress ratio.
"""
import argparse
import csv
import glob
import json
import math
import os
import sys
import tomllib

import numpy as np
from scipy import stats

from demkit.curves import CurveError, read_curve
from demkit import figures
from demkit.rounding import pm

CS_WINDOW = (0.25, 0.30)
LATE_WINDOW = (0.15, 0.30)
SLOPE_WINDOW = 0.03
# A peak is a maximum the curve has passed: at least this much strain, and a drop below it, after it.
PEAK_AFTER = 0.02


def t975(dof):
    """The 97.5 % quantile of Student's t with dof degrees of freedom (scipy); NaN for dof < 1."""
    return float(stats.t.ppf(0.975, dof)) if dof >= 1 else math.nan


def friction_of(folder):
    """mu of an ensemble folder, from its resolved scene (absent key: frictionless, 0)."""
    with open(os.path.join(folder, "scene.toml"), "rb") as fh:
        scene = tomllib.load(fh)
    return float(scene.get("contact", {}).get("friction", 0.0))


def window_mean(x, y, lo, hi):
    sel = (x >= lo) & (x <= hi)
    return float(np.mean(y[sel])) if sel.any() else math.nan


def jamming(branch, p_solid=1e-3, n_line=3, n_sqrt=6):
    """{nu_J, C_star, C_star_nr, nu_bracket} of one unloading branch; NaNs when it never unjams.
    nu_J: root of the line through the n_line lowest solid samples of p*(nu) (solid: p* > p_solid;
    below it the packing is coming apart at the unloading rate, and unjammed samples sit at
    p* ~ 1e-7, the gas's kinetic pressure). C_star: the intercept of C = C* + a sqrt(nu - nu_J)
    over the n_sqrt lowest solid samples (the group's exponent 1/2 near jamming); C_star_nr the same
    for C_nonrattler, NaN where the rattler rule (< 4 contacts, recursively) removes every particle."""
    order = np.argsort(branch["nu"])
    nu, p = branch["nu"][order], branch["p_star"][order]
    c, cnr = branch["C"][order], branch["C_nonrattler"][order]
    idx = np.flatnonzero(p > p_solid)
    out = {"nu_J": math.nan, "C_star": math.nan, "C_star_nr": math.nan, "nu_bracket": math.nan}
    if len(idx) < n_sqrt or idx[0] == 0 or np.any(np.diff(idx[:n_sqrt]) != 1):
        return out
    slope, icpt = np.polyfit(nu[idx[:n_line]], p[idx[:n_line]], 1)
    if not slope > 0:
        return out
    nu_j = -icpt / slope
    out["nu_J"], out["nu_bracket"] = float(nu_j), float(nu[idx[0]] - nu[idx[0] - 1])
    x = np.sqrt(np.maximum(nu[idx[:n_sqrt]] - nu_j, 0))
    out["C_star"] = float(np.polyfit(x, c[idx[:n_sqrt]], 1)[1])
    if np.all(cnr[idx[:n_sqrt]] > 0):
        out["C_star_nr"] = float(np.polyfit(x, cnr[idx[:n_sqrt]], 1)[1])
    return out


def peak(e, s):
    """(s_peak, eps_peak) of a curve that has passed its maximum: at least PEAK_AFTER of strain after
    it, with the curve below it there. (NaN, NaN) for a curve still rising at its end: its last point
    is no peak, whatever the maximum of the data says."""
    k = int(np.argmax(s))
    if e[-1] - e[k] < PEAK_AFTER or not s[-1] < s[k]:
        return math.nan, math.nan
    return float(s[k]), float(e[k])


def deviatoric(curve):
    e, s, f = curve["eps_d"], curve["s_dev"], curve["F_dev"]
    s_peak, eps_peak = peak(e, s)
    s_cs = window_mean(e, s, *CS_WINDOW)
    return {"s_peak": s_peak, "eps_peak": eps_peak, "s_cs": s_cs, "F_cs": window_mean(e, f, *CS_WINDOW),
            "s_softening": s_peak - s_cs, "p_star_cs": window_mean(e, curve["p_star"], *CS_WINDOW)}


def slopes(e, v, width):
    """d v / d e by a straight line over each window [e_i, e_i + width]."""
    out = []
    for i, e0 in enumerate(e):
        sel = (e >= e0) & (e <= e0 + width)
        if sel.sum() >= 4 and e[sel][-1] - e0 >= 0.8 * width:
            out.append(np.polyfit(e[sel], v[sel], 1)[0])
    return np.array(out)


def isobaric(curve):
    e, ev = curve["eps_d"], 3 * curve["eps_v"]   # tr E: the volumetric strain (the curve's eps_v is tr E / 3)
    sl = slopes(e, ev, SLOPE_WINDOW)
    late = (e >= LATE_WINDOW[0]) & (e <= LATE_WINDOW[1])
    return {"dilatancy_max": float(sl.max()) if len(sl) else math.nan,
            "dilatancy_late": float(np.polyfit(e[late], ev[late], 1)[0]) if late.sum() >= 4 else math.nan,
            "nu_cs": window_mean(e, curve["nu"], *CS_WINDOW), "s_cs": window_mean(e, curve["s_dev"], *CS_WINDOW),
            "s_peak": peak(e, curve["s_dev"])[0]}


def member_values(member):
    """{(mode, nu, quantity): value} of one packing's folder."""
    out = {}
    branch = os.path.join(member, "prep", "cycle_unloading.csv")
    if os.path.isfile(branch):
        out.update({("isotropic", "", q): v for q, v in jamming(read_curve(branch)).items()})
    for path in sorted(glob.glob(os.path.join(member, "deviatoric", "*_phi*.csv"))):
        name = os.path.basename(path)[:-4]
        mode, nu = name.rsplit("_phi", 1)
        try:
            curve = read_curve(path)
        except CurveError as e:
            print(f"friction_study: skipped {path}: {e}", file=sys.stderr)
            continue
        values = isobaric(curve) if mode.startswith("isobaric") else deviatoric(curve)
        out.update({(mode, nu, q): v for q, v in values.items()})
    return out


def summarise(folder):
    """Rows (mu, mode, nu, quantity, K, mean, se, lo95, hi95) of one ensemble folder."""
    mu = friction_of(folder)
    members = sorted(glob.glob(os.path.join(folder, "members", "m*")))
    per = [member_values(m) for m in members]
    keys = sorted({k for p in per for k in p})
    rows = []
    for key in keys:
        vals = np.array([p[key] for p in per if key in p and math.isfinite(p[key])])
        k = len(vals)
        mean = float(vals.mean()) if k else math.nan
        se = float(vals.std(ddof=1) / math.sqrt(k)) if k > 1 else math.nan
        half = t975(k - 1) * se if k > 1 else math.nan
        rows.append({"mu": mu, "mode": key[0], "nu": key[1], "quantity": key[2], "packings": k, "mean": mean,
                     "se": se, "lo95": mean - half, "hi95": mean + half})
    return rows


def round_to_error(v, e):
    """'0.197 ± 0.002': the value rounded to its error, the rule of every table (demkit.rounding); "not
    determined" where there is no value (a peak no packing has: every curve still rising at its end)."""
    return pm(v, e) if math.isfinite(v) else "not determined"


UNITS = {"nu_J": "", "C_star_nr": "", "nu_bracket": "", "s_peak": "", "eps_peak": "", "s_cs": "", "F_cs": "",
         "s_softening": "", "p_star_cs": "", "dilatancy_max": "", "dilatancy_late": "", "nu_cs": ""}


def write_tables(rows, out):
    os.makedirs(out, exist_ok=True)
    cols = ["mu", "mode", "nu", "quantity", "packings", "mean", "se", "lo95", "hi95"]
    tmp = os.path.join(out, "summary.csv.part")
    with open(tmp, "w", newline="") as fh:
        fh.write("# friction study: per-packing values averaged over the packings; se = sd/sqrt(K); "
                 "lo95/hi95 = mean -+ t(K-1) se; all quantities dimensionless (demkit/friction_study.py)\n")
        w = csv.DictWriter(fh, fieldnames=cols, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({c: (f"{r[c]:.6g}" if isinstance(r[c], float) else r[c]) for c in cols})
    os.replace(tmp, os.path.join(out, "summary.csv"))
    lines = ["| mu | mode | nu | quantity | K | mean ± SE | 95 % interval |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mu']:g} | {r['mode']} | {r['nu']} | {r['quantity']} | {r['packings']} | "
                     f"{round_to_error(r['mean'], r['se'])} | [{r['lo95']:.4g}, {r['hi95']:.4g}] |")
    tmp = os.path.join(out, "summary.md.part")
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    os.replace(tmp, os.path.join(out, "summary.md"))


HEADLINE = [("isotropic", "nu_J", r"ν_J"), ("D2", "s_peak", "s_peak D2"), ("D2", "s_cs", "s_cs D2"),
            ("D3", "s_cs", "s_cs D3"), ("D2", "F_cs", "F_cs D2"), ("isobaric_D2", "s_cs", "s_cs isobaric"),
            ("isobaric_D2", "dilatancy_max", "max dε_vol/dε_d"), ("isobaric_D2", "nu_cs", "ν_cs (isobaric)")]


def write_headline(rows, out):
    """headline.md: one table per volume fraction, one row per mu, the quantities of HEADLINE
    (mean ± SE over the packings, rounded to the error)."""
    nus = sorted({r["nu"] for r in rows if r["nu"]})
    mus = sorted({r["mu"] for r in rows})
    find = {(r["mu"], r["mode"], r["nu"], r["quantity"]): r for r in rows}
    lines = []
    for nu in nus:
        lines += [f"**ν = {nu}** (K = packings per cell; a peak is averaged over the packings whose curve has "
                  "one, none on a curve still rising at its end, so K can differ between columns)", "",
                  "| μ | K | " + " | ".join(h[2] for h in HEADLINE) + " |", "|---" * (len(HEADLINE) + 2) + "|"]
        for mu in mus:
            cells, ks = [], set()
            for mode, q, _ in HEADLINE:
                r = find.get((mu, mode, "" if mode == "isotropic" else nu, q))
                cells.append(round_to_error(r["mean"], r["se"]) if r else "–")
                if r and mode != "isotropic":
                    ks.add(r["packings"])
            lines.append(f"| {mu:g} | {','.join(map(str, sorted(ks)))} | " + " | ".join(cells) + " |")
        lines.append("")
    tmp = os.path.join(out, "headline.md.part")
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines))
    os.replace(tmp, os.path.join(out, "headline.md"))


def series(rows, mode, nu, quantity):
    sel = sorted((r for r in rows if r["mode"] == mode and r["nu"] == nu and r["quantity"] == quantity),
                 key=lambda r: r["mu"])
    return (np.array([r["mu"] for r in sel]), np.array([r["mean"] for r in sel]),
            np.array([r["hi95"] - r["mean"] for r in sel]))


def mu_axis(ax, mus):
    """mu = 0 on a log axis: a symlog axis linear below 0.01."""
    ax.set_xscale("symlog", linthresh=0.01, linscale=0.5)
    ax.set_xlim(-0.002, max(mus) * 1.3)
    ax.set_xlabel(r"friction coefficient $\mu$")


def plot_stress_ratio(rows, out, run):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    nus = sorted({r["nu"] for r in rows if r["nu"]})
    mus = sorted({r["mu"] for r in rows})
    # a panel only for a mode with some finite value (short curves have no peak and no critical state)
    modes = [m for m in ["D2", "D3", "isobaric_D2"]
             if any(r["mode"] == m and r["quantity"] in ("s_peak", "s_cs") and math.isfinite(r["mean"]) for r in rows)]
    if not modes:
        print("friction_study: no stress-ratio figure: no curve reaches a peak or the critical-state window "
              f"eps_d = {CS_WINDOW[0]}-{CS_WINDOW[1]} (run the modes further)", file=sys.stderr)
        return
    fig, axes = plt.subplots(1, len(modes), figsize=(3.5 * len(modes), 3.4), sharey=True, squeeze=False)
    axes = axes[0]
    for ax, mode in zip(axes, modes):
        for i, nu in enumerate(nus):
            for q, ls, mk in (("s_peak", "-", "o"), ("s_cs", "--", "s")):
                x, y, h = series(rows, mode, nu, q)
                if len(x):
                    ax.errorbar(x, y, yerr=np.nan_to_num(h), ls=ls, marker=mk, ms=4, color=f"C{i}", capsize=2,
                                label=(rf"$\nu$ = {nu}" if q == "s_peak" else None))
        mu_axis(ax, mus)
        ax.set_title(mode.replace("_", " "))
    axes[0].set_ylabel(r"$s_\mathrm{dev}$: peak (solid), critical state (dashed)")
    figures.legend_if_any(axes[0], fontsize=8)
    fig.tight_layout()
    figures.save(fig, os.path.join(out, "stress_ratio_vs_mu"), run)


def plot_isotropic(rows, out, run):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    mus = sorted({r["mu"] for r in rows})
    fig, (a, b) = plt.subplots(1, 2, figsize=(7.5, 3.2))
    x, y, h = series(rows, "isotropic", "", "nu_J")
    a.errorbar(x, y, yerr=np.nan_to_num(h), marker="o", capsize=2)
    a.set_ylabel(r"jamming volume fraction $\nu_J$")
    x, y, h = series(rows, "isotropic", "", "C_star")
    b.errorbar(x, y, yerr=np.nan_to_num(h), marker="s", capsize=2, label=r"$C$ (all particles)")
    x, y, h = series(rows, "isotropic", "", "C_star_nr")
    ok = np.isfinite(y)
    b.errorbar(x[ok], y[ok], yerr=np.nan_to_num(h[ok]), marker="o", capsize=2, label=r"$C_\mathrm{nr}$ (rattlers removed)")
    b.axhline(6, color="0.5", ls=":", label="isostatic, frictionless (2d = 6)")
    b.axhline(4, color="0.5", ls="--", label=r"isostatic, $\mu \to \infty$ (d + 1 = 4)")
    b.set_ylabel(r"non-rattler coordination at jamming")
    figures.legend_if_any(b, fontsize=7)
    for ax in (a, b):
        mu_axis(ax, mus)
    fig.tight_layout()
    figures.save(fig, os.path.join(out, "jamming_vs_mu"), run)


def plot_dilatancy(rows, out, run):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    nus = sorted({r["nu"] for r in rows if r["mode"] == "isobaric_D2"})
    mus = sorted({r["mu"] for r in rows})
    if not nus:
        return
    fig, (a, b) = plt.subplots(1, 2, figsize=(7.5, 3.2))
    for i, nu in enumerate(nus):
        x, y, h = series(rows, "isobaric_D2", nu, "dilatancy_max")
        a.errorbar(x, y, yerr=np.nan_to_num(h), marker="o", capsize=2, color=f"C{i}", label=rf"from $\nu$ = {nu}")
        x, y, h = series(rows, "isobaric_D2", nu, "nu_cs")
        b.errorbar(x, y, yerr=np.nan_to_num(h), marker="o", capsize=2, color=f"C{i}")
    a.axhline(0, color="0.6", lw=0.8)
    a.set_ylabel(r"max d$\varepsilon_v$/d$\varepsilon_d$ (isobaric D2; > 0 dilates)")
    b.set_ylabel(r"$\nu$ at $\varepsilon_d$ = 0.25–0.30 (isobaric)")
    figures.legend_if_any(a, fontsize=8)
    for ax in (a, b):
        mu_axis(ax, mus)
    fig.tight_layout()
    figures.save(fig, os.path.join(out, "dilatancy_vs_mu"), run)


def plot_curves(folders, out, nu="0.740", quantity="s_dev"):
    """The ensemble-mean curves with their 95 % bands, one colour per mu (D2 and D3 side by side)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.3), sharey=True)
    for ax, mode in zip(axes, ["D2", "D3"]):
        for i, f in enumerate(sorted(folders, key=friction_of)):
            path = os.path.join(f, "ensemble", f"{mode}_phi{nu}.csv")
            if not os.path.isfile(path):
                continue
            c = read_curve(path)
            ax.plot(c["eps_d"], c[f"{quantity}_mean"], color=f"C{i}", label=rf"$\mu$ = {friction_of(f):g}")
            ax.fill_between(c["eps_d"], c[f"{quantity}_lo95"], c[f"{quantity}_hi95"], color=f"C{i}", alpha=0.25, lw=0)
        ax.set_title(rf"{mode}, $\nu$ = {nu}")
        ax.set_xlabel(r"$\varepsilon_d$")
    axes[0].set_ylabel(rf"${figures.SYMBOL.get(quantity, quantity)}$ (mean, 95 % band)")
    figures.legend_if_any(axes[0], fontsize=8)
    fig.tight_layout()
    figures.save(fig, os.path.join(out, f"{quantity}_curves_phi{nu}"), folders[0])


KEEP = ["step", "eps_d", "eps_v", "nu", "p_star", "s_dev", "F_dev", "C", "C_nonrattler", "rattler_fraction",
        "E_kin_J", "E_pot_J", "sliding_fraction", "n_packings"]


def trim_csv(src, dst):
    """src -> dst with the comment lines and only the KEEP columns (and their _mean/_sd/_se/_lo95/
    _hi95 in ensemble files): what this study and `dem model` read, a fraction of the bytes."""
    with open(src, newline="") as fh:
        lines = fh.read().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.reader(ln for ln in lines if ln and not ln.startswith("#")))
    keep = [k for k, name in enumerate(rows[0]) if name in KEEP or name.rsplit("_", 1)[0] in KEEP]
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    with open(dst + ".part", "w", newline="") as fh:
        fh.write("\n".join(comments + [f"# trimmed copy of {os.path.relpath(src)} (columns {', '.join(rows[0][k] for k in keep)})"]) + "\n")
        csv.writer(fh, lineterminator="\n").writerows([[r[k] for k in keep] for r in rows])
    os.replace(dst + ".part", dst)


def store(folder, dst):
    """A trimmed copy of one ensemble folder for data/: scene, ensemble means, fit tables, and per
    member the isotropic unloading branch and the mode curves (the checkpoints and plots stay out)."""
    import shutil
    os.makedirs(dst, exist_ok=True)
    shutil.copy(os.path.join(folder, "scene.toml"), dst)
    for sub in ("fit",):
        if os.path.isdir(os.path.join(folder, sub)):
            shutil.copytree(os.path.join(folder, sub), os.path.join(dst, sub), dirs_exist_ok=True)
    for f in glob.glob(os.path.join(folder, "ensemble", "*")):
        name = os.path.basename(f)
        if name.endswith(".csv") and not name.startswith("members"):
            trim_csv(f, os.path.join(dst, "ensemble", name))
        elif name.startswith("members"):
            shutil.copy(f, os.path.join(dst, "ensemble", name))
    for m in glob.glob(os.path.join(folder, "members", "m*")):
        b = os.path.basename(m)
        for f in glob.glob(os.path.join(m, "prep", "cycle_unloading.csv")) + glob.glob(os.path.join(m, "deviatoric", "*.csv")):
            trim_csv(f, os.path.join(dst, "members", b, os.path.basename(os.path.dirname(f)), os.path.basename(f)))


def source_path(folder, a):
    """Where the summary's data lie, relative to the summary's folder (a stored copy if --store made one), so
    that a stored study names its own folders wherever it is cloned."""
    if a.store:
        folder = os.path.join(a.store, f"mu_{friction_of(folder):g}")
    return os.path.relpath(folder, a.out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="+", help="ensemble folders (dem ensemble --out), one per friction coefficient")
    ap.add_argument("--out", required=True, help="folder for summary.{csv,md,json} and the figures")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--store", metavar="DIR", help="also copy each folder, trimmed, to DIR/mu_MU (for data/)")
    a = ap.parse_args(argv)
    for f in a.folders:
        if not os.path.isfile(os.path.join(f, "scene.toml")):
            sys.exit(f"friction_study: {f} is not an ensemble folder (no scene.toml): give `dem ensemble --out` folders")
    rows = [r for f in a.folders for r in summarise(f)]
    mus = [friction_of(f) for f in a.folders]
    if len(set(mus)) != len(mus):
        sys.exit(f"friction_study: two folders have the same friction coefficient ({sorted(mus)}): give one per mu")
    write_tables(rows, a.out)
    write_headline(rows, a.out)
    if a.store:
        for f in a.folders:
            store(f, os.path.join(a.store, f"mu_{friction_of(f):g}"))
    tmp = os.path.join(a.out, "summary.json.part")
    with open(tmp, "w") as fh:
        json.dump({"folders": {f"{friction_of(f):g}": source_path(f, a) for f in a.folders},
                   "rows": [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()}
                            for r in rows]}, fh, indent=1)
    os.replace(tmp, os.path.join(a.out, "summary.json"))
    if not a.no_plots:
        plot_stress_ratio(rows, a.out, a.folders[0])
        plot_isotropic(rows, a.out, a.folders[0])
        plot_dilatancy(rows, a.out, a.folders[0])
        nus = sorted({r["nu"] for r in rows if r["mode"] == "D2"})
        for nu in nus[:1] + nus[-1:] if nus else []:
            plot_curves(a.folders, a.out, nu)
    print(f"friction_study: {len(rows)} rows from {len(a.folders)} ensembles -> {a.out}/summary.{{csv,md,json}}",
          file=sys.stderr)


if __name__ == "__main__":
    main()
