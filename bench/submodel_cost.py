#!/usr/bin/python3
"""The speed cost of each contact sub-model: `dem bench` on the shared N = 9261 packing, one
thread, D2, the models interleaved round by round (so that a change of the machine's load hits
all of them alike), the median of the rounds; optionally callgrind's instruction count per
particle-step (a reproducible ratio on a shared machine).

    /usr/bin/python3 bench/submodel_cost.py [--dem build/dem] [--steps 300] [--rounds 5] [--callgrind]
"""
import argparse
import os
import re
import statistics
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKING = os.path.join(REPO, "data", "packings", "n9261_phi0.70.txt")
# Luding's t_c (and so dt) comes from kp = 5 k1: dt_over_tc = 0.02 sqrt(5) gives it the linear
# models' dt, so that every row advances the same time per step (a smaller dt means fewer list
# rebuilds and fewer contacts at a limit per step, which would flatter the per-step cost).
SAME_DT = "integration.dt_over_tc=0.044721359549995794"
MODELS = [
    ("frictionless (linear)", []),
    ("friction mu = 0.5", ["contact.friction=0.5"]),
    ("friction + rolling mu_r = 0.1", ["contact.friction=0.5", "contact.rolling_friction=0.1"]),
    ("friction + twisting mu_o = 0.1", ["contact.friction=0.5", "contact.twisting_friction=0.1"]),
    ("friction + rolling + twisting", ["contact.friction=0.5", "contact.rolling_friction=0.1",
                                       "contact.twisting_friction=0.1"]),
    ("Luding normal (frictionless)", ["contact.normal=luding", "contact.luding_kc_N_m=1e8", SAME_DT]),
    ("Luding + friction", ["contact.normal=luding", "contact.luding_kc_N_m=1e8", "contact.friction=0.5", SAME_DT]),
    ("Luding + friction + rolling + twisting", ["contact.normal=luding", "contact.luding_kc_N_m=1e8", SAME_DT,
                                                "contact.friction=0.5", "contact.rolling_friction=0.1",
                                                "contact.twisting_friction=0.1"]),
]


def bench_args(dem, steps, keys):
    cmd = [dem, "bench", "--packing", PACKING, "--steps", str(steps), "--threads", "1"]
    for k in keys:
        cmd += ["--set", k]
    return cmd


def run_once(dem, steps, keys):
    out = subprocess.run(bench_args(dem, steps, keys), capture_output=True, text=True, check=True).stdout
    return float(re.search(r"particle_steps_per_s=([0-9.eE+-]+)", out).group(1))


def callgrind(dem, steps, keys):
    """Instructions (Ir) of `dem bench` with `steps` and with 2 x `steps` timed steps: their
    difference over steps x N is the cost of one particle-step, setup and warm-up removed."""
    def ir(n):
        f = f"/tmp/submodel_cost.callgrind.{os.getpid()}"
        r = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={f}"] + bench_args(dem, n, keys),
                           capture_output=True, text=True, check=True)
        os.remove(f)
        return int(re.search(r"Collected : (\d+)", r.stderr).group(1))
    return (ir(2 * steps) - ir(steps)) / (steps * 9261)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dem", default=os.path.join(REPO, "build", "dem"))
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--callgrind", action="store_true")
    ap.add_argument("--callgrind-steps", type=int, default=20)
    ap.add_argument("--only", default="", help="models whose name contains this text (and the first two, the references)")
    a = ap.parse_args(argv)
    global MODELS
    if a.only:
        MODELS = MODELS[:2] + [m for m in MODELS[2:] if a.only in m[0]]
    speeds = {name: [] for name, _ in MODELS}
    for r in range(a.rounds):
        for name, keys in MODELS:
            speeds[name].append(run_once(a.dem, a.steps, keys))
        print(f"round {r + 1}: " + ", ".join(f"{v[-1] / 1e6:.2f}" for v in speeds.values()), flush=True)
    base = statistics.median(speeds[MODELS[0][0]])
    fric = statistics.median(speeds[MODELS[1][0]])
    print("| model | median M particle-steps/s (rounds) | / frictionless | / friction |" +
          (" instructions per particle-step |" if a.callgrind else ""))
    print("|---|---|---|---|" + ("---|" if a.callgrind else ""))
    for name, keys in MODELS:
        med = statistics.median(speeds[name])
        row = (f"| {name} | {med / 1e6:.2f} ({', '.join(f'{v / 1e6:.2f}' for v in speeds[name])}) | "
               f"{med / base:.2f} | {med / fric:.2f} |")
        if a.callgrind:
            row += f" {callgrind(a.dem, a.callgrind_steps, keys):.0f} |"
        print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
