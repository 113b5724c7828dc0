"""A relaxing anisotropic pressure against the permanent one (issue 31, eighteenth round).

With the volume-form state parameter the anisotropy's pressure A d eps_d either moves the elastic state and never
relaxes (`permanent`, the tenth to seventeenth rounds: a constant-p path is steady only where the dilatancy cancels
a_A F, and can run away) or is an excess over the isotropic law that relaxes at beta_p (`--anisotropy-pressure
relaxing`: steady at psi = 0). This predicts every laboratory test with each step-8 calibration of data/geotech/model
and its restart with the relaxing excess (README step 11), and writes per calibration chi2/dof, the worst fitted and
predicted curve, and where the model's drained paths end: the largest |psi| at the end of a laboratory path, how many
paths still move at their end (|d nu/d eps_d| over the last 0.1 of strain above 0.01 and five times the DEM's: the
rule of dem model's warning), and the path whose drift most exceeds the DEM's; `--make-starts` writes step 11's extra
starts, and the figure runaway_paths.{png,svg} shows the two paths the permanent law runs away on. `--excess-size`
(nineteenth round) adds excess_size.{md,csv}: the largest relaxing excess q/p* per calibration over the laboratory
paths (the path curves' q_star_model), and how many paths have q > p* (the elastic state below jamming).

    /usr/bin/python3 -m demkit.model_excess --stored data/geotech/model/state_volume \\
        --relaxing data/geotech/model/state_volume/relaxing_excess --work WORK --out OUT
"""
import argparse
import csv
import glob
import math
import os
import sys

from demkit.atomic import write_atomic
from demkit.model_jamming import LAB, lab_group, run, summary, write_csv

ENSEMBLE = {"loose": "runs/geotech_model/ensemble_loose", "dense": "runs/geotech_model/ensemble_dense",
            "three_pressures/joint": "runs/geotech_model3_mu0.5/ensemble_joint",
            "three_pressures/dense": "runs/geotech_model3_mu0.5/ensemble_dense",
            "three_pressures/mu_0/dense": "runs/geotech_model3_mu0/ensemble_dense"}
for _mu in ("0", "0.1", "0.3", "1"):
    ENSEMBLE[f"mu_{_mu}/dense"] = f"runs/geotech_model_mu{_mu}/ensemble_dense"
for _mu in ("0.1", "0.3", "1"):
    ENSEMBLE[f"three_pressures/mu_{_mu}/joint"] = f"runs/geotech_model3_mu{_mu}/ensemble_joint"
WAYS = ("permanent", "relaxing")
TAIL = 0.1   # the strain window of the end drift
HEAD = ["calibration", "chi2_dof_permanent [-]", "chi2_dof_relaxing [-]", "worst_fitted_permanent [band]",
        "worst_fitted_relaxing [band]", "worst_lab_predicted_permanent [band]", "worst_lab_predicted_relaxing [band]",
        "worst_D2_D3_permanent [band]", "worst_D2_D3_relaxing [band]", "end_psi_max_permanent [-]",
        "end_psi_max_relaxing [-]", "paths_moving_permanent", "paths_moving_relaxing", "worst_drift_path_permanent",
        "worst_drift_model_permanent [-]", "worst_drift_dem_permanent [-]", "worst_drift_path_relaxing",
        "worst_drift_model_relaxing [-]", "worst_drift_dem_relaxing [-]", "paths", "beta_p_relaxing [1/eps_d]",
        "a_A_a_permanent [-]", "a_A_a_relaxing [-]", "converged_relaxing", "beta_p_lo95_relaxing [1/eps_d]",
        "beta_p_hi95_relaxing [1/eps_d]"]


def values(path):
    """name -> value (float; nan where not a number) of a parameters.csv."""
    with open(path, newline="") as fh:
        out = {}
        for r in csv.DictReader(fh):
            try:
                out[r["parameter"]] = float(r["value"])
            except ValueError:
                out[r["parameter"]] = float("nan")
        return out


BETA_P_NOTE = (" β_p: with its 95 % interval from ln β_p (its parameters.csv: the covariance errors of a fit "
               "without jackknife), or the bound it sits on (within 1 %)")
BETA_P_BOUNDS = (1e-3, 300.0)   # the extended family's bounds on beta_p at nu_ref (fit/src/model_fit.cpp, set_bounds)


def beta_p_interval(path):
    """(lo, hi): the 95 % interval of beta_p from the lo95/hi95 of ln_beta_p_a in the parameters.csv at PATH (the
    jackknife's where it was used, else the covariance's); nan where it has none."""
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["parameter"] == "ln_beta_p_a":
                try:
                    return math.exp(float(r["lo95"])), math.exp(float(r["hi95"]))
                except (ValueError, OverflowError):
                    break
    return float("nan"), float("nan")


def plain(v, sig=2):
    """V to SIG significant digits without an exponent (0.0065, 42, 170)."""
    if not math.isfinite(v) or v == 0:
        return cell(v)
    d = sig - 1 - math.floor(math.log10(abs(v)))
    return f"{round(v, d):.{max(d, 0)}f}"


def beta_p_cell(bp, lo, hi):
    """beta_p with its 95 % interval, or the bound it sits on within 1 % (where the interval says nothing)."""
    for b, side in zip(BETA_P_BOUNDS, ("lower", "upper")):
        if math.isfinite(bp) and abs(math.log(bp / b)) < 1e-2:
            return f"{cell(bp)} ({side} bound)"
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return f"{cell(bp)} (interval not determined)"
    return f"{cell(bp)} ({plain(lo)}–{plain(hi)})"


def nu_cs(P, p):
    """The critical-state line nu_cs + lambda_cs ln(p*/1e-3) + c_cs (p* - 1e-3) (demfit/model.hpp, state_psi)."""
    return P["nu_cs"] + P.get("lambda_cs", 0.0) * math.log(max(p, 1e-12) / 1e-3) + P.get("c_cs", 0.0) * (p - 1e-3)


def end_drift(eps, nu):
    """|d nu/d eps_d| over the last TAIL of strain."""
    i = max(j for j in range(len(eps)) if eps[j] <= eps[-1] - TAIL)
    return abs(nu[-1] - nu[i]) / (eps[-1] - eps[i])


def read_curve(path):
    """A model path curve of `dem model` (curves/paths/*.csv) as column name -> floats."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def path_ends(model_dir, P):
    """Per laboratory path of MODEL_DIR/curves/paths: (name, the model's psi at the end, the model's end drift, the
    DEM's end drift), the DEM's nu = nu0 e^{-3 eps_v} (eps_v = tr E/3, as the model's nu)."""
    out = []
    for f in sorted(glob.glob(os.path.join(model_dir, "curves", "paths", "*.csv"))):
        c = read_curve(f)
        eps, nu, p = c["eps_d_accumulated"], c["nu_model"], c["p_star_model"]
        dem = [nu[0] * math.exp(-3 * ev) for ev in c["eps_v_mean"]]
        name = os.path.basename(f)[:-4]
        if not all(math.isfinite(x) for x in nu + p):
            out.append((name, float("nan"), float("nan"), end_drift(eps, dem)))
            continue
        out.append((name, nu[-1] - nu_cs(P, p[-1]), end_drift(eps, nu), end_drift(eps, dem)))
    if not out:
        raise SystemExit(f"model_excess: no model paths under {model_dir}/curves/paths")
    return out


BETA_P_STARTS = (30.0, 200.0)


def make_starts(stored, out):
    """OUT/NAME/beta_p_B.csv: each step-8 parameters.csv with ln_beta_p_a set to ln B (B in BETA_P_STARTS), the extra
    starts of step 11 (the stored value is the held start of the permanent law, which it never read)."""
    for name in LAB:
        with open(os.path.join(stored, name, "parameters.csv"), newline="") as fh:
            rows = list(csv.reader(fh))
        col = rows[0].index("value")
        for b in BETA_P_STARTS:
            for r in rows[1:]:
                if r[0] == "ln_beta_p_a":
                    r[col] = repr(math.log(b))
            path = os.path.join(out, name, f"beta_p_{b:g}.csv")
            os.makedirs(os.path.dirname(path), exist_ok=True)
            lines = [",".join(f'"{v}"' if ("," in v or '"' in v) else v for v in r) for r in rows]
            write_atomic(path, "\n".join(lines) + "\n")


def predict(stored, relaxing, work, dem):
    """Every laboratory test predicted with each calibration, both ways, into WORK/{permanent,relaxing}/NAME."""
    for name in LAB:
        for way, root in zip(WAYS, (stored, relaxing)):
            out = os.path.join(work, way, name)
            os.makedirs(os.path.dirname(out), exist_ok=True)
            run([dem, "model", ENSEMBLE[name], "--predict-with", os.path.join(root, name, "parameters.csv"),
                 "--family", "extended", "--no-plots", "--out", out, "--force"], out + ".log")


def largest(values):
    """The largest finite entry (by its first element) of a list of tuples; None without one."""
    ok = [v for v in values if math.isfinite(v[0])]
    return max(ok) if ok else None


def moving(model, dem):
    """A path still moving at its end, by dem model's rule (drift_on_path): the model's drift above 0.01 and five times
    the DEM's."""
    return model > 0.01 and model > 5 * dem


def ends_summary(ends):
    """(largest end |psi|, how many paths still move (moving), the path whose drift most exceeds the DEM's, its
    model drift, the DEM's); nan where none is finite."""
    psi = largest([(abs(x),) for _, x, _, _ in ends])
    n = sum(1 for _, _, m, dem in ends if math.isfinite(m) and moving(m, dem))
    d = largest([(m - dem, n, m, dem) for n, _, m, dem in ends])
    nan = float("nan")
    return (psi[0] if psi else nan, n) + (d[1:] if d else ("", nan, nan))


def table(stored, relaxing, work):
    """Per calibration: chi2/dof and the worst curves (each calibration's own summary.csv), the model paths' ends
    (WORK's predictions), beta_p, a_A."""
    rows = []
    for name in LAB:
        A, B = (values(os.path.join(r, name, "parameters.csv")) for r in (stored, relaxing))
        s, t = (summary(os.path.join(r, name), lab_group, ("fitted", "lab", "d2d3")) for r in (stored, relaxing))
        ends = [path_ends(os.path.join(work, w, name), P) for w, P in zip(WAYS, (A, B))]
        e = [ends_summary(x) for x in ends]
        rows.append([name, A["chi2_per_dof"], B["chi2_per_dof"], s["fitted"], t["fitted"], s["lab"], t["lab"],
                     s["d2d3"], t["d2d3"], e[0][0], e[1][0], e[0][1], e[1][1], *e[0][2:], *e[1][2:], len(ends[0]),
                     math.exp(B["ln_beta_p_a"]), A["a_A_a"], B["a_A_a"], "no" if "converged" in B else "yes",
                     *beta_p_interval(os.path.join(relaxing, name, "parameters.csv"))])
    return rows


RUNAWAYS = (("loose", "TC_p_loose_phi0.593", "loose μ = 0.5: TC_p at p* = 10⁻³"),
            ("mu_0.3/dense", "TT_b050_dense_phi0.658", "μ = 0.3 dense: TT b = 0.5 at p* = 10⁻³"))


def figure(work, out):
    """OUT/runaway_paths.{png,svg}: the two paths the permanent law runs away on, eps_v and s_dev against eps_d, the
    DEM's mean and 95 % band and both laws (from WORK's predictions)."""
    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["svg.hashsalt"] = "model_excess"   # the same SVG from the same data
    import matplotlib.pyplot as plt
    from demkit.atomic import write_figure
    fig, ax = plt.subplots(2, len(RUNAWAYS), figsize=(4.2 * len(RUNAWAYS), 6.2), sharex="col", squeeze=False)
    for j, (name, path, title) in enumerate(RUNAWAYS):
        c = {w: read_curve(os.path.join(work, w, name, "curves", "paths", path + ".csv")) for w in WAYS}
        d = c["permanent"]
        for i, (q, label) in enumerate((("eps_v", "ε_v = tr E/3 (extension +)"), ("s_dev", "s_dev = σ_dev/p"))):
            a = ax[i][j]
            a.fill_between(d["eps_d_accumulated"], d[q + "_lo95"], d[q + "_hi95"], color="0.8", label="DEM, 95 % band")
            a.plot(d["eps_d_accumulated"], d[q + "_mean"], color="k", lw=1.2, label="DEM mean (4 packings)")
            for w, style in zip(WAYS, ("--", "-")):
                a.plot(c[w]["eps_d_accumulated"], c[w][q + "_model"], style, color="C3" if w == "permanent" else "C0",
                       label=f"model, {w} anisotropic pressure")
            a.set_ylabel(label)
            if i == 0:
                a.set_title(title, fontsize=10)
            else:
                a.set_xlabel("ε_d accumulated")
    ax[0][0].legend(fontsize=7, loc="best")
    fig.suptitle("Constant-p runaway of the permanent anisotropic pressure (data/geotech/model README step 11)",
                 fontsize=10)
    fig.tight_layout()
    write_figure(fig, os.path.join(out, "runaway_paths"), metadata={
        "png": {"Title": "runaway_paths", "Source": "demkit/model_excess.py"},
        "svg": {"Title": "runaway_paths", "Source": "demkit/model_excess.py", "Date": None}})


def cell(v, digits=3):
    """A number to `digits`; inf (a curve the model diverged along, or could not start) and nan as such."""
    return ("inf" if v > 0 else "-inf") if math.isinf(v) else "nan" if math.isnan(v) else f"{v:.{digits}g}"


def write(rows, out, stored, relaxing):
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "comparison.csv"), HEAD, rows)
    md = [f"<!-- demkit/model_excess.py: every calibration of {stored} (permanent) against its restart in {relaxing} "
          "with --anisotropy-pressure relaxing (data/geotech/model README step 11: from the stored optimum and two "
          "more values of beta_p, the lowest chi2/dof kept; the stored one's held set, no jackknife); worst: largest "
          "RMS error over the 95 % band half-width; end |psi|: the largest over the model's laboratory paths at their "
          f"ends; drift: |d nu/d eps_d| over the last {TAIL} of strain of a laboratory path; still moving: paths whose "
          "model drift is above 0.01 and five times the DEM's (dem model warns about them); worst drift: the path whose "
          "model drift most exceeds the DEM's, model (DEM);" + BETA_P_NOTE + " -->",
          "| calibration | χ²/dof permanent → relaxing | worst fitted | worst predicted, laboratory | worst predicted, "
          "D2/D3 | end \\|ψ\\| | paths still moving | worst drift, permanent: model (DEM) | relaxing | β_p "
          "| a_A at ψ = 0 | converged |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r[0]} | {cell(r[1], 4)} → {cell(r[2], 4)} | {cell(r[3])} → {cell(r[4])} | {cell(r[5])} → "
                  f"{cell(r[6])} | {cell(r[7])} → {cell(r[8])} | {cell(r[9], 2)} → {cell(r[10], 2)} | "
                  f"{r[11]} → {r[12]} of {r[19]} | {r[13]}: {cell(r[14], 2)} ({cell(r[15], 2)}) | "
                  f"{r[16]}: {cell(r[17], 2)} ({cell(r[18], 2)}) | {beta_p_cell(r[20], r[24], r[25])} "
                  f"| {cell(r[21])} → {cell(r[22])} "
                  f"| {r[23]} |")
    write_atomic(os.path.join(out, "comparison.md"), "\n".join(md) + "\n")


SIZE_HEAD = ["calibration", "largest_q_over_p [-]", "path_of_largest", "eps_d_accumulated_of_largest [-]",
             "paths_q_above_p", "paths", "beta_p_relaxing [1/eps_d]", "a_A_a_relaxing [-]",
             "beta_p_lo95_relaxing [1/eps_d]", "beta_p_hi95_relaxing [1/eps_d]"]


def excess_size(relaxing, work):
    """Per calibration of WORK/relaxing (the predictions of `predict`): the largest relaxing excess over the pressure,
    q/p* with q = p* - p_iso(nu_el) (dem model's column q_star_model), the path and strain where it is largest, and how
    many laboratory paths have q > p* somewhere (their elastic state below the isotropic law's jamming fraction)."""
    rows = []
    for name in LAB:
        P = values(os.path.join(relaxing, name, "parameters.csv"))
        worst, where, at, above, n = 0.0, "", float("nan"), 0, 0
        for f in sorted(glob.glob(os.path.join(work, "relaxing", name, "curves", "paths", "*.csv"))):
            c = read_curve(f)
            if "q_star_model" not in c:
                raise SystemExit(f"model_excess: {f} has no q_star_model column: predict with a dem built from the "
                                 "nineteenth round on (rerun without --table-only)")
            n += 1
            ratio = [(q / p, e) for q, p, e in zip(c["q_star_model"], c["p_star_model"], c["eps_d_accumulated"])
                     if p > 0 and math.isfinite(q)]
            top = max(ratio, default=(0.0, float("nan")))
            above += top[0] > 1
            if top[0] > worst:
                worst, where, at = top[0], os.path.basename(f)[:-4], top[1]
        rows.append([name, worst, where, at, above, n, math.exp(P["ln_beta_p_a"]), P["a_A_a"],
                     *beta_p_interval(os.path.join(relaxing, name, "parameters.csv"))])
    return rows


def write_size(rows, out, relaxing):
    """excess_size.{csv,md} in OUT."""
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "excess_size.csv"), SIZE_HEAD, rows)
    md = ["# How large the relaxing anisotropic excess grows on the laboratory paths", "",
          f"Every laboratory test predicted with each calibration of `{relaxing}` (`dem model --predict-with`). q = p* -"
          " p_iso(nu_el) is the excess over the isotropic law at the elastic state (the path curves' column "
          "q_star_model). Where q > p* the elastic state lies below the isotropic law's jamming fraction: a negative "
          "isotropic pressure, outside the law's domain (docs/model.md, \"How large the relaxing excess grows\"). "
          "Made by `python3 -m demkit.model_excess ... --excess-size`." + BETA_P_NOTE + ".", "",
          "| calibration | largest q/p* | on path (at eps_d) | paths with q > p* | beta_p | a_A (psi = 0) |",
          "|---|---|---|---|---|---|"]
    for name, worst, where, at, above, n, bp, aa, lo, hi in rows:
        md.append(f"| {name} | {cell(worst)} | {where or '-'} ({cell(at)}) | {above} of {n} | {beta_p_cell(bp, lo, hi)} "
                  f"| {cell(aa)} |")
    write_atomic(os.path.join(out, "excess_size.md"), "\n".join(md) + "\n")


BOUNDED_HEAD = ["calibration", "chi2_dof_permanent [-]", "chi2_dof_relaxing [-]", "chi2_dof_bounded [-]",
                "worst_lab_predicted_permanent [band]", "worst_lab_predicted_relaxing [band]",
                "worst_lab_predicted_bounded [band]", "worst_D2_D3_permanent [band]", "worst_D2_D3_relaxing [band]",
                "worst_D2_D3_bounded [band]", "paths_moving_relaxing", "paths_moving_bounded",
                "largest_q_over_p_relaxing [-]", "largest_q_over_p_bounded [-]", "paths_q_above_p_relaxing",
                "paths_q_above_p_bounded", "paths", "beta_p_bounded [1/eps_d]", "a_A_a_bounded [-]",
                "beta_p_lo95_bounded [1/eps_d]", "beta_p_hi95_bounded [1/eps_d]"]


def largest_ratio(model_dir):
    """(largest q/p* over MODEL_DIR's laboratory path curves, how many paths have q > p* somewhere)."""
    worst, above = 0.0, 0
    for f in sorted(glob.glob(os.path.join(model_dir, "curves", "paths", "*.csv"))):
        c = read_curve(f)
        top = max((q / p for q, p in zip(c["q_star_model"], c["p_star_model"]) if p > 0 and math.isfinite(q)),
                  default=0.0)
        worst, above = max(worst, top), above + (top > 1)
    return worst, above


def bounded_table(stored, relaxing, bounded, work, dem, predict_again=True):
    """Per calibration refitted with --anisotropy-pressure bounded (the folders of BOUNDED): chi2/dof, the worst
    laboratory and D2/D3 predictions of the three laws (each calibration's own summary.csv), paths still moving, and
    the largest excess q/p* (relaxing and bounded, from WORK/{relaxing,bounded}'s predictions)."""
    rows = []
    for name in LAB:
        if not os.path.exists(os.path.join(bounded, name, "parameters.csv")):
            continue
        out = os.path.join(work, "bounded", name)
        if predict_again:
            os.makedirs(os.path.dirname(out), exist_ok=True)
            run([dem, "model", ENSEMBLE[name], "--predict-with", os.path.join(bounded, name, "parameters.csv"),
                 "--family", "extended", "--no-plots", "--out", out, "--force"], out + ".log")
        P = [values(os.path.join(r, name, "parameters.csv")) for r in (stored, relaxing, bounded)]
        S = [summary(os.path.join(r, name), lab_group, ("fitted", "lab", "d2d3")) for r in (stored, relaxing, bounded)]
        moving_n = [ends_summary(path_ends(os.path.join(work, w, name), Q))[1]
                    for w, Q in (("relaxing", P[1]), ("bounded", P[2]))]
        size = [largest_ratio(os.path.join(work, w, name)) for w in ("relaxing", "bounded")]
        n = len(glob.glob(os.path.join(out, "curves", "paths", "*.csv")))
        rows.append([name, *[q["chi2_per_dof"] for q in P], *[x["lab"] for x in S], *[x["d2d3"] for x in S],
                     *moving_n, size[0][0], size[1][0], size[0][1], size[1][1], n, math.exp(P[2]["ln_beta_p_a"]),
                     P[2]["a_A_a"], *beta_p_interval(os.path.join(bounded, name, "parameters.csv"))])
    return rows


def write_bounded(rows, out, bounded):
    """bounded.{csv,md} in OUT."""
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "bounded.csv"), BOUNDED_HEAD, rows)
    md = [f"<!-- demkit/model_excess.py --bounded {bounded}: each calibration refitted with --anisotropy-pressure "
          "bounded (the excess's source gated by 1 - (q/p)^2; data/geotech/model README step 12) against the permanent "
          "(step 8) and relaxing (step 11) laws; worst: largest RMS error over the 95 % band half-width; still moving: "
          "dem model's drift rule; q/p*: the largest excess over the pressure on the laboratory paths, and how many "
          "paths have q > p* (the elastic state below jamming);" + BETA_P_NOTE + " -->",
          "| calibration | χ²/dof permanent → relaxing → bounded | worst laboratory | worst D2/D3 | paths still moving, "
          "relaxing → bounded | largest q/p*, relaxing → bounded | paths with q > p* | β_p | a_A at ψ = 0 |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r[0]} | {cell(r[1], 4)} → {cell(r[2], 4)} → {cell(r[3], 4)} | {cell(r[4])} → {cell(r[5])} → "
                  f"{cell(r[6])} | {cell(r[7])} → {cell(r[8])} → {cell(r[9])} | {r[10]} → {r[11]} of {r[16]} | "
                  f"{cell(r[12])} → {cell(r[13])} | {r[14]} → {r[15]} | {beta_p_cell(r[17], r[19], r[20])} | {cell(r[18])} |")
    write_atomic(os.path.join(out, "bounded.md"), "\n".join(md) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stored", required=True, help="the step-8 calibrations (data/geotech/model/state_volume)")
    ap.add_argument("--relaxing", required=True, help="their restarts with --anisotropy-pressure relaxing (step 11)")
    ap.add_argument("--work", required=True, help="where the predictions go (model curves of every path)")
    ap.add_argument("--out", required=True, help="where comparison.{md,csv} go")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--table-only", action="store_true", help="the table from WORK's predictions")
    ap.add_argument("--make-starts", metavar="DIR", help="instead: write the extra starts of README step 11 to DIR")
    ap.add_argument("--excess-size", action="store_true",
                    help="also write excess_size.{md,csv}: the largest relaxing excess q/p* per calibration")
    ap.add_argument("--bounded", metavar="DIR", help="instead: the calibrations refitted with --anisotropy-pressure "
                    "bounded (README step 12) predicted into WORK/bounded and compared in OUT/bounded.{md,csv} with "
                    "WORK's relaxing and STORED's permanent ones")
    a = ap.parse_args(argv)
    if a.bounded:
        write_bounded(bounded_table(a.stored, a.relaxing, a.bounded, a.work, a.dem, not a.table_only), a.out, a.bounded)
        print(f"model_excess: {a.out}/bounded.md", file=sys.stderr)
        return
    if a.make_starts:
        make_starts(a.stored, a.make_starts)
        return
    for name in LAB:
        for root in (a.stored, a.relaxing):
            if not os.path.exists(os.path.join(root, name, "parameters.csv")):
                raise SystemExit(f"model_excess: {root}/{name}/parameters.csv is missing: run README step 8 and 11 "
                                 "of data/geotech/model first")
    if not a.table_only:
        missing = [e for e in ENSEMBLE.values() if not os.path.isdir(e)]
        if missing:
            raise SystemExit(f"model_excess: ensembles missing ({', '.join(sorted(set(missing)))}): make them with "
                             "README steps 1-8b of data/geotech/model")
        predict(a.stored, a.relaxing, a.work, a.dem)
    write(table(a.stored, a.relaxing, a.work), a.out, a.stored, a.relaxing)
    figure(a.work, a.out)
    if a.excess_size:
        write_size(excess_size(a.relaxing, a.work), a.out, a.relaxing)
    print(f"model_excess: {a.out}/comparison.md", file=sys.stderr)


if __name__ == "__main__":
    main()
