#!/usr/bin/env python3
"""The neighbour skin against cost: where the default "auto" skin comes from.

    /usr/bin/python3 bench/skin_scan.py [--quick] [--rounds 3]   (about 10 minutes, 1 thread; a quiet machine)

For relaxed quickstart members (N = 1000, D2 at 3e-5/t_c from the unloading checkpoints at
phi = 0.80 and 0.69) at dt = t_c/5 ... t_c/50, `dem bench` at skins 0.2 ... 2 r_min gives the
throughput, the listed pairs per particle P and the rebuilds per step f. One cost model is
fitted to all runs by least squares (outliers of this drifting VM dropped):

    time per particle-step = c0 + c_pair P(skin) + c_rebuild f(skin)

Its minimum over the skin, per dt and summed over the two volume fractions, is what the rule
skin/r_min = 0.4 (dt/t_c / 0.02)^0.4 (dem::auto_skin_over_rmin) follows. The counts P and f are
deterministic (the same bits on any machine); only the three constants depend on the machine.
This VM's speed drifts by tens of per cent within minutes, so every configuration runs in
`--rounds` interleaved rounds and its median throughput enters the fit.
Writes bench/skin_scan.json and docs/skin_scan.md (+ .png).
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from report import save_figure, write_markdown  # noqa: E402

DEM = os.path.join(ROOT, "build", "dem")
DTS = (0.2, 0.1, 0.05, 0.02)
PHIS = ("0.800", "0.690")
SKINS = (0.2, 0.3, 0.4, 0.6, 0.8, 1.0, 1.3, 2.0)


def auto_skin(dt_over_tc):
    """The rule of dem::auto_skin_over_rmin (sim/src/core/model.cpp), for the tables."""
    return 0.4 * max(1.0, dt_over_tc / 0.02) ** 0.4


def checkpoints(work):
    """A relaxed quickstart member's unloading checkpoints (its preparation only; seconds)."""
    out = os.path.join(work, "qs")
    subprocess.run([DEM, "run", os.path.join(ROOT, "data", "scenes", "quickstart.toml"), "--out", out, "--quiet",
                    "--threads", "1", "--set", "ensemble.packings=1", "--set", "protocol.modes=[]",
                    "--set", "protocol.checkpoints_unloading=[0.80, 0.69]"], check=True, stdout=subprocess.DEVNULL)
    return {phi: os.path.join(out, "checkpoints", f"unloading_phi{phi}.ckpt") for phi in PHIS}


def bench(ckpt, dt, skin, steps):
    """One `dem bench`: throughput [particle-steps/s], listed pairs per particle, rebuilds per step."""
    p = subprocess.run([DEM, "bench", "--packing", ckpt, "--threads", "1", "--steps", str(steps), "--rate-tc", "3e-5",
                        "--set", f"integration.dt_over_tc={dt}", "--set", f"integration.skin_over_rmin={skin}"],
                       capture_output=True, text=True)
    thr = re.search(r"particle_steps_per_s=([0-9.eE+]+)", p.stdout + p.stderr)
    pairs = re.search(r"([0-9.]+) listed pairs per particle", p.stdout + p.stderr)
    nl = re.search(r"neighbor_list=(\{.*\})", p.stdout + p.stderr)
    if p.returncode or not (thr and pairs and nl):
        return None
    stats = json.loads(nl.group(1))
    return {"throughput": float(thr.group(1)), "pairs": float(pairs.group(1)),
            "rebuilds_per_step": stats["rebuilds"] / stats["steps"], "rebuild_share": stats["rebuild_share"]}


def median_run(rs, dt, phi, skin):
    """The configuration's run of median throughput, with every round's throughput (`rounds`)."""
    med = sorted(rs, key=lambda r: r["throughput"])[len(rs) // 2]
    return dict(med, dt=dt, phi=phi, skin=skin, rounds=[r["throughput"] for r in rs])


def fit_cost(runs):
    """c0, c_pair, c_rebuild [ns] by least squares on the time per particle-step, refitted without
    the runs more than 2.5 median absolute residuals off (a VM's slow moments)."""
    A = np.array([[1.0, r["pairs"], r["rebuilds_per_step"]] for r in runs])
    b = np.array([1e9 / r["throughput"] for r in runs])
    keep = np.ones(len(b), bool)
    for _ in range(3):
        c, *_ = np.linalg.lstsq(A[keep], b[keep], rcond=None)
        res = np.abs(b - A @ c)
        keep = res <= 2.5 * np.median(res[keep]) + 1e-12
    return c, int((~keep).sum())


def best_skins(runs, c):
    """Per dt: the skin minimising the model (P and log f interpolated in log skin), per phi and summed."""
    grid = np.exp(np.linspace(np.log(min(SKINS)), np.log(max(SKINS)), 400))
    out = {}
    for dt in DTS:
        total, per = np.zeros_like(grid), {}
        for phi in PHIS:
            rs = sorted((r for r in runs if r["dt"] == dt and r["phi"] == phi), key=lambda r: r["skin"])
            if len(rs) < 3:
                continue
            s = np.log([r["skin"] for r in rs])
            P = np.interp(np.log(grid), s, [r["pairs"] for r in rs])
            f = np.exp(np.interp(np.log(grid), s, np.log([max(r["rebuilds_per_step"], 1e-6) for r in rs])))
            cost = c[0] + c[1] * P + c[2] * f
            total += cost
            per[phi] = float(grid[np.argmin(cost)])
        at_auto = float(np.interp(np.log(auto_skin(dt)), np.log(grid), total))
        out[dt] = {"per_phi": per, "summed": float(grid[np.argmin(total)]), "auto": auto_skin(dt),
                   "auto_excess": at_auto / float(total.min()) - 1}
    return out


def figure(runs, c, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(PHIS), figsize=(10, 3.8), sharey=True)
    for ax, phi in zip(axes, PHIS):
        for dt in DTS:
            rs = sorted((r for r in runs if r["dt"] == dt and r["phi"] == phi), key=lambda r: r["skin"])
            sk = [r["skin"] for r in rs]
            med = np.array([r["throughput"] / 1e6 for r in rs])
            lo = med - np.array([min(r.get("rounds", [r["throughput"]])) / 1e6 for r in rs])
            hi = np.array([max(r.get("rounds", [r["throughput"]])) / 1e6 for r in rs]) - med
            line = ax.errorbar(sk, med, yerr=[lo, hi], fmt="o", ms=4, capsize=2, label=f"t_c/{1 / dt:.0f}").lines[0]
            model = [1e3 / (c[0] + c[1] * r["pairs"] + c[2] * r["rebuilds_per_step"]) for r in rs]
            ax.plot(sk, model, "-", color=line.get_color())
            ax.axvline(auto_skin(dt), color=line.get_color(), ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("skin / r_min")
        ax.set_title(f"quickstart member, φ = {float(phi):.2f}, D2 at 3e-5/t_c", fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("M particle-steps/s (1 thread)")
    axes[0].legend(fontsize=8, title="points: median (bars: range) of the rounds;\nlines: cost model; dotted: auto",
                   title_fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, exts=("png",))


def report(res):
    c, runs, best = res["cost_ns"], res["runs"], res["best"]
    lines = ["# The neighbour skin against cost", "",
             f"Generated by `/usr/bin/python3 bench/skin_scan.py` ({res['machine']}). Relaxed quickstart members "
             "(N = 1000), D2 at 3e-5/t_c, one thread; `dem bench` per (dt, φ, skin), the median of "
             f"{res.get('rounds', 1)} interleaved rounds.", "",
             "![skin against throughput](skin_scan.png)", "",
             f"Cost model fitted to all {len(runs)} runs ({res['dropped']} dropped as outliers): time per particle-step = "
             f"{c[0]:.1f} ns + {c[1]:.2f} ns × listed pairs per particle + {c[2]:.0f} ns × rebuilds per step "
             f"(one rebuild costs {c[2] / c[1]:.0f} listed pairs' worth per particle).", "",
             "| dt | best skin/r_min at φ = 0.80 | at φ = 0.69 | best for both (summed cost) | auto | auto's cost above the best |",
             "|---|---|---|---|---|---|"]
    for dt, b in best.items():
        pp = b["per_phi"]
        lines.append(f"| t_c/{1 / float(dt):.0f} | {pp.get('0.800', float('nan')):.2f} | {pp.get('0.690', float('nan')):.2f} | "
                     f"{b['summed']:.2f} | {b['auto']:.2f} | {b['auto_excess']:.1%} |")
    lines += ["", "| dt | φ | skin/r_min | M particle-steps/s | listed pairs per particle | rebuilds per 10⁴ steps | rebuild share |",
              "|---|---|---|---|---|---|---|"]
    for r in runs:
        lines.append(f"| t_c/{1 / r['dt']:.0f} | {r['phi']} | {r['skin']} | {r['throughput'] / 1e6:.2f} | {r['pairs']:.2f} | "
                     f"{1e4 * r['rebuilds_per_step']:.0f} | {r['rebuild_share']:.0%} |")
    write_markdown(os.path.join(ROOT, "docs", "skin_scan.md"), lines, os.path.join(HERE, "skin_scan_notes.md"))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a fifth of the steps")
    ap.add_argument("--replot", action="store_true", help="redraw from bench/skin_scan.json")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds per configuration (median)")
    a = ap.parse_args()
    jpath = os.path.join(HERE, "skin_scan.json")
    if a.replot:
        with open(jpath) as fh:
            res = json.load(fh)
        res["best"] = {str(k): v for k, v in best_skins(res["runs"], np.array(res["cost_ns"])).items()}
    else:
        ck = checkpoints(tempfile.mkdtemp(prefix="dem_skin_"))
        configs = [(dt, phi, skin) for dt in DTS for phi in PHIS for skin in SKINS]
        measured = {cfg: [] for cfg in configs}
        for rnd in range(a.rounds):
            for dt, phi, skin in configs:
                steps = int((2000 if a.quick else 10000) * 0.2 / dt)   # the same simulated time at every dt
                r = bench(ck[phi], dt, skin, steps)
                if r:
                    measured[(dt, phi, skin)].append(r)
                print(rnd, dt, phi, skin, r, file=sys.stderr)
        runs = [median_run(rs, dt, phi, skin) for (dt, phi, skin), rs in measured.items() if rs]
        c, dropped = fit_cost(runs)
        import platform
        res = {"machine": f"{os.cpu_count()} cores, {platform.machine()}", "rounds": a.rounds, "runs": runs, "cost_ns": c.tolist(),
               "dropped": dropped, "best": {str(k): v for k, v in best_skins(runs, c).items()}}
        with open(jpath, "w") as fh:
            json.dump(res, fh, indent=2)
    figure(res["runs"], res["cost_ns"], os.path.join(ROOT, "docs", "skin_scan"))
    report(res)


if __name__ == "__main__":
    main()
