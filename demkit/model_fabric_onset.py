"""The onset of the deviatoric fabric in D2 and D3, per packing, from the friction study's stored member
curves (issue 31, third round; docs/model.md, "The fabric's onset: why one gate cannot serve both densities").

    python3 -m demkit.model_fabric_onset [--store data/friction_n1000] [--out DIR] [--level 0.2]

For every mu, nu and packing: the member's D2 and D3 curves (deviatoric/D[23]_phiX.csv) resampled on
eps_d = 0, 0.001, ..., 0.3 and smoothed by a 9-point running mean (the fabric's start value is the
packing's random anisotropy, noisy at the 0.005 level); F0 the mean of the two curves' start values;
the onset of a curve is the strain where F_dev - F0 first reaches `level` times the D2 rise at the end
(the mean of eps_d >= 0.27), the same absolute step for D2 and D3 of a packing. Per packing: the two
onsets and their ratio; the extension (minor principal) strain at each onset, eps_on/sqrt(3) in D2,
eps_on/3 in D3 (docs/model.md: c_3 = 1/sqrt(3), 1/3); the mean contact overlap over the diameter at the
start, delta/d = pi p*/(C nu) (Hookean contacts; fit/include/demfit/model.hpp `mean_overlap`); the
mobilisation s_dev/s_dev(end) at each onset; the rise of D3 over that of D2 at the end and the ratio
of their largest slopes. Mean and standard error over the packings where the onset was reached (the
count is given where some D3 curves at nu = 0.80 had not reached it by eps_d = 0.3).
Writes DIR/fabric_onset.{md,csv}.
"""
import argparse
import csv
import glob
import os

import numpy as np

from demkit.atomic import write_atomic

MUS = ("0", "0.01", "0.1", "0.3", "0.5", "1")
NUS = ("0.690", "0.740", "0.800")
GRID = np.linspace(0.0, 0.3, 301)
C3 = {"D2": 1 / np.sqrt(3.0), "D3": 1 / 3.0}   # minor principal strain per unit eps_d


def read_curve(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#") and ln.strip()))
    head = rows[0]
    data = np.array([[float(v) for v in r] for r in rows[1:]])
    return {h: data[:, i] for i, h in enumerate(head)}


def smooth(y, w=9):
    pad = np.concatenate([np.full(w // 2, y[0]), y, np.full(w // 2, y[-1])])
    return np.convolve(pad, np.ones(w) / w, "valid")


def crossing(y, level):
    """First eps on GRID where y reaches level (linear between grid points); nan if never."""
    i = np.nonzero(y >= level)[0]
    if len(i) == 0:
        return np.nan
    i = i[0]
    if i == 0:
        return 0.0
    return GRID[i - 1] + (level - y[i - 1]) / (y[i] - y[i - 1]) * (GRID[i] - GRID[i - 1])


def packing_row(member, nu, level):
    c = {m: read_curve(os.path.join(member, "deviatoric", f"{m}_phi{nu}.csv")) for m in ("D2", "D3")}
    F = {m: smooth(np.interp(GRID, c[m]["eps_d"], c[m]["F_dev"])) for m in c}
    S = {m: smooth(np.interp(GRID, c[m]["eps_d"], c[m]["s_dev"])) for m in c}
    F0 = 0.5 * (F["D2"][0] + F["D3"][0])
    end = {m: F[m][GRID >= 0.27].mean() for m in c}
    s_end = {m: S[m][GRID >= 0.27].mean() for m in c}
    step = level * (end["D2"] - F0)
    p0, C0 = c["D2"]["p_star"][0], c["D2"]["C"][0]
    row = {"p_star": p0, "overlap": np.pi * p0 / (C0 * float(nu))}
    for m in c:
        on = crossing(F[m] - F0, step)
        row[f"on_{m}"] = on
        row[f"ext_{m}"] = C3[m] * on
        row[f"r_{m}"] = np.interp(on, GRID, S[m]) / s_end[m] if np.isfinite(on) else np.nan
        row[f"slope_{m}"] = np.max(np.gradient(F[m], GRID))
    row["ratio_on"] = row["on_D3"] / row["on_D2"]
    row["ext_D2_over_overlap"] = row["ext_D2"] / row["overlap"]
    row["ext_D3_over_overlap"] = row["ext_D3"] / row["overlap"]
    row["ratio_rise"] = (end["D3"] - F0) / (end["D2"] - F0)
    row["ratio_slope"] = row["slope_D3"] / row["slope_D2"]
    return row


COLS = (("p_star", "p*(0)"), ("overlap", "delta/d"), ("on_D2", "eps_on D2"), ("on_D3", "eps_on D3"),
        ("ratio_on", "D3/D2 onset"), ("ext_D2_over_overlap", "e3_on/delta D2"), ("ext_D3_over_overlap", "e3_on/delta D3"),
        ("r_D2", "s/s_end at onset D2"), ("r_D3", "s/s_end at onset D3"), ("ratio_rise", "D3/D2 rise at 0.27-0.3"),
        ("ratio_slope", "D3/D2 largest slope"))


def summary(store, level, mus=MUS, nus=NUS):
    out = []
    for mu in mus:
        members = sorted(glob.glob(os.path.join(store, f"mu_{mu}", "members", "m*")))
        for nu in nus:
            rows = [packing_row(m, nu, level) for m in members]
            rec = {"mu": mu, "nu": nu, "K": len(rows)}
            for key, _ in COLS:
                v = np.array([r[key] for r in rows])
                n = int(np.isfinite(v).sum())
                rec[key] = (np.nanmean(v) if n else np.nan, np.nanstd(v, ddof=1) / np.sqrt(n) if n > 1 else np.nan, n)
            out.append(rec)
    return out


def write(recs, out_dir, level):
    def cell(v):
        m, se, n = v
        k = recs[0]["K"]
        return f"{m:.3g} ± {se:.2g}" + ("" if n == k else f" ({n})")
    md = [f"<!-- demkit/model_fabric_onset.py --level {level}: per mu and nu, mean ± SE over the packings; onset = "
          f"F_dev - F0 reaches {level} x the D2 rise at eps_d = 0.27-0.3; (n): packings that reached it -->\n",
          "| μ | ν | " + " | ".join(name for _, name in COLS) + " |\n", "|---|---|" + "---|" * len(COLS) + "\n"]
    lines = ["mu,nu," + ",".join(f"{k}_mean,{k}_se,{k}_n" for k, _ in COLS) + "\n"]
    for r in recs:
        md.append(f"| {r['mu']} | {float(r['nu']):.2f} | " + " | ".join(cell(r[k]) for k, _ in COLS) + " |\n")
        lines.append(f"{r['mu']},{r['nu']}," + ",".join(f"{r[k][0]:.6g},{r[k][1]:.6g},{r[k][2]}" for k, _ in COLS) + "\n")
    os.makedirs(out_dir, exist_ok=True)
    write_atomic(os.path.join(out_dir, "fabric_onset.md"), "".join(md))
    write_atomic(os.path.join(out_dir, "fabric_onset.csv"), "".join(lines))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", default="data/friction_n1000")
    ap.add_argument("--out", default="data/friction_n1000/model_friction")
    ap.add_argument("--level", type=float, default=0.2, help="onset: this fraction of the D2 rise (0 < level < 1)")
    a = ap.parse_args(argv)
    if not 0 < a.level < 1:
        raise SystemExit(f"model_fabric_onset: --level {a.level}: give a fraction between 0 and 1")
    if not glob.glob(os.path.join(a.store, "mu_*", "members", "m*")):
        raise SystemExit(f"model_fabric_onset: no members under {a.store}/mu_*/members (--store: the friction study)")
    write(summary(a.store, a.level), a.out, a.level)


if __name__ == "__main__":
    main()
