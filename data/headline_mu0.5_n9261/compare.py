"""An N = 9261 frictional headline (mu = 0.5, or --mu) against (a) the N = 1000 friction study at
the same mu and nu and (b) the frictionless N = 9261 Figure 3 at the nearest nu: per-packing levels
(model-free, the friction study's definitions, demkit.friction_study), mean +- SE over packings,
their differences with the combined SE, the curve-wise difference in combined SEs, D3 - D2 paired
per packing (the same packing sheared both ways) at both N, and two figures with 95 % bands.

    PYTHONPATH=. /usr/bin/python3 data/headline_mu0.5_n9261/compare.py [--store runs/headline_mu0.5] \
        --headline data/headline_mu0.5_n9261 --n1000 data/friction_n1000/mu_0.5 \
        --frictionless data/figure3_n9261 --out data/headline_mu0.5_n9261/compare [--mu 0.5]

Levels per packing: s_cs, F_cs, p*_cs = window means over eps_d in [0.25, 0.30] (the friction
study's critical-state window); the same over [0.35, 0.40] where both curves reach 0.4 (the
headline and Figure 3); s_peak, the maximum of s_dev when the curve has passed it (else none).
"""
import argparse
import csv
import glob
import json
import math
import os
import sys

import numpy as np

from demkit import figures
from demkit.curves import read_curve
from demkit import friction_study
from demkit.friction_study import window_mean, peak

WINDOWS = {"cs": (0.25, 0.30), "late": (0.35, 0.40)}
QUANTITIES = ("s_dev", "F_dev", "p_star")
NUS = ("0.690", "0.740", "0.800")
# Figure 3's checkpoints nearest to ours (0.80: 0.819 is 0.019 away, 0.78 is 0.020; both shown in the table)
NEAREST_FRICTIONLESS = {"0.690": ["0.690"], "0.740": ["0.750", "0.720"], "0.800": ["0.819", "0.780"]}
MU = "0.5"   # the headline's friction coefficient, for the labels (--mu)


def member_curves(folder, mode, nu):
    """The packings' curves of one cell: members/mKKK/deviatoric/MODE_phiNU.csv (dem ensemble) or
    members/mKKK/MODE_phiNU.csv (the layout of dem 0.1, Figure 3)."""
    paths = sorted(glob.glob(os.path.join(folder, "members", "m*", "deviatoric", f"{mode}_phi{nu}.csv")))
    if not paths:
        paths = sorted(glob.glob(os.path.join(folder, "members", "m*", f"{mode}_phi{nu}.csv")))
    return [read_curve(p) for p in paths]


def levels(curve):
    """{quantity_window: value, s_peak, I_max} of one packing's curve (NaN where the curve is too short)."""
    e = curve["eps_d"]
    out = {f"{q}_{w}": window_mean(e, curve[q], *lim) if e[-1] >= lim[1] - 1e-9 else math.nan
           for q in QUANTITIES for w, lim in WINDOWS.items()}
    out["s_peak"] = peak(e, curve["s_dev"])[0]
    if "inertial_number" in curve:
        out["I_max"] = float(np.max(curve["inertial_number"][e >= 0.01]))
    return out


def stats_of(values):
    """(mean, se, K) over the finite values."""
    v = np.array([x for x in values if math.isfinite(x)])
    k = len(v)
    if k == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), (float(v.std(ddof=1) / math.sqrt(k)) if k > 1 else math.nan), k


def cell(folder, mode, nu):
    per = [levels(c) for c in member_curves(folder, mode, nu)]
    keys = sorted({k for p in per for k in p})
    return {k: stats_of([p.get(k, math.nan) for p in per]) for k in keys}


def fmt(m, se):
    if not math.isfinite(m):
        return "–"
    if not math.isfinite(se) or se <= 0:
        return f"{m:.4g}"
    digits = max(0, -int(math.floor(math.log10(se))) + (1 if f"{se:.1e}"[0] == "1" else 0))
    return f"{m:.{digits}f} ± {se:.{digits}f}"


def diff(a, b):
    """(difference a - b, its combined SE, z) of two (mean, se, K)."""
    d = a[0] - b[0]
    s = math.hypot(a[1], b[1])
    return d, s, d / s if s > 0 else math.nan


def curve_difference(fa, fb, mode, nu_a, nu_b, q, emax):
    """Largest and RMS |mean_a - mean_b| / sqrt(se_a^2 + se_b^2) over eps_d in [0.02, emax] of the
    ensemble-mean curves (ensemble/MODE_phiNU.csv), b interpolated on a's grid."""
    a = read_curve(os.path.join(fa, "ensemble", f"{mode}_phi{nu_a}.csv"))
    b = read_curve(os.path.join(fb, "ensemble", f"{mode}_phi{nu_b}.csv"))
    e = a["eps_d"]
    sel = (e >= 0.02) & (e <= min(emax, b["eps_d"][-1], e[-1]))
    mb = np.interp(e[sel], b["eps_d"], b[f"{q}_mean"])
    sb = np.interp(e[sel], b["eps_d"], b[f"{q}_se"])
    z = (a[f"{q}_mean"][sel] - mb) / np.hypot(a[f"{q}_se"][sel], sb)
    return float(np.max(np.abs(z))), float(np.sqrt(np.mean(z ** 2)))


def table_finite_size(head, n1000):
    rows, lines = [], ["| mode | ν | quantity | N = 9261 (K) | N = 1000 (K) | difference ± combined SE | z | curve: max, RMS of |Δ|/SE | SD ratio 1000/9261 |",
                       "|---|---|---|---|---|---|---|---|---|"]
    for mode in ("D2", "D3"):
        for nu in NUS:
            a, b = cell(head, mode, nu), cell(n1000, mode, nu)
            for key, q in (("s_dev_cs", "s_dev"), ("F_dev_cs", "F_dev"), ("p_star_cs", "p_star"), ("s_peak", None)):
                if key not in a or key not in b:
                    continue
                d, s, z = diff(a[key], b[key])
                zc = curve_difference(head, n1000, mode, nu, nu, q, 0.30) if q else (math.nan, math.nan)
                # spread between packings: sqrt(9261/1000) = 3.04 if it falls as 1/sqrt(N)
                sd_ratio = (b[key][1] * math.sqrt(b[key][2])) / (a[key][1] * math.sqrt(a[key][2]))
                rows.append({"mode": mode, "nu": nu, "quantity": key, "mean_9261": a[key][0], "se_9261": a[key][1],
                             "K_9261": a[key][2], "mean_1000": b[key][0], "se_1000": b[key][1], "K_1000": b[key][2],
                             "difference": d, "se_difference": s, "z": z, "curve_max_z": zc[0], "curve_rms_z": zc[1],
                             "sd_ratio": sd_ratio})
                lines.append(f"| {mode} | {nu} | {key} | {fmt(*a[key][:2])} ({a[key][2]}) | {fmt(*b[key][:2])} ({b[key][2]}) "
                             f"| {fmt(d, s)} | {z:.1f} | {zc[0]:.1f}, {zc[1]:.1f} | {sd_ratio:.1f} |")
    return rows, lines


def table_frictionless(head, fig3):
    rows, lines = [], [f"| mode | ν (μ = {MU}) | ν (μ = 0) | quantity | μ = {MU}, N = 9261 | μ = 0, N = 9261 | ratio |",
                       "|---|---|---|---|---|---|---|"]
    for mode in ("D2", "D3"):
        for nu in NUS:
            a = cell(head, mode, nu)
            for nu0 in NEAREST_FRICTIONLESS[nu]:
                b = cell(fig3, mode, nu0)
                for key in ("s_dev_cs", "s_dev_late", "F_dev_cs", "F_dev_late", "p_star_cs", "p_star_late", "s_peak"):
                    if key not in a or key not in b:
                        continue
                    r = a[key][0] / b[key][0] if b[key][0] else math.nan
                    rows.append({"mode": mode, "nu": nu, "nu_frictionless": nu0, "quantity": key, f"mean_mu{MU}": a[key][0],
                                 f"se_mu{MU}": a[key][1], f"K_mu{MU}": a[key][2], "mean_mu0": b[key][0], "se_mu0": b[key][1],
                                 "K_mu0": b[key][2], "ratio": r})
                    lines.append(f"| {mode} | {nu} | {nu0} | {key} | {fmt(*a[key][:2])} | {fmt(*b[key][:2])} | {r:.2f} |")
    return rows, lines


def fit_rows(folder):
    """{(mode, nu as '0.690', quantity): row} of folder/fit/parameters.csv (dem fit)."""
    path = os.path.join(folder, "fit", "parameters.csv")
    if not os.path.isfile(path):
        return {}
    with open(path, newline="") as fh:
        return {(r["mode"], f"{float(r['nu']):.3f}", r["quantity"]): r for r in csv.DictReader(fh)}


def fit_cell(r):
    """'x_max ± se (model; peak x_peak, critical x_crit)' of one fit row, '–' without one."""
    if r is None:
        return "–"
    num = lambda k: float(r[k]) if r.get(k) not in (None, "") else math.nan
    out = fmt(num("x_max"), num("se_x_max"))
    extra = [r.get("model", "")]
    if math.isfinite(num("x_peak")):
        extra.append(f"peak {fmt(num('x_peak'), num('se_x_peak'))}")
    if math.isfinite(num("x_crit")) if "x_crit" in r else False:
        extra.append(f"critical {fmt(num('x_crit'), num('se_x_crit'))}")
    if r.get("warnings"):
        extra.append("⚠")
    if r.get("usable") == "no":
        extra.append("not usable")
    return f"{out} ({'; '.join(e for e in extra if e)})"


def table_fits(head, fig3):
    """The fitted saturation levels (dem fit, jackknife SE) of s_dev and F_dev, the headline's mu against mu = 0."""
    a, b = fit_rows(head), fit_rows(fig3)
    lines = [f"| mode | ν (μ = {MU}) | ν (μ = 0) | quantity | x_max, μ = {MU} | x_max, μ = 0 |", "|---|---|---|---|---|---|"]
    for mode in ("D2", "D3"):
        for nu in NUS:
            for nu0 in NEAREST_FRICTIONLESS[nu][:1]:
                for q in ("s_dev", "F_dev"):
                    lines.append(f"| {mode} | {nu} | {nu0} | {q} | {fit_cell(a.get((mode, nu, q)))} | {fit_cell(b.get((mode, nu0, q)))} |")
    return lines


def table_d3_minus_d2(folders):
    """D3 - D2 of each level, paired per packing (member k of D2 and of D3 is the same packing from the
    same checkpoint): mean +- SE over the packings and z, for each (label, folder)."""
    rows, lines = [], ["| N | ν | quantity | D3 − D2 (paired, mean ± SE) | K | z |", "|---|---|---|---|---|---|"]
    for label, folder in folders:
        for nu in NUS:
            d2 = [levels(c) for c in member_curves(folder, "D2", nu)]
            d3 = [levels(c) for c in member_curves(folder, "D3", nu)]
            if len(d2) != len(d3):
                continue
            for key in ("s_dev_cs", "F_dev_cs", "p_star_cs", "s_dev_late", "F_dev_late"):
                m, se, k = stats_of([b.get(key, math.nan) - a.get(key, math.nan) for a, b in zip(d2, d3)])
                if k < 2:
                    continue
                z = m / se if se > 0 else math.nan
                rows.append({"N": label, "nu": nu, "quantity": key, "d3_minus_d2": m, "se": se, "K": k, "z": z})
                lines.append(f"| {label} | {nu} | {key} | {fmt(m, se)} | {k} | {z:.1f} |")
    return rows, lines


def inertial(head):
    lines = ["| mode | ν | largest inertial number I over ε_d ≥ 0.01 (mean ± SE over packings) |", "|---|---|---|"]
    out = []
    for mode in ("D2", "D3"):
        for nu in NUS:
            a = cell(head, mode, nu)
            if "I_max" in a:
                lines.append(f"| {mode} | {nu} | {a['I_max'][0]:.2e} ± {a['I_max'][1]:.1e} |")
                out.append({"mode": mode, "nu": nu, "I_max": a["I_max"][0], "se": a["I_max"][1]})
    return out, lines


def band(ax, c, q, color, ls, label):
    ax.plot(c["eps_d"], c[f"{q}_mean"], color=color, ls=ls, label=label, lw=1.2)
    ax.fill_between(c["eps_d"], c[f"{q}_lo95"], c[f"{q}_hi95"], color=color, alpha=0.25 if ls == "-" else 0.12, lw=0)


def plot(pairs, out, stem, run, titles):
    """Rows: s_dev, F_dev, p*; columns: the nu of the headline; per panel each (folder, nu map, colour,
    style, label) of pairs as mean with its 95 % band, D2 and D3 both."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 3, figsize=(11, 8.5), sharex=True)
    for j, nu in enumerate(NUS):
        for i, q in enumerate(QUANTITIES):
            ax = axes[i, j]
            for folder, numap, ls, label in pairs:
                for mode, color in (("D2", "C0"), ("D3", "C3")):
                    path = os.path.join(folder, "ensemble", f"{mode}_phi{numap[nu]}.csv")
                    if os.path.isfile(path):
                        band(ax, read_curve(path), q, color, ls, f"{mode}, {label}")
            if i == 0:
                ax.set_title(titles[nu], fontsize=9)
            if i == 2:
                ax.set_xlabel(r"$\varepsilon_d$")
            if j == 0:
                ax.set_ylabel(rf"${figures.SYMBOL[q]}$")
    figures.legend_if_any(axes[0, 0], fontsize=7)
    fig.tight_layout()
    figures.save(fig, os.path.join(out, stem), run)
    plt.close(fig)


def write(path, text):
    with open(path + ".part", "w") as fh:
        fh.write(text)
    os.replace(path + ".part", path)


def write_csv(path, rows):
    with open(path + ".part", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    os.replace(path + ".part", path)


def store(run, dst):
    """A trimmed copy of the ensemble folder run in dst (demkit.friction_study.store: scene, ensemble
    means, fit tables, each member's unloading branch and mode curves, here with the inertial number
    and the kinetic pressure kept), and its plots/."""
    import shutil
    friction_study.KEEP.extend(k for k in ("inertial_number", "p_kin_Pa") if k not in friction_study.KEEP)
    friction_study.store(run, dst)
    if os.path.isdir(os.path.join(run, "plots")):
        shutil.copytree(os.path.join(run, "plots"), os.path.join(dst, "plots"), dirs_exist_ok=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--headline", required=True)
    ap.add_argument("--n1000", required=True)
    ap.add_argument("--frictionless", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--mu", default="0.5", help="the headline's friction coefficient, for the labels")
    ap.add_argument("--store", metavar="RUN", help="first copy the ensemble folder RUN (dem ensemble --out), trimmed, to --headline")
    a = ap.parse_args(argv)
    global MU
    MU = a.mu
    if a.store:
        store(a.store, a.headline)
    for f in (a.headline, a.n1000, a.frictionless):
        if not os.path.isdir(os.path.join(f, "ensemble")):
            sys.exit(f"compare: {f} has no ensemble/ folder: give a stored ensemble (dem ensemble --out or data/...)")
    os.makedirs(a.out, exist_ok=True)
    fs_rows, fs_lines = table_finite_size(a.headline, a.n1000)
    fl_rows, fl_lines = table_frictionless(a.headline, a.frictionless)
    in_rows, in_lines = inertial(a.headline)
    fit_lines = table_fits(a.headline, a.frictionless)
    dd_rows, dd_lines = table_d3_minus_d2([("9261", a.headline), ("1000", a.n1000)])
    write_csv(os.path.join(a.out, "finite_size.csv"), fs_rows)
    write_csv(os.path.join(a.out, "vs_frictionless.csv"), fl_rows)
    write_csv(os.path.join(a.out, "d3_minus_d2.csv"), dd_rows)
    text = [f"# N = 9261 against N = 1000 at μ = {MU} (same scene but N; levels: means over ε_d ∈ [0.25, 0.30] per packing)",
            "", *fs_lines, "",
            f"# D3 − D2 at μ = {MU}, paired per packing (_late: ε_d ∈ [0.35, 0.40], N = 9261 only)", "", *dd_lines, "",
            f"# μ = {MU} against μ = 0 (Figure 3), both N = 9261 (_cs: ε_d ∈ [0.25, 0.30], _late: [0.35, 0.40])",
            "", *fl_lines, "",
            "# Fitted levels (dem fit: the saturating law's x_max ± jackknife SE; the chosen model, its peak and critical state; ⚠: the fit warns, parameters.md)",
            "", *fit_lines, "", "# Inertial number of the headline (quasi-static warning above 1e-3)", "", *in_lines, ""]
    write(os.path.join(a.out, "compare.md"), "\n".join(text))
    write(os.path.join(a.out, "compare.json"), json.dumps(
        {"finite_size": fs_rows, "d3_minus_d2": dd_rows, "vs_frictionless": fl_rows, "inertial": in_rows}, indent=1,
        default=lambda x: None))
    if not a.no_plots:
        same = {nu: nu for nu in NUS}
        near = {nu: v[0] for nu, v in NEAREST_FRICTIONLESS.items()}
        plot([(a.n1000, same, "--", "N = 1000 (K = 8)"), (a.headline, same, "-", "N = 9261 (K = 4)")], a.out,
             "finite_size", a.headline, {nu: rf"$\mu$ = {MU}, $\nu$ = {nu}" for nu in NUS})
        plot([(a.frictionless, near, "--", r"$\mu$ = 0"), (a.headline, same, "-", rf"$\mu$ = {MU}")], a.out,
             "vs_frictionless", a.headline, {nu: rf"N = 9261, $\nu$ = {nu} ($\mu$ = {MU}), {near[nu]} ($\mu$ = 0)" for nu in NUS})
    print("\n".join(text))


if __name__ == "__main__":
    main()
