"""Two friction-study summaries of the same cells compared quantity by quantity (issue 31, seventh round: a fresh
K = 12 ensemble against the stored K = 8 one): per cell both means ± SE, the difference in combined standard
errors z = (b - a)/sqrt(se_a^2 + se_b^2), and how many cells lie beyond |z| = 2 against the number expected
(5 % of the cells compared) if both ensembles sample the same packings' statistics.

    /usr/bin/python3 -m demkit.summary_compare A/summary.csv B/summary.csv --out OUT [--mu 0.5 1]

OUT.md and OUT.csv; the cells are matched on (mu, mode, nu, quantity); a cell without an SE in either file
(one packing, or "not determined") is listed with z "not determined" and not counted.
"""
import argparse
import csv
import math

from demkit.atomic import write_atomic


def read(path, mus=None):
    """{(mu, mode, nu, quantity): (mean, se, packings)} of a demkit.friction_study summary.csv."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(l for l in fh if not l.startswith("#")))
    out = {}
    for r in rows:
        if mus and r["mu"] not in mus:
            continue
        out[(r["mu"], r["mode"], r["nu"], r["quantity"])] = (float(r["mean"]), float(r["se"]), r["packings"])
    return out


def compare(a, b):
    """Rows (key, a, b, z) over the cells in both; z nan where an SE is missing or both are 0."""
    rows = []
    for key in sorted(set(a) & set(b)):
        (ma, sa, _), (mb, sb, _) = a[key], b[key]
        se = math.hypot(sa, sb)
        z = (mb - ma) / se if se > 0 and math.isfinite(se) and math.isfinite(ma) and math.isfinite(mb) else math.nan
        rows.append((key, a[key], b[key], z))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a", help="the first summary.csv (demkit.friction_study)")
    ap.add_argument("b", help="the second summary.csv")
    ap.add_argument("--out", required=True, help="OUT.md and OUT.csv are written")
    ap.add_argument("--mu", nargs="+", help="only these friction coefficients")
    ap.add_argument("--labels", nargs=2, default=("A", "B"), help="names of the two summaries in the tables")
    o = ap.parse_args(argv)
    rows = compare(read(o.a, o.mu), read(o.b, o.mu))
    if not rows:
        raise SystemExit(f"summary_compare: {o.a} and {o.b} share no cell (mu, mode, nu, quantity)"
                         + (f" at mu {', '.join(o.mu)}" if o.mu else ""))
    la, lb = o.labels
    n = sum(1 for r in rows if math.isfinite(r[3]))
    beyond = [r for r in rows if math.isfinite(r[3]) and abs(r[3]) > 2]
    md = [f"<!-- demkit/summary_compare.py: {o.a} ({la}) against {o.b} ({lb}); z = ({lb} - {la}) / combined SE -->",
          f"{len(beyond)} of {n} cells beyond |z| = 2 (expected {0.05 * n:.1f} if both sample the same statistics; "
          "the cells are correlated, the same packings giving several).", "",
          f"| μ | mode | ν | quantity | {la}: mean ± SE (K) | {lb}: mean ± SE (K) | z |", "|---|---|---|---|---|---|---|"]
    lines = ["mu,mode,nu,quantity," + f"{la}_mean,{la}_se,{la}_packings,{lb}_mean,{lb}_se,{lb}_packings,z\n"]
    for key, (ma, sa, ka), (mb, sb, kb), z in rows:
        zs = f"{z:.2f}" if math.isfinite(z) else "not determined"
        mark = "**" if math.isfinite(z) and abs(z) > 2 else ""
        md.append(f"| {' | '.join(key)} | {ma:.4g} ± {sa:.2g} ({ka}) | {mb:.4g} ± {sb:.2g} ({kb}) | {mark}{zs}{mark} |")
        lines.append(",".join([*key, f"{ma:.6g}", f"{sa:.3g}", ka, f"{mb:.6g}", f"{sb:.3g}", kb,
                               f"{z:.4g}" if math.isfinite(z) else "nan"]) + "\n")
    write_atomic(o.out + ".md", "\n".join(md) + "\n")
    write_atomic(o.out + ".csv", "".join(lines))
    print(md[1])


if __name__ == "__main__":
    main()
