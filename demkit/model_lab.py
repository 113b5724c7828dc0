"""Each mu's D2 + D3 choice predicting the laboratory tests (issue 31, thirty-first round): the friction study's
calibration on constant-volume D2 and D3 at nu = 0.69-0.80 (demkit.model_choice) run with `dem model --predict-with`
on the drained triaxial, constant-p and true-triaxial tests of data/geotech (dense and loose preparations, p* = 1e-3
and 1e-2, nu = 0.59-0.68), every curve's RMS error over the DEM's band.

    /usr/bin/python3 -m demkit.model_lab [--out DIR] [--work WORK] [--dem build/dem] [--mu 0 0.1 0.3 0.5 1]
    /usr/bin/python3 -m demkit.model_lab --out DIR --table-only      # DIR/blind.{md,csv} from DIR/mu_MU/PREP

WORK/mu_MU/ensemble_PREP/   the laboratory curves as path ensembles (demkit.geotech_model.convert, with the friction
                            study's D2/D3 means of that mu), regenerated, not stored
DIR/mu_MU/PREP/             `dem model --predict-with`'s summary.{md,csv} (the stored copy keeps these two)
DIR/blind.{md,csv}          per mu and preparation: the laboratory curves within 1 band, not integrable (the start
                            volume fraction at or below the calibration's jamming fraction nu_c), diverged, the median
                            and the largest worst error
DIR/curves.{md,csv}         every laboratory curve's error per quantity

mu = 0.01 has no laboratory tests (data/geotech/curves holds mu = 0, 0.1, 0.3, 0.5, 1); mu = 0 has no loose
preparation (a frictionless packing has one jamming density).
"""
import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys

from demkit import geotech_model, model_choice
from demkit.atomic import write_md_csv

OUT = os.path.join("data", "geotech", "model", "choice_blind")
QUANTITIES = ("p_star", "eps_v", "s_dev", "F_dev")
NOT_INTEGRABLE = "not integrable"


def choice_options(mu):
    """`dem model` options predicting with MU's choice (its --calibrate-on dropped: every curve here is predicted)."""
    opts = model_choice.options(mu)
    i = opts.index("--calibrate-on")
    return opts[:i] + opts[i + 2:]


def predict(mu, work, out, dem, lw=model_choice.LW, curves=os.path.join("data", "geotech", "curves"),
            friction=os.path.join("data", "friction_n1000")):
    """Convert MU's laboratory curves into WORK/mu_MU and predict each preparation with MU's choice into OUT/mu_MU/PREP
    (summary tables only kept). Returns the preparations run."""
    ens = os.path.join(work, f"mu_{mu}")
    geotech_model.convert(curves, mu, ens, geotech_model.TESTS, force=True, friction=os.path.join(friction, f"mu_{mu}"))
    params = os.path.join(lw, model_choice.CHOICES[mu][1], "parameters.csv")
    preps = []
    for prep in ("dense", "loose"):
        src = os.path.join(ens, f"ensemble_{prep}")
        if not os.path.isdir(src):
            continue
        run = os.path.join(work, "runs", f"mu_{mu}", prep)
        r = subprocess.run([dem, "model", src, "--predict-with", params, *choice_options(mu), "--no-plots",
                            "--out", run, "--force"], capture_output=True, text=True)
        if r.returncode:
            raise SystemExit(f"model_lab: dem model failed on mu = {mu} {prep} (exit {r.returncode}):\n{r.stderr[-2000:]}")
        dest = os.path.join(out, f"mu_{mu}", prep)
        os.makedirs(dest, exist_ok=True)
        for f in ("summary.csv", "summary.md"):
            shutil.copy2(os.path.join(run, f), os.path.join(dest, f))
        preps.append(prep)
    return preps


def laboratory_rows(summary_csv):
    """[(test, nu, {quantity: error or nan}, worst, what)] of the laboratory curves in a summary.csv; what: the worst
    quantity, NOT_INTEGRABLE or 'diverged' (an infinite error: the model's path stopped)."""
    with open(summary_csv, newline="") as fh:
        rows = [r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))
                if r["mode"] not in ("calibration", "D2", "D3")]
    out = []
    for r in rows:
        errs = {q: float(r[f"{q} [band]"]) if r[f"{q} [band]"] else float("nan") for q in QUANTITIES}
        if NOT_INTEGRABLE in r["role"]:
            out.append((r["mode"], r["nu [-]"], errs, float("nan"), NOT_INTEGRABLE))
            continue
        finite = {q: v for q, v in errs.items() if v == v}
        q = max(finite, key=finite.get)
        out.append((r["mode"], r["nu [-]"], errs, finite[q], "diverged" if finite[q] == float("inf") else q))
    return out


def runs(out):
    """[(mu, prep, summary.csv)] stored under OUT, in the order of model_choice.CHOICES."""
    found = []
    for mu in model_choice.CHOICES:
        for prep in ("dense", "loose"):
            path = os.path.join(out, f"mu_{mu}", prep, "summary.csv")
            if os.path.exists(path):
                found.append((mu, prep, path))
    if not found:
        raise SystemExit(f"model_lab: no {out}/mu_MU/PREP/summary.csv: run without --table-only first")
    return found


def counts(rows):
    """(curves, within 1 band, not integrable, diverged, median worst, largest worst) over ROWS; the median and the
    largest over the curves that integrated and stayed finite (nan where none did)."""
    finite = [w for _, _, _, w, what in rows if what not in (NOT_INTEGRABLE, "diverged")]
    return (len(rows), sum(w <= 1.0 for w in finite), sum(what == NOT_INTEGRABLE for *_, what in rows),
            sum(what == "diverged" for *_, what in rows), statistics.median(finite) if finite else float("nan"),
            max(finite) if finite else float("nan"))


def write(out):
    head = ["mu", "prep", "choice", "curves", "within_1_band", "not_integrable", "diverged", "median_worst [band]",
            "largest_worst [band]"]
    md = ["<!-- demkit/model_lab.py: each mu's D2 + D3 choice (model_choice) predicting the laboratory tests of "
          "data/geotech (TC_s3, TE_s3, TC_p, TE_p, TT_b025-075 at p* = 1e-3 and 1e-2); per curve the worst RMS of model "
          "- DEM mean over the mean 95 % band half-width (p* where not held, eps_v, s_dev, F_dev signed); median and "
          "largest over the curves that integrated and stayed finite; not integrable: start nu <= the calibration's "
          "nu_c; diverged: the model's path stopped (inf) -->",
          "| μ | preparation | choice | curves | within 1 band | not integrable | diverged | median worst | largest worst |",
          "|---|---|---|---|---|---|---|---|---|"]
    lines = [",".join(head) + "\n"]
    per_curve = []
    for mu, prep, path in runs(out):
        rows = laboratory_rows(path)
        n, ok, ni, dv, med, top = counts(rows)
        name = model_choice.CHOICES[mu][0]
        md.append(f"| {mu} | {prep} | {name} | {n} | {ok} | {ni} | {dv} | {med:.3g} | {top:.3g} |")
        lines.append(f'{mu},{prep},"{name}",{n},{ok},{ni},{dv},{med:.4g},{top:.4g}\n')
        per_curve += [(mu, prep, *r) for r in rows]
    write_md_csv(out, "blind", md, lines)
    write_curves(out, per_curve)


def write_curves(out, per_curve):
    md = ["<!-- demkit/model_lab.py: every laboratory curve predicted by its mu's D2 + D3 choice; RMS of model - DEM "
          "mean over the mean 95 % band half-width per quantity (nan: not a quantity of that test, e.g. p* where it is "
          "held; inf: the path stopped) -->",
          "| μ | preparation | test | ν | p* | ε_v | s_dev | F_dev | worst |", "|---|---|---|---|---|---|---|---|---|"]
    lines = ["mu,prep,test,nu [-],p_star [band],eps_v [band],s_dev [band],F_dev [band],worst [band],worst_of\n"]
    for mu, prep, test, nu, errs, worst, what in per_curve:
        cells = [f"{errs[q]:.3g}" for q in QUANTITIES]
        shown = NOT_INTEGRABLE if what == NOT_INTEGRABLE else f"{worst:.3g} ({what})"
        md.append(f"| {mu} | {prep} | {test} | {nu} | " + " | ".join(cells) + f" | {shown} |")
        lines.append(",".join([mu, prep, test, nu, *(f"{errs[q]:.4g}" for q in QUANTITIES), f"{worst:.4g}", what]) + "\n")
    write_md_csv(out, "curves", md, lines, show=False)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=OUT, help=f"where the tables go (default {OUT})")
    ap.add_argument("--work", default=os.path.join("runs", "model_lab"), help="working folder (ensembles, full runs)")
    ap.add_argument("--dem", default=os.path.join("build", "dem"), help="the dem binary")
    ap.add_argument("--mu", nargs="+", default=["0", "0.1", "0.3", "0.5", "1"],
                    help="friction coefficients (each with a choice and laboratory curves)")
    ap.add_argument("--table-only", action="store_true", help="only rebuild OUT/blind and OUT/curves from OUT/mu_MU/PREP")
    a = ap.parse_args(argv)
    if not a.table_only:
        for mu in a.mu:
            if mu not in model_choice.CHOICES:
                raise SystemExit(f"model_lab: mu = {mu} has no choice (model_choice.CHOICES: {', '.join(model_choice.CHOICES)})")
            if not os.path.isdir(os.path.join("data", "geotech", "curves", f"mu_{mu}")):
                raise SystemExit(f"model_lab: mu = {mu} has no laboratory curves under data/geotech/curves")
            preps = predict(mu, a.work, a.out, a.dem)
            print(f"model_lab: mu = {mu}: {', '.join(preps)} predicted", file=sys.stderr)
    write(a.out)


if __name__ == "__main__":
    sys.exit(main())
