"""Variants of the frictional family on D2 + D3, chosen by the held-out test (issue 31, seventh and eighth
rounds): the overlap or the weighted fabric rule (`--fabric-lode`), each with or without the state-dependent
stress-ratio limit (`--state-limit pressure`), and with `--lode-limit` each with that limit's exponent scaled by
the Lode angle (`--state-limit pressure-lode`). Calibrated on D2 + D3 + the isotropic branch of the friction
study's ensembles, the isobaric D2 path predicted, jackknife over the packings.

    /usr/bin/python3 -m demkit.model_variants --work WORK --out OUT             # the two runs without the limit
    /usr/bin/python3 -m demkit.model_variants --work WORK --out OUT --lode-limit   # + the two Lode-limit runs
    /usr/bin/python3 -m demkit.model_variants --work WORK --out OUT --table-only

OUT is the sixth round's folder (data/friction_n1000/model_friction/lode_weight): OUT/RULE/mu_MU holds the runs
with the limit (`demkit.model_lode_weight`), OUT/RULE_no_limit/mu_MU those without (made here). The choice: a
variant is beaten when another's held-out scores are lower on average by more than t_{K-1,0.975} times the SE
of the paired difference; the variant with the fewest coefficients that no other beats is chosen (a tie: the
lower mean score). OUT/variants.{md,csv}: per mu and variant chi2/dof, the worst fitted and predicted curve,
the mean held-out score, what beats it, and the choice; the target (every curve within one band half-width,
chi2/dof <= 3) with the chosen variant. docs/model.md, "Which variant: the held-out test over four" and "The
state exponent at another Lode angle".
"""
import argparse
import csv
import os
import shutil
import sys

from scipy import stats

from demkit import model_friction, model_lode_weight, model_state_limit
from demkit.atomic import write_atomic

MUS = model_lode_weight.MUS
# (name, folder under OUT, fabric rule, state limit, extension coefficients in all)
BASE = (("overlap", "overlap_no_limit", "overlap", False, 7),
        ("overlap + limit", "overlap", "overlap", True, 9),
        ("weighted", "weighted_no_limit", "weighted", False, 9),
        ("weighted + limit", "weighted", "weighted", True, 11))
# The eighth round's two (--lode-limit): the limit's state exponent scaled by (c_3(1/2)/c_3(b))^lambda_psi, one
# coefficient more. Optional: a table lists them as "not run" where their runs do not exist.
LODE = (("overlap + Lode limit", "overlap_lode_limit", "overlap", "pressure-lode", 10),
        ("weighted + Lode limit", "weighted_lode_limit", "weighted", "pressure-lode", 12))
VARIANTS = BASE + LODE
KINDS = (("D2", "fitted"), ("D3", "fitted"), ("isobaric", "predicted"))


def holm_beats(scores, alpha=0.05):
    """{(a, b): True where b beats a} under Holm's step-down correction over the n(n-1)/2 pairs of variants:
    each pair's two-sided paired t-test (K-1 degrees of freedom; the uncorrected rule is the same test at
    alpha, one side), the p-values sorted, the i-th smallest rejected while p_(i) <= alpha/(m - i + 1); a
    rejected pair is a beat of the lower-scoring variant over the other."""
    names = list(scores)
    pairs = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            mean, se, _, K, _ = model_state_limit.paired_choice(scores[a], scores[b])
            p = (0.0 if mean else 1.0) if se == 0 else 2 * float(stats.t.sf(abs(mean) / se, K - 1))
            pairs.append((p, (a, b) if mean > 0 else (b, a)))
    beats, m = {}, len(pairs)
    for i, (p, (loser, winner)) in enumerate(sorted(pairs, key=lambda x: x[0])):
        if p > alpha / (m - i):
            break
        beats[(loser, winner)] = True
    return beats


def choose(scores, sizes, holm=False):
    """The held-out choice among variants. scores: {name: {packing: score}}, sizes: {name: coefficients}.
    Returns (chosen, {name: [names that beat it]}, {name: mean score}): b beats a when the paired mean of
    a - b exceeds t_{K-1,0.975} SE (model_state_limit.paired_choice), or with holm=True when Holm's correction
    over all pairs still rejects (holm_beats); the chosen variant is the one with the fewest coefficients that
    nothing beats, ties broken by the lower mean score."""
    if holm:
        hb = holm_beats(scores)
        beaten = {a: [b for b in scores if (a, b) in hb] for a in scores}
    else:
        beaten = {a: [b for b in scores if b != a and model_state_limit.paired_choice(scores[a], scores[b])[4]]
                  for a in scores}
    means = {a: sum(s.values()) / len(s) for a, s in scores.items()}
    free = [a for a in scores if not beaten[a]]
    return min(free, key=lambda a: (sizes[a], means[a])), beaten, means


def run_missing(dem, work, out, mus, store, lode=False):
    """The runs without the limit (OUT/RULE_no_limit/mu_MU) that do not exist yet, on working copies made when
    missing; with `lode`, the two Lode-limit variants too (OUT/RULE_lode_limit/mu_MU), each a multi-start
    calibration (`dem model --start default,A,B`) from its default start and from both rules' fits with the
    limit (lambda_psi = 0 there: the same exponent at every Lode angle), the lowest chi2/dof kept."""
    for mu in mus:
        w = model_friction.working_copy(store, work, mu, "model_variants")
        for _, folder, rule, limit, _ in VARIANTS:
            run = os.path.join(out, folder, f"mu_{mu}")
            if os.path.exists(os.path.join(run, "summary.csv")):   # a run that exists is kept
                continue
            if not limit:
                model_lode_weight.run_rule(dem, w, run, rule, state_limit=False)
            elif limit == "pressure-lode" and lode:
                own, other = (("weighted", "overlap") if rule == "weighted" else ("overlap", "weighted"))
                starts = ["default"] + [os.path.join(out, f, f"mu_{mu}", "parameters.csv") for f in (own, other)]
                model_lode_weight.run_rule(dem, w, run, rule, state_limit=limit, start=",".join(starts))


def cross_start(dem, work, out, mu, scratch):
    """Each variant calibrated again (without the jackknife) from every other variant's calibrated parameters
    (`dem model --start`); where one of those starts ends at a lower chi2/dof than the default start (by more
    than 0.1 %), the variant is run again from it with the jackknife, in place, and OUT/FOLDER/mu_MU/start.txt
    names the start. The fits are multi-modal: the default start can stop in a worse minimum."""
    runs = {v[0]: os.path.join(out, v[1], f"mu_{mu}") for v in BASE}
    starts = {}
    for name, folder, rule, limit, _ in BASE:   # the default runs' parameters, copied before any is replaced
        starts[name] = os.path.join(scratch, f"mu_{mu}", f"start_{folder}.csv")
        os.makedirs(os.path.dirname(starts[name]), exist_ok=True)
        shutil.copy(os.path.join(runs[name], "parameters.csv"), starts[name])
    for name, folder, rule, limit, _ in BASE:
        best = (model_lode_weight.worst(os.path.join(runs[name], "summary.csv"))[0], None)
        base = best[0]
        for other in starts:
            if other == name:
                continue
            trial = os.path.join(scratch, f"mu_{mu}", f"{folder}_from_{other.replace(' + ', '_')}")
            model_lode_weight.run_rule(dem, work, trial, rule, jackknife=False, state_limit=limit, start=starts[other])
            chi = model_lode_weight.worst(os.path.join(trial, "summary.csv"))[0]
            if chi < best[0]:
                best = (chi, other)
        if best[1] is not None and best[0] < base * (1 - 1e-3):
            model_lode_weight.run_rule(dem, work, runs[name], rule, state_limit=limit, start=starts[best[1]])
            write_atomic(os.path.join(runs[name], "start.txt"),
                         f"started from the calibrated parameters of the variant '{best[1]}' (chi2/dof {base:.4g} from "
                         f"the default start, {best[0]:.4g} from this one; demkit.model_variants --cross-start)\n")


def start_of(run):
    """'default', or the variant whose calibrated parameters the run started from: start.txt (--cross-start), or
    the kept row of a multi-start run's starts.csv (a path OUT/FOLDER/mu_MU/parameters.csv names the variant)."""
    path = os.path.join(run, "start.txt")
    if os.path.exists(path):
        text = open(path).read()
        return text.split("'")[1] if "'" in text else "default"
    path = os.path.join(run, "starts.csv")
    if not os.path.exists(path):
        return "default"
    with open(path, newline="") as fh:
        kept = [r["start"] for r in csv.DictReader(l for l in fh if not l.startswith("#")) if r["kept"] == "yes"]
    folder = os.path.basename(os.path.dirname(os.path.dirname(kept[0]))) if kept and kept[0] != "default" else ""
    return next((v[0] for v in VARIANTS if v[1] == folder), "default")


def target_met(chi, w):
    """The target: chi2/dof <= 3 and every curve within one band half-width (W: {kind: (worst RMS, curve)})."""
    return chi <= 3 and max(x[0] for x in w.values()) <= 1


def target_cells(name, chi, w):
    """'name | chi2/dof | worst curve | met' of the target table for one chosen variant."""
    top = max(w.items(), key=lambda kv: kv[1][0])
    return f"{name} | {chi:.3g} | {top[1][0]:.2f} ({top[0][0]} {top[1][1]}) | {'yes' if target_met(chi, w) else 'no'}"


def table(out, mus):
    """OUT/variants.{md,csv} from the variants' runs (the two Lode-limit variants "not run" where absent: the
    choice is then among the others)."""
    md = ["<!-- demkit/model_variants.py: the extended family on D2 + D3 under its variants, RMS over the mean 95 % "
          "band half-width; held-out: mean score over the {K} left-out packings; beaten by: variants whose paired "
          "held-out scores are lower by more than t_{K-1,0.975} SE; Holm: the same two-sided paired tests with Holm's "
          "step-down correction over all pairs of the variants run (family-wise 5 %) -->",
          "| μ | variant | extension coefficients | start | χ²/dof | worst fitted D2 | worst fitted D3 | worst predicted isobaric | "
          "mean held-out score | beaten by | chosen | beaten by (Holm) | chosen (Holm) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    head = ["mu", "variant", "extension_coefficients", "start", "chi2_per_dof [-]", "worst_fitted_D2 [band]",
            "worst_fitted_D3 [band]", "worst_predicted_isobaric [band]", "heldout_mean [-]", "beaten_by", "chosen",
            "beaten_by_holm", "chosen_holm"]
    lines = [",".join(head) + "\n"]
    target = ["", "| μ | chosen | χ²/dof | worst curve | target met | chosen (Holm) | χ²/dof | worst curve | target met |",
              "|---|---|---|---|---|---|---|---|---|"]
    for mu in mus:
        res, scores = {}, {}
        for name, folder, _, limit, _ in VARIANTS:
            d = os.path.join(out, folder, f"mu_{mu}")
            if limit == "pressure-lode" and not os.path.exists(os.path.join(d, "summary.csv")):
                continue
            if not os.path.exists(os.path.join(d, "summary.csv")):
                raise SystemExit(f"model_variants: {d}/summary.csv does not exist: run without --table-only first "
                                 "(the runs with the limit: demkit.model_lode_weight), or give --mu the values run")
            res[name] = model_lode_weight.worst(os.path.join(d, "summary.csv"))
            scores[name] = model_state_limit.extended_scores(d)
        sizes = {v[0]: v[4] for v in VARIANTS if v[0] in scores}
        chosen, beaten, means = choose(scores, sizes)
        chosen_h, beaten_h, _ = choose(scores, sizes, holm=True)
        for name, folder, _, _, k in VARIANTS:
            if name not in res:
                md.append(f"| {mu} | {name} | {k} | not run | | | | | | | no | | no |")
                lines.append(",".join([mu, name, str(k), "not run", *[""] * 6, "no", "", "no"]) + "\n")
                continue
            chi, w = res[name]
            st = start_of(os.path.join(out, folder, f"mu_{mu}"))
            cells = [f"{w[key][0]:.2f} ({w[key][1]})" for key in KINDS]
            by = "; ".join(beaten[name]) or "none"
            by_h = "; ".join(beaten_h[name]) or "none"
            mark, mark_h = ("**yes**" if name == c else "no" for c in (chosen, chosen_h))
            md.append(f"| {mu} | {name} | {k} | {st} | {chi:.3g} | " + " | ".join(cells) +
                      f" | {means[name]:.4g} | {by} | {mark} | {by_h} | {mark_h} |")
            lines.append(",".join([mu, name, str(k), st, f"{chi:.4g}", *(f"{w[key][0]:.4g}" for key in KINDS),
                                   f"{means[name]:.4g}", by, "yes" if name == chosen else "no", by_h,
                                   "yes" if name == chosen_h else "no"]) + "\n")
        target.append(f"| {mu} | " + " | ".join(target_cells(c, *res[c]) for c in (chosen, chosen_h)) + " |")
    md[0] = md[0].replace("{K}", str(len(scores[chosen])))
    write_atomic(os.path.join(out, "variants.md"), "\n".join(md + target) + "\n")
    write_atomic(os.path.join(out, "variants.csv"), "".join(lines))
    print("\n".join(md + target))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", required=True, help="working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", required=True, help="the sixth round's folder: RULE/mu_MU (with the limit) read, "
                                                 "RULE_no_limit/mu_MU made")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--mu", nargs="+", default=list(MUS))
    ap.add_argument("--table-only", action="store_true", help="only collect the existing results")
    ap.add_argument("--cross-start", action="store_true",
                    help="then calibrate each of the four base variants from the others' parameters too, and keep the "
                         "lowest chi2/dof")
    ap.add_argument("--lode-limit", action="store_true",
                    help="also the two variants whose state exponent depends on the Lode angle (eighth round; each "
                         "started from its default and from both rules' fits with the limit, after --cross-start)")
    a = ap.parse_args(argv)
    if not a.table_only:
        run_missing(a.dem, a.work, a.out, a.mu, a.store)
        for mu in a.mu if a.cross_start else []:
            cross_start(a.dem, os.path.join(a.work, f"mu_{mu}"), a.out, mu, os.path.join(a.work, "cross_start"))
        if a.lode_limit:
            run_missing(a.dem, a.work, a.out, a.mu, a.store, lode=True)
    table(a.out, a.mu)


if __name__ == "__main__":
    sys.exit(main())
