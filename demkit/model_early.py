"""Where along the strain a model curve misses (issue 31, twenty-seventh round): for each curve of a `dem model`
output folder (OUT/curves/*.csv, OUT/curves/paths/*.csv), the RMS of model - DEM mean over the curve's mean 95 %
band half-width (the measure of `dem model`'s prediction table), over the whole curve and split at eps_d = SPLIT,
with the share of the squared error that lies before the split.

    /usr/bin/python3 -m demkit.model_early OUT [--split 0.1] [--table T]   # T.{csv,md}; without --table: stdout
    /usr/bin/python3 -m demkit.model_early --variants LW --work WORK --out E   # each mu's chosen D2 + D3 variant

With --variants (a folder of demkit.model_variants: variants.csv and the runs RULE_FOLDER/mu_MU), each mu's chosen
variant (the uncorrected choice) is applied with `dem model --predict-with` to a working copy of the friction study's
ensemble (WORK/mu_MU, made when missing) in E/mu_MU, and its table written as E/early_mu_MU.{csv,md}; the run's
summary rows must be the stored run's (else it stops: the stored run was made by another `dem`).

The quantities are `dem model`'s: p*, s_dev, F_dev on constant-volume curves; eps_v, s_dev, F_dev where the
pressure is held (isobaric rows). Points at eps_d = 0 are left out, as in `dem model` (the model starts there from
the measured state). docs/model.md, "The isobaric path's early contraction".
"""
import argparse
import csv
import glob
import os
import sys

import numpy as np

from demkit import curves
from demkit.atomic import write_atomic


def read_curve(path):
    """A model curve file (demkit.curves' reader: '#' lines skipped, ragged rows refused) as column -> floats."""
    try:
        curve = curves.read_curve(path)
    except curves.CurveError as e:
        raise SystemExit(f"model_early: {e}: give a `dem model` output folder (OUT/curves)")
    if not len(curve.get("eps_d", curve.get("eps_d_accumulated", []))):
        raise SystemExit(f"model_early: {path} has no rows: give a `dem model` output folder (OUT/curves)")
    return curve


def quantities(curve):
    """p*, s_dev, F_dev on constant-volume curves; eps_v, s_dev, F_dev where the pressure is held."""
    held = "isobaric" in curve and bool((curve["isobaric"] == 1).any())
    return ("eps_v" if held else "p_star", "s_dev", "F_dev")


def split_rms(curve, q, split):
    """(rms_all, rms_early, rms_late, early share of the squared error, n_early, n_late) of q over its mean band
    half-width, eps_d > 0; rms of an empty part: nan."""
    x = curve["eps_d_accumulated" if "eps_d_accumulated" in curve else "eps_d"]
    on = x > 0
    band = np.mean((curve[q + "_hi95"][on] - curve[q + "_lo95"][on]) / 2)
    err = ((curve[q + "_model"][on] - curve[q + "_mean"][on]) / band) ** 2
    early, late = err[x[on] < split], err[x[on] >= split]
    rms = lambda v: float(np.sqrt(v.mean())) if len(v) else float("nan")
    total = err.sum()
    return rms(err), rms(early), rms(late), float(early.sum() / total) if total > 0 else float("nan"), len(early), len(late)


def table(run, split):
    """One row per curve and quantity of the run's model curves."""
    files = sorted(glob.glob(os.path.join(run, "curves", "*.csv"))) + \
        sorted(glob.glob(os.path.join(run, "curves", "paths", "*.csv")))
    if not files:
        raise SystemExit(f"model_early: no model curves in {run}/curves: run `dem model` there first")
    out = []
    for f in files:
        curve = read_curve(f)
        if not any(k.endswith("_mean") for k in curve):   # a model-only path (cyclic, isobaric): no DEM to judge
            continue
        for q in quantities(curve):
            out.append([os.path.splitext(os.path.relpath(f, os.path.join(run, "curves")))[0], q,
                        *split_rms(curve, q, split)])
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


def chosen_runs(lw):
    """[(mu, variant folder, fabric rule, --state-limit)] of each mu's chosen variant in LW/variants.csv."""
    from demkit.model_lode_weight import state_limit_value
    from demkit.model_variants import VARIANTS
    spec = {v[0]: v for v in VARIANTS}
    with open(os.path.join(lw, "variants.csv"), newline="") as fh:
        rows = [r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#")) if r["chosen"] == "yes"]
    if not rows:
        raise SystemExit(f"model_early: {lw}/variants.csv names no chosen variant: give demkit.model_variants' --out")
    return [(r["mu"], spec[r["variant"]][1], spec[r["variant"]][2], state_limit_value(spec[r["variant"]][3]))
            for r in rows]


def curve_rows(path):
    """summary.csv's curve rows without the role (fitted there, predicted here)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))
    return [r[:2] + r[3:] for r in rows[1:] if r[0] != "calibration"]


def same_curves(a, b):
    """True where two summaries' curve rows are equal, False where their numbers differ by at most 0.002 band (the
    table's last digit), None otherwise."""
    if a == b:
        return True
    if len(a) != len(b) or any(x[:2] != y[:2] or len(x) != len(y) for x, y in zip(a, b)):
        return None
    num = lambda v: float(v) if v not in ("nan", "inf") else v
    for x, y in zip(a, b):
        for u, v in zip(map(num, x[2:]), map(num, y[2:])):
            if isinstance(u, str) or isinstance(v, str):
                if u != v:
                    return None
            elif abs(u - v) > 0.002 + 1e-12:   # the last digit, rounding aside
                return None
    return False


def run_variants(lw, work, out, dem, store, split):
    """Each mu's chosen variant applied and split (the module's --variants)."""
    import subprocess
    from demkit import model_friction
    for mu, folder, rule, limit in chosen_runs(lw):
        stored = os.path.join(lw, folder, f"mu_{mu}")
        w = model_friction.working_copy(store, work, mu, "model_early")
        run = os.path.join(out, f"mu_{mu}")
        r = subprocess.run([dem, "model", w, "--predict-with", os.path.join(stored, "parameters.csv"), "--family",
                            "extended", "--fabric-lode", rule, "--state-limit", limit, "--calibrate-on", "D2,D3",
                            "--no-plots", "--out", run, "--force"], capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(f"model_early: dem model --predict-with {stored} failed:\n{r.stderr[-2000:]}")
        agree = same_curves(curve_rows(os.path.join(run, "summary.csv")), curve_rows(os.path.join(stored, "summary.csv")))
        if agree is None:
            raise SystemExit(f"model_early: {run}/summary.csv is not {stored}'s: that run was made by another `dem`")
        if not agree:
            print(f"model_early: mu = {mu}: {run}/summary.csv agrees with the stored run's within 0.002 band, not to "
                  f"the last digit (made by an earlier `dem`)", file=sys.stderr)
        write(table(run, split), split, os.path.join(out, f"early_mu_{mu}"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", nargs="?", help="a `dem model` output folder (with curves/)")
    ap.add_argument("--variants", help="instead: demkit.model_variants' folder; each mu's chosen variant applied")
    ap.add_argument("--work", help="with --variants: working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", help="with --variants: the runs and tables")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--split", type=float, default=0.1, help="the strain eps_d that splits early from late (0.1)")
    ap.add_argument("--table", help="write TABLE.csv and TABLE.md instead of printing")
    a = ap.parse_args(argv)
    if not a.split > 0:
        raise SystemExit(f"model_early: --split {a.split}: give a strain above 0, e.g. --split 0.1")
    if a.variants:
        if not (a.work and a.out) or a.run:
            raise SystemExit("model_early: --variants needs --work and --out, and no run folder")
        return run_variants(a.variants, a.work, a.out, a.dem, a.store, a.split)
    if not a.run:
        raise SystemExit("model_early: give a `dem model` output folder, or --variants LW --work WORK --out E")
    write(table(a.run, a.split), a.split, a.table)


if __name__ == "__main__":
    sys.exit(main())
