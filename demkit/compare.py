"""Compare two curve CSVs (ours vs YADE, or two runs of one code): `dem compare A.csv B.csv`.

Both curves are put on a common eps_d grid (the overlap of their ranges, linear interpolation)
and the largest and RMS differences of p, s_dev, F_dev, C and eps_v are reported:
  p      relative to the mean p of A over the grid
  s_dev  absolute, and relative to A's plateau (mean over the second half of the grid)
  F_dev  likewise
  C      absolute
  eps_v  absolute (the volume change of stress-controlled tests; 0 for both at constant volume)
Exit code 0 when every difference is within its tolerance, 4 otherwise, 1 on bad input
(eps_d must increase from row to row in both curves).
Default tolerances (see docs/yade.md for how they were calibrated): p 3 % (max), s_dev 15 %
and F_dev 25 % of the plateau (RMS), C 0.15 (RMS), eps_v 5e-4 (RMS; 7x the floor of a
1000-sphere triaxial test, docs/control.md); and the common eps_d range must cover at
least 90 % of each curve's range (a curve that stopped early is compared over its end only,
which is not a comparison of the two curves).
"""
import argparse
import os
import sys

import numpy as np

from demkit.atomic import finite_or_null, write_json_atomic  # noqa: F401 (finite_or_null: also imported from here)
from demkit.curves import read_curve, require, CurveError

QUANTITIES = ("p_Pa", "s_dev", "F_dev", "C", "eps_v")


def check_increasing(curve, name):
    """eps_d must increase strictly from row to row (interpolation needs it)."""
    e = curve["eps_d"]
    bad = np.nonzero(~(np.diff(e) > 0))[0]
    if len(e) < 2 or len(bad):
        row = int(bad[0]) + 2 if len(bad) else 1
        raise CurveError(f"{name}: eps_d does not increase at data row {row} "
                         f"({'fewer than 2 rows' if len(e) < 2 else f'{e[row - 2]:.6g} then {e[row - 1]:.6g}'}): "
                         "not a deviatoric curve of one run")


def coverage(a, b, lo, hi):
    """Fraction of each curve's eps_d range that the common range [lo, hi] covers."""
    ranges = [float(c["eps_d"].max() - c["eps_d"].min()) for c in (a, b)]
    return min((hi - lo) / r if r > 0 else 0.0 for r in ranges)


def compare(a, b, npoints=200):
    """Return a dict of differences between curve dicts a and b (see module doc)."""
    require(a, ("eps_d",) + QUANTITIES, "first curve")
    require(b, ("eps_d",) + QUANTITIES, "second curve")
    check_increasing(a, "first curve")
    check_increasing(b, "second curve")
    lo = max(a["eps_d"].min(), b["eps_d"].min())
    hi = min(a["eps_d"].max(), b["eps_d"].max())
    if not hi > lo:
        raise CurveError("the two curves do not overlap in eps_d")
    grid = np.linspace(lo, hi, npoints)
    res = {"eps_d_range": [float(lo), float(hi)], "points": npoints, "coverage": coverage(a, b, lo, hi)}
    for q in QUANTITIES:
        ya = np.interp(grid, a["eps_d"], a[q])
        yb = np.interp(grid, b["eps_d"], b[q])
        d = yb - ya
        entry = {"max_abs": float(np.max(np.abs(d))), "rms_abs": float(np.sqrt(np.mean(d * d)))}
        if q == "p_Pa":
            scale = float(np.mean(np.abs(ya)))
            entry.update(max_rel=entry["max_abs"] / scale, rms_rel=entry["rms_abs"] / scale, scale=scale)
        elif q in ("s_dev", "F_dev"):
            plateau = float(np.mean(ya[grid >= 0.5 * (lo + hi)]))
            entry.update(plateau_a=plateau, plateau_b=float(np.mean(yb[grid >= 0.5 * (lo + hi)])),
                         max_rel=entry["max_abs"] / plateau, rms_rel=entry["rms_abs"] / plateau)
        res[q] = entry
    return res, grid


def verdict(res, tol):
    checks = {
        "p_Pa": ("max_rel", tol["p"]),
        "s_dev": ("rms_rel", tol["s_dev"]),
        "F_dev": ("rms_rel", tol["F_dev"]),
        "C": ("rms_abs", tol["C"]),
        "eps_v": ("rms_abs", tol["eps_v"]),
    }
    out = {}
    for q, (key, limit) in checks.items():
        value = float(res[q][key])               # builtin types: --json writes them (numpy bools it cannot)
        out[q] = {"measure": key, "value": value, "tolerance": limit, "ok": bool(value <= limit)}
    cov = tol.get("coverage", 0.9)
    value = float(res["coverage"])
    out["coverage"] = {"measure": "min", "value": value, "tolerance": cov, "ok": bool(value >= cov)}
    return out


OVERLAY_LABELS = {"p_Pa": "pressure $p$ [Pa]", "s_dev": r"$s_\mathrm{dev} = \sigma_\mathrm{dev}/p$",
                  "F_dev": r"$F_\mathrm{dev}$", "C": "coordination number $C$",
                  "eps_v": r"volumetric strain $\varepsilon_v$"}


def overlay(a, b, labels, path):
    """Both curves against eps_d, one panel per quantity (2 x 2 or 2 x 3); a quantity both hold
    constant (eps_v at constant volume: round-off) is left out and the title says so."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from demkit.figures import save
    shown, constant = [], []
    for q in QUANTITIES:
        va, vb = np.asarray(a[q], float), np.asarray(b[q], float)
        scale = max(np.max(np.abs(va)), np.max(np.abs(vb)), 1e-300)
        if q == "eps_v" and np.ptp(va) <= 1e-9 and np.ptp(vb) <= 1e-9:
            constant.append(r"$\varepsilon_v$ = 0 in both (constant volume)")
        elif np.ptp(va) <= 1e-12 * scale and np.ptp(vb) <= 1e-12 * scale:
            constant.append(f"{q} constant in both")
        else:
            shown.append(q)
    ncols = 2 if len(shown) <= 4 else 3
    nrows = (len(shown) + ncols - 1) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols, 2.8 * nrows + 0.6), sharex=True, squeeze=False)
    for ax, q in zip(axes.flat, shown):
        ax.plot(a["eps_d"], a[q], "-", lw=1.1, color="#1f77b4", label=labels[0])
        ax.plot(b["eps_d"], b[q], "--", lw=1.1, color="#d62728", label=labels[1])
        ax.set_ylabel(OVERLAY_LABELS.get(q, q), fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(shown):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(r"deviatoric strain $\varepsilon_d$")
    handles, labs = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labs, loc="lower center", ncol=2, fontsize=8, frameon=False)
    if constant:
        fig.suptitle("; ".join(constant), fontsize=8)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    stem = path[:-4] if path.endswith(".png") else path
    save(fig, stem)


def short_labels(first, second):
    """The two file names, or their paths below the common folder when the names are equal."""
    a, b = os.path.basename(first), os.path.basename(second)
    if a != b:
        return [a, b]
    common = os.path.commonpath([os.path.abspath(first), os.path.abspath(second)])
    return [os.path.relpath(os.path.abspath(first), common), os.path.relpath(os.path.abspath(second), common)]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="dem compare", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("first", help="curve CSV (ours: deviatoric/MODE_phiX.csv, or `dem mode --out`)")
    ap.add_argument("second", help="curve CSV with the same columns (e.g. yade_ref/run_mode.py's)")
    ap.add_argument("--labels", default=None,
                    help="legend labels of the two curves, comma-separated (default: the file names)")
    ap.add_argument("--plot", metavar="OUT.png", help="write an overlay plot (OUT.png and OUT.svg)")
    ap.add_argument("--json", metavar="OUT.json", help="write the differences as JSON")
    ap.add_argument("--tol-p", type=float, default=0.03, help="largest difference of p relative to its mean (default: %(default)s)")
    ap.add_argument("--tol-s-dev", type=float, default=0.15,
                    help="RMS difference of s_dev relative to its plateau (default: %(default)s)")
    ap.add_argument("--tol-f-dev", type=float, default=0.25,
                    help="RMS difference of F_dev relative to its plateau (default: %(default)s)")
    ap.add_argument("--tol-c", type=float, default=0.15, help="RMS difference of C (default: %(default)s)")
    ap.add_argument("--tol-eps-v", type=float, default=5e-4,
                    help="RMS |d eps_v| (dilatancy of stress-controlled tests; 0 for both at constant volume)")
    ap.add_argument("--min-coverage", type=float, default=0.9,
                    help="smallest fraction of each curve's eps_d range the comparison must cover")
    a = ap.parse_args(argv)
    try:
        ca, cb = read_curve(a.first), read_curve(b_path := a.second)
        res, _ = compare(ca, cb)
    except CurveError as e:
        print(f"dem compare: {e}", file=sys.stderr)
        return 1
    tol = {"p": a.tol_p, "s_dev": a.tol_s_dev, "F_dev": a.tol_f_dev, "C": a.tol_c, "eps_v": a.tol_eps_v,
           "coverage": a.min_coverage}
    v = verdict(res, tol)
    res["verdict"] = v
    print(f"compare {a.first} vs {b_path} over eps_d in [{res['eps_d_range'][0]:.4f}, {res['eps_d_range'][1]:.4f}]")
    print(f"{'quantity':8s} {'max |d|':>12s} {'rms |d|':>12s} {'checked':>10s} {'value':>10s} {'tolerance':>10s}  ok")
    for q in QUANTITIES:
        r = res[q]
        print(f"{q:8s} {r['max_abs']:12.4g} {r['rms_abs']:12.4g} {v[q]['measure']:>10s} {v[q]['value']:10.4g} "
              f"{v[q]['tolerance']:10.4g}  {'yes' if v[q]['ok'] else 'NO'}")
    c = v["coverage"]
    print(f"{'coverage':8s} {'':12s} {'':12s} {'min':>10s} {c['value']:10.4g} {c['tolerance']:10.4g}  "
          f"{'yes' if c['ok'] else 'NO (the curves cover different eps_d ranges)'}")
    if a.plot:
        overlay(ca, cb, a.labels.split(",") if a.labels else short_labels(a.first, a.second), a.plot)
    if a.json:
        write_json_atomic(a.json, res, indent=2)   # NaN/inf: null (valid JSON)
    return 0 if all(x["ok"] for x in v.values()) else 4


if __name__ == "__main__":
    sys.exit(main())
