"""Two variance-reduction ideas for the quickstart's F_dev bands (issue 36), measured:

    build/dem ensemble bench/quickstart_orientations.toml --out runs/q36_orient     # ~8 min, 2 cores
    /usr/bin/python3 bench/quickstart_orientations.py runs/q36_orient [--out bench/quickstart_orientations]

1. **Orientation averaging.** Each packing's modes run along the three cyclic permutations of their
   axes (D2 = [1, 0, -1], [-1, 1, 0], [0, -1, 1]; D3 = [1/2, 1/2, -1] and its two permutations) from
   the same checkpoints. The projection of the preparation's own (random, traceless) fabric and stress
   anisotropy on the three loading directions sums to zero, so the per-packing average of the three
   cancels that part of the between-packing spread exactly at first order; the packing stays the
   statistical unit (K - 1 degrees of freedom). It costs three mode runs per packing. Compared at equal
   CPU with single-orientation ensembles of more packings, with the bench/quickstart_shape.py criterion
   (the plateau mean of the 95 % band's full width over the plateau level, plateau = last third).
2. **A control variate.** The initial anisotropy's signed projection X on the loading direction has
   mean zero by the preparation's symmetry under axis permutations, so Y - b (X - 0) estimates the same
   mean with variance (1 - rho^2) Var(Y) (rho = corr(X, Y) over the packings); rho is reported per curve.

Writes OUT.md (the tables) and prints them.
"""
import argparse
import glob
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from demkit.curves import read_curve  # noqa: E402
from quickstart_shape import judge  # noqa: E402

FAMILIES = {"D2": {"D2": (1, 0, -1), "D2y": (-1, 1, 0), "D2z": (0, -1, 1)},
            "D3": {"D3": (.5, .5, -1), "D3x": (-1, .5, .5), "D3y": (.5, -1, .5)}}
NUS = ("0.800", "0.740", "0.690")
DIAG = {"F_dev": ("F_xx", "F_yy", "F_zz"), "s_dev": ("sigma_xx_Pa", "sigma_yy_Pa", "sigma_zz_Pa")}


def load(members, name, q):
    """(eps_d, K x rows of q, mean CPU s, K initial signed projections)."""
    curves = [read_curve(os.path.join(m, "deviatoric", name + ".csv")) for m in members]
    n = min(len(c["eps_d"]) for c in curves)
    cpu = np.mean([json.load(open(os.path.join(m, "deviatoric", name + ".json")))["cpu_s"] for m in members])
    return np.asarray(curves[0]["eps_d"][:n]), np.array([np.asarray(c[q][:n]) for c in curves]), cpu, curves


def projection(curves, q, shape):
    """The first row's deviatoric diagonal of F or sigma on the compressed direction, over its trace/3."""
    r = -np.array(shape, float)
    r = (r - r.mean()) / np.linalg.norm(r - r.mean())
    out = []
    for c in curves:
        d = np.array([np.asarray(c[k])[0] for k in DIAG[q]])
        out.append((d - d.mean()) @ r / d.mean())
    return np.array(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run")
    ap.add_argument("--out", default="bench/quickstart_orientations")
    a = ap.parse_args(argv)
    members = sorted(glob.glob(os.path.join(a.run, "members", "m*")))
    k_all = len(members)
    emax = 0.2
    prep = float(np.mean([json.load(open(os.path.join(m, "prep.json")))["cpu_s"] for m in members]))
    cells = {(f, nu, q): [load(members, f"{n}_phi{nu}", q) for n in FAMILIES[f]]
             for f in FAMILIES for nu in NUS for q in DIAG}
    single_cpu = prep + sum(cells[(f, nu, "F_dev")][0][2] for f in FAMILIES for nu in NUS)
    triple_cpu = prep + sum(v[2] for f in FAMILIES for nu in NUS for v in cells[(f, nu, "F_dev")])
    lines = [f"K = {k_all} packings of `{a.run}`; CPU per packing: one orientation {single_cpu:.1f} s, "
             f"three {triple_cpu:.1f} s (preparation {prep:.1f} s)", ""]
    pairs = []
    for k3 in (4, 6, 8):
        k1 = int(round(k3 * triple_cpu / single_cpu))
        if k1 <= k_all and k_all // k3 >= 1:
            pairs.append((k1, k3))
    head = "| curve | ν | mode | " + " | ".join(f"one orientation, K = {k1} | three, K = {k3}" for k1, k3 in pairs) + \
        " | var(mean of 3)/var(one), K = %d (independent: 0.333) | ρ(initial projection, plateau) |" % k_all
    lines += [head, "|" + "---|" * (3 + 2 * len(pairs) + 2)]
    for q in DIAG:
        for nu in NUS:
            for f in FAMILIES:
                data = cells[(f, nu, q)]
                n = min(len(d[0]) for d in data)
                eps = data[0][0][:n]
                y = np.array([d[1][:, :n] for d in data])          # 3 x K x rows
                mean3 = y.mean(axis=0)
                row = [q, nu, f]
                for k1, k3 in pairs:   # disjoint subsets of packings, averaged
                    one = [judge(eps, y[i][j * k1:(j + 1) * k1], k1, emax)[0] for i in range(3) for j in range(k_all // k1)]
                    three = [judge(eps, mean3[j * k3:(j + 1) * k3], k3, emax)[0] for j in range(k_all // k3)]
                    row += [f"{np.mean(one):.3f}", f"{np.mean(three):.3f}"]
                plateau = eps >= 2 * emax / 3
                p = y[:, :, plateau].mean(axis=2)                   # 3 x K plateau means
                ratio = p.mean(axis=0).var(ddof=1) / np.mean([p[i].var(ddof=1) for i in range(3)])
                x = projection(data[0][3], q, list(FAMILIES[f].values())[0])
                rho = np.corrcoef(x, p[0])[0, 1]
                row += [f"{ratio:.3f}", f"{rho:+.2f}"]
                lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines) + "\n"
    tmp = a.out + ".md.part"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, a.out + ".md")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
