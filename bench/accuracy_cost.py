#!/usr/bin/env python3
"""Accuracy against cost for one D2 run from one packing (N = 9261, phi = 0.74 from the
unloading branch): vary dt/t_c, the strain rate, the Verlet skin and the integrator; measure
the error of s_dev, F_dev and p against a converged reference and the wall time.

    /usr/bin/python3 bench/accuracy_cost.py [--eps 0.06]        (about 30 minutes, 1 thread)
    /usr/bin/python3 bench/accuracy_cost.py --only-n            (just the N series, merged into the JSON)
    /usr/bin/python3 bench/accuracy_cost.py --only-auto-skin    (just the dt series at the default "auto"
                                                                 skin, merged; a minute)

Writes docs/accuracy_cost.md, docs/accuracy_cost.png/.svg and bench/accuracy_cost.json.
Error: RMS over eps_d of |x - x_ref| for s_dev and F_dev; RMS relative error for p.
References: dt/t_c = 0.005 at the default rate (for dt, skin and integrator), and the slowest
rate (1e-5/t_c) for the rate series. DEM is chaotic: below some dt the error is the
trajectory-divergence floor, not the integration error; the chart shows where.
N series: packings of N = 1000 ... 100 000 made by our runner (fast protocol, several seeds
each, phi = 0.74 on the unloading branch), the same D2 run from each; the error of one run is
the seed-to-seed standard deviation of its curve (RMS over eps_d), the cost its CPU time.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
from demkit.curves import read_curve  # noqa: E402
sys.path.insert(0, HERE)
from report import save_figure, write_markdown  # noqa: E402
from skin_scan import auto_skin  # noqa: E402

DEM = os.path.join(ROOT, "build", "dem")
PACKING = os.path.join(ROOT, "data", "yade", "packing_phi0.740.txt")
DEFAULT = {"dt": 0.02, "rate": 1e-4, "skin": 0.4, "integrator": "velocity_verlet"}


REFERENCE_CSV = os.path.join(HERE, "accuracy_reference_D2_phi0.740.csv")
YADE_CURVE = os.path.join(ROOT, "data", "yade", "yade_D2_phi0.740.csv")


N_SEEDS = {1000: 6, 3000: 6, 9261: 6, 30000: 4, 100000: 3}
N_PREP_SCENE = """[particles]
count = {n}
seed = {seed}
[protocol]
target_phi = 0.64
compress_rate_tc = 2e-4
cycle_rate_tc = 1e-4
cycle_phi_max = 0.82
checkpoints_unloading = [0.74]
[integration]
dt_over_tc = 0.1
threads = 1
[output]
vtk = false
"""


def n_series(eps, tmp):
    """Seed-to-seed spread of the D2 curves against N (and its CPU cost)."""
    out = []
    for n, seeds in N_SEEDS.items():
        curves, cpu = [], []
        for seed in range(1, seeds + 1):
            scene = os.path.join(tmp, "prep.toml")
            with open(scene, "w") as fh:
                fh.write(N_PREP_SCENE.format(n=n, seed=seed))
            rdir = os.path.join(tmp, f"n{n}_s{seed}")
            subprocess.run([DEM, "run", scene, "--out", rdir, "--stages", "prep", "--quiet", "--force"], check=True)
            c, wall = run(DEFAULT, eps, tmp, packing=os.path.join(rdir, "checkpoints", "unloading_phi0.740.txt"))
            if c is not None:
                curves.append(c)
                cpu.append(wall)
            print("N", n, "seed", seed, f"{wall:.1f}s", file=sys.stderr)
        g = np.linspace(0, min(c["eps_d"].max() for c in curves), 100)
        res = {"N": n, "seeds": len(curves), "wall_s": float(np.mean(cpu)), "spread": {}, "mean": {}}
        for q in ("s_dev", "F_dev", "p_Pa"):
            ys = np.array([np.interp(g, c["eps_d"], c[q]) for c in curves])
            sd = ys.std(axis=0, ddof=1)
            if q == "p_Pa":
                sd = sd / ys.mean(axis=0)
            res["spread"]["p_rel" if q == "p_Pa" else q] = float(np.sqrt(np.mean(sd * sd)))
            res["mean"][q] = ys.mean(axis=0).tolist()
        res["eps_grid"] = g.tolist()
        out.append(res)
    return out


def run(cfg, eps, tmp, keep=None, packing=PACKING):
    out = keep or os.path.join(tmp, "c.csv")
    t0 = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
    p = subprocess.run([DEM, "mode", "--packing", packing, "--mode", "D2", "--rate-tc", str(cfg["rate"]),
                        "--eps-max", str(eps), "--quiet", "--force", "--out", out,
                        "--set", f"integration.dt_over_tc={cfg['dt']}", "--set", f"integration.integrator={cfg['integrator']}",
                        "--set", f"integration.skin_over_rmin={cfg['skin']}", "--set", "integration.threads=1",
                        "--set", f"output.sample_strain={eps / 60:.6g}"], capture_output=True, text=True)
    wall = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime - t0   # CPU time: robust to a busy machine
    if p.returncode:
        return None, wall
    return read_curve(out), wall


def error(c, ref):
    g = np.linspace(0, min(c["eps_d"].max(), ref["eps_d"].max()), 100)
    e = {}
    for q in ("s_dev", "F_dev"):
        d = np.interp(g, c["eps_d"], c[q]) - np.interp(g, ref["eps_d"], ref[q])
        e[q] = float(np.sqrt(np.mean(d * d)))
    pr = np.interp(g, ref["eps_d"], ref["p_Pa"])
    d = (np.interp(g, c["eps_d"], c["p_Pa"]) - pr) / pr
    e["p_rel"] = float(np.sqrt(np.mean(d * d)))
    return e


def yade_point(eps):
    """YADE on the same axes: its stored curve of the same packing and physics (data/yade, made
    with gamma_b = 0 and the leapfrog) against our reference, and its cost from the throughput
    measured by bench/run_benchmarks.py (one core, quiet machine)."""
    res_json = os.path.join(HERE, "results.json")
    if not (os.path.exists(YADE_CURVE) and os.path.exists(REFERENCE_CSV) and os.path.exists(res_json)):
        return None
    with open(res_json) as fh:
        codes = json.load(fh)["codes"]
    thr = [v.get("particle_steps_per_s") for k, v in codes.items() if k.startswith("YADE")]
    if not thr or not thr[0]:
        return None
    y, ref = read_curve(YADE_CURVE), read_curve(REFERENCE_CSV)
    steps = eps / (3 ** 0.5 * 1e-4 * 0.02)
    return {"error": error(y, ref), "cpu_s": steps * 9261 / thr[0], "throughput": thr[0]}


# The scenes' default skin ("auto": thicker at larger dt, sim/include/dem/core/model.hpp) against
# the dt series at 0.4 r_min: the list is exact, so only the summation order should differ.
AUTO_SKIN_SERIES = "dt (auto skin)"
AUTO_SKIN_CONFIGS = [dict(DEFAULT, dt=d, skin="auto") for d in (0.05, 0.1, 0.2, 0.3, 0.4)]


def run_series(cfgs, eps, tmp, ref):
    """Each config's run, its error against `ref` and its CPU time."""
    out = []
    for cfg in cfgs:
        c, wall = run(cfg, eps, tmp)
        err = error(c, ref) if c is not None and ref is not None else None
        out.append({"config": cfg, "wall_s": wall, "error": err,
                    "max_inertial_number": float(c["inertial_number"].max()) if c is not None else None})
        print(cfg, f"{wall:.1f}s", err, file=sys.stderr)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--eps", type=float, default=0.06)
    ap.add_argument("--replot", action="store_true", help="redraw from bench/accuracy_cost.json without running")
    ap.add_argument("--only-n", action="store_true", help="run only the N series and merge it into the JSON")
    ap.add_argument("--only-auto-skin", action="store_true",
                    help="run only the dt series at the auto skin (against the stored reference) and merge it")
    a = ap.parse_args()
    jpath = os.path.join(HERE, "accuracy_cost.json")
    if a.replot or a.only_n or a.only_auto_skin:
        with open(jpath) as fh:
            results = json.load(fh)
        if a.only_n:
            results["N (spread over seeds)"] = n_series(a.eps, tempfile.mkdtemp())
        if a.only_auto_skin:
            results[AUTO_SKIN_SERIES] = run_series(AUTO_SKIN_CONFIGS, a.eps, tempfile.mkdtemp(), read_curve(REFERENCE_CSV))
        if a.only_n or a.only_auto_skin:
            with open(jpath, "w") as fh:
                json.dump(results, fh, indent=2)
        report(results, a.eps)
        return
    if not os.path.exists(PACKING):
        sys.exit(f"{PACKING} missing: run yade_ref/make_reference.sh (or its prep step) first")
    tmp = tempfile.mkdtemp()
    series = {
        "dt (velocity Verlet)": [dict(DEFAULT, dt=d) for d in (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4)],
        "dt (symplectic Euler)": [dict(DEFAULT, dt=d, integrator="symplectic_euler") for d in (0.01, 0.02, 0.05, 0.1, 0.2, 0.4)],
        "rate": [dict(DEFAULT, rate=r) for r in (1e-5, 3e-5, 1e-4, 3e-4, 1e-3)],
        "skin": [dict(DEFAULT, skin=s) for s in (0.1, 0.2, 0.4, 0.8)],
        AUTO_SKIN_SERIES: AUTO_SKIN_CONFIGS,
    }
    results = {}
    ref_dt, _ = run(dict(DEFAULT, dt=0.005), a.eps, tmp, keep=REFERENCE_CSV)
    ref_rate = None
    for name, cfgs in series.items():
        results[name] = []
        for cfg in cfgs:
            c, wall = run(cfg, a.eps, tmp)
            if name == "rate" and cfg["rate"] == 1e-5:
                ref_rate = c
            ref = ref_rate if name == "rate" else ref_dt
            err = error(c, ref) if c is not None and ref is not None else None
            results[name].append({"config": cfg, "wall_s": wall, "error": err,
                                  "max_inertial_number": float(c["inertial_number"].max()) if c is not None else None})
            print(name, cfg, f"{wall:.1f}s", err, file=sys.stderr)
    results["N (spread over seeds)"] = n_series(a.eps, tmp)
    with open(jpath, "w") as fh:
        json.dump(results, fh, indent=2)
    report(results, a.eps)


def report(results, eps):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    pts = []
    nser = results.get("N (spread over seeds)")
    for name, rs in results.items():
        if name.startswith("N "):
            continue
        ok = [r for r in rs if r["error"] and r["error"]["s_dev"] > 0]
        for ax, q in zip(axes, ("s_dev", "F_dev", "p_rel")):
            ax.loglog([r["wall_s"] for r in ok], [max(r["error"][q], 1e-7) for r in ok], "o-", label=name)
        pts += [(r["wall_s"], r["error"]["s_dev"], name, r["config"]) for r in ok]
    # Pareto front on s_dev error among the runs at the base rate (same reference)
    front, best = [], float("inf")
    for w, e, n, cfg in sorted(pts):
        if n != "rate" and e < best:
            front.append((w, e))
            best = e
    axes[0].loglog(*zip(*front), "k--", lw=1, label="Pareto front (base rate)")
    yade = yade_point(eps)
    if yade:
        for ax, q in zip(axes, ("s_dev", "F_dev", "p_rel")):
            ax.loglog([yade["cpu_s"]], [yade["error"][q]], "ks", ms=9, label="YADE (dt = t_c/50, rate 1e-4)")
    if nser:
        for ax, q in zip(axes, ("s_dev", "F_dev", "p_rel")):
            ax.loglog([r["wall_s"] for r in nser], [r["spread"][q] for r in nser], "D-", color="tab:brown",
                      label="N = 1000 … 10⁵: spread over seeds")
            for r in nser:
                ax.annotate(f"{r['N']:g}", (r["wall_s"], r["spread"][q]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points", color="tab:brown")
    d = [r for r in results["dt (velocity Verlet)"] if r["config"]["dt"] == 0.02][0]
    for ax, q in zip(axes, ("s_dev", "F_dev", "p_rel")):
        ax.loglog([d["wall_s"]], [max(d["error"][q], 1e-7)], "r*", ms=14,
                  label="default dt, skin, integrator (rate 1e-4)")
        ax.set_xlabel("CPU time [s] (1 thread)")
        ax.set_ylabel({"s_dev": "RMS error of s_dev", "F_dev": "RMS error of F_dev", "p_rel": "RMS relative error of p"}[q])
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"accuracy against cost: D2 to eps_d = {eps}, N = 9261, phi = 0.74. dt/skin/integrator series: "
                 "error against dt = t_c/200 at rate 1e-4; rate series: against rate 1e-5", fontsize=9)
    fig.tight_layout()
    save_figure(fig, os.path.join(ROOT, "docs", "accuracy_cost"))
    lines = ["# Accuracy against cost", "", f"Generated by `/usr/bin/python3 bench/accuracy_cost.py --eps {eps}`.",
             "", "![accuracy against cost](accuracy_cost.png)", "",
             "| series | dt/t_c | rate·t_c | skin/r_min | integrator | CPU [s] | err s_dev | err F_dev | rel err p | max I |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, rs in results.items():
        if name.startswith("N "):
            continue
        for r in rs:
            c, e = r["config"], r["error"]
            es = ("blew up", "", "") if e is None else (f"{e['s_dev']:.2e}", f"{e['F_dev']:.2e}", f"{e['p_rel']:.2e}")
            mi = "" if r["max_inertial_number"] is None else f"{r['max_inertial_number']:.1e}"
            skin = c["skin"] if c["skin"] != "auto" else f"auto ({auto_skin(c['dt']):.2f})"
            lines.append(f"| {name} | {c['dt']} | {c['rate']} | {skin} | {c['integrator']} | {r['wall_s']:.1f} | "
                         f"{es[0]} | {es[1]} | {es[2]} | {mi} |")
    if yade:
        e = yade["error"]
        lines.append(f"| YADE 2023.02a (stored reference curve) | 0.02 | 0.0001 | | leapfrog | {yade['cpu_s']:.0f} (from "
                     f"{yade['throughput'] / 1e6:.2f} M particle-steps/s) | {e['s_dev']:.2e} | {e['F_dev']:.2e} | {e['p_rel']:.2e} | |")
    if nser:
        lines += ["", "## N: the spread over seeds", "",
                  "Packings made by our runner (fast protocol: compression at 2e-4/t_c, cycle at 1e-4/t_c, "
                  "dt = t_c/10; φ = 0.74 on the unloading branch), one per seed, then the D2 run above (default "
                  "dt, rate, skin). Error of one run = standard deviation over seeds (RMS over ε_d); "
                  "it falls roughly as N^(-1/2), so each factor 10 of CPU buys a factor 3 in precision.", "",
                  "| N | seeds | CPU of one D2 run [s] | spread s_dev | spread F_dev | relative spread p |",
                  "|---|---|---|---|---|---|"]
        for r in nser:
            e = r["spread"]
            lines.append(f"| {r['N']} | {r['seeds']} | {r['wall_s']:.1f} | {e['s_dev']:.2e} | {e['F_dev']:.2e} | "
                         f"{e['p_rel']:.2e} |")
    write_markdown(os.path.join(ROOT, "docs", "accuracy_cost.md"), lines, os.path.join(HERE, "accuracy_cost_notes.md"))


if __name__ == "__main__":
    main()
