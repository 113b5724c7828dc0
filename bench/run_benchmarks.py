#!/usr/bin/env python3
"""Speed benchmarks: the same packing under D2 in our runner, YADE, LAMMPS and LIGGGHTS,
side by side in one run, plus our cost against N. Not a test: numbers depend on the machine.

    /usr/bin/python3 bench/run_benchmarks.py [--quick] [--production-only] [--out docs/benchmarks.md]

Writes a Markdown table (default docs/benchmarks.md) and bench/results.json. Codes that are
not installed are reported as such (scripts/install-deps.sh --bench installs LAMMPS and LIGGGHTS).
--production-only: only the production time steps (ours and LAMMPS at the same dt, rate and
skin; about 3-4 minutes), to bench/production.md and bench/production.json, and spliced into
docs/benchmarks.md in place of its production section (its notes from bench/benchmarks_notes.md anew).
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
WARMUP = 200   # `dem bench`'s untimed warm-up steps (sim/src/cli/main.cpp); LAMMPS' production runs do as many


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
    lp = re.search(r"([0-9.]+) listed pairs per particle", out)
    r["listed_pairs_per_particle"] = float(lp.group(1)) if lp else None
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


def production_cases(work):
    """label -> (ours' packing, LAMMPS' packing, dt / t_c, strain rate x t_c, steps factor, skin/r_min
    or None for the scenes' "auto"). The quickstart member: ours from the relaxed checkpoint
    (bit-exact state, velocities included), LAMMPS from the YADE text file `dem run` writes beside
    it (positions and radii: at rest); 9x the steps at N = 1000 for about the same particle-steps
    as at N = 9261. The production rows also at 0.4 r_min, the skin before "auto"."""
    ckpt = relaxed_quickstart_checkpoint(work)
    txt = os.path.splitext(ckpt)[0] + ".txt"
    qs, fig3 = "quickstart member (N = 1000, φ = 0.80), t_c/5, 3e-5/t_c", "shared N = 9261, t_c/10, 1e-5/t_c (Figure 3)"
    return {qs: (ckpt, txt, 0.2, 3e-5, 9, None),
            qs + ", skin 0.4 r_min": (ckpt, txt, 0.2, 3e-5, 9, 0.4),
            fig3: (PACKING, PACKING, 0.1, 1e-5, 1, None),
            fig3 + ", skin 0.4 r_min": (PACKING, PACKING, 0.1, 1e-5, 1, 0.4),
            "shared N = 9261, t_c/50, 5e-6/t_c (default dt)": (PACKING, PACKING, 0.02, RATE_TC, 1, None)}


def median_run(rs):
    """The run of median throughput among the good ones (with all throughputs as `runs`)."""
    good = [r for r in rs if "error" not in r]
    if not good:
        return rs[0]
    med = sorted(good, key=lambda r: r["particle_steps_per_s"])[len(good) // 2]
    return dict(med, runs=[r["particle_steps_per_s"] for r in good])


def production_rows(work, steps, rounds):
    """The production time steps beside the default dt: the quickstart's physics (t_c/5, 3e-5/t_c)
    from a relaxed member checkpoint, Figure 3's (t_c/10, 1e-5/t_c) and the default t_c/50 on
    the shared packing. Ours: interleaved rounds, medians. LAMMPS: once per row, in the first
    round right after ours' run of that row, at ours' dt, rate and skin (lammps_production).
    For a row whose LAMMPS packing is not ours' (the checkpoint's .txt), ours also runs once from
    that packing (`ours_from_lammps_packing`): what starting at rest changes."""
    cases = production_cases(work)
    runs, extra = {k: [] for k in cases}, {k: {} for k in cases}
    for rnd in range(rounds):
        for k, (pk, lpk, dt, rate, f, skin) in cases.items():
            runs[k].append(bench_production(pk, steps * f, dt, rate, skin))
            if rnd == 0:
                extra[k]["lammps"] = lammps_production(lpk, steps * f, dt, rate, runs[k][-1], work)
            if rnd == 0 and lpk != pk and skin is None:
                extra[k]["ours_from_lammps_packing"] = bench_production(lpk, steps * f, dt, rate)
    rows = {k: dict(median_run(rs), **extra[k]) for k, rs in runs.items()}
    for row in rows.values():
        ours, lmp = row.get("particle_steps_per_s"), row["lammps"].get("particle_steps_per_s")
        row["ours_over_lammps"] = ours / lmp if ours and lmp else None
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
    """(seconds, steps, atoms) of the last run in a LAMMPS/LIGGGHTS log (the timed one)."""
    m = re.findall(r"Loop time of ([0-9.eE+]+) on (\d+) procs for (\d+) steps with (\d+) atoms", out)
    return (float(m[-1][0]), int(m[-1][2]), int(m[-1][3])) if m else None


def lammps_neighbor(out, steps):
    """LAMMPS' own neighbour-list statistics of the last run in its log: "Neighbor list builds",
    "Dangerous builds", the "Neigh" row's %total of the MPI task timing breakdown (the share of
    the loop time spent building lists) and "Neighs" (listed pairs) per atom. {} if absent."""
    builds = re.findall(r"Neighbor list builds = (\d+)", out)
    danger = re.findall(r"Dangerous builds = (\d+)", out)
    neigh = re.findall(r"^Neigh\s*\|.*\|\s*([0-9.eE+-]+)\s*$", out, re.M)
    pairs = re.findall(r"^Neighs:\s*([0-9.eE+]+) ave", out, re.M)
    lt = loop_time(out)
    if not (builds and neigh and lt):
        return {}
    return {"neighbor_list_builds": int(builds[-1]), "dangerous_builds": int(danger[-1]) if danger else None,
            "builds_per_1e4_steps": 1e4 * int(builds[-1]) / steps, "neigh_share": float(neigh[-1]) / 100,
            "neighs_per_atom": float(pairs[-1]) / lt[2] if pairs else None}


def bench_lammps(exe, deck_fn, packing, ranks, steps, workdir, style, dt_over_tc=0.02, rate_tc=RATE_TC, tc=None,
                 density=2000.0, **deck_kw):
    """Throughput of LAMMPS or LIGGGHTS on `packing` under D2 at dt = dt_over_tc t_c and strain rate
    rate_tc / t_c (t_c: `tc`, else that of the packing's smallest sphere), deck_fn's deck with
    deck_kw (skin, warmup, physics); with the list statistics of its timed run."""
    if not shutil.which(exe):
        return {"error": f"{exe} not installed"}
    cell, spheres = decks.read_packing(packing)
    tc = tc or decks.tc_smallest(spheres)
    data = os.path.join(workdir, f"{exe}.data")
    decks.write_lammps_data(data, cell, spheres, density, style)
    deck = os.path.join(workdir, f"in.{exe}")
    text = deck_fn(data, steps, rate_tc / tc, tc * dt_over_tc, **deck_kw)
    with open(deck, "w") as fh:
        fh.write(text)
    cmd = [exe, "-in", deck, "-log", "none"]
    if ranks > 1:
        cmd = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(ranks)] + cmd
    out, _, rc, rss = with_rss(cmd, cwd=workdir)
    lt = loop_time(out)
    if rc or not lt:
        return {"error": out[-500:]}
    return dict({"particle_steps_per_s": lt[1] * lt[2] / lt[0], "peak_rss_mib": rss, "steps": lt[1],
                 "dt_s": tc * dt_over_tc, "rate_per_s": rate_tc / tc, "deck": text.replace(data, os.path.basename(data))},
                **lammps_neighbor(out, lt[1]))


def ours_physics():
    """t_c and the contact physics of the scene `dem bench` loads (the built-in defaults), read
    through demtk (build/python), so LAMMPS gets ours' dt, rate and forces exactly; {} when demtk
    is not built (bench_lammps then takes t_c of the packing's smallest sphere, decks' defaults)."""
    if os.path.join(ROOT, "build", "python") not in sys.path:
        sys.path.insert(0, os.path.join(ROOT, "build", "python"))
    try:
        import demtk
    except ImportError:
        return {}
    sc = demtk.load_scene(None)
    return {"tc": sc.t_c, "density": sc.density, "k": sc.stiffness, "gamma": sc.damping, "gamma_b": sc.background_damping}


def lammps_production(packing, steps, dt_over_tc, rate_tc, ours, work):
    """LAMMPS (pair granular, 1 MPI rank, decks.lammps_deck) on a production row's packing at ours'
    dt, strain rate and skin (the skin_m of ours' run `ours`), after ours' WARMUP untimed steps:
    throughput, its own list builds and their share of the loop time."""
    skin = ours.get("neighbor_list", {}).get("skin_m")
    if not skin:
        return {"error": "ours did not run: no skin to match"}
    phys = ours_physics()
    r = bench_lammps("lmp", decks.lammps_deck, packing, 1, steps, work, "sphere", dt_over_tc=dt_over_tc,
                     rate_tc=rate_tc, skin=skin, warmup=WARMUP, **phys)
    tc_from = "ours' scene (demtk)" if phys else "the packing's smallest sphere (demtk not built)"
    return dict(r, skin_m=skin, warmup_steps=WARMUP, packing=os.path.basename(packing), t_c_from=tc_from)


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


def step_counts(quick):
    """Steps of ours, of LAMMPS/LIGGGHTS and of YADE in the first table (production rows: ours' // 2)."""
    return (4000, 500, 200) if quick else (20000, 3000, 1000)


def production_rounds(quick):
    """Interleaved rounds of ours' production runs (the median of them is reported)."""
    return 2 if quick else 3


def machine():
    return {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(), "date": time.strftime("%Y-%m-%d")}


def generated_by(a, mach):
    flags = "".join(f" --{f}" for f, on in (("quick", a.quick), ("production-only", a.production_only)) if on)
    return (f"Generated by `/usr/bin/python3 bench/run_benchmarks.py{flags}` on {mach['date']}, {mach['cores']} cores "
            f"({mach['cpu']}).")


def lammps_cells(v):
    """A production row's LAMMPS cells: throughput, list builds, Neigh share, ours / LAMMPS."""
    lm = v.get("lammps", {})
    if "particle_steps_per_s" not in lm:
        msg = lm.get("error", "?").strip().splitlines()
        return f"not run: {msg[-1][:60].replace('|', '/') if msg else '?'} | | | "
    builds = (f"{lm['builds_per_1e4_steps']:.0f} ({lm['neighbor_list_builds']} in {lm['steps']})"
              if "neighbor_list_builds" in lm else "?")
    share = f"{lm['neigh_share']:.0%}" if "neigh_share" in lm else "?"
    ratio = f"{v['ours_over_lammps']:.2f}" if v.get("ours_over_lammps") else "?"
    return f"{lm['particle_steps_per_s'] / 1e6:.2f} M | {builds} | {share} | {ratio}"


def production_notes(prod):
    """What differs between ours' and LAMMPS' production runs (measured parts from `prod`)."""
    lines = []
    for k, v in prod.items():
        o, lm = v.get("ours_from_lammps_packing", {}), v.get("lammps", {})
        if "neighbor_list" in o and "neighbor_list" in v:
            lines.append(f"- {k}: LAMMPS starts at rest from `{lm.get('packing')}`, the YADE text file `dem run` "
                         "writes beside the checkpoint (positions and radii; the checkpoint's velocities are not in "
                         f"it). Ours from that file (one run): {o['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s, "
                         f"{o['neighbor_list']['rebuilds_per_1e4_steps']:.0f} rebuilds per 10⁴ steps (from the "
                         f"checkpoint: {v['neighbor_list']['rebuilds_per_1e4_steps']:.0f}).")
    pairs = [f"{k}: {v['lammps']['neighs_per_atom']:.2f} / {v['listed_pairs_per_particle']:.2f}" for k, v in prod.items()
             if v.get("lammps", {}).get("neighs_per_atom") and v.get("listed_pairs_per_particle")]
    if pairs:
        lines.append("- Listed pairs per particle at the end, LAMMPS / ours (the decks' `newton off`: a pair across the "
                     "periodic boundary is listed and computed from both sides): " + "; ".join(pairs) + ".")
    return lines + [
        "- Rebuild criterion: both rebuild when a particle has moved half the skin since the last build, every "
        "step. LAMMPS measures the displacement in absolute coordinates, so the affine motion that `fix deform "
        "... remap x` gives the atoms counts towards it; ours measures it in the box of the last build (the "
        "budget shrunk by the box's compression since).",
        "- Otherwise the physics of the first table of docs/benchmarks.md, with the differences its notes list "
        "(e.g. LAMMPS does not clamp the normal force at zero)."]


def production_section(prod):
    """The "Production time steps" section: ours beside LAMMPS at the same dt, rate and skin."""
    n_runs = len(next(iter(prod.values())).get("runs", [])) if prod else 0
    lm = next((v["lammps"] for v in prod.values() if "deck" in v.get("lammps", {})), {})
    lines = ["", "## Production time steps", "",
             "Ours, 1 thread, D2, at the time steps the scenes use (docs/accuracy_cost.md) beside the default; the "
             "list's rebuilds, their share of the wall time and what triggered them from `dem bench`'s "
             "`neighbor_list` line (diagnosed triggers: the first 32, then every 8th). \"Without rebuilds\": the "
             "same run's throughput with the rebuilds' time taken out (the issue's reference). Median of "
             f"{n_runs} interleaved runs.", "",
             "LAMMPS: `pair granular` (`bench/decks.py`'s `lammps_deck`), 1 MPI rank, on the same packing at ours' "
             "dt, strain rate and skin (ours' `skin_m`; `neighbor SKIN bin`, `neigh_modify delay 0 every 1 check "
             f"yes`), after {lm.get('warmup_steps', WARMUP)} untimed steps as `dem bench` (`run {WARMUP}`, then the "
             f"timed `run STEPS pre no`), t_c from {lm.get('t_c_from', '?')}; one run per row, right after ours' "
             "first. Its list builds are the log's \"Neighbor list builds\" of the timed run, their share the "
             "\"Neigh\" row's %total of its timing breakdown. Ours / LAMMPS: particle-steps/s, ours' median over "
             "LAMMPS' run. Rebuilds: per 10⁴ steps (count in steps).", "",
             "| physics | ours: particle-steps/s (median) | without rebuilds | rebuilds per 10⁴ steps | rebuild share | "
             "triggers: rattler / packing (diagnosed) | LAMMPS: particle-steps/s | LAMMPS: list builds per 10⁴ steps | "
             "LAMMPS: Neigh share | ours / LAMMPS |", "|---|---|---|---|---|---|---|---|---|---|"]
    for k, v in prod.items():
        if "error" in v:
            lines.append(f"| {k} | not run | | | | | {lammps_cells(v)} |")
            continue
        nl = v["neighbor_list"]
        lines.append(f"| {k} | {v['particle_steps_per_s'] / 1e6:.2f} M | {v['without_rebuilds_per_s'] / 1e6:.2f} M | "
                     f"{nl['rebuilds_per_1e4_steps']:.0f} ({nl['rebuilds']} in {nl['steps']}) | {nl['rebuild_share']:.0%} | "
                     f"{nl['trigger_rattler']} / {nl['trigger_packing']} | {lammps_cells(v)} |")
    return lines + ["", "What differs between the two codes' runs:", ""] + production_notes(prod)


def splice_production(page, section, note):
    """Puts `section` (its "## Production time steps" heading first) into the generated page in place
    of the one there (or before its notes), and the page's notes anew from bench/benchmarks_notes.md;
    the page's other tables are left as the last full run wrote them."""
    with open(page) as fh:
        text = fh.read()
    head = text.split("\n## Notes", 1)[0].split("\n## Production time steps", 1)[0].rstrip("\n")
    lines = [head] + section[:3] + [note, ""] + section[3:]
    write_markdown(page, lines, os.path.join(HERE, "benchmarks_notes.md"))


def production_only(a):
    """--production-only: the production rows (ours + LAMMPS) alone, written to bench/production.json
    and bench/production.md (or --out), and spliced into docs/benchmarks.md (splice_production);
    bench/results.json is left alone."""
    work = tempfile.mkdtemp(prefix="dem_bench_")
    res = {"machine": machine(), "production": production_rows(work, step_counts(a.quick)[0] // 2,
                                                               production_rounds(a.quick))}
    with open(os.path.join(HERE, "production.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    lines = ["# Production time steps: ours and LAMMPS", "", generated_by(a, res["machine"]),
             "The same section as in docs/benchmarks.md (a full run of the script regenerates both)."]
    section = production_section(res["production"])
    write_markdown(a.out or os.path.join(HERE, "production.md"), lines + section)
    if not a.out:
        splice_production(os.path.join(ROOT, "docs", "benchmarks.md"), section,
                          f"(This section: {generated_by(a, res['machine'])[0].lower()}{generated_by(a, res['machine'])[1:]})")
    shutil.rmtree(work, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps, N only to 74 088")
    ap.add_argument("--production-only", action="store_true",
                    help="only the production rows (ours + LAMMPS), to bench/production.md and bench/production.json")
    ap.add_argument("--out", help="Markdown page (default docs/benchmarks.md; bench/production.md with --production-only)")
    a = ap.parse_args()
    if not os.path.exists(DEM):
        sys.exit("run scripts/setup.sh first (build/dem missing)")
    if a.production_only:
        return production_only(a)
    s_ours, s_other, s_yade = step_counts(a.quick)
    work = tempfile.mkdtemp(prefix="dem_bench_")
    res = {"machine": machine(), "packing": os.path.relpath(PACKING, ROOT),
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
    res["production"] = production_rows(work, s_ours // 2, production_rounds(a.quick))
    with open(os.path.join(HERE, "results.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    lines = ["# Benchmarks", "",
             generated_by(a, res["machine"]),
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
    lines += production_section(res["production"])
    with open(os.path.join(HERE, "results.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    write_markdown(a.out or os.path.join(ROOT, "docs", "benchmarks.md"), lines, os.path.join(HERE, "benchmarks_notes.md"))
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
