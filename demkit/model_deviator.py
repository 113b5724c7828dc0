"""The deviatoric stress after the peak, at constant volume and at constant pressure (issue 31, thirtieth round).

For each mu of the friction study, `dem model --predict-with` writes the DEM means beside the chosen calibration's
curves (D2 and D3 at constant volume, the isobaric D2 paths); from the stress ratio's peak to the end of each curve
this table gives the change of ln s_dev, of ln sigma_dev = ln(s_dev p*), of ln p* and of ln p_iso(nu), the isotropic
law of the calibration at the DEM's volume fraction (nu = nu0 exp(-3 eps_v) on the isobaric paths, nu0 at constant
volume). Where sigma_dev stays where it is at constant volume and falls with p_iso(nu) at constant pressure, the
deviatoric stress scales with the isotropic reference pressure under a volume change, which `dem model
--deviator-volume reference` builds (docs/model.md, "The deviatoric stress under a volume change").

    /usr/bin/python3 -m demkit.model_deviator --work WORK --out OUT [--mu 0.5 1] [--dem build/dem]

OUT/after_peak.{md,csv}; OUT/runs/mu_MU holds the predictions it read (their curves).
"""
import argparse
import csv
import math
import os
import subprocess
import sys

from demkit import model_friction, model_lode_weight, model_onset, model_variants
from demkit.atomic import write_md_csv

LW = os.path.join("data", "friction_n1000", "model_friction", "lode_weight")
NUS = ("0.690", "0.740", "0.800")


def chosen(lw, mu):
    """(name, parameters.csv, fabric rule, --state-limit) of the current choice at MU (docs/model.md's target table:
    onset/gate.csv, at mu = 1 the twenty-ninth round's gated weighted Lode-limit run, at mu = 0.1 the stored
    cross-started weighted run)."""
    folder = {x[0]: x[1] for x in model_variants.VARIANTS}
    if mu == "1":
        name, run = "weighted + Lode limit + gate", os.path.join(lw, "onset", "lode_limit", "gate_weighted_lode_limit",
                                                                 "mu_1")
    elif mu == "0.1":
        name, run = "weighted", os.path.join(lw, folder["weighted"], "mu_0.1")
    else:
        name, run = model_onset.chosen_of(lw, os.path.join(lw, "onset"), "gate", None, mu)
    rule, limit = {x[0]: (x[2], model_lode_weight.state_limit_value(x[3])) for x in model_variants.VARIANTS}[
        name.removesuffix(" + gate")]
    return name, os.path.join(run, "parameters.csv"), rule, limit


def isotropic_law(parameters_csv):
    """p_iso(nu) of a calibration's parameters.csv: p0 (nu C(nu)/nu_c) x (1 + gamma_p x), x = ln(nu/nu_c), C(nu) = C0 +
    C1 (nu/nu_cC - 1)^alpha above nu_cC (fit/include/demfit/model.hpp, isotropic_pressure)."""
    with open(parameters_csv, newline="") as fh:
        v = {r["parameter"]: float(r["value"]) for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))
             if r["parameter"] in ("p0", "nu_c", "gamma_p", "C0", "C1", "nu_cC", "alpha")}

    def p_iso(nu):
        x = math.log(nu / v["nu_c"])
        C = v["C0"] + v["C1"] * max(nu / v["nu_cC"] - 1.0, 0.0) ** v["alpha"]
        return v["p0"] * (nu * C / v["nu_c"]) * x * (1.0 + v["gamma_p"] * x)
    return p_iso


def after_peak(rows, nu0, p_iso, isobaric):
    """(eps_d at the peak, d ln s, d ln sigma_dev, d ln p, d ln p_iso(nu)) from the DEM means' peak of s_dev to the
    last row. ROWS: the curve's rows (dicts with eps_d_accumulated or eps_d, s_dev_mean, p_star_mean, eps_v_mean)."""
    key = "eps_d_accumulated" if "eps_d_accumulated" in rows[0] else "eps_d"
    pts = []
    for r in rows:
        s, p = float(r["s_dev_mean"]), float(r["p_star_mean"])
        nu = nu0 * math.exp(-3.0 * float(r["eps_v_mean"])) if isobaric else nu0
        pts.append((float(r[key]), s, s * p, p, p_iso(nu)))
    a, b = max(pts, key=lambda x: x[1]), pts[-1]
    return (a[0],) + tuple(math.log(b[i] / a[i]) for i in range(1, 5))


def curve_files(nu):
    return ((f"D2 {nu}", f"D2_phi{nu}.csv", False), (f"D3 {nu}", f"D3_phi{nu}.csv", False),
            (f"isobaric {nu}", os.path.join("paths", f"isobaric_phi{nu}.csv"), True))


def table(out, results):
    """OUT/after_peak.{md,csv} from RESULTS [(mu, name, curve, values)]."""
    md = ["<!-- demkit/model_deviator.py: from the DEM mean's peak of s_dev to the curve's end; p_iso(nu) the isotropic "
          "law of each mu's chosen calibration at the DEM's volume fraction -->",
          "| μ | choice | curve | ε_d at the peak | Δ ln s_dev | Δ ln σ_dev | Δ ln p* | Δ ln p_iso(ν) |",
          "|---|---|---|---|---|---|---|---|"]
    lines = ["mu,choice,curve,eps_d_peak [-],dln_s_dev [-],dln_sigma_dev [-],dln_p [-],dln_p_iso [-]\n"]
    for mu, name, curve, v in results:
        md.append(f"| {mu} | {name} | {curve} | {v[0]:.3f} | " + " | ".join(f"{x:+.3f}" for x in v[1:]) + " |")
        lines.append(",".join([mu, name, curve] + [f"{x:.5g}" for x in v]) + "\n")
    write_md_csv(out, "after_peak", md, lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", required=True, help="working copies of the stored ensembles (made when missing)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--variants", default=LW, help="demkit.model_variants' folder (the stored choices)")
    ap.add_argument("--store", default=os.path.join("data", "friction_n1000"))
    ap.add_argument("--dem", default=os.path.join("build", "dem"))
    ap.add_argument("--mu", nargs="+", default=list(model_lode_weight.MUS))
    a = ap.parse_args(argv)
    results = []
    for mu in a.mu:
        name, params, rule, limit = chosen(a.variants, mu)
        work = model_friction.working_copy(a.store, a.work, mu, "model_deviator")
        run = os.path.join(a.out, "runs", f"mu_{mu}")
        cmd = [a.dem, "model", work, "--predict-with", params, "--family", "extended", "--fabric-lode", rule,
               "--state-limit", limit, "--calibrate-on", "D2,D3", "--no-plots", "--out", run, "--force"]
        if subprocess.run(cmd, capture_output=True, text=True).returncode != 0:
            raise SystemExit(f"model_deviator: {' '.join(cmd)} failed")
        p_iso = isotropic_law(params)
        for nu in NUS:
            for curve, f, isobaric in curve_files(nu):
                with open(os.path.join(run, "curves", f), newline="") as fh:
                    rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
                results.append((mu, name, curve, after_peak(rows, float(nu), p_iso, isobaric)))
    table(a.out, results)


if __name__ == "__main__":
    sys.exit(main())
