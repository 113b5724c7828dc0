"""The frictional family calibrated on two Lode angles (issue 31, sixth round): D2 + D3 + the isotropic
branch of the friction study's K = 8 ensembles, the isobaric D2 path predicted, under the overlap fabric rule
and under the weighted rule (`dem model --fabric-lode weighted`: the Lode dependence of the fabric's onset and
rate weighted by the contact overlap), both with the state-dependent stress-ratio limit; jackknife over the
packings, then the paired held-out test between the two rules (demkit.model_state_limit's rule).

    /usr/bin/python3 -m demkit.model_lode_weight --work WORK --out OUT            # about 5 min per mu and rule
    /usr/bin/python3 -m demkit.model_lode_weight --work WORK --out OUT --table-only

OUT/RULE/mu_MU/ holds `dem model`'s tables (curves and plots left out), OUT/lode_weight.{md,csv} the table:
per mu the calibration's chi2/dof, the worst fitted D2 and D3 curve, the worst predicted isobaric curve (RMS
over the mean 95 % band half-width, with the quantity and nu), the held-out scores' paired difference and the
choice. docs/model.md, "The Lode weight".
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys

from demkit import model_friction, model_state_limit
from demkit.atomic import write_atomic

MUS = ("0", "0.01", "0.1", "0.3", "0.5", "1")
RULES = ("overlap", "weighted")
QUANTITIES = (("p_star [band]", "p*"), ("eps_v [band]", "ε_v"), ("s_dev [band]", "s"), ("F_dev [band]", "F"))


def state_limit_value(state_limit):
    """`dem model --state-limit`'s value: a string as given, True "pressure", False "none"."""
    return state_limit if isinstance(state_limit, str) else "pressure" if state_limit else "none"


def run_rule(dem, work, out, rule, jackknife=True, state_limit=True, start=None, max_iterations=None, extra=()):
    """`dem model` on WORK (a working copy) into OUT, the extended family under RULE on D2 + D3 (with the
    state-dependent limit unless told: True or False, or a `--state-limit` value such as "pressure-lode"; from
    START, a parameters.csv or a comma-separated multi-start list, when given; `dem model`'s default
    --max-iterations unless MAX_ITERATIONS is given; EXTRA: further `dem model` arguments)."""
    limit = state_limit_value(state_limit)
    cmd = [dem, "model", work, "--out", out, "--family", "extended", "--fabric-lode", rule, "--state-limit",
           limit, "--calibrate-on", "D2,D3", "--no-plots", "--force"]
    if not jackknife:
        cmd.append("--no-jackknife")
    if max_iterations:
        cmd += ["--max-iterations", str(max_iterations)]
    if start:   # the isotropic block from the branch's own fit, as every stored variant run started (issue 31,
                # fifteenth round: `--start-isotropic file`, the default, would restart them from the files' values)
        cmd += ["--start", start, "--start-isotropic", "branch"]
    cmd += list(extra)
    print("model_lode_weight:", " ".join(cmd), file=sys.stderr)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "model.log"), "w") as log:
        if subprocess.call(cmd, stderr=log) not in (0, 1):   # 1: a fit stopped short (said in its tables)
            raise SystemExit(f"model_lode_weight: {' '.join(cmd)} failed (see {out}/model.log)")
    shutil.rmtree(os.path.join(out, "curves"), ignore_errors=True)


def worst(summary_csv):
    """(chi2/dof, {(mode, role): (worst RMS over the band, 'quantity ν')}) of a summary.csv."""
    with open(summary_csv, newline="") as fh:
        rows = list(csv.DictReader(l for l in fh if not l.startswith("#")))
    chi2, out = float("nan"), {}
    for r in rows:
        if r["mode"] == "calibration":
            chi2 = float(r["role"].split()[-1])
            continue
        for col, name in QUANTITIES:
            v = float(r[col])
            key = (r["mode"], r["role"])
            if v == v and (key not in out or v > out[key][0]):
                out[key] = (v, f"{name} {float(r['nu [-]']):.2f}")
    return chi2, out


def table(out, mus):
    """OUT/lode_weight.{md,csv}: per mu and rule the worst curves, and the held-out choice between the rules."""
    head = ["mu", "rule", "chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]",
            "worst_predicted_isobaric [band]", "heldout_mean [-]", "chosen"]
    md = ["<!-- demkit/model_lode_weight.py: the extended family on D2 + D3 (state limit on), RMS over the mean 95 % "
          "band half-width; held-out: mean score over the {K} left-out packings, the difference overlap - weighted "
          "paired (t_{K-1,0.975}) -->",
          "| μ | χ²/dof overlap → weighted | worst fitted D2 | worst fitted D3 | worst predicted isobaric | "
          "held-out difference ± SE | chosen |", "|---|---|---|---|---|---|---|"]
    lines = [",".join(head) + "\n"]
    for mu in mus:
        for rule in RULES:
            if not os.path.exists(os.path.join(out, rule, f"mu_{mu}", "summary.csv")):
                raise SystemExit(f"model_lode_weight: {out}/{rule}/mu_{mu}/summary.csv does not exist: run without "
                                 "--table-only first (or give --mu the values that were run)")
        res = {rule: worst(os.path.join(out, rule, f"mu_{mu}", "summary.csv")) for rule in RULES}
        scores = {rule: model_state_limit.extended_scores(os.path.join(out, rule, f"mu_{mu}")) for rule in RULES}
        mean, se, t, K, chosen = model_state_limit.paired_choice(scores["overlap"], scores["weighted"])
        pick = "weighted" if chosen else "overlap"
        cells = []
        for key in (("D2", "fitted"), ("D3", "fitted"), ("isobaric", "predicted")):
            cells.append(" → ".join(f"{res[r][1][key][0]:.2f} ({res[r][1][key][1]})" for r in RULES))
        md.append(f"| {mu} | {res['overlap'][0]:.3g} → {res['weighted'][0]:.3g} | " + " | ".join(cells) +
                  f" | {mean:.3g} ± {se:.2g} (t SE {t * se:.2g}) | {pick} |")
        for rule in RULES:
            m = sum(scores[rule].values()) / len(scores[rule])
            w = [f"{res[rule][1][k][0]:.4g}" for k in (("D2", "fitted"), ("D3", "fitted"), ("isobaric", "predicted"))]
            lines.append(",".join([mu, rule, f"{res[rule][0]:.4g}", *w, f"{m:.4g}", "yes" if rule == pick else "no"]) + "\n")
    md[0] = md[0].replace("{K}", str(K))
    write_atomic(os.path.join(out, "lode_weight.md"), "\n".join(md) + "\n")
    write_atomic(os.path.join(out, "lode_weight.csv"), "".join(lines))
    print("\n".join(md))


def parameter_tables(out, mus):
    """OUT/parameters_RULE.md: every coefficient per mu, value ± jackknife SE (covariance SE marked c)."""
    for rule in RULES:
        cols, names = [], []
        for mu in mus:
            with open(os.path.join(out, rule, f"mu_{mu}", "parameters.csv"), newline="") as fh:
                rows = list(csv.DictReader(l for l in fh if not l.startswith("#")))
            vals = {}
            for r in rows:
                if r["parameter"] in ("converged", "settled"):   # "no: <Ceres' summary>", "yes: <the fall>" (law)
                    vals[r["parameter"]] = r["law"].split(":")[0]
                    continue
                v, jk, cov = (float(r[k]) for k in ("value", "se_jackknife", "se_covariance"))
                se, mark = (jk, "") if jk == jk else (cov, " c")
                vals[r["parameter"]] = f"{v:.4g} ± {se:.2g}{mark}" if se == se else f"{v:.4g}"
            names += [n for n in vals if n not in names]
            cols.append(vals)
        K = len(model_state_limit.extended_scores(os.path.join(out, rule, f"mu_{mus[0]}")))
        md = [f"<!-- demkit/model_lode_weight.py: the {rule} rule on D2 + D3 (state limit on), value ± jackknife SE "
              f"over the {K} packings (c: covariance SE) -->",
              "| parameter | " + " | ".join(f"μ = {mu}" for mu in mus) + " |", "|---|" + "---|" * len(mus)]
        md += [f"| {n} | " + " | ".join(c.get(n, "") for c in cols) + " |" for n in names]
        write_atomic(os.path.join(out, f"parameters_{rule}.md"), "\n".join(md) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", required=True, help="working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", required=True, help="the two rules' `dem model` tables and the table")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--mu", nargs="+", default=list(MUS))
    ap.add_argument("--table-only", action="store_true", help="only collect the existing results")
    ap.add_argument("--max-iterations", type=int, default=None,
                    help="`dem model --max-iterations` (its default, 1000, when not given; the stored tables were made with 300)")
    a = ap.parse_args(argv)
    for mu in ([] if a.table_only else a.mu):
        work = model_friction.working_copy(a.store, a.work, mu, "model_lode_weight")
        for rule in RULES:
            run_rule(a.dem, work, os.path.join(a.out, rule, f"mu_{mu}"), rule, max_iterations=a.max_iterations)
    table(a.out, a.mu)
    parameter_tables(a.out, a.mu)


if __name__ == "__main__":
    main()
