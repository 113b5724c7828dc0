"""Where plastic flow starts (issue 31, twenty-eighth round): each mu's chosen D2 + D3 variant (LW/variants.csv, the
uncorrected choice) calibrated again with an alternative onset, then the paired held-out test against the stored run:

- `gate`: `dem model --dilatancy-gate mobilisation`, the plastic dilatancy d_D (r - chi_D)(1 - F/F_lim) times the
  mobilisation r, so that the volume under constant pressure starts flat as the DEM's does (ungated it starts at its
  largest contraction d_D chi_D);
- `unaligned`: `--start-anisotropy unaligned`, s and F integrated as the parts aligned with the loading from 0, the
  data's first-row s_dev and F_dev (the random deviators of a finite isotropic packing) observed as sqrt(x^2 + x0^2);
- `both`.

    /usr/bin/python3 -m demkit.model_onset --variants LW --work WORK --out OUT [--alternative gate] [--mu 1 0.5] \
        [--rerun-stored] [--variant 'weighted + limit'] [--no-jackknife]
    /usr/bin/python3 -m demkit.model_onset --variants LW --out OUT --table-only [--alternative gate] [--mu ...]
    /usr/bin/python3 -m demkit.model_onset --variants LW --out OUT --table-only --variant 'weighted + Lode limit' \
        --versus LW/onset [--mu ...]   # that variant's choice against the current one (twenty-ninth round)

Each run starts from the default start, with the jackknife over the packings; OUT/ALT/mu_MU. `--rerun-stored` also
reruns the stored variant as it is (OUT/none/mu_MU), which the table then compares with: `dem model`'s jackknife now
scores each left-out packing on its own predicted paths too (heldout.csv, heldout_predicted_paths: the isobaric D2
paths here, which no D2 + D3 calibration fits), and the stored runs predate it. Without the rerun the stored run
(LW/FOLDER/mu_MU) is compared on the fitted curves alone.

The choice (`decide`): the two have the same coefficients; a run beats the other on a score (the fitted curves', the
predicted paths') when its paired held-out scores are lower by more than t_{K-1,0.975} SE of the difference. The
alternative is chosen when it beats the stored run on one score and is beaten on neither; else the stored run.
OUT/LABEL.{md,csv} (LABEL: ALT, or ALT_FOLDER with --variant): per mu chi2/dof, the worst fitted D2 and D3 and predicted
isobaric curve (RMS over the mean 95 % band half-width), both held-out means and their paired differences, the choice,
and the target (every curve within one band half-width, chi2/dof <= 3) with the chosen one. docs/model.md, "Where
plastic flow starts".

`--versus CURRENT` (with --variant): the variant's choice (OUT/LABEL.csv, rerun or with ALT) against the choice in
CURRENT/ALT.csv (each mu's chosen variant, with or without ALT), OUT/versus_LABEL.{md,csv}. The one with fewer
coefficients stands left and is kept unless the other beats it on one held-out score and is beaten on neither (the
same `decide`). docs/model.md, "The Lode-dependent state limit, gated" (twenty-ninth round).

`--compare LEFT RIGHT --names A B --tag T` (thirtieth round): any two sets of runs, LEFT/mu_MU against RIGHT/mu_MU, the
left one kept unless the right one beats it (`decide`), OUT/T.{md,csv}: an option on top of a choice that --variant
and --alternative do not name (docs/model.md, "The deviatoric stress under a volume change").
"""
import argparse
import csv
import os
import sys

from demkit import model_early, model_friction, model_lode_weight, model_state_limit, model_variants
from demkit.atomic import write_md_csv

KINDS = model_variants.KINDS
ALTERNATIVES = {"gate": ["--dilatancy-gate", "mobilisation"], "unaligned": ["--start-anisotropy", "unaligned"],
                "both": ["--dilatancy-gate", "mobilisation", "--start-anisotropy", "unaligned"],
                # the thirtieth round: the fabric's limit times the stress ratio's state factor, on the gated dilatancy
                "gate_fabric": ["--dilatancy-gate", "mobilisation", "--fabric-limit", "state"],
                # sigma_dev scaling with the isotropic reference pressure under a volume change (thirtieth round)
                "deviator": ["--deviator-volume", "reference"],
                "gate_deviator": ["--dilatancy-gate", "mobilisation", "--deviator-volume", "reference"]}
BASE = "none"   # OUT/none/mu_MU: the stored variant rerun as stored, for its held-out scores of the predicted paths
STARTS = ("stored", "alternative")


def path_scores(d):
    """{packing: held-out score of its own predicted paths} from D/heldout.csv's heldout_predicted_paths column ({}
    where the run has none: made before the twenty-eighth round)."""
    return model_state_limit.extended_scores(d, prefix="heldout_predicted_paths", skip_nan=True)


def summary_of(d, who="model_onset"):
    """(chi2/dof, worst curves), the held-out scores of the fitted curves and of the predicted paths of the run in D."""
    if not os.path.exists(os.path.join(d, "summary.csv")):
        raise SystemExit(f"{who}: {d}/summary.csv does not exist: run without --table-only first (or give --mu the "
                         "values that were run)")
    return model_lode_weight.worst(os.path.join(d, "summary.csv")), model_state_limit.extended_scores(d), path_scores(d)


def decide(fitted, paths):
    """The choice between the stored run and the alternative (the same coefficients): a run beats the other on a score
    when its paired held-out scores are lower by more than t_{K-1,0.975} SE (model_state_limit.paired_choice). The
    alternative is chosen when it beats the stored run on one score (the fitted curves, or the predicted paths) and is
    beaten on neither; else the stored run. Returns (chosen, {score: (mean d, SE d, t, who beats or None)})."""
    tests = {}
    for name, sc in (("fitted", fitted), ("paths", paths)):
        if not all(sc.values()):
            tests[name] = None
            continue
        mean, se, t, _, _ = model_state_limit.paired_choice(sc["stored"], sc["alternative"])
        tests[name] = (mean, se, t, "alternative" if mean > t * se else "stored" if -mean > t * se else None)
    won = [x[3] for x in tests.values() if x]
    return ("alternative" if "alternative" in won and "stored" not in won else "stored"), tests


def test_cell(x):
    """'d ± SE (t SE; who beats)' of one paired test, or 'not scored'."""
    if x is None:
        return "not scored"
    return f"{x[0]:.3g} ± {x[1]:.2g} (t SE {x[2] * x[1]:.2g}; {x[3] + ' better' if x[3] else 'neither better'})"


def row(mu, variant, runs, names=None):
    """The md and csv rows of one mu: RUNS {start: folder}; NAMES {start: name} in the csv's variant column and the
    chosen cell (default: VARIANT, and the start)."""
    res, fitted, paths = {}, {}, {}
    for s in STARTS:
        res[s], fitted[s], paths[s] = summary_of(runs[s])
    chosen, tests = decide(fitted, paths)
    names = names or {s: variant for s in STARTS}
    K = len(fitted["stored"])
    mean = lambda sc: sum(sc.values()) / len(sc) if sc else float("nan")
    cells = [" → ".join(f"{res[s][1][k][0]:.2f} ({res[s][1][k][1]})" for s in STARTS) for k in KINDS]
    who = chosen if names[STARTS[0]] == names[STARTS[1]] else names[chosen]
    md = (f"| {mu} | {variant} | {res['stored'][0]:.3g} → {res['alternative'][0]:.3g} | " + " | ".join(cells) +
          f" | {mean(fitted['stored']):.4g} → {mean(fitted['alternative']):.4g} | {test_cell(tests['fitted'])} | "
          f"{mean(paths['stored']):.4g} → {mean(paths['alternative']):.4g} | {test_cell(tests['paths'])} | {who} | " +
          model_variants.target_cells(chosen, *res[chosen]).split(" | ", 1)[1] + " |")
    csv = [",".join([mu, names[s], s, f"{res[s][0]:.4g}", *(f"{res[s][1][k][0]:.4g}" for k in KINDS),
                     f"{mean(fitted[s]):.4g}", f"{mean(paths[s]):.4g}", "yes" if s == chosen else "no"]) + "\n"
           for s in STARTS]
    return md, csv, K


def specs(lw, mus, variant=None):
    """{mu: (variant folder, fabric rule, --state-limit)}: each mu's chosen variant in LW/variants.csv, or VARIANT."""
    if variant:
        v = {x[0]: x for x in model_variants.VARIANTS}.get(variant)
        if v is None:
            raise SystemExit(f"model_onset: --variant {variant!r} is none of " +
                             ", ".join(x[0] for x in model_variants.VARIANTS))
        return {mu: (v[1], v[2], model_lode_weight.state_limit_value(v[3])) for mu in mus}
    chosen = {mu: (folder, rule, limit) for mu, folder, rule, limit in model_early.chosen_runs(lw)}
    for mu in mus:
        if mu not in chosen:
            raise SystemExit(f"model_onset: {lw}/variants.csv chooses no variant at mu = {mu}")
    return {mu: chosen[mu] for mu in mus}


def label(alt, variant=None):
    """The runs' folder and the table's name: ALT, or ALT_FOLDER with a --variant."""
    return alt if not variant else alt + "_" + {x[0]: x[1] for x in model_variants.VARIANTS}[variant]


def table(lw, out, alt, mus, variant=None):
    """OUT/LABEL.{md,csv} from the stored runs (LW) and the alternative's (OUT/LABEL/mu_MU; label)."""
    spec = specs(lw, mus, variant)
    name = {v[1]: v[0] for v in model_variants.VARIANTS}
    tag = label(alt, variant)
    md = [f"<!-- demkit/model_onset.py: {'each mu' + chr(39) + 's chosen D2 + D3 variant' if not variant else variant}, "
          f"the stored variant (its rerun in {label(BASE, variant)}/ where one exists) → the same with `{alt}` "
          f"({' '.join(ALTERNATIVES[alt])}); RMS over the mean 95 % band "
          "half-width; held-out: mean score over the {K} left-out packings, the difference stored - alternative paired "
          "(t_{K-1,0.975}); target: every curve within 1 band, chi2/dof <= 3 -->",
          "| μ | variant | χ²/dof | worst fitted D2 | worst fitted D3 | worst predicted isobaric | held-out, fitted curves | "
          "difference ± SE | held-out, predicted paths | difference ± SE | chosen | χ²/dof | worst curve | target met |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines = [",".join(["mu", "variant", "start", "chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]",
                       "worst_predicted_isobaric [band]", "heldout_mean [-]", "heldout_paths_mean [-]", "chosen"]) + "\n"]
    K = 0
    for mu in mus:
        folder = spec[mu][0]
        rerun = os.path.join(out, label(BASE, variant), f"mu_{mu}")
        stored = rerun if os.path.exists(os.path.join(rerun, "summary.csv")) else os.path.join(lw, folder, f"mu_{mu}")
        runs = {"stored": stored, "alternative": os.path.join(out, tag, f"mu_{mu}")}
        m, c, K = row(mu, name[folder], runs)
        md.append(m)
        lines += c
    md[0] = md[0].replace("{K}", str(K))
    write_md_csv(out, tag, md, lines)


def chosen_of(lw, onset, alt, variant, mu):
    """(name, run folder) of the run chosen at MU in ONSET/LABEL.csv (label(ALT, VARIANT)): the alternative's run
    ('NAME + ALT'), or the stored variant's (its rerun in ONSET where one exists, else LW's)."""
    path = os.path.join(onset, label(alt, variant) + ".csv")
    if not os.path.exists(path):
        raise SystemExit(f"model_onset: {path} does not exist: make that table first (--table-only)")
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["mu"] == mu and r["chosen"] == "yes"]
    if not rows:
        raise SystemExit(f"model_onset: {path} has no chosen run at mu = {mu}")
    name = rows[0]["variant"]
    if rows[0]["start"] == "alternative":
        return f"{name} + {alt}", os.path.join(onset, label(alt, variant), f"mu_{mu}")
    rerun = os.path.join(onset, label(BASE, variant), f"mu_{mu}")
    if os.path.exists(os.path.join(rerun, "summary.csv")):
        return name, rerun
    return name, os.path.join(lw, {x[0]: x[1] for x in model_variants.VARIANTS}[name], f"mu_{mu}")


def pair_table(out, tag, comment, pairs):
    """OUT/TAG.{md,csv}: per mu (PAIRS {mu: [(name, run folder) left, right]}) the two runs side by side, the left one
    kept unless the right one beats it on one held-out score and is beaten on neither (`decide`)."""
    md = [comment, "| μ | left → right | χ²/dof | worst fitted D2 | worst fitted D3 | worst predicted isobaric | held-out, "
          "fitted curves | difference ± SE | held-out, predicted paths | difference ± SE | chosen | χ²/dof | worst curve "
          "| target met |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines = ["mu,variant,side,chi2_per_dof [-],worst_fitted_D2 [band],worst_fitted_D3 [band],"
             "worst_predicted_isobaric [band],heldout_mean [-],heldout_paths_mean [-],chosen\n"]
    for mu, pair in pairs.items():
        names = dict(zip(STARTS, (p[0] for p in pair)))
        m, c, K = row(mu, " → ".join(names.values()), dict(zip(STARTS, (p[1] for p in pair))), names)
        md.append(m)
        lines += [x.replace(",stored,", ",left,").replace(",alternative,", ",right,") for x in c]
    write_md_csv(out, tag, md, lines)


def compare(out, tag, left, right, mus):
    """OUT/TAG.{md,csv}: the runs LEFT = (name, folder) and RIGHT at each mu (FOLDER/mu_MU), the left one kept unless
    the right one beats it on one held-out score and is beaten on neither (thirtieth round: an option on top of a
    choice, where `--variant` and `--alternative` do not name the left run)."""
    for name, folder in (left, right):
        for mu in mus:
            if not os.path.exists(os.path.join(folder, f"mu_{mu}", "summary.csv")):
                raise SystemExit(f"model_onset: --compare: {folder}/mu_{mu}/summary.csv does not exist ({name}): run "
                                 "it first, or give --mu the values that were run")
    comment = (f"<!-- demkit/model_onset.py --compare: {left[0]} ({left[1]}) against {right[0]} ({right[1]}); the left "
               "one kept unless the right one beats it on one held-out score by more than t_{K-1,0.975} SE of the "
               "paired difference and is beaten on neither; RMS over the mean 95 % band half-width; target: every curve "
               "within 1 band, chi2/dof <= 3 -->")
    pairs = {mu: [(left[0], os.path.join(left[1], f"mu_{mu}")), (right[0], os.path.join(right[1], f"mu_{mu}"))]
             for mu in mus}
    pair_table(out, tag, comment, pairs)


def versus(lw, out, alt, mus, variant, current):
    """OUT/versus_LABEL.{md,csv}: at each mu the run chosen in CURRENT/ALT.csv (each mu's chosen variant, with or
    without ALT) against the one chosen in OUT/LABEL.csv (VARIANT, with or without ALT). The one with fewer
    coefficients stands on the left ('stored') and is kept unless the other beats it on one held-out score and is
    beaten on neither (`decide`); at equal counts the current one stands on the left."""
    size = {x[0]: x[4] for x in model_variants.VARIANTS}
    tag = "versus_" + label(alt, variant)
    where = os.path.join(os.path.basename(os.path.normpath(current)), f"{alt}.csv")
    comment = (f"<!-- demkit/model_onset.py --versus: the current choice ({where}) against {variant}'s "
               f"({label(alt, variant)}.csv); left the variant with fewer coefficients, kept unless the right one beats "
               "it on one held-out score by more than t_{K-1,0.975} SE of the paired difference and is beaten on "
               "neither; RMS over the mean 95 % band half-width; target: every curve within 1 band, chi2/dof <= 3 -->")
    pairs = {}
    for mu in mus:
        pair = [chosen_of(lw, current, alt, None, mu), chosen_of(lw, out, alt, variant, mu)]
        coefficients = [size[name.removesuffix(" + " + alt)] for name, _ in pair]
        if coefficients[1] < coefficients[0]:
            pair.reverse()
        pairs[mu] = pair
    pair_table(out, tag, comment, pairs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", required=True, help="demkit.model_variants' folder (variants.csv and its runs)")
    ap.add_argument("--work", help="working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", required=True, help="the runs (OUT/ALT/mu_MU) and the table (OUT/ALT.{md,csv})")
    ap.add_argument("--alternative", choices=sorted(ALTERNATIVES), default="gate")
    ap.add_argument("--variant", help="this variant (e.g. 'weighted + Lode limit') instead of each mu's chosen one: "
                                      "OUT/ALT_FOLDER/mu_MU and OUT/ALT_FOLDER.{md,csv}")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--mu", nargs="+", default=list(model_lode_weight.MUS))
    ap.add_argument("--no-jackknife", action="store_true", help="no held-out scores (no table): a quick look")
    ap.add_argument("--rerun-stored", action="store_true", help="also rerun the stored variant as it is (OUT/none/mu_MU, "
                                                                "the table's stored run): its held-out scores of the "
                                                                "predicted paths, which runs before this round lack")
    ap.add_argument("--table-only", action="store_true", help="only collect the existing results")
    ap.add_argument("--versus", metavar="CURRENT", help="with --variant: also compare its choice (OUT/LABEL.csv) with "
                                                        "the choice in CURRENT/ALT.csv (e.g. LW/onset), "
                                                        "OUT/versus_LABEL.{md,csv}")
    ap.add_argument("--compare", nargs=2, metavar=("LEFT", "RIGHT"), help="only compare two sets of runs, LEFT/mu_MU and "
                    "RIGHT/mu_MU (the left one kept unless the right one beats it): OUT/TAG.{md,csv}")
    ap.add_argument("--names", nargs=2, metavar=("LEFT_NAME", "RIGHT_NAME"), help="with --compare: the runs' names")
    ap.add_argument("--tag", help="with --compare: the table's name")
    a = ap.parse_args(argv)
    if a.compare:
        if not (a.names and a.tag):
            raise SystemExit("model_onset: --compare needs --names LEFT_NAME RIGHT_NAME and --tag NAME (the table's)")
        compare(a.out, a.tag, (a.names[0], a.compare[0]), (a.names[1], a.compare[1]), a.mu)
        return 0
    if a.versus and not a.variant:
        raise SystemExit("model_onset: --versus compares a --variant's choice with the current one: give --variant")
    spec = specs(a.variants, a.mu, a.variant)
    if not a.table_only:
        if not a.work:
            raise SystemExit("model_onset: give --work (the working copies), or --table-only")
        for mu in a.mu:
            _, rule, limit = spec[mu]
            w = model_friction.working_copy(a.store, a.work, mu, "model_onset")
            runs = [(label(a.alternative, a.variant), ALTERNATIVES[a.alternative])]
            if a.rerun_stored:
                runs.insert(0, (label(BASE, a.variant), []))
            for tag, extra in runs:
                model_lode_weight.run_rule(a.dem, w, os.path.join(a.out, tag, f"mu_{mu}"), rule,
                                           jackknife=not a.no_jackknife, state_limit=limit, extra=extra)
    if not a.no_jackknife:
        table(a.variants, a.out, a.alternative, a.mu, a.variant)
        if a.versus:
            versus(a.variants, a.out, a.alternative, a.mu, a.variant, a.versus)


if __name__ == "__main__":
    sys.exit(main())
