"""The D3/D2 fabric rise at equal strain and at equal extension strain, and the stress peak, per packing,
from the friction study's stored member curves (issue 31, fourth round; docs/model.md, "The fabric's
rate, and the default rule").

    python3 -m demkit.model_fabric_rate [--store data/friction_n1000] [--out DIR]

Curves resampled on eps_d = 0, 0.001, ..., 0.3 and smoothed by a 9-point running mean
(demkit.model_fabric_onset). Per packing, mu >= 0.1, every nu:
  fabric_rate.{md,csv}: (F - F0) of D3 at eps_d = 0.3 over D2's at eps_d = 0.3 (equal eps_d) and over
  D2's at 0.3/sqrt(3) (equal extension, i.e. minor principal, strain: eps/sqrt(3) in D2, eps/3 in D3),
  and the ratio of the largest slopes dF/deps_d;
  stress_peak.{md,csv}: for D2, D3 and isobaric D2, the peak of s_dev minus its mean over
  eps_d >= 0.27 (biased up by the noise of a maximum), the strain of the peak, F at the peak over its
  end value, p* at the peak and at the end over p*(0), and nu at the end.
Mean and standard error over the packings.
"""
import argparse
import glob
import os

import numpy as np

from demkit.atomic import write_atomic
from demkit.model_fabric_onset import GRID, NUS, read_curve, smooth

MUS = ("0.1", "0.3", "0.5", "1")
END = GRID >= 0.27


def resampled(path):
    c = read_curve(path)
    x = c["eps_d_accumulated"] if "eps_d_accumulated" in c else c["eps_d"]
    return {q: smooth(np.interp(GRID, x, c[q])) for q in ("F_dev", "s_dev", "p_star", "nu") if q in c}


def rate_row(d2, d3):
    """(D3/D2 rise at equal eps_d, at equal extension strain, largest-slope ratio) of one packing."""
    r2, r3 = d2["F_dev"] - d2["F_dev"][0], d3["F_dev"] - d3["F_dev"][0]
    at_e3 = np.interp(GRID[-1] / np.sqrt(3.0), GRID, r2)
    slope = np.gradient(d3["F_dev"], GRID).max() / np.gradient(d2["F_dev"], GRID).max()
    return r3[-1] / r2[-1], r3[-1] / at_e3, slope


def peak_row(c):
    """(drop, eps at the peak, F_peak/F_end, p_peak/p0, p_end/p0, nu_end) of one curve."""
    i = int(np.argmax(c["s_dev"]))
    p = c["p_star"]
    return (c["s_dev"][i] - c["s_dev"][END].mean(), GRID[i], c["F_dev"][i] / c["F_dev"][END].mean(),
            p[i] / p[0], p[END].mean() / p[0], c["nu"][END].mean() if "nu" in c else np.nan)


def mean_se(rows):
    a = np.array(rows, dtype=float)
    return a.mean(0), a.std(0, ddof=1) / np.sqrt(len(a))


def tables(store, mus=MUS, nus=NUS):
    rate, peak = [], []
    for mu in mus:
        members = sorted(glob.glob(os.path.join(store, f"mu_{mu}", "members", "m*")))
        for nu in nus:
            cur = {m: {k: resampled(os.path.join(m, "deviatoric", f"{k}_phi{nu}.csv"))
                       for k in ("D2", "D3", "isobaric_D2")} for m in members}
            rate.append((mu, nu, *mean_se([rate_row(c["D2"], c["D3"]) for c in cur.values()])))
            for k in ("D2", "D3", "isobaric_D2"):
                peak.append((mu, nu, k, *mean_se([peak_row(c[k]) for c in cur.values()])))
    return rate, peak


RATE_COLS = ("D3/D2 at equal eps_d", "D3/D2 at equal e3", "largest slope D3/D2")
PEAK_COLS = ("drop", "eps_d at peak", "F_peak/F_end", "p_peak/p0", "p_end/p0", "nu_end")


def write(rate, peak, out):
    def cells(m, s):
        return " | ".join(f"{a:.3g} ± {b:.2g}" for a, b in zip(m, s))
    def csv_cells(m, s):
        return ",".join(f"{a:.6g},{b:.6g}" for a, b in zip(m, s))
    head = "<!-- demkit/model_fabric_rate.py: mean ± SE over the packings (9-point running mean, eps_d <= 0.3) -->\n"
    md = [head, "| μ | ν | " + " | ".join(RATE_COLS) + " |\n", "|---|---|" + "---|" * len(RATE_COLS) + "\n"]
    md += [f"| {mu} | {float(nu):.2f} | {cells(m, s)} |\n" for mu, nu, m, s in rate]
    cs = ["mu,nu," + ",".join(f"{n}_mean,{n}_se" for n in ("equal_eps_d", "equal_e3", "slope")) + "\n"]
    cs += [f"{mu},{nu},{csv_cells(m, s)}\n" for mu, nu, m, s in rate]
    pm = [head, "| μ | ν | curve | " + " | ".join(PEAK_COLS) + " |\n", "|---|---|---|" + "---|" * len(PEAK_COLS) + "\n"]
    pm += [f"| {mu} | {float(nu):.2f} | {k} | {cells(m, s)} |\n" for mu, nu, k, m, s in peak]
    pc = ["mu,nu,curve," + ",".join(f"{n}_mean,{n}_se" for n in ("drop", "eps_peak", "F_peak_over_end",
                                                                  "p_peak_over_p0", "p_end_over_p0", "nu_end")) + "\n"]
    pc += [f"{mu},{nu},{k},{csv_cells(m, s)}\n" for mu, nu, k, m, s in peak]
    os.makedirs(out, exist_ok=True)
    for name, text in (("fabric_rate.md", md), ("fabric_rate.csv", cs), ("stress_peak.md", pm), ("stress_peak.csv", pc)):
        write_atomic(os.path.join(out, name), "".join(text))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--store", default="data/friction_n1000")
    ap.add_argument("--out", default="data/friction_n1000/model_friction")
    a = ap.parse_args(argv)
    if not glob.glob(os.path.join(a.store, "mu_*", "members", "m*")):
        raise SystemExit(f"model_fabric_rate: no members under {a.store}/mu_*/members (--store: the friction study)")
    write(*tables(a.store), a.out)


if __name__ == "__main__":
    main()
