"""Is each stored laboratory calibration's cost smooth at its optimum? (issue 31, twenty-second round)

Runs `dem model` from every stored step-8 (permanent), step-11 (relaxing) and step-12 (bounded) calibration of
data/geotech/model for one iteration, without the jackknife, with the options it was fitted with, and collects the
Jacobian check that `dem model` makes at the end of a fit: each Jacobian column against central differences of the
residuals (docs/model.md, "A cost that is not smooth at its optimum"). Writes smoothness.{md,csv}: per calibration the
largest disagreement and its coefficient, how many columns miss by more than 1 %, and the causes `dem model` names (a
fitted path against the drained control's margin, or through the isotropic law's cusp). The one iteration may move the
coefficients a little from the stored optimum; the table quotes the χ²/dof there.
"""

import argparse
import os
import re
import sys

from demkit.atomic import write_atomic
from demkit.model_excess import ENSEMBLE
from demkit.model_jamming import LAB, run, write_csv

LAWS = (("permanent", ""), ("relaxing", "relaxing_excess"), ("bounded", "bounded_excess"))
HEAD = ["law", "calibration", "largest_disagreement [-]", "coefficient", "columns_above_1pct", "columns_checked",
        "smooth", "chi2_dof [-]", "fitted_paths_through_cusp", "against_margin", "errors_quoted",
        "error_rise_below_half", "error_rise_above_2", "error_bound_within", "error_furthest_coefficient",
        "error_furthest_rise_minus [-]", "error_furthest_rise_plus [-]"]


def command(dem, stored, law, name, out, tied=False, free=True):
    """The one-iteration restart of `name` under `law` (README steps 8, 11, 12 of data/geotech/model; with `tied`,
    steps 10, 11 and 12's one-jamming-fraction calibrations under jamming_shared/); `free`: with `--coordination free`
    (coordination_free)."""
    sub = dict(LAWS)[law]
    start = os.path.join(stored, sub, "jamming_shared" if tied else "", name, "parameters.csv")
    on = "TC_s3_dense,TC_s3_loose" if name.endswith("joint") else "TC_s3_loose" if name == "loose" else "TC_s3_dense"
    cmd = [dem, "model", ENSEMBLE[name], "--start", start, "--calibrate-on", on, "--family", "extended", "--state-limit",
           "volume", "--hold-isotropic", "gamma_p,alpha" if tied else "gamma_p,nu_cC,alpha", "--max-iterations", "1",
           "--no-jackknife", "--no-plots", "--out", out, "--force"]
    if tied:
        cmd += ["--jamming", "shared"]
    if free:
        cmd += ["--coordination", "free"]
    if law != "permanent":
        cmd += ["--anisotropy-pressure", law]
    if name == "loose":
        cmd += ["--hold", "n_rate"]
    return cmd


def coordination_free(parameters):
    """Whether a stored calibration is restarted with `--coordination free`: every fit before the twenty-third round
    was free to let C1 fall, and restarts so; one with C1 = 0 exactly sits on the rising law's bound, and restarts with
    the default (rising), so that the iteration does not leave it."""
    with open(parameters) as fh:
        for line in fh:
            if line.startswith("C1,"):
                return float(line.split(",")[2]) != 0.0
    return True


def parse(log):
    """The check's numbers and the named causes from a `dem model` log (nan and "" where absent)."""
    text = open(log).read()
    m = re.search(r"largest disagreement (\S+)(?: \(a stepped point not evaluated\))? \(([^;]*); (smooth|not smooth); "
                  r"(\d+) of (\d+) columns above", text)
    chi = re.findall(r"chi2/dof = (\S+)", text)
    cusp = sorted(set(re.findall(r"warning: (\S+) \(fitted\) crosses the isotropic law's cusp", text)))
    margin = re.search(r"against the drained control's margin on (\S+)", text)
    e = re.search(r"of (\d+) quoted coefficients (\d+) rise by less than \S+ of the quadratic's \(the error "
                  r"understated\), (\d+) by more than \S+, (\d+) reach a bound within it; furthest (\S+) \((\S+), "
                  r"(\S+)\)", text)
    return {"largest": float(m.group(1)) if m else float("nan"), "coefficient": m.group(2) if m else "",
            "above": int(m.group(4)) if m else 0, "checked": int(m.group(5)) if m else 0,
            "smooth": (m.group(3) == "smooth") if m else None, "chi2": float(chi[-1]) if chi else float("nan"),
            "cusp": " ".join(cusp), "margin": margin.group(1).rstrip(":") if margin else "",
            "quoted": int(e.group(1)) if e else 0, "rise_below": int(e.group(2)) if e else 0,
            "rise_above": int(e.group(3)) if e else 0, "rise_bound": int(e.group(4)) if e else 0,
            "rise_coefficient": e.group(5) if e else "", "rise_minus": float(e.group(6)) if e else float("nan"),
            "rise_plus": float(e.group(7)) if e else float("nan")}


def table(stored, work, dem, run_again=True, tied=False):
    rows = []
    for law, _ in LAWS:
        for name in LAB:
            out = os.path.join(work, law, name)
            log = out + ".log"
            start = os.path.join(stored, dict(LAWS)[law], "jamming_shared" if tied else "", name, "parameters.csv")
            if not os.path.exists(start):
                continue   # the tied bounded refits that were cut (twenty-first round)
            if run_again:
                os.makedirs(os.path.dirname(log), exist_ok=True)
                run(command(dem, stored, law, name, out, tied, coordination_free(start)), log)
            p = parse(log)
            smooth = "yes" if p["smooth"] else "no" if p["smooth"] is not None else "not checked"
            rows.append([law, name, p["largest"], p["coefficient"], p["above"], p["checked"], smooth, p["chi2"],
                         p["cusp"], p["margin"], p["quoted"], p["rise_below"], p["rise_above"], p["rise_bound"],
                         p["rise_coefficient"], p["rise_minus"], p["rise_plus"]])
    return rows


def cell(v):
    if isinstance(v, float):
        return "inf (a stepped point not evaluated)" if v == float("inf") else "nan" if v != v else f"{v:.3g}"
    return str(v) if v != "" else "—"


def write(rows, out, tied=False):
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "smoothness.csv"), HEAD, rows)
    lines = ["# The cost at each stored laboratory calibration's optimum: the Jacobian against central differences",
             "",
             "`python3 -m demkit.model_smoothness` (data/geotech/model/README.md step 14; docs/model.md, \"A cost that "
             "is not smooth at its optimum\"). One iteration of `dem model` from each stored optimum with the options "
             "it was fitted with; the Jacobian column of every free coefficient against central differences of the "
             "residuals (step 10⁻⁶ × max(1, |value|)). Disagreement: |difference − column| / max(the two norms); a "
             "cost is not smooth where a column misses by more than 0.01, and its errors are then not determined. "
             "Then (twenty-third round, docs/model.md \"The cost over one quoted error\") χ² one covariance error "
             "either way along each quoted coefficient's linearised profile, over the quadratic model's rise: of the "
             "quoted coefficients, how many rise by less than 1/2 on a side (the error understated), by more than 2, "
             "or meet a bound within one error, and the coefficient furthest from 1 with its pair (− and +); — where "
             "no error is quoted. A restart of a calibration fitted before that round passes `--coordination free` "
             "(C1 of either sign), as it was fitted." +
             (" One jamming fraction (`--jamming shared`, the calibrations under jamming_shared/)." if tied else ""),
             "",
             "| law | calibration | largest disagreement (coefficient) | columns above 1 % | smooth | χ²/dof | fitted "
             "paths through the cusp | against the margin | errors quoted | below 1/2 | above 2 | bound within | "
             "furthest from 1: − and + (coefficient) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        scale = ((str(r[10]), str(r[11]), str(r[12]), str(r[13]), f"{cell(r[15])}, {cell(r[16])} ({r[14]})")
                 if r[10] else ("0", "—", "—", "—", "—"))
        lines.append(f"| {r[0]} | {r[1]} | {cell(r[2])} ({cell(r[3])}) | {r[4]} of {r[5]} | {r[6]} | {cell(r[7])} | "
                     f"{cell(r[8])} | {cell(r[9])} | " + " | ".join(scale) + " |")
    write_atomic(os.path.join(out, "smoothness.md"), "\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stored", required=True, help="the step-8 calibrations (data/geotech/model/state_volume), with "
                    "relaxing_excess/ and bounded_excess/ beside")
    ap.add_argument("--work", required=True, help="where the one-iteration runs and their logs go")
    ap.add_argument("--out", required=True, help="where smoothness.{md,csv} go")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--table-only", action="store_true", help="the table from WORK's logs")
    ap.add_argument("--tied", action="store_true", help="the one-jamming-fraction calibrations (jamming_shared/ under "
                    "each law's folder, --jamming shared) instead")
    a = ap.parse_args(argv)
    if not a.table_only:
        missing = sorted({e for e in ENSEMBLE.values() if not os.path.isdir(e)})
        if missing:
            raise SystemExit(f"model_smoothness: ensembles missing ({', '.join(missing)}): make them with README steps "
                             "1-8b of data/geotech/model")
    write(table(a.stored, a.work, a.dem, not a.table_only, a.tied), a.out, a.tied)
    print(f"model_smoothness: {os.path.join(a.out, 'smoothness.md')}", file=sys.stderr)


if __name__ == "__main__":
    main()
