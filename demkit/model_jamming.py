"""One jamming fraction against two (issue 31, seventeenth round): `dem model --jamming shared` ties the coordination
law's jamming fraction nu_cC to the pressure law's nu_c, which removes the cusp of the isotropic stiffness
(docs/model.md, "One jamming fraction"). This runs the friction study's calibrations (`demkit.model_friction`, no
jackknife) and the N = 9261 group model (data/figure3_n9261) both ways and writes, per ensemble and family, the
calibration's chi2/dof (the isotropic branch weighted alike in both: by its scatter about the separate laws), the worst
fitted and predicted curve, the isotropic laws and their RMS misfit of the branch, and where the separate laws' cusp
sits.

    /usr/bin/python3 -m demkit.model_jamming --work WORK --out data/friction_n1000/model_friction/jamming
    /usr/bin/python3 -m demkit.model_jamming --work WORK --out OUT --table-only   # the table from WORK's runs
    /usr/bin/python3 -m demkit.model_jamming --lab data/geotech/model/state_volume SHARED --out OUT   # step 10
"""
import argparse
import csv
import glob
import json
import math
import os
import subprocess
import sys

from demkit.atomic import write_atomic

MUS = ("0", "0.01", "0.1", "0.3", "0.5", "1")
WAYS = ("separate", "shared")


def read_law(path):
    """The isotropic coefficients of a parameters.csv (name -> float)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    law = {}
    for r in rows:
        if r["parameter"] in ("p0", "nu_c", "gamma_p", "C0", "C1", "nu_cC", "alpha"):
            law[r["parameter"]] = float(r["value"])
    if len(law) != 7:
        raise SystemExit(f"model_jamming: {path} lacks isotropic coefficients (has {sorted(law)})")
    return law


def coordination(L, nu):
    """C(nu) = C0 + C1 (nu/nu_cC - 1)^alpha, C0 below nu_cC (demfit/model.hpp)."""
    base = nu / L["nu_cC"] - 1
    return L["C0"] + (L["C1"] * base ** L["alpha"] if base > 0 else 0.0)


def pressure(L, nu):
    """p*(nu) = p0 (nu C(nu)/nu_c) x (1 + gamma_p x), x = ln(nu/nu_c)."""
    x = math.log(nu / L["nu_c"])
    return L["p0"] * nu * coordination(L, nu) / L["nu_c"] * x * (1 + L["gamma_p"] * x)


def branch(ensemble):
    """The isotropic branch `dem model` reads: (nu, p*, C) of every member's cycle_unloading.csv with p* > 1e-7."""
    files = sorted(glob.glob(os.path.join(ensemble, "members", "*", "prep", "cycle_unloading.csv")) +
                   glob.glob(os.path.join(ensemble, "members", "*", "cycle_unloading.csv")))
    if not files:
        raise SystemExit(f"model_jamming: no members/*/[prep/]cycle_unloading.csv under {ensemble}")
    out = []
    for f in files:
        with open(f, newline="") as fh:
            for r in csv.DictReader(ln for ln in fh if not ln.startswith("#")):
                nu, p, c = float(r["nu"]), float(r["p_star"]), float(r["C_nonrattler"])
                if p > 1e-7 and c > 0 and math.isfinite(nu):
                    out.append((nu, p, c))
    return out


def branch_misfit(L, points):
    """RMS of p*_law/p* - 1 and of C_law - C over the branch points."""
    n = len(points)
    rp = math.sqrt(sum((pressure(L, nu) / p - 1) ** 2 for nu, p, _ in points) / n)
    rc = math.sqrt(sum((coordination(L, nu) - c) ** 2 for nu, _, c in points) / n)
    return rp, rc


def relaxed_points(path, mu):
    """(nu, p*) of the relaxed static packings of data/isostatic_n1000 at friction mu (E_kin/E_pot < 1e-9, p* > 1e-6):
    states the moving unloading branch does not hold, an independent check of the pressure law near jamming."""
    if not path or not os.path.exists(path):
        return []
    with open(path) as fh:
        runs = json.load(fh)["runs"]
    return [(q["nu"], q["p_star"]) for r in runs for q in r["points"]
            if abs(q["mu"] - mu) < 1e-9 and q["E_kin_over_E_pot"] < 1e-9 and q["p_star"] > 1e-6]


def relaxed_misfit(L, points):
    """RMS of p*_law/p* - 1 over the relaxed points above the law's nu_c, and how many those are (nan, 0 without)."""
    ok = [(nu, p) for nu, p in points if nu > L["nu_c"]]
    if not ok:
        return float("nan"), 0
    return math.sqrt(sum((pressure(L, nu) / p - 1) ** 2 for nu, p in ok) / len(ok)), len(ok)


def summary(model_dir, group=lambda r: "fitted" if r["role"] == "fitted" else "predicted",
            keys=("fitted", "predicted")):
    """chi2/dof and the worst band error per group of curves of a summary.csv (`group`: a row -> one of `keys`;
    default 'fitted' and 'predicted'); a group without a finite row is nan."""
    with open(os.path.join(model_dir, "summary.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = dict.fromkeys(keys, float("nan"))
    for r in rows:
        if r["mode"] == "calibration":
            out["chi2"] = float(r["role"].split()[-1])
            continue
        key, w = group(r), float(r["worst [band]"])
        if not math.isnan(w):
            out[key] = w if math.isnan(out[key]) else max(out[key], w)
    return out


def write_csv(path, head, rows):
    """A table as CSV (strings quoted, numbers to the last bit), written atomically."""
    lines = [",".join(head)] + [",".join(f'"{v}"' if isinstance(v, str) else repr(v) for v in r) for r in rows]
    write_atomic(path, "\n".join(lines) + "\n")


def run(cmd, log):
    print("model_jamming:", " ".join(cmd), file=sys.stderr)
    with open(log, "w") as fh:
        if subprocess.call(cmd, stderr=fh, stdout=fh) not in (0, 1):
            raise SystemExit(f"model_jamming: {' '.join(cmd)} failed (see {log})")


def compute(work, dem, figure3):
    """Both calibrations of every ensemble into WORK/{separate,shared}/ and WORK/figure3_{separate,shared}/."""
    os.makedirs(work, exist_ok=True)
    for way in WAYS:
        run([sys.executable, "-m", "demkit.model_friction", "--out", os.path.join(work, way), "--no-jackknife",
             "--jamming", way, "--dem", dem], os.path.join(work, f"friction_{way}.log"))
        run([dem, "model", figure3, "--out", os.path.join(work, f"figure3_{way}"), "--no-jackknife", "--jamming", way,
             "--force"], os.path.join(work, f"figure3_{way}.log"))


def cases(work, figure3):
    """(label, family, ensemble with members, {way: model dir}, mu)."""
    out = [("figure3_n9261 (N = 9261, μ = 0)", "group", figure3,
            {w: os.path.join(work, f"figure3_{w}") for w in WAYS}, 0.0)]
    for mu in MUS:
        ens = os.path.join(work, "separate", f"mu_{mu}")
        for fam, sub in (("group", ""), ("extended", "extended")):
            out.append((f"friction_n1000 μ = {mu}", fam, ens,
                        {w: os.path.join(work, w, f"mu_{mu}", "model", sub) for w in WAYS}, float(mu)))
    return out


HEAD = ["ensemble", "family", "chi2_dof_separate [-]", "chi2_dof_shared [-]", "chi2_change [%]",
        "worst_fitted_separate [band]", "worst_fitted_shared [band]", "worst_predicted_separate [band]",
        "worst_predicted_shared [band]", "nu_c_separate [-]", "nu_cC_separate [-]", "nu_c_shared [-]",
        "C0_separate [-]", "C0_shared [-]", "alpha_separate [-]", "alpha_shared [-]",
        "branch_rms_p_rel_separate [-]", "branch_rms_p_rel_shared [-]", "branch_rms_C_separate [-]",
        "branch_rms_C_shared [-]", "branch_lowest_nu [-]", "cusp_p_star_separate [-]",
        "relaxed_rms_p_rel_separate [-]", "relaxed_rms_p_rel_shared [-]", "relaxed_points_separate",
        "relaxed_points_shared"]


def row(label, fam, ens, dirs, mu=None, relaxed=None):
    s, t = (summary(dirs[w]) for w in WAYS)
    A, B = (read_law(os.path.join(dirs[w], "parameters.csv")) for w in WAYS)
    if B["nu_cC"] != B["nu_c"]:
        raise SystemExit(f"model_jamming: {dirs['shared']} has nu_cC != nu_c: not a --jamming shared run")
    pts = branch(ens)
    (pa, ca), (pb, cb) = branch_misfit(A, pts), branch_misfit(B, pts)
    cusp = pressure(A, A["nu_cC"]) if A["nu_cC"] > A["nu_c"] else float("nan")
    rel = relaxed_points(relaxed, mu) if mu is not None else []
    (ra, na), (rb, nb) = relaxed_misfit(A, rel), relaxed_misfit(B, rel)
    return [label, fam, s["chi2"], t["chi2"], 100 * (t["chi2"] / s["chi2"] - 1), s["fitted"], t["fitted"],
            s["predicted"], t["predicted"], A["nu_c"], A["nu_cC"], B["nu_c"], A["C0"], B["C0"], A["alpha"],
            B["alpha"], pa, pb, ca, cb, min(p[0] for p in pts), cusp, ra, rb, na, nb]


def cell(v, digits=4):
    if isinstance(v, str):
        return v
    return "none" if math.isnan(v) else f"{v:.{digits}g}"


def write(rows, out):
    write_csv(os.path.join(out, "jamming.csv"), HEAD, rows)
    md = ["<!-- demkit/model_jamming.py: dem model with two jamming fractions (nu_c, nu_cC; the default) and with one "
          "(--jamming shared), no jackknife; chi2/dof with the isotropic branch weighted alike (its scatter about the "
          "separate laws); worst: largest RMS error over the 95 % band half-width of a fitted / predicted curve; branch: "
          "RMS misfit of the isotropic branch, p* relative, C absolute; cusp: p*(nu_cC) of the separate laws, none where "
          "nu_cC <= nu_c; relaxed: RMS of p*_law/p* - 1 over the relaxed static packings of data/isostatic_n1000 at "
          "this mu above the law's nu_c (how many), none where there are none -->",
          "| ensemble | family | χ²/dof separate → shared | change | worst fitted | worst predicted | ν_c, ν_cC separate "
          "| ν_c shared | C0 | α | branch p* RMS (rel.) | branch C RMS | lowest branch ν | cusp p* (separate) "
          "| relaxed p* RMS (rel.; points) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r[0]} | {r[1]} | {cell(r[2])} → {cell(r[3])} | {r[4]:+.1f} % | {cell(r[5], 3)} → {cell(r[6], 3)} "
                  f"| {cell(r[7], 3)} → {cell(r[8], 3)} | {r[9]:.4f}, {r[10]:.4f} | {r[11]:.4f} "
                  f"| {r[12]:.3f} → {r[13]:.3f} | {r[14]:.3f} → {r[15]:.3f} | {r[16]:.4f} → {r[17]:.4f} "
                  f"| {r[18]:.4f} → {r[19]:.4f} | {r[20]:.4f} | {cell(r[21], 3)} "
                  f"| {relaxed_cell(r)} |")
    write_atomic(os.path.join(out, "jamming.md"), "\n".join(md) + "\n")


def relaxed_cell(r):
    if not r[24] and not r[25]:
        return "none"
    return f"{cell(r[22], 3)} ({r[24]}) → {cell(r[23], 3)} ({r[25]})"


LAB = ("loose", "dense", "mu_0/dense", "mu_0.1/dense", "mu_0.3/dense", "mu_1/dense", "three_pressures/joint",
       "three_pressures/dense", "three_pressures/mu_0/dense", "three_pressures/mu_0.1/joint",
       "three_pressures/mu_0.3/joint", "three_pressures/mu_1/joint")
LAB_HEAD = ["calibration", "chi2_dof_separate [-]", "chi2_dof_shared [-]", "worst_fitted_separate [band]",
            "worst_fitted_shared [band]", "worst_lab_predicted_separate [band]", "worst_lab_predicted_shared [band]",
            "worst_D2_D3_separate [band]", "worst_D2_D3_shared [band]", "nu_c_separate [-]", "nu_cC_separate [-]",
            "nu_c_shared [-]", "C0_separate [-]", "C0_shared [-]", "converged_shared"]


def lab_group(r):
    """The fitted curves, the predicted D2/D3 of the friction study, the predicted laboratory tests."""
    return "fitted" if r["role"] == "fitted" else "d2d3" if r["mode"] in ("D2", "D3") else "lab"


def lab_table(stored, shared, out):
    """Every step-8 calibration of data/geotech/model (README) against its restart with --jamming shared."""
    rows = []
    for name in LAB:
        a, b = os.path.join(stored, name), os.path.join(shared, name)
        s, t = (summary(d, lab_group, ("fitted", "lab", "d2d3")) for d in (a, b))
        A, B = read_law(os.path.join(a, "parameters.csv")), read_law(os.path.join(b, "parameters.csv"))
        with open(os.path.join(b, "parameters.csv"), newline="") as fh:
            conv = "no" if any(r["parameter"] == "converged" for r in csv.DictReader(fh)) else "yes"
        rows.append([name, s["chi2"], t["chi2"], s["fitted"], t["fitted"], s["lab"], t["lab"], s["d2d3"], t["d2d3"],
                     A["nu_c"], A["nu_cC"], B["nu_c"], A["C0"], B["C0"], conv])
    write_csv(os.path.join(out, "comparison.csv"), LAB_HEAD, rows)
    md = ["<!-- demkit/model_jamming.py --lab: every README step-8 calibration of data/geotech/model (separate: the "
          "stored one, nu_cC held) against its restart from the stored optimum with one jamming fraction "
          "(--jamming shared, gamma_p and alpha held, no jackknife); worst: largest RMS error over the 95 % band "
          "half-width of a fitted curve, a predicted laboratory curve, a predicted D2/D3 curve of the friction study -->",
          "| calibration | χ²/dof separate → shared | worst fitted | worst predicted, laboratory | worst predicted, D2/D3 "
          "| ν_c, ν_cC separate | ν_c shared | C0 | converged (shared) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r[0]} | {cell(r[1])} → {cell(r[2])} | {cell(r[3], 3)} → {cell(r[4], 3)} "
                  f"| {cell(r[5], 3)} → {cell(r[6], 3)} | {cell(r[7], 3)} → {cell(r[8], 3)} "
                  f"| {r[9]:.4f}, {r[10]:.4f} | {r[11]:.4f} | {r[12]:.3f} → {r[13]:.3f} | {r[14]} |")
    write_atomic(os.path.join(out, "comparison.md"), "\n".join(md) + "\n")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", help="working folder (the calibrations, regenerated unless --table-only)")
    ap.add_argument("--out", required=True, help="folder of jamming.{md,csv}")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--figure3", default="data/figure3_n9261", help="the N = 9261 ensemble")
    ap.add_argument("--relaxed", default="data/isostatic_n1000/isostatic.json",
                    help="relaxed static packings (demkit.isostatic's json): the pressure law checked on them")
    ap.add_argument("--table-only", action="store_true", help="only collect WORK's existing runs")
    ap.add_argument("--lab", nargs=2, metavar=("STORED", "SHARED"),
                    help="instead: the step-8 calibrations of data/geotech/model (STORED: state_volume) against their "
                         "--jamming shared restarts (SHARED, the same layout); OUT/comparison.{md,csv}")
    a = ap.parse_args(argv)
    if a.lab:
        rows = lab_table(a.lab[0], a.lab[1], a.out)
        print(f"model_jamming: {len(rows)} rows written to {a.out}/comparison.{{md,csv}}", file=sys.stderr)
        return
    if not a.work:
        ap.error("--work WORK is needed (or --lab STORED SHARED)")
    if not a.table_only:
        compute(a.work, a.dem, a.figure3)
    rows = [row(*c, relaxed=a.relaxed) for c in cases(a.work, a.figure3)]
    write(rows, a.out)
    for way in WAYS:   # the N = 9261 model paths (the isobaric kink at nu = 0.671 with separate fractions)
        png = os.path.join(a.work, f"figure3_{way}", "model_paths.png")
        if os.path.exists(png):
            with open(png, "rb") as fh:
                write_atomic(os.path.join(a.out, f"figure3_model_paths_{way}.png"), fh.read())
    print(f"model_jamming: {len(rows)} rows written to {a.out}/jamming.{{md,csv}}", file=sys.stderr)


if __name__ == "__main__":
    main()
