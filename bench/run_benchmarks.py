#!/usr/bin/env python3
"""Speed benchmarks: the same packing under D2 in our runner, YADE, LAMMPS and LIGGGHTS,
side by side in one run, plus our cost against N. Not a test: numbers depend on the machine.

    /usr/bin/python3 bench/run_benchmarks.py [--quick] [--out docs/benchmarks.md]

Writes a Markdown table (default docs/benchmarks.md) and bench/results.json. Codes that are
not installed are reported as such (scripts/install-deps.sh --bench installs LAMMPS and LIGGGHTS).
"""
import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import decks  # noqa: E402
from report import write_markdown  # noqa: E402

DEM = os.path.join(ROOT, "build", "dem")
PACKING = os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt")
RATE_TC = 5e-6


def timed(cmd, cwd=None, env=None):
    """Run cmd; return (stdout+stderr, wall seconds, exit code)."""
    t0 = time.time()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd, env=env)
    out, _ = p.communicate()
    return out, time.time() - t0, p.returncode


def with_rss(cmd, **kw):
    """Like timed, but measures the peak RSS with GNU time."""
    if shutil.which("time") or os.path.exists("/usr/bin/time"):
        out, wall, rc = timed(["/usr/bin/time", "-f", "PEAK_RSS_KB=%M"] + cmd, **kw)
        m = re.findall(r"PEAK_RSS_KB=(\d+)", out)
        return out, wall, rc, (int(m[-1]) / 1024 if m else float("nan"))
    out, wall, rc = timed(cmd, **kw)
    return out, wall, rc, float("nan")


def bench_ours(packing, threads, steps, kernel="auto"):
    out, _, rc, rss = with_rss([DEM, "bench", "--packing", packing, "--threads", str(threads), "--steps", str(steps),
                                "--rate-tc", str(RATE_TC), "--kernel", kernel])
    m = re.search(r"particle_steps_per_s=([0-9.eE+]+)", out)
    if rc or not m:
        return {"error": out[-500:]}
    rb = re.search(r"(\d+) list rebuilds", out)
    kn = re.search(r"pair kernel (\w+)", out)
    return {"particle_steps_per_s": float(m.group(1)), "peak_rss_mib": rss,
            "list_rebuilds": int(rb.group(1)) if rb else None, "steps": steps, "kernel": kn.group(1) if kn else "?"}


def bench_production(packing, steps, dt_over_tc, rate_tc, skin=None):
    """One `dem bench` at a production time step: throughput, and the neighbour list's rebuilds,
    their share of the wall time and triggers (its `neighbor_list={...}` line). The throughput
    without the rebuilds' time is the target's reference (the same run, minus rebuilding)."""
    cmd = [DEM, "bench", "--packing", packing, "--threads", "1", "--steps", str(steps), "--rate-tc", str(rate_tc),
           "--set", f"integration.dt_over_tc={dt_over_tc}"]
    if skin is not None:
        cmd += ["--set", f"integration.skin_over_rmin={skin}"]
    out, wall, rc = timed(cmd)
    m = re.search(r"particle_steps_per_s=([0-9.eE+]+)", out)
    nl = re.search(r"neighbor_list=(\{.*\})", out)
    if rc or not m or not nl:
        return {"error": out[-500:]}
    r = {"particle_steps_per_s": float(m.group(1)), "neighbor_list": json.loads(nl.group(1))}
    share = r["neighbor_list"]["rebuild_share"]
    r["without_rebuilds_per_s"] = r["particle_steps_per_s"] / (1 - share) if share < 1 else float("nan")
    return r


def relaxed_quickstart_checkpoint(work):
    """A relaxed quickstart member at phi = 0.80 (its preparation only; seconds)."""
    out = os.path.join(work, "qs")
    subprocess.run([DEM, "run", os.path.join(ROOT, "data", "scenes", "quickstart.toml"), "--out", out, "--quiet",
                    "--threads", "1", "--set", "ensemble.packings=1", "--set", "protocol.modes=[]",
                    "--set", "protocol.checkpoints_unloading=[0.80]"], check=True, stdout=subprocess.DEVNULL)
    return os.path.join(out, "checkpoints", "unloading_phi0.800.ckpt")


def production_rows(work, steps, rounds):
    """The production time steps beside the default dt: the quickstart's physics (t_c/5, 3e-5/t_c)
    from a relaxed member checkpoint, Figure 3's (t_c/10, 1e-5/t_c) and the default t_c/50 on
    the shared packing. Interleaved rounds, medians."""
    ckpt = relaxed_quickstart_checkpoint(work)
    cases = {"quickstart member (N = 1000, φ = 0.80), t_c/5, 3e-5/t_c": (ckpt, 0.2, 3e-5),
             "shared N = 9261, t_c/10, 1e-5/t_c (Figure 3)": (PACKING, 0.1, 1e-5),
             "shared N = 9261, t_c/50, 5e-6/t_c (default dt)": (PACKING, 0.02, RATE_TC)}
    runs = {k: [] for k in cases}
    for _ in range(rounds):
        for k, (pk, dt, rate) in cases.items():
            runs[k].append(bench_production(pk, steps if "9261" in k else steps * 9, dt, rate))
    rows = {}
    for k, rs in runs.items():
        good = [r for r in rs if "error" not in r]
        if not good:
            rows[k] = rs[0]
            continue
        med = sorted(good, key=lambda r: r["particle_steps_per_s"])[len(good) // 2]
        rows[k] = dict(med, runs=[r["particle_steps_per_s"] for r in good])
    return rows


def supported_kernels():
    """The pair kernels this CPU runs (dem bench refuses the others)."""
    out = []
    for k in ("reference", "generic", "avx2", "avx512"):
        p = subprocess.run([DEM, "bench", "--steps", "1", "--kernel", k], capture_output=True, text=True)
        if p.returncode == 0:
            out.append(k)
    return out


def bench_kernels(packing, steps, rounds):
    """Each kernel on one thread, interleaved over `rounds` rounds (the VM drifts); the median."""
    kernels = supported_kernels()
    runs = {k: [] for k in kernels}
    for _ in range(rounds):
        for k in kernels:
            r = bench_ours(packing, 1, steps, k)
            if "particle_steps_per_s" in r:
                runs[k].append(r["particle_steps_per_s"])
    return {k: {"median": sorted(v)[len(v) // 2], "runs": v} for k, v in runs.items() if v}


def loop_time(out):
    m = re.search(r"Loop time of ([0-9.eE+]+) on (\d+) procs for (\d+) steps with (\d+) atoms", out)
    return (float(m.group(1)), int(m.group(3)), int(m.group(4))) if m else None


def bench_lammps(exe, deck_fn, packing, ranks, steps, workdir, style):
    if not shutil.which(exe):
        return {"error": f"{exe} not installed"}
    cell, spheres = decks.read_packing(packing)
    tc = decks.tc_smallest(spheres)
    data = os.path.join(workdir, f"{exe}.data")
    decks.write_lammps_data(data, cell, spheres, 2000.0, style)
    deck = os.path.join(workdir, f"in.{exe}")
    with open(deck, "w") as fh:
        fh.write(deck_fn(data, steps, RATE_TC / tc, tc / 50))
    cmd = [exe, "-in", deck, "-log", "none"]
    if ranks > 1:
        cmd = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(ranks)] + cmd
    out, _, rc, rss = with_rss(cmd, cwd=workdir)
    lt = loop_time(out)
    if rc or not lt:
        return {"error": out[-500:]}
    return {"particle_steps_per_s": lt[1] * lt[2] / lt[0], "peak_rss_mib": rss}


def bench_yade(packing, steps, workdir):
    if not shutil.which("yade"):
        return {"error": "yade not installed"}
    out, _, rc, rss = with_rss(["yade", "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", "run_mode.py"),
                                "--packing", packing, "--mode", "D2", "--rate-tc", str(RATE_TC),
                                "--max-steps", str(steps), "--sample-strain", "1", "--out",
                                os.path.join(workdir, "yade.csv")], cwd=workdir)
    m = re.search(r"([0-9.]+) M particle-steps/s", out)
    if rc or not m:
        return {"error": out[-500:]}
    return {"particle_steps_per_s": float(m.group(1)) * 1e6, "peak_rss_mib": rss}


def make_packing(n, workdir):
    """A packing of n spheres at phi = 0.70 made by our runner (fast compression, short relaxation)."""
    scene = os.path.join(workdir, f"make_{n}.toml")
    with open(scene, "w") as fh:
        fh.write(f"[particles]\ncount = {n}\nseed = 5\n[protocol]\ntarget_phi = 0.70\ncompress_rate_tc = 2e-4\n"
                 "relax_max_time_tc = 500\ncycle_phi_max = 0.70\ncheckpoints_unloading = [0.70]\n"
                 "[integration]\ndt_over_tc = 0.1\n[output]\nvtk = false\n")
    out = os.path.join(workdir, f"run_{n}")
    subprocess.run([DEM, "run", scene, "--out", out, "--stages", "prep", "--quiet", "--force"], check=True)
    return os.path.join(out, "checkpoints", "unloading_phi0.700.txt")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps, N only to 74 088")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "benchmarks.md"))
    a = ap.parse_args()
    if not os.path.exists(DEM):
        sys.exit("run scripts/setup.sh first (build/dem missing)")
    s_ours, s_other, s_yade = (4000, 500, 200) if a.quick else (20000, 3000, 1000)
    work = tempfile.mkdtemp(prefix="dem_bench_")
    res = {"machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                       "date": time.strftime("%Y-%m-%d")}, "packing": os.path.relpath(PACKING, ROOT),
           "mode": f"D2 at rate*t_c = {RATE_TC}", "codes": {}}
    C = res["codes"]
    print("benchmark: pair kernels, interleaved", file=sys.stderr)
    res["kernels"] = bench_kernels(PACKING, s_ours // 2, 2 if a.quick else 3)
    print("benchmark: same packing, D2, one code after the other", file=sys.stderr)
    for th in (1, 2):
        C[f"ours, {th} thread(s)"] = bench_ours(PACKING, th, s_ours)
    C["YADE 2023.02a, 1 thread"] = bench_yade(PACKING, s_yade, work)
    for r in (1, 2):
        C[f"LAMMPS pair granular, {r} MPI rank(s)"] = bench_lammps("lmp", decks.lammps_deck, PACKING, r, s_other, work, "sphere")
    C["LIGGGHTS hooke/stiffness, 1 MPI rank"] = bench_lammps("liggghts", decks.liggghts_deck, PACKING, 1, s_other, work, "granular")
    base = C["ours, 1 thread(s)"].get("particle_steps_per_s")
    for k, v in C.items():
        if "particle_steps_per_s" in v and base:
            v["ours_1thread_over_this"] = base / v["particle_steps_per_s"]
    # cost against N (ours)
    scaling = {}
    # N = 9261 k^3: the shared packing repeated k times along each axis, so every particle
    # sees the same neighbourhood and only N changes; N = 1000: a packing made by our runner.
    packings = {1000: make_packing(1000, work)}
    for k in ((1, 2) if a.quick else (1, 2, 3, 5)):
        n = 9261 * k ** 3
        packings[n] = PACKING if k == 1 else decks.replicate_packing(PACKING, k, os.path.join(work, f"rep{k}.txt"))
    for n, pk in packings.items():
        steps = max(200, int(s_ours * 9261 / n))
        scaling[n] = {th: bench_ours(pk, th, steps) for th in (1, 2)}
    res["scaling"] = scaling
    print("benchmark: production time steps, interleaved", file=sys.stderr)
    res["production"] = production_rows(work, s_ours // 2, 2 if a.quick else 3)
    with open(os.path.join(HERE, "results.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    lines = ["# Benchmarks", "",
             f"Generated by `/usr/bin/python3 bench/run_benchmarks.py{' --quick' if a.quick else ''}` on "
             f"{res['machine']['date']}, {res['machine']['cores']} cores ({res['machine']['cpu']}).",
             f"Packing `{res['packing']}` (N = 9261, φ = 0.70), {res['mode']}, timings of the stepping loop only.", "",
             "| code | particle-steps/s | peak RSS [MiB] | ours (1 thread) / this |", "|---|---|---|---|"]
    for k, v in C.items():
        if "error" in v:
            lines.append(f"| {k} | not run: {v['error'].strip().splitlines()[-1][:80] if v['error'].strip() else '?'} | | |")
        else:
            lines.append(f"| {k} | {v['particle_steps_per_s'] / 1e6:.2f} M | {v['peak_rss_mib']:.0f} | "
                         f"{v.get('ours_1thread_over_this', float('nan')):.2f} |")
    lines += ["", "## Pair kernels", "",
              "Ours, 1 thread, the same packing and steps; the kernels give the same bits (sim/src/forces/pair_kernels.cpp), so only the "
              f"speed differs. Median of {len(next(iter(res['kernels'].values()))['runs']) if res['kernels'] else 0} "
              "interleaved runs (the machine's speed drifts).", "",
              "| kernel | particle-steps/s (median) | runs | / reference |", "|---|---|---|---|"]
    ref = res["kernels"].get("reference", {}).get("median")
    for k, v in res["kernels"].items():
        lines.append(f"| {k} | {v['median'] / 1e6:.2f} M | {', '.join(f'{x / 1e6:.1f}' for x in v['runs'])} | "
                     f"{v['median'] / ref if ref else float('nan'):.2f} |")
    lines += ["", "## Our cost against N", "",
              "D2 as above. N = 9261 k³ is the shared packing repeated k times along each axis (the same "
              "neighbourhood for every particle, so only N changes); N = 1000 is a φ = 0.70 packing made by our runner.", "",
              "| N | packing | 1 thread | ns per particle-step (× N = 9261) | 2 threads | parallel efficiency | list rebuilds (1 thread) |",
              "|---|---|---|---|---|---|---|"]
    base_ns = None
    for n, r in scaling.items():
        p1, p2 = r[1].get("particle_steps_per_s"), r[2].get("particle_steps_per_s")
        kind = "runner" if n == 1000 else ("shared" if n == 9261 else f"shared × {round((n / 9261) ** (1 / 3))}³")
        if n == 9261:
            base_ns = 1e9 / p1 if p1 else None
        if p1 and p2:
            rel = f" ({1e9 / p1 / base_ns:.2f}×)" if n > 9261 and base_ns else ""
            lines.append(f"| {n} | {kind} | {p1 / 1e6:.2f} M | {1e9 / p1:.1f}{rel} | {p2 / 1e6:.2f} M | {p2 / (2 * p1):.0%} | "
                         f"{r[1].get('list_rebuilds')} in {r[1].get('steps')} steps |")
    lines += ["", "## Production time steps", "",
              "Ours, 1 thread, D2, at the time steps the scenes use (docs/accuracy_cost.md) beside the default; the "
              "list's rebuilds, their share of the wall time and what triggered them from `dem bench`'s "
              "`neighbor_list` line (diagnosed triggers: the first 32, then every 8th). \"Without rebuilds\": the "
              "same run's throughput with the rebuilds' time taken out (the issue's reference). Median of "
              f"{len(next(iter(res['production'].values())).get('runs', [])) if res['production'] else 0} interleaved runs.", "",
              "| physics | particle-steps/s (median) | without rebuilds | rebuilds per 10⁴ steps | rebuild share | "
              "triggers: rattler / packing (diagnosed) |", "|---|---|---|---|---|---|"]
    for k, v in res["production"].items():
        if "error" in v:
            lines.append(f"| {k} | not run | | | | |")
            continue
        nl = v["neighbor_list"]
        lines.append(f"| {k} | {v['particle_steps_per_s'] / 1e6:.2f} M | {v['without_rebuilds_per_s'] / 1e6:.2f} M | "
                     f"{nl['rebuilds_per_1e4_steps']:.0f} | {nl['rebuild_share']:.0%} | "
                     f"{nl['trigger_rattler']} / {nl['trigger_packing']} |")
    with open(os.path.join(HERE, "results.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    write_markdown(a.out, lines, os.path.join(HERE, "benchmarks_notes.md"))
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
