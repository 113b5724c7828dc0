"""The quickstart's shape by measurement: band width of the mean F_dev curve at nu = 0.80 against
cost, for shapes (N, K, deviatoric rate, eps_d_max) of the quickstart scene with the seed's physics.

    /usr/bin/python3 bench/quickstart_shape.py RUN [RUN ...] [--md docs/quickstart_shape.md]

Each RUN is a finished `dem ensemble` folder of data/scenes/quickstart.toml with some of N, K,
rate and eps_d_max changed by --set. From one RUN of K packings up to strain E, every shape with
K' <= K packings and strain E' <= E follows without running it again:
  - a mode stopped at E' gives the first rows of the curve stopped at E (same steps, same samples),
    so its members are the rows with eps_d <= E'; its cost is the mode's CPU time x E'/E (constant
    rate: steps proportional to the strain);
  - the between-packing SD of K packings estimates that of K' (the same population), so the 95 %
    band of K' packings is 2 t(0.975, K'-1) SD / sqrt(K') (full width);
  - cost = K' x (mean CPU s of a preparation + sum over (nu, mode) of the mean CPU s of the mode x E'/E),
    the CPU seconds (user+sys, demkit.task's cpu_s) that `dem ensemble` spends in its tasks; the
    fixed part (startup, reduce, plots) is the same for every shape and is left out.
The criteria, on every mean curve (s_dev and F_dev, D2 and D3, every nu), the plateau being the
last third of [0, E']:
  band    plateau mean of the full 95 % band width / plateau level <= 0.3
  rises   plateau level - first value > half the plateau band width
  settles |mean over the plateau's second half - over its first half| <= half the plateau band width
          (no drift of the mean that its own 95 % band could tell from the noise between packings),
          and the plateau level within half the band of the level over the last third of the run's
          whole strain E with all K packings (a curve stopped before it saturates fails)
"""
import argparse
import glob
import json
import os
import re
import sys

import numpy as np
from scipy import stats

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from demkit.curves import read_curve  # noqa: E402

QS = ("s_dev", "F_dev")
BAND_MAX = 0.3


def scene_value(text, key, cast=float):
    m = re.search(rf"^{key}\s*=\s*([^\s#]+)", text, re.M)
    return cast(m.group(1)) if m else None


def load_run(run):
    text = open(os.path.join(run, "scene.toml")).read()
    shape = {"N": scene_value(text, "count", int), "K": scene_value(text, "packings", int),
             "rate": scene_value(text, "deviatoric_rate_tc"), "eps": scene_value(text, "eps_d_max")}
    members = sorted(glob.glob(os.path.join(run, "members", "m*")))
    prep_cpu = [json.load(open(os.path.join(m, "prep.json")))["cpu_s"] for m in members]
    cells, mode_cpu = {}, {}
    for f in sorted(glob.glob(os.path.join(members[0], "deviatoric", "*_phi*.csv"))):
        name = os.path.basename(f)[:-4]
        mode, nu = name.split("_phi")
        curves = [read_curve(os.path.join(m, "deviatoric", name + ".csv")) for m in members]
        n = min(len(c["eps_d"]) for c in curves)
        cells[(mode, float(nu))] = {"eps": curves[0]["eps_d"][:n], **{q: np.array([c[q][:n] for c in curves]) for q in QS}}
        mode_cpu[name] = np.mean([json.load(open(os.path.join(m, "deviatoric", name + ".json")))["cpu_s"] for m in members])
    return {"run": run, "shape": shape, "prep_cpu": float(np.mean(prep_cpu)), "mode_cpu": mode_cpu, "cells": cells}


def judge(eps, y, k, e_max):
    """(band/level, rises, settles) of the mean of members y (K x rows) with k' packings, up to e_max."""
    keep = eps <= e_max + 1e-12
    eps, y = eps[keep], y[:, keep]
    mean, sd = y.mean(axis=0), y.std(axis=0, ddof=1)
    band = 2 * stats.t.ppf(0.975, k - 1) * sd / np.sqrt(k)
    plateau = eps >= 2 * e_max / 3
    level = mean[plateau].mean()
    rel = band[plateau].mean() / abs(level)
    rise = level - mean[0]
    half = len(mean[plateau]) // 2
    change = mean[plateau][half:].mean() - mean[plateau][:half].mean()
    return rel, bool(rise > band[plateau].mean() / 2), bool(abs(change) <= band[plateau].mean() / 2), level, band[plateau].mean()


def variants(r, ks, fractions):
    s = r["shape"]
    for k in ks:
        if k > s["K"] or k < 3:
            continue
        for f in fractions:
            e = s["eps"] * f
            cost = float(k * (r["prep_cpu"] + f * sum(r["mode_cpu"].values())))
            row = {"N": s["N"], "K": k, "rate": s["rate"], "eps_d_max": round(e, 2), "cpu_s": round(cost, 1),
                   "run": os.path.basename(os.path.normpath(r["run"]))}
            worst, ok = 0.0, True
            for (mode, nu), c in sorted(r["cells"].items()):
                for q in QS:
                    rel, rises, settles, level, width = judge(c["eps"], c[q], k, e)
                    full = judge(c["eps"], c[q], s["K"], s["eps"])[3]   # the plateau of the whole run
                    settles = settles and abs(level - full) <= width / 2
                    worst = max(worst, rel)
                    ok = ok and rises and settles and rel <= BAND_MAX
                    if q == "F_dev" and abs(nu - 0.80) < 1e-6:
                        row[f"F_dev_{mode}_0.80"] = round(float(rel), 3)
                    if not (rises and settles):
                        row.setdefault("fails", []).append(f"{mode} {nu:.2f} {q}: " +
                                                           ("no rise" if not rises else "not settled"))
            row["worst_band"] = round(float(worst), 3)
            row["ok"] = bool(ok)
            yield row


def chart(rows, stem):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from demkit.figures import save
    fig, ax = plt.subplots(figsize=(7, 4.5))
    runs = sorted({(r["N"], r["rate"]) for r in rows})
    epss = sorted({r["eps_d_max"] for r in rows})
    styles = ["-", "--", "-.", ":"]
    for (n, rate, e) in sorted({(r["N"], r["rate"], r["eps_d_max"]) for r in rows}):
        rs = sorted((r for r in rows if (r["N"], r["rate"], r["eps_d_max"]) == (n, rate, e)), key=lambda r: r["cpu_s"])
        x = [r["cpu_s"] for r in rs]
        y = [max(r.get("F_dev_D2_0.80", np.nan), r.get("F_dev_D3_0.80", np.nan)) for r in rs]
        color = f"C{runs.index((n, rate)) % 10}"
        ax.plot(x, y, styles[epss.index(e) % 4], color=color, lw=0.9,
                label=f"N = {n}, rate {rate:g}/t_c, ε_d ≤ {e:.2f}")
        for r, xi, yi in zip(rs, x, y):
            ax.plot([xi], [yi], "o", color=color, mfc=color if r["ok"] else "white", ms=4)
            ax.annotate(f"{r['K']}", (xi, yi), fontsize=5, xytext=(2, 2), textcoords="offset points")
    ax.axhline(BAND_MAX, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("CPU seconds in the tasks (user + sys)")
    ax.set_ylabel("F_dev, ν = 0.80: band / level (worse of D2, D3)")
    ax.set_title("numbers: packings K; filled: every mean curve rises and settles with plateau bands ≤ 0.3 of its level",
                 fontsize=7)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=5, ncol=2)
    fig.tight_layout()
    save(fig, stem)


def markdown(rows, path, argv):
    cols = ["N", "K", "rate", "eps_d_max", "cpu_s", "F_dev_D2_0.80", "F_dev_D3_0.80", "worst_band", "ok", "fails"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in sorted(rows, key=lambda r: (r["cpu_s"], r["N"])):
        lines.append("| " + " | ".join("; ".join(r.get(c, [])[:3]) if c == "fails" else str(r.get(c, "")) for c in cols) + " |")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--ks", default="4,6,8,10,14")
    ap.add_argument("--fractions", default="0.5,0.667,0.833,1.0", help="E'/E of each run's eps_d_max")
    ap.add_argument("--out", default="bench/quickstart_shape", help="stem of the CSV/JSON table and the chart")
    a = ap.parse_args(argv)
    rows = []
    for run in a.runs:
        rows += list(variants(load_run(run), [int(k) for k in a.ks.split(",")], [float(f) for f in a.fractions.split(",")]))
    with open(a.out + ".json", "w") as fh:
        json.dump(rows, fh, indent=1)
    markdown(rows, a.out + "_table.md", argv)
    chart(rows, a.out)
    for r in sorted(rows, key=lambda r: r["cpu_s"]):
        print(r)
    return 0


if __name__ == "__main__":
    sys.exit(main())
