"""Each mu's current D2 + D3 choice of the friction study in one table (issue 31, thirtieth round): which run, its
parameters.csv, the `dem model` options that predict with it, its chi2/dof and worst curves, and the table that
decided it.

The choices were made round by round (docs/model.md: the eighth round's variants, the twenty-eighth's gate, the
twenty-ninth's Lode-limit versus, the thirtieth's deviator); this table gathers them so that a user finds the
calibrated parameters of a friction coefficient in one place:

    /usr/bin/python3 -m demkit.model_choice [--variants LW] [--out LW]

LW/choice.{md,csv}. Each row's numbers are read from its run's summary.csv; tests/python/test_model_deviator.py checks
that each deciding table chose that run with those numbers.
"""
import argparse
import os
import sys

from demkit import model_lode_weight, model_variants
from demkit.atomic import write_md_csv

LW = os.path.join("data", "friction_n1000", "model_friction", "lode_weight")
KINDS = model_variants.KINDS
# mu: (name, run folder under LW, fabric rule, --state-limit, further options, deciding table under LW, its row's
# side: the table's csv names the chosen run by its `variant` cell)
CHOICES = {
    "0": ("overlap", "onset/none/mu_0", "overlap", "none", [], "onset/deviator/deviator_overlap", "overlap"),
    "0.01": ("overlap + limit", "onset/none/mu_0.01", "overlap", "pressure", [], "onset/gate", "overlap + limit"),
    "0.1": ("weighted", "weighted_no_limit/mu_0.1", "weighted", "none", [], "onset/deviator/deviator_mu_0.1",
            "weighted"),
    "0.3": ("weighted", "onset/none/mu_0.3", "weighted", "none", [], "onset/deviator/deviator_weighted", "weighted"),
    "0.5": ("weighted", "onset/none/mu_0.5", "weighted", "none", [], "onset/deviator/deviator_weighted", "weighted"),
    "1": ("weighted + Lode limit + gate + deviator reference", "onset/deviator/gate_deviator_weighted_lode_limit/mu_1",
          "weighted", "pressure-lode", ["--dilatancy-gate", "mobilisation", "--deviator-volume", "reference"],
          "onset/deviator/deviator_mu_1", "... + deviator reference"),
}


def options(mu):
    """The `dem model` options that predict with MU's choice (`--predict-with` reads the option rows too)."""
    _, _, rule, limit, extra, _, _ = CHOICES[mu]
    return ["--family", "extended", "--fabric-lode", rule, "--state-limit", limit, "--calibrate-on", "D2,D3", *extra]


def rows(lw):
    """[(mu, name, parameters.csv, options, chi2/dof, {kind: (worst, curve)}, deciding table)] per mu."""
    out = []
    for mu, (name, run, _, _, _, table, _) in CHOICES.items():
        chi, worst = model_lode_weight.worst(os.path.join(lw, run, "summary.csv"))
        out.append((mu, name, os.path.join(run, "parameters.csv"), options(mu), chi, worst, table))
    return out


def write(lw, out):
    md = ["<!-- demkit/model_choice.py: each mu's current D2 + D3 choice; RMS over the mean 95 % band half-width; "
          "target: every curve within 1 band, chi2/dof <= 3 -->",
          "| μ | choice | parameters (under this folder) | χ²/dof | worst fitted D2 | worst fitted D3 | worst predicted "
          "isobaric | target met | decided in | predict with |", "|---|---|---|---|---|---|---|---|---|---|"]
    lines = ["mu,choice,parameters,chi2_per_dof [-],worst_fitted_D2 [band],worst_fitted_D3 [band],"
             "worst_predicted_isobaric [band],target_met,decided_in,dem_model_options\n"]
    for mu, name, params, opts, chi, worst, table in rows(lw):
        cells = [f"{worst[k][0]:.2f} ({worst[k][1]})" for k in KINDS]
        md.append(f"| {mu} | {name} | `{params}` | {chi:.3g} | " + " | ".join(cells) +
                  f" | {'yes' if model_variants.target_met(chi, worst) else 'no'} | `{table}.md` | `{' '.join(opts)}` |")
        lines.append(",".join([mu, f'"{name}"', params, f"{chi:.4g}", *(f"{worst[k][0]:.4g}" for k in KINDS),
                               "yes" if model_variants.target_met(chi, worst) else "no", table + ".md", " ".join(opts)]) + "\n")
    write_md_csv(out, "choice", md, lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", default=LW, help="the friction study's variant folder (the runs)")
    ap.add_argument("--out", help="where choice.{md,csv} go (default: --variants)")
    a = ap.parse_args(argv)
    write(a.variants, a.out or a.variants)


if __name__ == "__main__":
    sys.exit(main())
