#!/usr/bin/env python3
"""Threads on a busy machine: particle-steps/s of `dem bench` (shared N = 9261 packing, D2) with
1 and 2 threads, alone and beside BURNERS busy processes (`yes > /dev/null`), for this build and
optionally another binary (e.g. one built from an earlier commit), alternating runs so that
both see the same machine. Also the cost of a fixed block count (integration.blocks).

    /usr/bin/python3 bench/busy_machine.py [--other /path/to/old/dem] [--repeats 3] [--burners 2]

Writes bench/busy_machine.csv and prints a table (Markdown). Reports the machine's load average
before each run: an "idle" row measured on a loaded machine is not idle.
"""
import argparse
import csv
import os
import re
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DEM = os.path.join(ROOT, "build", "dem")
PACKING = os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt")


def bench(binary, threads, steps, extra=(), env=None):
    p = subprocess.run([binary, "bench", "--packing", PACKING, "--steps", str(steps), "--threads", str(threads),
                        *extra], capture_output=True, text=True, env=env, check=True)
    return float(re.search(r"particle_steps_per_s=([0-9.eE+-]+)", p.stdout).group(1))


def with_burners(n, fn):
    burners = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(n)]
    try:
        return fn()
    finally:
        for b in burners:
            b.kill()
            b.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--other", help="another dem binary to compare with (same packing, same runs)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--burners", type=int, default=2)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--busy-steps", type=int, default=300)
    args = ap.parse_args()
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    binaries = [("this build", DEM)] + ([("other", args.other)] if args.other else [])
    cases = [("alone", 1, ()), ("alone", 2, ()), ("alone", 1, ("--set", "integration.blocks=12")),
             ("alone", 2, ("--set", "integration.blocks=12")), ("busy", 1, ()), ("busy", 2, ())]
    rows = []
    for where, threads, extra in cases:
        for label, binary in binaries:
            if extra and label != "this build":
                continue
            vals = []
            for _ in range(args.repeats):
                load = os.getloadavg()[0]
                steps = args.steps if where == "alone" else args.busy_steps
                run = lambda: bench(binary, threads, steps, extra, env)  # noqa: E731
                vals.append(with_burners(args.burners, run) if where == "busy" else run())
                print(f"{label:10s} {where:5s} threads={threads} {' '.join(extra):28s} {vals[-1] / 1e6:7.2f} M/s "
                      f"(load {load:.2f})", file=sys.stderr)
            rows.append({"binary": label, "where": where if where == "alone" else f"beside {args.burners} busy",
                         "threads": threads, "options": " ".join(extra) or "default",
                         "median_M_particle_steps_per_s": f"{statistics.median(vals) / 1e6:.2f}",
                         "min": f"{min(vals) / 1e6:.2f}", "max": f"{max(vals) / 1e6:.2f}", "runs": len(vals)})
    out = os.path.join(HERE, "busy_machine.csv")
    with open(out + ".part", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(out + ".part", out)
    print("| binary | where | threads | options | median M particle-steps/s | min | max |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['binary']} | {r['where']} | {r['threads']} | {r['options']} | {r['median_M_particle_steps_per_s']} "
              f"| {r['min']} | {r['max']} |")


if __name__ == "__main__":
    main()
