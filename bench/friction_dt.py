#!/usr/bin/env python3
"""Accuracy against cost with friction on (issue 24, item 6): one frictional D2 run from one
relaxed N = 1000 checkpoint at several dt/t_c and two strain rates, each against the reference
(dt = t_c/50) and against the chaos floor (the reference with dt perturbed by 0.1 %).

    /usr/bin/python3 bench/friction_dt.py CHECKPOINT.ckpt --out data/friction_n1000/dt   (about 3 min, 1 thread)

The time scales with friction: the tangential spring k_t = (2/7) k has the normal contact's half
period for a sticking contact (m_t = (2/7) m of a sphere rolling without slip), so t_c stays the
step's scale; rotations add no shorter one. This measures it: error of s_dev (RMS over eps_d) and
of p (relative RMS), wall time per run, and blow-ups, at dt/t_c in DTS.
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
from demkit.curves import read_curve  # noqa: E402

DEM = os.path.join(ROOT, "build", "dem")
DTS = [0.05, 0.1, 0.2, 0.3, 0.4, 0.5]
REF_DT = 0.02


def run(ckpt, out, dt, rate, eps):
    t0 = time.time()
    p = subprocess.run([DEM, "mode", "--packing", ckpt, "--mode", "D2", "--rate-tc", str(rate), "--eps-max", str(eps),
                        "--out", out, "--threads", "1", "--quiet", "--force",
                        "--set", f"integration.dt_over_tc={dt}"], capture_output=True, text=True)
    return {"dt_over_tc": dt, "rate_tc": rate, "rc": p.returncode, "wall_s": time.time() - t0,
            "stderr": p.stderr.strip().splitlines()[-1] if p.returncode else ""}


def errors(path, ref):
    c, r = read_curve(path), read_curve(ref)
    grid = np.linspace(0, min(c["eps_d"][-1], r["eps_d"][-1]), 100)
    s = np.interp(grid, c["eps_d"], c["s_dev"]) - np.interp(grid, r["eps_d"], r["s_dev"])
    rp = np.interp(grid, r["eps_d"], r["p_Pa"])
    p = np.interp(grid, c["eps_d"], c["p_Pa"]) / rp - 1
    return {"err_s_dev": float(np.sqrt(np.mean(s ** 2))), "err_p_rel": float(np.sqrt(np.mean(p ** 2)))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint")
    ap.add_argument("--out", required=True)
    ap.add_argument("--eps", type=float, default=0.06)
    ap.add_argument("--rate", type=float, default=3e-5)
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    ref = os.path.join(a.out, "ref.csv")
    rows = [run(a.checkpoint, ref, REF_DT, a.rate, a.eps)]
    floor = os.path.join(a.out, "floor.csv")
    rows.append(run(a.checkpoint, floor, REF_DT * 1.001, a.rate, a.eps))
    rows[-1].update(errors(floor, ref), kind="chaos floor")
    for dt in DTS:
        f = os.path.join(a.out, f"dt{dt}.csv")
        rows.append(run(a.checkpoint, f, dt, a.rate, a.eps))
        if rows[-1]["rc"] == 0:
            rows[-1].update(errors(f, ref))
        rows[-1]["kind"] = "dt"
    for rate in (a.rate / 2, a.rate * 2):
        f = os.path.join(a.out, f"rate{rate:g}.csv")
        rows.append(run(a.checkpoint, f, 0.2, rate, a.eps))
        if rows[-1]["rc"] == 0:
            rows[-1].update(errors(f, ref))
        rows[-1]["kind"] = "rate (dt = t_c/5)"
    with open(os.path.join(a.out, "friction_dt.json"), "w") as fh:
        json.dump({"checkpoint": a.checkpoint, "reference_dt_over_tc": REF_DT, "rows": rows}, fh, indent=1)
    lines = ["| run | dt/t_c | rate·t_c | error s_dev (RMS) | error p (rel. RMS) | wall [s] | exit |",
             "|---|---|---|---|---|---|---|"]
    for r in rows[1:]:
        lines.append(f"| {r.get('kind', '')} | {r['dt_over_tc']:g} | {r['rate_tc']:g} | {r.get('err_s_dev', float('nan')):.2e} | "
                     f"{r.get('err_p_rel', float('nan')):.2e} | {r['wall_s']:.1f} | {r['rc']} {r['stderr'][:80]} |")
    with open(os.path.join(a.out, "friction_dt.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
