"""Stored calibrations predicted again by two `dem` builds (issue 31, thirty-sixth round): each calibration's stored
parameters on its own ensemble (`dem model --predict-with`), by an earlier build (--old, e.g. dem at e8a417aa with the
fixed RK4 step) and by another (--new, today's), and one table of how each calibration's curves move.

    /usr/bin/python3 -m demkit.model_audit --old OLD_DEM --new build/dem --work WORK --out data/geotech/model/integration_audit
    /usr/bin/python3 -m demkit.model_audit --table-only --work WORK --out ...   # the table from WORK's runs

WORK/NAME/{old,new}/  each build's `dem model --predict-with` run (summary.csv is what the table reads)
OUT.{md,csv}          per calibration: curves, curves whose worst quantity moved, curves within 1 band (old -> new), the
                      worst curve (old -> new; inf: not a number along the curve) and the curve that moved most

The ensembles are regenerated as data/geotech/model/README.md says (runs/model_joint/mu_MU/ensemble_all by
demkit.model_joint.ensemble, runs/geotech_model/ensemble_PREP by demkit.geotech_model, WORK/friction/mu_MU by
demkit.model_friction.working_copy).
"""
import argparse
import csv
import math
import os
import subprocess

from demkit import geotech_model, model_friction, model_joint
from demkit.atomic import write_md_csv

M = os.path.join("data", "geotech", "model")
FRICTION = os.path.join("data", "friction_n1000", "model_friction")
LODE = os.path.join(FRICTION, "lode_weight", "overlap")
COMMENT = ("Stored calibrations predicted from their stored parameters (`dem model --predict-with`) by two dem builds "
           "(old: the fixed RK4 step of 5e-4; new: the step control and graded singular starts of issue 31's "
           "thirty-sixth round; docs/model.md, \"RK4's step where the law is stiff\"): RMS of model - DEM mean over the "
           "mean 95 % band half-width, each curve's worst quantity; inf: not a number along the curve")


def calibrations(work):
    """(name, label, ensemble, parameters, options) of every calibration the table covers; the ensembles made."""
    out = []
    for mu in ("0", "0.1", "0.3", "0.5", "1"):
        ens = model_joint.ensemble(mu, os.path.join("runs", "model_joint"))
        out.append((f"joint_mu{mu}", f"joint/mu_{mu}", ens, os.path.join(M, "joint", f"mu_{mu}", "parameters.csv"),
                    ["--family", "extended", "--state-limit", "volume"]))
    geotech_model.main(["--curves", os.path.join("data", "geotech", "curves"), "--mu", "0.5", "--out",
                        os.path.join("runs", "geotech_model"), "--friction", os.path.join("data", "friction_n1000", "mu_0.5"),
                        "--force"])
    for prep, folders in (("dense", ("", "basin_check")), ("loose", ("", "start_state_jackknife"))):
        for sub in folders:
            label = f"lab_{prep}" + (f"/{sub}" if sub else "")
            out.append((label.replace("/", "_"), label, os.path.join("runs", "geotech_model", f"ensemble_{prep}"),
                        os.path.join(M, label, "parameters.csv"), ["--family", "extended"]))
    for mu in ("0", "0.01", "0.1", "0.3", "0.5", "1"):
        ens = model_friction.working_copy(os.path.join("data", "friction_n1000"), os.path.join(work, "friction"), mu,
                                          "model_audit")
        out.append((f"overlap_k8_mu{mu}", f"friction K = 8 overlap, mu = {mu}", ens,
                    os.path.join(LODE, f"mu_{mu}", "parameters.csv"),
                    ["--family", "extended", "--fabric-lode", "overlap", "--state-limit", "pressure"]))
        group = os.path.join(FRICTION, f"mu_{mu}", "group", "parameters.csv")
        if os.path.exists(group):   # the group model, fitted on D2 (demkit.model_friction's `auto` runs)
            out.append((f"group_k8_mu{mu}", f"friction K = 8 group model, mu = {mu}", ens, group, ["--family", "group"]))
    return out


def predict(dem, ens, parameters, options, dest):
    cmd = [dem, "model", ens, "--predict-with", parameters] + options + ["--no-plots", "--no-jackknife", "--out", dest,
                                                                         "--force"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0 or not os.path.exists(os.path.join(dest, "summary.csv")):
        raise SystemExit(f"model_audit: {' '.join(cmd)} failed (exit {r.returncode}):\n{r.stderr[-2000:]}")


def worst_by_curve(summary_csv):
    """{(mode, nu): worst [band]} of a summary.csv (the calibration row left out)."""
    with open(summary_csv) as fh:
        rows = csv.DictReader(l for l in fh if not l.startswith("#"))
        return {(r["mode"], r["nu [-]"]): number(r["worst [band]"]) for r in rows if r["mode"] != "calibration"}


def number(x):
    try:
        return float(x)
    except ValueError:
        return math.nan


def short(x):
    return "inf" if x == math.inf else ("nan" if math.isnan(x) else f"{x:.3g}")


def compare(old, new):
    """How the curves of OLD ({curve: worst}) move in NEW: counts, worst, and the curve that moved most."""
    moved, inside, worst, big = 0, [0, 0], [0.0, 0.0], (0.0, None)
    for k, x in old.items():
        y = new.get(k, math.nan)
        same = x == y or (math.isnan(x) and math.isnan(y))
        moved += not same
        inside[0] += x <= 1
        inside[1] += y <= 1
        worst = [max(worst[0], 0 if math.isnan(x) else x), max(worst[1], 0 if math.isnan(y) else y)]
        d = 0.0 if same else (abs(y - x) if math.isfinite(x) and math.isfinite(y) else math.inf)
        if d > big[0]:
            big = (d, k)
    return {"curves": len(old), "moved": moved, "inside": inside, "worst": worst, "largest": big[1]}


def table(rows, work, out):
    md, cs = [], []
    for name, label, *_ in rows:
        old = worst_by_curve(os.path.join(work, name, "old", "summary.csv"))
        new = worst_by_curve(os.path.join(work, name, "new", "summary.csv"))
        c = compare(old, new)
        k = c["largest"]
        move = f"{k[0]} nu = {k[1]}: {short(old[k])} -> {short(new[k])}" if k else "none"
        md.append([label, c["curves"], c["moved"], f"{c['inside'][0]} -> {c['inside'][1]}",
                   f"{short(c['worst'][0])} -> {short(c['worst'][1])}", move])
        cs.append([label, c["curves"], c["moved"], c["inside"][0], c["inside"][1], short(c["worst"][0]),
                   short(c["worst"][1]), f"{k[0]} {k[1]}" if k else "", short(old[k]) if k else "",
                   short(new[k]) if k else ""])
    head_md = ["calibration", "curves", "curves that move", "within 1 band (old -> new)", "worst curve (old -> new)",
               "largest move"]
    head_cs = ["calibration", "curves", "curves_moved", "within_1_old", "within_1_new", "worst_old [band]",
               "worst_new [band]", "largest_move_curve", "largest_move_old [band]", "largest_move_new [band]"]
    lines = [f"<!-- {COMMENT} -->", "| " + " | ".join(head_md) + " |", "|" + "---|" * len(head_md)]
    lines += ["| " + " | ".join(str(x) for x in r) + " |" for r in md]
    write_md_csv(os.path.dirname(out) or ".", os.path.basename(out), lines,
                 [model_joint.csv_line(head_cs)] + [model_joint.csv_line(r) for r in cs], show=False)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", help="the earlier dem build")
    ap.add_argument("--new", default=os.path.join("build", "dem"), help="the other dem build (default build/dem)")
    ap.add_argument("--work", required=True, help="where the runs go (and the friction study's working copies)")
    ap.add_argument("--out", default=os.path.join(M, "integration_audit"), help="the table's path without extension")
    ap.add_argument("--table-only", action="store_true", help="the table from WORK's runs, nothing run")
    a = ap.parse_args(argv)
    if not a.table_only and not a.old:
        ap.error("--old DEM is needed unless --table-only")
    rows = calibrations(a.work)
    if not a.table_only:
        for name, _, ens, parameters, options in rows:
            for tag, dem in (("old", a.old), ("new", a.new)):
                predict(dem, ens, parameters, options, os.path.join(a.work, name, tag))
    table(rows, a.work, a.out)
    print(f"model_audit: {a.out}.md and .csv")


if __name__ == "__main__":
    main()
