"""The held-out test between two rules of the extended family (issue 31, fifth round): the state-dependent
stress-ratio limit (`dem model --state-limit pressure`) against the plain limit (the default), on the same
packings.

Each `dem model --family auto` run with the jackknife writes `selection.csv`: per left-out packing the
extended family's held-out score (that packing's own fitted D2 curves predicted by the fit without it,
mean squared error in units of the between-packing SD). The two runs leave out the same packings, so the
scores pair: d_k = score(plain) - score(state limit); the state limit is chosen when mean(d) exceeds
t_{K-1,0.975} SE(d), the rule `dem model` uses between the two families (docs/model.md).

    /usr/bin/python3 -m demkit.model_state_limit --plain data/friction_n1000/model_friction \
        --state WORK --mu 0.5 1 --out WORK/state_limit_choice.md
"""
import argparse
import csv
import math
import os

from scipy import stats


def extended_scores(model_dir, prefix="heldout_extended", skip_nan=False):
    """Per left-out packing, the extended family's held-out score from MODEL_DIR/selection.csv (a `--family
    auto` run), or from MODEL_DIR/heldout.csv (a `--family extended` run with the jackknife): the column whose name
    starts with PREFIX ({} where there is none: `heldout_predicted_paths` of a run without predicted paths, or made
    before issue 31's twenty-eighth round); SKIP_NAN leaves out the packings it scores nan."""
    name = "selection.csv" if os.path.exists(os.path.join(model_dir, "selection.csv")) else "heldout.csv"
    with open(os.path.join(model_dir, name), newline="") as fh:
        lines = [l for l in fh if not l.startswith("#")]
    rows = list(csv.reader(lines))
    head = rows[0]
    col = next((i for i, h in enumerate(head) if h.startswith(prefix)), None)
    out = {}
    for r in rows[1:]:
        if col is not None and r and r[0].strip().isdigit() and not (skip_nan and r[col] in ("", "nan")):
            out[int(r[0])] = float(r[col])
    return out


def paired_choice(plain, state):
    """(mean d, SE d, t quantile, K, chosen) for d = plain - state over the packings both left out."""
    keys = sorted(set(plain) & set(state))
    if len(keys) < 2:
        raise ValueError("model_state_limit: fewer than 2 packings left out in both runs")
    d = [plain[k] - state[k] for k in keys]
    K = len(d)
    mean = sum(d) / K
    se = math.sqrt(sum((x - mean) ** 2 for x in d) / (K - 1) / K)
    t = float(stats.t.ppf(0.975, K - 1))
    return mean, se, t, K, mean > t * se


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--plain", required=True, help="folder with mu_MU/selection.csv of the default rule's run")
    ap.add_argument("--state", required=True, help="WORK of `demkit.model_friction --state-limit pressure` (mu_MU/model/)")
    ap.add_argument("--mu", nargs="+", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    md = ["<!-- demkit/model_state_limit.py: held-out scores of the extended family, plain limit minus state-dependent "
          "limit, paired over the left-out packings -->",
          "| μ | K | mean held-out score, plain | mean, state limit | mean difference ± SE | t_{K-1,0.975} SE | chosen |",
          "|---|---|---|---|---|---|---|"]
    for mu in a.mu:
        plain = extended_scores(os.path.join(a.plain, f"mu_{mu}"))
        state = extended_scores(os.path.join(a.state, f"mu_{mu}", "model"))
        mean, se, t, K, chosen = paired_choice(plain, state)
        mp, ms = sum(plain.values()) / len(plain), sum(state.values()) / len(state)
        md.append(f"| {mu} | {K} | {mp:.3g} | {ms:.3g} | {mean:.3g} ± {se:.2g} | {t * se:.2g} | "
                  f"{'state limit' if chosen else 'plain limit'} |")
    text = "\n".join(md) + "\n"
    with open(a.out, "w") as fh:
        fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
