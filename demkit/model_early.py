"""Where along the strain a model curve misses (issue 31, twenty-seventh round): for each curve of a `dem model`
output folder (OUT/curves/*.csv, OUT/curves/paths/*.csv), the RMS of model - DEM mean over the curve's mean 95 %
band half-width (the measure of `dem model`'s prediction table), over the whole curve and split at eps_d = SPLIT,
with the share of the squared error that lies before the split.

    /usr/bin/python3 -m demkit.model_early OUT [--split 0.1] [--table T]   # T.{csv,md}; without --table: stdout

The quantities are `dem model`'s: p*, s_dev, F_dev on constant-volume curves; eps_v, s_dev, F_dev where the
pressure is held (isobaric rows). Points at eps_d = 0 are left out, as in `dem model` (the model starts there from
the measured state). docs/model.md, "The isobaric path's early contraction".
"""
import argparse
import csv
import glob
import math
import os
import sys

from demkit.atomic import write_atomic


def read_curve(path):
    """The rows of a model curve file as dicts of floats ('#' lines skipped)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    if not rows:
        raise SystemExit(f"model_early: {path} has no rows: give a `dem model` output folder (OUT/curves)")
    return [{k: float(v) for k, v in r.items()} for r in rows]


def quantities(rows):
    """p*, s_dev, F_dev on constant-volume curves; eps_v, s_dev, F_dev where the pressure is held."""
    held = any(r.get("isobaric", 0) == 1 for r in rows)
    return ("eps_v" if held else "p_star", "s_dev", "F_dev")


def split_rms(rows, q, split):
    """(rms_all, rms_early, rms_late, early share of the squared error, n_early, n_late) of q over its mean band
    half-width, eps_d > 0; rms of an empty part: nan."""
    x = "eps_d_accumulated" if "eps_d_accumulated" in rows[0] else "eps_d"
    pts = [r for r in rows if r[x] > 0]
    band = sum((r[q + "_hi95"] - r[q + "_lo95"]) / 2 for r in pts) / len(pts)
    err = [((r[q + "_model"] - r[q + "_mean"]) / band) ** 2 for r in pts]
    early = [e for e, r in zip(err, pts) if r[x] < split]
    late = [e for e, r in zip(err, pts) if r[x] >= split]
    rms = lambda v: math.sqrt(sum(v) / len(v)) if v else float("nan")
    total = sum(err)
    return rms(err), rms(early), rms(late), sum(early) / total if total > 0 else float("nan"), len(early), len(late)


def table(run, split):
    """One row per curve and quantity of the run's model curves."""
    files = sorted(glob.glob(os.path.join(run, "curves", "*.csv"))) + \
        sorted(glob.glob(os.path.join(run, "curves", "paths", "*.csv")))
    if not files:
        raise SystemExit(f"model_early: no model curves in {run}/curves: run `dem model` there first")
    out = []
    for f in files:
        rows = read_curve(f)
        for q in quantities(rows):
            out.append([os.path.splitext(os.path.relpath(f, os.path.join(run, "curves")))[0], q,
                        *split_rms(rows, q, split)])
    return out


HEADER = ["curve", "quantity", "rms_over_band [-]", "rms_early_over_band [-]", "rms_late_over_band [-]",
          "early_share_of_squared_error [-]", "n_early", "n_late"]


def write(rows, split, dest):
    """T.csv and T.md (atomic), or the Markdown table on stdout."""
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)
    note = (f"RMS of model - DEM mean over the curve's mean 95 % band half-width (dem model's measure), over eps_d > 0 "
            f"and split at eps_d = {split} (early: below it); share: the part of the squared error before the split")
    md = [f"<!-- demkit/model_early.py: {note} -->", "| " + " | ".join(HEADER) + " |",
          "|" + "---|" * len(HEADER)] + ["| " + " | ".join(fmt(v) for v in r) + " |" for r in rows]
    if dest is None:
        print("\n".join(md))
        return
    lines = ["# " + note, ",".join(HEADER)] + [",".join(fmt(v) for v in r) for r in rows]
    write_atomic(dest + ".csv", "\n".join(lines) + "\n")
    write_atomic(dest + ".md", "\n".join(md) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a `dem model` output folder (with curves/)")
    ap.add_argument("--split", type=float, default=0.1, help="the strain eps_d that splits early from late (0.1)")
    ap.add_argument("--table", help="write TABLE.csv and TABLE.md instead of printing")
    a = ap.parse_args(argv)
    if not a.split > 0:
        raise SystemExit(f"model_early: --split {a.split}: give a strain above 0, e.g. --split 0.1")
    write(table(a.run, a.split), a.split, a.table)


if __name__ == "__main__":
    sys.exit(main())
