"""Chaos floor from an ensemble of our runs (dt perturbed by -0.2 % ... +0.5 %) against the
distances of YADE's curve to each member: is YADE distinguishable from one more member of our
ensemble? Distances are `dem compare`'s checked measures (p max rel, s_dev and F_dev RMS rel to
the first curve's plateau, C RMS, eps_v RMS).
Run: /usr/bin/python3 yade_ref/floor_ensemble.py YADE.csv OURS1.csv OURS2.csv ...
"""
import itertools
import sys
import os

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from demkit.compare import compare  # noqa: E402
from demkit.curves import read_curve  # noqa: E402

MEASURES = [("p_Pa", "max_rel"), ("s_dev", "rms_rel"), ("F_dev", "rms_rel"), ("C", "rms_abs"), ("eps_v", "rms_abs")]

yade = read_curve(sys.argv[1])
ours = [read_curve(f) for f in sys.argv[2:]]
floor = {q: [] for q, _ in MEASURES}
vs_yade = {q: [] for q, _ in MEASURES}
for a, b in itertools.permutations(range(len(ours)), 2):     # ordered: the plateau scale is the first curve's
    res, _ = compare(ours[a], ours[b])
    for q, k in MEASURES:
        floor[q].append(res[q][k])
for a in ours:
    res, _ = compare(a, yade)
    for q, k in MEASURES:
        vs_yade[q].append(res[q][k])
n = len(ours)
print(f"{n} runs of ours: {n * (n - 1)} ordered pairs; YADE against each of the {n}")
print(f"{'quantity':10s} {'measure':8s} {'ours-ours median':>16s} {'90%':>9s} {'max':>9s} | {'ours-YADE median':>16s} {'max':>9s}"
      f" | {'YADE-median rank':>16s}")
for q, k in MEASURES:
    f, y = np.array(floor[q]), np.array(vs_yade[q])
    rank = (f < np.median(y)).mean()
    print(f"{q:10s} {k:8s} {np.median(f):16.4g} {np.percentile(f, 90):9.4g} {f.max():9.4g} | {np.median(y):16.4g} "
          f"{y.max():9.4g} | {rank:16.2f}")
