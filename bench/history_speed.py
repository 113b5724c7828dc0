#!/usr/bin/python3
"""The cost of a step with per-contact history against a frictionless one, two ways that survive a
shared machine (docs/benchmarks.md, "Friction on the vector kernels, faster"):

  --callgrind   instructions per particle-step, per function: `valgrind --tool=callgrind` of
                `dem bench` at 20 and at 220 timed steps (both after its 200 warm-up steps), the
                difference over 200 x N (setup and warm-up cancel); deterministic.
  (default)     alternating rounds of CPU time: per run `perf stat -e task-clock` of `dem bench
                --steps S+1` minus `--steps 1`, i.e. the CPU seconds of S timed steps (the other
                sessions' load costs less than in wall time), for each binary given, and LAMMPS
                (`lmp`, bench/decks.py's decks) the same way at `run S'+1` minus `run 1`.

    /usr/bin/python3 bench/history_speed.py --dem OLD=old/dem --dem NEW=build/dem [--rounds 3] [--callgrind]

Models: frictionless, frictional (mu = 0.5, k_t = 2/7 k), friction + rolling + twisting
(mu_r = mu_o = 0.1), Luding's normal law (its defaults). Shared N = 9261 packing, D2 at 5e-6/t_c,
dt = t_c/50, one thread.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "bench"))
import decks  # noqa: E402
import run_benchmarks  # noqa: E402

PACKING = os.path.join(REPO, "..", "shared", "packings", "n9261_phi0.70.txt")
MODELS = {
    "frictionless": [],
    "frictional": ["contact.friction=0.5"],
    "friction+rolling+twisting": ["contact.friction=0.5", "contact.rolling_friction=0.1",
                                  "contact.twisting_friction=0.1"],
    "luding": ["contact.normal=luding"],
    "hertz_mindlin": ["contact.normal=hertz", "contact.tangential=mindlin", "contact.friction=0.5"],
}
LAMMPS_MODELS = ["frictionless", "frictional", "friction+rolling+twisting", "hertz_mindlin"]
LIGGGHTS_MODELS = ["frictionless", "frictional"]   # the laws with a LIGGGHTS counterpart in the registry


def bench_cmd(dem, packing, model, steps):
    cmd = [dem, "bench", "--packing", packing, "--steps", str(steps), "--threads", "1",
           "--set", "integration.dt_over_tc=0.02"]
    for key in MODELS[model]:
        cmd += ["--set", key]
    return cmd


def task_clock_ms(cmd, cwd=None):
    """CPU milliseconds of a command (perf's task-clock)."""
    r = subprocess.run(["perf", "stat", "-x,", "-e", "task-clock"] + cmd, capture_output=True, text=True, cwd=cwd)
    if r.returncode:
        raise RuntimeError(f"{cmd[0]} failed: {r.stderr[-1000:]}")
    return float(next(line for line in r.stderr.splitlines() if "task-clock" in line).split(",")[0])


def callgrind_per_function(dem, packing, model, n_particles, workdir):
    """Instructions per particle-step of the 200-step difference, total and per function."""
    totals = {}
    for steps in (20, 220):
        out = os.path.join(workdir, f"cg.{steps}.out")
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}"] +
                       bench_cmd(dem, packing, model, steps), check=True, capture_output=True)
        ann = subprocess.run(["callgrind_annotate", "--threshold=100", out], capture_output=True, text=True,
                             check=True).stdout
        per = {}
        for line in ann.splitlines():
            m = re.match(r"\s*([\d,]+) \(\s*[\d.]+%\)\s+(.*)", line)
            if m:
                name = re.sub(r"<.*>", "<>", re.sub(r"^\S*?:", "", m.group(2), count=1))[:80]
                per[name] = per.get(name, 0) + int(m.group(1).replace(",", ""))
        totals[steps] = per
    scale = 200.0 * n_particles
    return {k: (totals[220][k] - totals[20].get(k, 0)) / scale for k in totals[220]}


def lammps_deck(model, data, steps, tc, r_min):
    """LAMMPS' deck of one of MODELS: the pair_coeff line from ours' registry (decks.pair_coeff) with
    the model's --set keys, at ours' dt = 0.02 t_c (Hertz: t_c the Rayleigh time, ours' defaults
    E = 1e8 Pa, nu = 0.3)."""
    if model == "hertz_mindlin":
        tc = decks.rayleigh_time(r_min, 1e8, 0.3, 2000.0)
    return decks.lammps_deck(data, steps, run_benchmarks.RATE_TC / tc, 0.02 * tc, sets=tuple(MODELS[model]),
                             thermo=model != "frictionless")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dem", action="append", required=True, help="LABEL=PATH of a dem binary (repeatable)")
    ap.add_argument("--packing", default=PACKING)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=1000, help="timed steps of ours")
    ap.add_argument("--lammps-steps", type=int, default=300)
    ap.add_argument("--callgrind", action="store_true")
    ap.add_argument("--models", default=",".join(MODELS), help="comma-separated subset of: " + ", ".join(MODELS))
    args = ap.parse_args()
    models = args.models.split(",")
    unknown = [m for m in models if m not in MODELS]
    if unknown:
        ap.error(f"unknown model(s) {unknown}: choose from {', '.join(MODELS)}")
    bins = [tuple(d.split("=", 1)) for d in args.dem]
    cell, spheres = decks.read_packing(args.packing)
    n = len(spheres)
    work = tempfile.mkdtemp(prefix="history_speed")
    if args.callgrind:
        for label, dem in bins:
            for model in models:
                per = callgrind_per_function(dem, args.packing, model, n, work)
                print(f"{label} {model}: {per.pop('PROGRAM TOTALS'):.1f} instructions per particle-step")
                for name, v in sorted(per.items(), key=lambda kv: -kv[1]):
                    if v >= 1.0:
                        print(f"    {v:8.1f}  {name}")
        return
    tc = decks.tc_smallest(spheres)
    data = os.path.join(work, "lmp.data")
    decks.write_lammps_data(data, cell, spheres, 2000.0, "sphere")
    data_granular = os.path.join(work, "liggghts.data")
    decks.write_lammps_data(data_granular, cell, spheres, 2000.0, "granular")
    rates = {}

    def record(key, rate):
        rates.setdefault(key, []).append(rate)
        print(f"  {key}: {rate:.2f} M particle-steps per CPU-second", flush=True)

    for r in range(args.rounds):
        print(f"round {r + 1}", flush=True)
        for model in models:
            for label, dem in bins:
                t = task_clock_ms(bench_cmd(dem, args.packing, model, args.steps + 1)) - \
                    task_clock_ms(bench_cmd(dem, args.packing, model, 1))
                record(f"{label} {model}", args.steps * n / t / 1e3)
        for model in [m for m in LAMMPS_MODELS if m in models and run_benchmarks.shutil.which("lmp")]:
            ms = []
            for steps in (args.lammps_steps + 1, 1):
                deck = os.path.join(work, f"in.{model}.{steps}")
                with open(deck, "w") as fh:
                    fh.write(lammps_deck(model, data, steps, tc, min(sp[3] for sp in spheres)))
                ms.append(task_clock_ms(["lmp", "-in", deck, "-log", "none"], cwd=work))
            record(f"lammps {model}", args.lammps_steps * n / (ms[0] - ms[1]) / 1e3)
        for model in [m for m in LIGGGHTS_MODELS if m in models and run_benchmarks.shutil.which("liggghts")]:
            ms = []
            for steps in (args.lammps_steps + 1, 1):
                deck = os.path.join(work, f"in.liggghts.{model}.{steps}")
                with open(deck, "w") as fh:
                    fh.write(decks.liggghts_deck(data_granular, steps, run_benchmarks.RATE_TC / tc, 0.02 * tc,
                                                 sets=tuple(MODELS[model])))
                ms.append(task_clock_ms(["liggghts", "-in", deck, "-log", "none"], cwd=work))
            record(f"liggghts {model}", args.lammps_steps * n / (ms[0] - ms[1]) / 1e3)
    print("medians (the rounds):")
    for key, v in rates.items():
        print(f"  {key}: {statistics.median(v):.2f} ({', '.join(f'{x:.2f}' for x in v)})")


if __name__ == "__main__":
    main()
