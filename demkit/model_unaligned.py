"""An unaligned start (issue 31, twenty-eighth round): each mu's chosen D2 + D3 variant (LW/variants.csv, the
uncorrected choice) calibrated again with `dem model --start-anisotropy unaligned`, so that s and F integrate the
part aligned with the loading from 0 and the data's first-row s_dev and F_dev (the random deviators of a finite
isotropic packing) are observed as sqrt(x^2 + x0^2); then the paired held-out test against the stored aligned run.

    /usr/bin/python3 -m demkit.model_unaligned --variants LW --work WORK --out OUT [--mu 1 0.5]
    /usr/bin/python3 -m demkit.model_unaligned --variants LW --out OUT --table-only [--mu ...]

Each run starts from the default start and from the stored aligned fit (`--start default,STORED/parameters.csv`, the
lower chi2/dof kept; OUT/mu_MU/starts.md), with the jackknife over the packings (its held-out scores). The two starts
have the same coefficients, so the choice is model_variants.choose's: the aligned start is beaten when the unaligned
one's held-out scores are lower by more than t_{K-1,0.975} SE of the paired difference (and the other way round);
neither beaten: the lower mean score. OUT/unaligned.{md,csv}: per mu chi2/dof, the worst fitted D2 and D3 and
predicted isobaric curve (RMS over the mean 95 % band half-width), the held-out means and their paired difference,
the choice, and the target (every curve within one band half-width, chi2/dof <= 3) with the chosen start.
docs/model.md, "An unaligned start".
"""
import argparse
import os
import sys

from demkit import model_early, model_friction, model_lode_weight, model_state_limit, model_variants
from demkit.atomic import write_atomic

KINDS = model_variants.KINDS
STARTS = ("aligned", "unaligned")


def run_unaligned(dem, w, out, stored, rule, limit):
    """The unaligned calibration of one mu into OUT (from the default start and from STORED's fit)."""
    model_lode_weight.run_rule(dem, w, out, rule, state_limit=limit,
                               start="default," + os.path.join(stored, "parameters.csv"),
                               extra=["--start-anisotropy", "unaligned"])


def summary_of(d, who="model_unaligned"):
    """(chi2/dof, worst curves) and the held-out scores of the `dem model` run in D."""
    if not os.path.exists(os.path.join(d, "summary.csv")):
        raise SystemExit(f"{who}: {d}/summary.csv does not exist: run without --table-only first (or give --mu the "
                         "values that were run)")
    return model_lode_weight.worst(os.path.join(d, "summary.csv")), model_state_limit.extended_scores(d)


def row(mu, variant, runs):
    """The md and csv rows of one mu: RUNS {start: folder}."""
    res, scores = {}, {}
    for s in STARTS:
        res[s], scores[s] = summary_of(runs[s])
    chosen, beaten, means = model_variants.choose(scores, {s: 0 for s in STARTS})
    mean, se, t, K, _ = model_state_limit.paired_choice(scores["aligned"], scores["unaligned"])
    cells = [" → ".join(f"{res[s][1][k][0]:.2f} ({res[s][1][k][1]})" for s in STARTS) for k in KINDS]
    beat = next((f"{s} beaten" for s in STARTS if beaten[s]), "neither beaten")
    md = (f"| {mu} | {variant} | {res['aligned'][0]:.3g} → {res['unaligned'][0]:.3g} | " + " | ".join(cells) +
          f" | {means['aligned']:.4g} → {means['unaligned']:.4g} | {mean:.3g} ± {se:.2g} (t SE {t * se:.2g}) | "
          f"{beat} | {chosen} | " + model_variants.target_cells(chosen, *res[chosen]).split(" | ", 1)[1] + " |")
    csv = [",".join([mu, variant, s, f"{res[s][0]:.4g}", *(f"{res[s][1][k][0]:.4g}" for k in KINDS),
                     f"{means[s]:.4g}", "yes" if beaten[s] else "no", "yes" if s == chosen else "no"]) + "\n"
           for s in STARTS]
    return md, csv, K


def table(lw, out, mus):
    """OUT/unaligned.{md,csv} from the stored aligned runs (LW) and the unaligned ones (OUT/mu_MU)."""
    chosen = {mu: (folder, rule, limit) for mu, folder, rule, limit in model_early.chosen_runs(lw)}
    name = {v[1]: v[0] for v in model_variants.VARIANTS}
    md = ["<!-- demkit/model_unaligned.py: each mu's chosen D2 + D3 variant, the stored aligned start → the unaligned "
          "start; RMS over the mean 95 % band half-width; held-out: mean score over the {K} left-out packings, the "
          "difference aligned - unaligned paired (t_{K-1,0.975}); target: every curve within 1 band, chi2/dof <= 3 -->",
          "| μ | variant | χ²/dof | worst fitted D2 | worst fitted D3 | worst predicted isobaric | mean held-out score | "
          "difference ± SE | beaten | chosen | χ²/dof | worst curve | target met |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines = [",".join(["mu", "variant", "start", "chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]",
                       "worst_predicted_isobaric [band]", "heldout_mean [-]", "beaten", "chosen"]) + "\n"]
    K = 0
    for mu in mus:
        if mu not in chosen:
            raise SystemExit(f"model_unaligned: {lw}/variants.csv chooses no variant at mu = {mu}")
        folder = chosen[mu][0]
        runs = {"aligned": os.path.join(lw, folder, f"mu_{mu}"), "unaligned": os.path.join(out, f"mu_{mu}")}
        m, c, K = row(mu, name[folder], runs)
        md.append(m)
        lines += c
    md[0] = md[0].replace("{K}", str(K))
    write_atomic(os.path.join(out, "unaligned.md"), "\n".join(md) + "\n")
    write_atomic(os.path.join(out, "unaligned.csv"), "".join(lines))
    print("\n".join(md))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", required=True, help="demkit.model_variants' folder (variants.csv and its runs)")
    ap.add_argument("--work", help="working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", required=True, help="the unaligned runs (OUT/mu_MU) and the table")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--mu", nargs="+", default=list(model_lode_weight.MUS))
    ap.add_argument("--table-only", action="store_true", help="only collect the existing results")
    a = ap.parse_args(argv)
    if not a.table_only:
        if not a.work:
            raise SystemExit("model_unaligned: give --work (the working copies), or --table-only")
        chosen = {mu: v for mu, *v in model_early.chosen_runs(a.variants)}
        for mu in a.mu:
            if mu not in chosen:
                raise SystemExit(f"model_unaligned: {a.variants}/variants.csv chooses no variant at mu = {mu}")
            folder, rule, limit = chosen[mu]
            w = model_friction.working_copy(a.store, a.work, mu, "model_unaligned")
            run_unaligned(a.dem, w, os.path.join(a.out, f"mu_{mu}"), os.path.join(a.variants, folder, f"mu_{mu}"),
                          rule, limit)
    table(a.variants, a.out, a.mu)


if __name__ == "__main__":
    sys.exit(main())
