"""One calibration for the constant-volume and the laboratory tests (issue 31, thirty-first round): the volume-form state
parameter (`dem model --state-limit volume`) calibrated on the friction study's constant-volume D2 + D3 (K = 8,
nu = 0.69-0.80) and the dense preparation's drained triaxial compression TC_s3 at p* = 1e-3 and 1e-2 (K = 4, with its
isotropic states); every other curve predicted with the same parameters: the dense preparation's other laboratory
tests, the loose preparation's (another preparation, nu = 0.59-0.65), and the friction study's isobaric D2 paths.

    /usr/bin/python3 -m demkit.model_joint --mu 0.5 [--out DIR] [--work WORK] [--dem build/dem] [--no-jackknife]
    /usr/bin/python3 -m demkit.model_joint --table-only [--out DIR]      # DIR/joint.{md,csv} from DIR/mu_MU
    /usr/bin/python3 -m demkit.model_joint --jackknife 0.5 [--out DIR]  # DIR/mu_MU/jackknife_two_sample.{md,csv}
    /usr/bin/python3 -m demkit.model_joint --compare-jackknives 0.5     # DIR/mu_MU/jackknife_compare.{md,csv}
    /usr/bin/python3 -m demkit.model_joint --choose 0.5                 # DIR/variants_mu_MU/heldout_choice.{md,csv}

WORK/mu_MU/ensemble_all/   the laboratory curves of both preparations (demkit.geotech_model, --joint; mu = 0: dense
                           only), the friction study's D2/D3 means and its isobaric D2 paths, and in members/ both the
                           laboratory's packings (m1-m4) and the friction study's (m000-m007: D2/D3 curves and
                           isobaric paths, no isotropic branch; thirty-second round), so that `dem model`'s jackknife
                           leaves out each packing of either set from the means it holds; regenerated, not stored
DIR/mu_MU/                 `dem model`'s summary, prediction, parameters (and with the jackknife heldout, jackknife and
                           jackknife_estimates) tables
DIR/mu_MU/jackknife_two_sample.{md,csv}   (and each refit's parameters.csv in jackknife_refits/) the two-sample jackknife (`dem model`'s own needs every fitted curve from
                           the same packings): each of the friction study's 8 packings left out of the D2/D3 means and
                           each of the laboratory's 4 left out of its curves and isotropic states, one refit each from
                           the calibration's optimum; se^2 = (8-1)/8 sum over the first + (4-1)/4 sum over the second
DIR/joint.{md,csv}         per mu: chi2/dof and the worst curve of each group (fitted D2/D3, fitted TC_s3, predicted
                           dense and loose laboratory tests, predicted isobaric paths), with the count within 1 band

The start is the stored laboratory calibration with the volume-form state parameter of that mu
(data/geotech/model/state_volume: dense/ at mu = 0.5, mu_MU/dense/ otherwise); the isotropic law's gamma_p, nu_cC and
alpha are held at its values (the laboratory's isotropic states are two pressures).
"""
import argparse
import csv
import glob
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

from demkit import geotech_model, model_friction, path_ensemble
from demkit.atomic import write_atomic, write_md_csv

OUT = os.path.join("data", "geotech", "model", "joint")
STATE = os.path.join("data", "geotech", "model", "state_volume")
CALIBRATE = "D2,D3,TC_s3_dense"
KEEP = ("summary", "prediction", "parameters", "heldout", "jackknife", "jackknife_estimates")
# group: (label, which rows of summary.csv, fitted or predicted)
GROUPS = (("D2 + D3", lambda m: m in ("D2", "D3")),
          ("TC_s3 dense", lambda m: m == "TC_s3_dense"),
          ("dense laboratory", lambda m: m.endswith("_dense") and m != "TC_s3_dense"),
          ("loose laboratory", lambda m: m.endswith("_loose")),
          ("isobaric D2", lambda m: m == "isobaric"))


def start_of(mu):
    return os.path.join(STATE, "dense" if mu == "0.5" else f"mu_{mu}/dense", "parameters.csv")


def command(mu, ens, out, dem, jackknife=True):
    """The `dem model` line of MU's joint calibration."""
    return [dem, "model", ens, "--start", start_of(mu), "--calibrate-on", CALIBRATE, "--family", "extended",
            "--state-limit", "volume", "--hold-isotropic", "gamma_p,nu_cC,alpha", "--max-iterations", "1000",
            "--no-plots", "--out", out, "--force"] + ([] if jackknife else ["--no-jackknife"])


def ensemble(mu, work, curves=os.path.join("data", "geotech", "curves"), friction=os.path.join("data", "friction_n1000")):
    """WORK/mu_MU/ensemble_all: both preparations' laboratory paths, the D2/D3 means, the isobaric D2 path ensembles."""
    root = os.path.join(work, f"mu_{mu}")
    made = geotech_model.convert(curves, mu, root, geotech_model.TESTS, force=True,
                                 friction=os.path.join(friction, f"mu_{mu}"))
    two = sorted({m[0] for m in made}) == ["dense", "loose"]
    if two:
        geotech_model.write_joint(root, made)
    src = os.path.join(root, "ensemble_joint" if two else "ensemble_dense")
    ens = os.path.join(root, "ensemble_all")
    if os.path.exists(ens):
        shutil.rmtree(ens)
    shutil.copytree(src, ens)
    with tempfile.TemporaryDirectory() as tmp:   # the ensemble files only, not the friction study's members
        model_friction.isobaric_paths(os.path.join(friction, f"mu_{mu}"), tmp)
        files = sorted(glob.glob(os.path.join(tmp, "paths", "isobaric_phi*.csv")))
        if not files:
            raise SystemExit(f"model_joint: {friction}/mu_{mu} has no isobaric D2 curves")
        for f in files:
            shutil.copy2(f, os.path.join(ens, "paths", os.path.basename(f)))
        add_friction_members(os.path.join(friction, f"mu_{mu}"), tmp, ens)
    return ens


def add_friction_members(friction_mu, isobaric, ens):
    """ENS/members/mNNN/: each friction-study packing's D2/D3 curves (deviatoric/) and its isobaric D2 paths (paths/,
    from ISOBARIC, model_friction.isobaric_paths' folder), without its isotropic branch (the laboratory's states are the
    calibration's): `dem model`'s jackknife then leaves out each packing of either set from the means it holds."""
    for m in sorted(glob.glob(os.path.join(friction_mu, "members", "m*"))):
        name = os.path.basename(m)
        if os.path.exists(os.path.join(ens, "members", name)):
            raise SystemExit(f"model_joint: {ens}/members/{name} exists already: the laboratory's and the friction "
                             "study's packings must have different names")
        dev = os.path.join(ens, "members", name, "deviatoric")
        os.makedirs(dev)
        for f in sorted(glob.glob(os.path.join(m, "deviatoric", "D[23]_phi*.csv"))):
            shutil.copy2(f, dev)
        own = sorted(glob.glob(os.path.join(isobaric, "members", name, "paths", "isobaric_phi*.csv")))
        if own:
            os.makedirs(os.path.join(ens, "members", name, "paths"))
            for f in own:
                shutil.copy2(f, os.path.join(ens, "members", name, "paths"))


def calibrate(mu, work, out, dem, jackknife=True):
    """MU's joint calibration into WORK/runs/mu_MU; its tables (KEEP, csv and md) copied into OUT/mu_MU. A fit that
    does not converge still writes its tables (`dem model` exits 1; parameters' row `converged` says so)."""
    ens = ensemble(mu, work)
    run = os.path.join(work, "runs", f"mu_{mu}")
    r = subprocess.run(command(mu, ens, run, dem, jackknife), capture_output=True, text=True)
    if r.returncode not in (0, 1) or not os.path.exists(os.path.join(run, "summary.csv")):
        raise SystemExit(f"model_joint: dem model failed on mu = {mu} (exit {r.returncode}):\n{r.stderr[-2000:]}")
    dest = os.path.join(out, f"mu_{mu}")
    if os.path.exists(dest):
        shutil.rmtree(dest)
    os.makedirs(dest)
    for stem in KEEP:
        for ext in ("csv", "md"):
            f = os.path.join(run, f"{stem}.{ext}")
            if os.path.exists(f):
                shutil.copy2(f, os.path.join(dest, f"{stem}.{ext}"))
    return r.returncode


def read(summary_csv):
    """(chi2/dof, [(mode, nu, role, worst, worst quantity)]) of a summary.csv."""
    with open(summary_csv, newline="") as fh:
        rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    chi, out = float("nan"), []
    for r in rows:
        if r["mode"] == "calibration":
            chi = float(r["role"].split()[-1])
            continue
        errs = {q: float(r[f"{q} [band]"]) for q in ("p_star", "eps_v", "s_dev", "F_dev") if r[f"{q} [band]"]}
        errs = {q: v for q, v in errs.items() if v == v}
        q = max(errs, key=errs.get) if errs else "nan"
        out.append((r["mode"], r["nu [-]"], r["role"], errs.get(q, float("nan")), q))
    return chi, out


def converged(parameters_csv):
    """'no' where parameters.csv has the row `converged` (a fit that stopped short), 'settled' where it stopped at the
    iteration limit with chi2 settled, else 'yes'."""
    with open(parameters_csv, newline="") as fh:
        names = {r["parameter"] for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}
    return "no" if "converged" in names else "settled" if "settled" in names else "yes"


def groups(rows):
    """{label: (curves, within 1 band, worst, 'mode nu quantity', not integrable)} over the GROUPS; the worst over the
    curves that integrated (inf where a path was lost), nan where none did."""
    out = {}
    for label, member in GROUPS:
        sel = [r for r in rows if member(r[0])]
        if not sel:
            continue
        ran = [r for r in sel if r[3] == r[3]]
        top = max(ran, key=lambda r: r[3]) if ran else None
        out[label] = (len(sel), sum(r[3] <= 1.0 for r in ran), top[3] if top else float("nan"),
                      f"{top[0]} {float(top[1]):.3f} {top[4]}" if top else "", len(sel) - len(ran))
    return out


def cell(g):
    """'within/curves, worst (curve)', and the curves not integrable where there are any."""
    n, ok, worst, curve, bad = g
    return f"{ok}/{n}, {worst:.3g} ({curve})" + (f", {bad} not integrable" if bad else "")


def table(entries, first, out, stem, comment):
    """OUT/STEM.{md,csv}: one row per (name, folder) of ENTRIES from its summary.csv and parameters.csv."""
    labels = [g[0] for g in GROUPS]
    md = [f"<!-- demkit/model_joint.py: {comment}. Per group: the curves within 1 band of all, and the worst RMS of model "
          "- DEM mean over the mean 95 % band half-width (p*, eps_v, s_dev, F_dev) -->",
          f"| {first} | χ²/dof | converged | " + " | ".join(labels) + " |", "|---|---|---|" + "---|" * len(labels)]
    head = [first.replace("μ", "mu"), "chi2_per_dof [-]", "converged"]
    for g in labels:
        key = g.replace(" + ", "_").replace(" ", "_")
        head += [f"{key}_curves", f"{key}_within_1_band", f"{key}_worst [band]", f"{key}_worst_curve"]
    lines = [",".join(head) + "\n"]
    for name, folder in entries:
        chi, rows = read(os.path.join(folder, "summary.csv"))
        conv = converged(os.path.join(folder, "parameters.csv"))
        g = groups(rows)
        md.append(f"| {name} | {chi:.4g} | {conv} | " + " | ".join(cell(g[k]) if k in g else "" for k in labels) + " |")
        vals = []
        for k in labels:
            vals += [str(g[k][0]), str(g[k][1]), f"{g[k][2]:.4g}", g[k][3]] if k in g else ["0", "0", "nan", ""]
        lines.append(",".join([name, f"{chi:.4g}", conv, *vals]) + "\n")
    write_md_csv(out, stem, md, lines)


def write(out):
    """OUT/joint.{md,csv} over OUT/mu_MU, and OUT/variants_mu_MU/variants.{md,csv} over each one's runs."""
    if not os.path.isdir(out):
        raise SystemExit(f"model_joint: {out} is not a folder: run with --mu first (or give --out the stored folder)")
    mus = sorted((d[len("mu_"):] for d in os.listdir(out) if d.startswith("mu_")), key=float)
    if not mus:
        raise SystemExit(f"model_joint: no {out}/mu_MU: run with --mu first")
    table([(mu, os.path.join(out, f"mu_{mu}")) for mu in mus], "μ", out, "joint",
          "the volume-form state parameter calibrated on D2 + D3 (friction study, K = 8) and the dense TC_s3 at p* = "
          "1e-3, 1e-2 (K = 4); the rest predicted")
    for d in sorted(d for d in os.listdir(out) if d.startswith("variants_mu_")):
        folder = os.path.join(out, d)
        names = sorted(n for n in os.listdir(folder) if os.path.isfile(os.path.join(folder, n, "summary.csv")))
        table([(n, os.path.join(folder, n)) for n in names], "variant", folder, "variants",
              f"mu = {d[len('variants_mu_'):]}: the joint calibration with one option changed (README), no jackknife")


ENS_Q = ("nu", "p_star", "s_dev", "F_dev")


def read_columns(path):
    """(comment lines, {column: array}) of a csv with # comments (path_ensemble's reader)."""
    comments, cols = path_ensemble.read_csv(path)
    return comments, {k: path_ensemble.fnum(v) for k, v in cols.items()}


def friction_means(friction_mu, kept, dest, note):
    """DEST/ensemble/D[23]_phiX.csv: the friction study's ensemble means over the member folders KEPT (each member
    resampled linearly on the ensemble's eps_d grid, as `dem ensemble` does: with every member the stored means come
    back to their printed digits), in the columns geotech_model.copy_friction keeps; NOTE the comment line."""
    from scipy import stats
    K, t = len(kept), stats.t.ppf(0.975, len(kept) - 1)
    for f in sorted(glob.glob(os.path.join(friction_mu, "ensemble", "D[23]_phi*.csv"))):
        name = os.path.basename(f)
        _, e = read_columns(f)
        head, cols = ["eps_d", "n_packings"], [e["eps_d"], np.full(len(e["eps_d"]), float(K))]
        for q in ENS_Q:
            x = []
            for m in kept:
                _, c = read_columns(os.path.join(m, "deviatoric", name))
                x.append(np.interp(e["eps_d"], c["eps_d"], c[q]))
            x = np.array(x)
            mean, sd = x.mean(axis=0), x.std(axis=0, ddof=1)
            se = sd / np.sqrt(K)
            head += [f"{q}_{k}" for k in ("mean", "sd", "se", "lo95", "hi95")]
            cols += [mean, sd, se, mean - t * se, mean + t * se]
        body = [",".join(head) + "\n"] + [",".join(repr(float(c[i])) for c in cols) + "\n" for i in range(len(cols[0]))]
        write_atomic(os.path.join(dest, "ensemble", name), f"# model_joint: {note}\n" + "".join(body))


def friction_means_without(friction_mu, left, dest):
    """friction_means without the member LEFT."""
    members = sorted(glob.glob(os.path.join(friction_mu, "members", "m*")))
    kept = [m for m in members if os.path.basename(m) != left]
    if len(kept) != len(members) - 1:
        raise SystemExit(f"model_joint: {friction_mu} has no member {left}")
    friction_means(friction_mu, kept, dest, f"{friction_mu}'s D2/D3 means without {left} ({len(kept)} packings)")


def loo_ensembles(mu, work, curves=os.path.join("data", "geotech", "curves"),
                  friction=os.path.join("data", "friction_n1000")):
    """{('friction' | 'laboratory', member): ensemble folder} for the two-sample jackknife (dense laboratory paths)."""
    out, fmu = {}, os.path.join(friction, f"mu_{mu}")
    base = os.path.join(work, f"mu_{mu}", "ensemble_dense")
    if not os.path.isdir(base):
        ensemble(mu, work, curves, friction)
    for m in sorted(os.listdir(os.path.join(fmu, "members"))):
        dest = os.path.join(work, "loo", f"friction_{m}")
        if os.path.exists(dest):
            shutil.rmtree(dest)
        shutil.copytree(base, dest)
        friction_means_without(fmu, m, dest)
        out[("friction", m)] = dest
    lab = os.path.join(curves, f"mu_{mu}", "dense")
    seeds = sorted(os.path.splitext(os.path.basename(f))[0]
                   for f in glob.glob(os.path.join(lab, geotech_model.LEVELS[0], "TC_s3", "m*.csv")))
    for m in seeds:
        tmp = os.path.join(work, "loo", f"curves_{m}")
        if os.path.exists(tmp):
            shutil.rmtree(tmp)
        for level in geotech_model.LEVELS:   # the calibration's curves only: TC_s3 at both pressures, without m
            src = os.path.join(lab, level, "TC_s3")
            dst = os.path.join(tmp, f"mu_{mu}", "dense", level, "TC_s3")
            os.makedirs(dst)
            for f in sorted(glob.glob(os.path.join(src, "m*.csv"))):
                if os.path.basename(f) != f"{m}.csv":
                    shutil.copy2(f, dst)
        root = os.path.join(work, "loo", f"laboratory_{m}")
        geotech_model.convert(tmp, mu, root, ("TC_s3",), force=True, friction=fmu)
        out[("laboratory", m)] = os.path.join(root, "ensemble_dense")
    return out


def free_values(parameters_csv):
    """{parameter: its row} of a parameters.csv (every row; jackknife_rows keeps those with a covariance error)."""
    with open(parameters_csv, newline="") as fh:
        return {r["parameter"]: r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}


def two_sample_jackknife(mu, out, work, dem, jobs=2):
    """Refit MU's joint calibration once per left-out packing (from its optimum), then OUT/mu_MU/
    jackknife_two_sample.{md,csv}: per coefficient the value, the covariance error and the jackknife's, each sample's
    part, and the refits' count."""
    from concurrent.futures import ThreadPoolExecutor
    full = os.path.join(out, f"mu_{mu}", "parameters.csv")
    ens = loo_ensembles(mu, work)
    runs = {}

    def refit(key):
        run = os.path.join(work, "loo", "runs", f"{key[0]}_{key[1]}")
        cmd = [dem, "model", ens[key], "--start", full, "--calibrate-on", CALIBRATE, "--family", "extended",
               "--state-limit", "volume", "--hold-isotropic", "gamma_p,nu_cC,alpha", "--max-iterations", "1000",
               "--no-jackknife", "--no-plots", "--out", run, "--force"]
        r = subprocess.run(cmd, capture_output=True, text=True)
        return key, run, r.returncode
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        for key, run, rc in pool.map(refit, sorted(ens)):
            if rc not in (0, 1) or not os.path.exists(os.path.join(run, "parameters.csv")):
                raise SystemExit(f"model_joint: the refit without {key[0]} packing {key[1]} failed (exit {rc})")
            keep = os.path.join(out, f"mu_{mu}", "jackknife_refits", f"{key[0]}_{key[1]}")
            os.makedirs(keep, exist_ok=True)
            shutil.copy2(os.path.join(run, "parameters.csv"), keep)
            runs[key] = keep
            print(f"model_joint: refit without {key[0]} {key[1]}: exit {rc}", file=sys.stderr)
    write_jackknife(mu, out, full, runs)


def jackknife_rows(full, refits):
    """[(name, value, se_covariance, se_friction, se_laboratory, se_jackknife)] over the coefficients with a quoted
    covariance error; REFITS {('friction'|'laboratory', member): parameters.csv}."""
    base = free_values(full)
    vals = {k: free_values(p) for k, p in refits.items()}
    rows = []
    for name, r in base.items():
        try:
            se_cov = float(r["se_covariance"])
            value = float(r["value"])
        except (KeyError, ValueError):
            continue
        if not se_cov == se_cov or r.get("se_method", "") == "fixed":
            continue
        parts = {}
        for sample in ("friction", "laboratory"):
            x = np.array([float(v[name]["value"]) for (s, _), v in vals.items() if s == sample])
            n = len(x)
            parts[sample] = float(np.sqrt((n - 1) / n * np.sum((x - x.mean()) ** 2))) if n > 1 else float("nan")
        rows.append((name, value, se_cov, parts["friction"], parts["laboratory"],
                     float(np.hypot(parts["friction"], parts["laboratory"]))))
    return rows


def write_jackknife(mu, out, full, runs):
    """OUT/mu_MU/jackknife_two_sample.{md,csv} from RUNS {(sample, member): folder of the refit's parameters.csv}."""
    rows = jackknife_rows(full, {k: os.path.join(run, "parameters.csv") for k, run in runs.items()})
    n_f = sum(1 for k in runs if k[0] == "friction")
    n_l = sum(1 for k in runs if k[0] == "laboratory")
    stopped = sorted(f"{k[0]} {k[1]}" for k, run in runs.items()
                     if converged(os.path.join(run, "parameters.csv")) == "no")
    md = [f"<!-- demkit/model_joint.py: mu = {mu}, the two-sample jackknife of the joint calibration: {n_f} refits without "
          f"one friction-study packing (D2/D3 means of the rest), {n_l} without one laboratory packing (its TC_s3 and "
          "isotropic states), each from the calibration's optimum; se_jackknife^2 = se_friction^2 + se_laboratory^2, "
          "each ((n-1)/n) sum (x_i - mean)^2; refits that stopped at their iteration limit: "
          f"{', '.join(stopped) if stopped else 'none'} -->",
          "| coefficient | value | se (covariance) | se (friction packings) | se (laboratory packings) | se (jackknife) |",
          "|---|---|---|---|---|---|"]
    lines = ["coefficient,value,se_covariance,se_friction,se_laboratory,se_jackknife\n"]
    for name, v, c, f, l, j in rows:
        md.append(f"| {name} | {v:.6g} | {c:.3g} | {f:.3g} | {l:.3g} | {j:.3g} |")
        lines.append(f"{name},{v!r},{c!r},{f!r},{l!r},{j!r}\n")
    write_md_csv(os.path.join(out, f"mu_{mu}"), "jackknife_two_sample", md, lines, show=False)


SPREAD = ("_sd", "_se", "_lo95", "_hi95")


def keep_weights(loo, full):
    """The ensemble files of LOO (ensemble/*.csv, paths/*.csv: means without one packing) given the spread columns
    (X_sd, X_se, X_lo95, X_hi95) and n_packings of the same file under FULL, so that a refit on LOO weights its points
    as `dem model`'s jackknife does (the full ensemble's weights); the means stay LOO's. Rows must match."""
    def mode_nu(path):   # MODE_phiX.csv -> (MODE, X)
        stem = os.path.basename(path)[:-len(".csv")]
        mode, _, nu = stem.rpartition("_phi")
        return mode, float(nu) if mode else float("nan")
    for sub in ("ensemble", "paths"):
        bases = [mode_nu(g) + (g,) for g in glob.glob(os.path.join(full, sub, "*_phi*.csv"))]
        for f in sorted(glob.glob(os.path.join(loo, sub, "*_phi*.csv"))):
            mode, nu = mode_nu(f)   # its tag moves with the mean start state: the same mode's nearest nu
            near = sorted((abs(b[1] - nu), b[2]) for b in bases if b[0] == mode)
            if not near or near[0][0] > 0.005:
                continue
            g = near[0][1]
            comments, cols = path_ensemble.read_csv(f)
            _, base = path_ensemble.read_csv(g)
            n = len(next(iter(cols.values())))
            for name in cols:
                if name == "n_packings" or name.endswith(SPREAD):
                    if len(base.get(name, [])) != n:
                        raise SystemExit(f"model_joint: {f} and {g} differ in rows or columns ({name})")
                    cols[name] = base[name]
            head = list(cols)
            body = [",".join(head) + "\n"] + [",".join(cols[h][i] for h in head) + "\n" for i in range(n)]
            write_atomic(f, "".join(comments) + "".join(body))


def crosscheck(mu, out, work, dem, keys=(("friction", "m003"), ("laboratory", "m2"))):
    """OUT/mu_MU/jackknife_crosscheck.{md,csv}: for each (set, packing) of KEYS, the refit on this module's ensembles
    without it (rebuilt from the members; loo_ensembles) with the full ensemble's weights (keep_weights), against
    `dem model`'s own refit without it (mu_MU/jackknife_estimates.csv): the largest difference over the coefficients in
    units of the jackknife error. Agreement tests `dem model`'s leave-one-out means of both sets, the paths' start
    states included, against an independent construction."""
    d = os.path.join(out, f"mu_{mu}")
    with open(os.path.join(d, "jackknife_estimates.csv"), newline="") as fh:
        est = {r["packing_left_out"]: r for r in csv.DictReader(fh)}
    full = free_values(os.path.join(d, "parameters.csv"))
    ens = loo_ensembles(mu, work)
    base = os.path.join(work, f"mu_{mu}", "ensemble_dense")
    md = [f"<!-- demkit/model_joint.py: mu = {mu}, `dem model`'s jackknife refits against refits on ensembles rebuilt "
          "without the packing (its set's means recomputed from the members, the full ensembles' weights kept), both "
          "from the calibration's optimum; largest difference over the coefficients with a jackknife error, in those "
          "errors, and the refits' chi2/dof -->",
          "| packing left out | set | largest difference [se_jackknife] | coefficient | chi2/dof (dem model) | "
          "chi2/dof (rebuilt) |", "|---|---|---|---|---|---|"]
    lines = ["packing_left_out,set,largest_difference [se],coefficient,chi2_per_dof_dem,chi2_per_dof_rebuilt\n"]
    jk = {}
    with open(os.path.join(d, "jackknife.csv"), newline="") as fh:
        for r in csv.DictReader(ln for ln in fh if not ln.startswith("#")):
            jk[r["packing_left_out"]] = r
    for sample, m in keys:
        loo = ens[(sample, m)]
        keep_weights(loo, base)
        run = os.path.join(work, "crosscheck", f"{sample}_{m}")
        cmd = [dem, "model", loo, "--start", os.path.join(d, "parameters.csv"), "--calibrate-on", CALIBRATE,
               "--family", "extended", "--state-limit", "volume", "--hold-isotropic", "gamma_p,nu_cC,alpha",
               "--max-iterations", "1000", "--no-jackknife", "--no-plots", "--out", run, "--force"]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode not in (0, 1):
            raise SystemExit(f"model_joint: the rebuilt refit without {sample} {m} failed:\n{r.stderr[-2000:]}")
        again = free_values(os.path.join(run, "parameters.csv"))
        worst, which = 0.0, ""
        for name, row in full.items():
            try:
                se = float(row["se_jackknife"])
                diff = abs(float(again[name]["value"]) - float(est[m][name])) / se
            except (KeyError, ValueError, ZeroDivisionError):
                continue
            if se > 0 and diff > worst:
                worst, which = diff, name
        chi_r = float(again["chi2_per_dof"]["value"])
        md.append(f"| {m} | {sample} | {worst:.3g} | {which} | {float(jk[m]['chi2_per_dof [-]']):.6g} | {chi_r:.6g} |")
        lines.append(f"{m},{sample},{worst!r},{which},{jk[m]['chi2_per_dof [-]']},{chi_r!r}\n")
    write_md_csv(d, "jackknife_crosscheck", md, lines, show=False)


def compare_jackknives(mu, out):
    """OUT/mu_MU/jackknife_compare.{md,csv}: per coefficient the covariance error, `dem model`'s jackknife over the two
    sets of packings (parameters.csv's se_jackknife: each packing left out of the means it holds, the weights kept) and
    this module's two-sample jackknife (jackknife_two_sample.csv: the ensembles rebuilt without the packing, their
    standard errors, and so the weights, recomputed), and their ratio."""
    d = os.path.join(out, f"mu_{mu}")
    full = free_values(os.path.join(d, "parameters.csv"))
    with open(os.path.join(d, "jackknife_two_sample.csv"), newline="") as fh:
        two = {r["coefficient"]: r for r in csv.DictReader(fh)}
    md = [f"<!-- demkit/model_joint.py: mu = {mu}, the joint calibration's errors three ways: the covariance (x max(1, "
          "chi2/dof)); `dem model`'s jackknife over its two sets of packings (each left out of the means it holds, the "
          "weights of the full ensembles kept; parameters.csv); the two-sample jackknife of `--jackknife` (each "
          "refit on ensembles rebuilt without the packing, their standard errors recomputed; jackknife_two_sample.csv) "
          "-->", "| coefficient | value | se (covariance) | se (dem model, weights kept) | se (two-sample, weights "
          "recomputed) | ratio |", "|---|---|---|---|---|---|"]
    lines = ["coefficient,value,se_covariance,se_jackknife_dem,se_jackknife_two_sample,ratio [-]\n"]
    for name, r in two.items():
        dem = float(full[name]["se_jackknife"]) if name in full else float("nan")
        t = float(r["se_jackknife"])
        ratio = t / dem if dem > 0 else float("nan")
        md.append(f"| {name} | {float(r['value']):.6g} | {float(r['se_covariance']):.3g} | {dem:.3g} | {t:.3g} | "
                  f"{ratio:.3g} |")
        lines.append(f"{name},{float(r['value'])!r},{float(r['se_covariance'])!r},{dem!r},{t!r},{ratio!r}\n")
    write_md_csv(d, "jackknife_compare", md, lines, show=False)


def csv_line(fields):
    """FIELDS as one csv line (the csv module's quoting: a field with a comma or a quote is quoted)."""
    import io
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(fields)
    return buf.getvalue()


def compare_errors(before, after, out, stem, comment):
    """OUT/STEM.{md,csv}: per coefficient with a quoted error in either parameters.csv (BEFORE, AFTER) the values, the
    quoted errors (se, with their method) and after/before; COMMENT heads the markdown."""
    a, b = free_values(before), free_values(after)
    md = [f"<!-- demkit/model_joint.py: {comment} -->",
          "| coefficient | value (before) | se (before) | value (after) | se (after) | se after/before |",
          "|---|---|---|---|---|---|"]
    lines = ["coefficient,value_before,se_before,se_method_before,value_after,se_after,se_method_after,ratio [-]\n"]
    for name, r in a.items():
        if name not in b:
            continue
        try:
            sa, sb = float(r["se"]), float(b[name]["se"])
            va, vb = float(r["value"]), float(b[name]["value"])
        except (KeyError, ValueError):
            continue
        if not (sa == sa or sb == sb) or r.get("se_method", "") == "fixed":
            continue
        ratio = sb / sa if sa > 0 else float("nan")
        md.append(f"| {name} | {va:.6g} | {sa:.3g} | {vb:.6g} | {sb:.3g} | {ratio:.3g} |")
        lines.append(csv_line([name, repr(va), repr(sa), r["se_method"], repr(vb), repr(sb), b[name]["se_method"],
                               repr(ratio)]))
    write_md_csv(out, stem, md, lines, show=False)


HELDOUT_VARIANTS = ("weighted", "bounded")   # the variants fitted on the joint calibration's curves (with_isobaric is not)


def coefficients(parameters_csv):
    """The model's coefficients in a parameters.csv: its rows but the fixed ones (nu_ref, psi_min, psi_max, the
    anisotropy excess rule) and the fit's summary rows."""
    return sum(1 for n, r in free_values(parameters_csv).items()
               if r.get("se_method", "") != "fixed" and n not in ("chi2_per_dof", "converged"))


def heldout_sets(heldout_csv):
    """{packing: (set, score)} of a `dem model` heldout.csv with its sets of packings (thirty-second round)."""
    with open(heldout_csv, newline="") as fh:
        rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    return {r["packing"]: (int(r["set"]), float(r["heldout_extended [-]"])) for r in rows}


def heldout_choice(mu, out):
    """OUT/variants_mu_MU/heldout_choice.{md,csv}: the held-out test among the joint calibration (OUT/mu_MU) and the
    variants fitted on the same curves (HELDOUT_VARIANTS under OUT/variants_mu_MU, each with `dem model`'s jackknife
    over both sets of packings), paired over the 12 left-out packings: model_variants.choose (the variant with the
    fewest coefficients that no other beats)."""
    from demkit import model_variants
    runs = {"overlap": os.path.join(out, f"mu_{mu}")}
    runs.update({v: os.path.join(out, f"variants_mu_{mu}", v) for v in HELDOUT_VARIANTS})
    missing = [d for d in runs.values() if not os.path.exists(os.path.join(d, "heldout.csv"))]
    if missing:
        raise SystemExit(f"model_joint: no heldout.csv in {', '.join(missing)}: run the variants with the jackknife "
                         "(data/geotech/model/joint/README.md)")
    failed = {v: refits_failed(os.path.join(d, "jackknife.csv")) for v, d in runs.items()}
    runs = {v: d for v, d in runs.items() if not failed[v]}   # a failed refit's score is its start's: not held out
    every = {v: heldout_sets(os.path.join(d, "heldout.csv")) for v, d in runs.items()}
    # a packing whose held-out prediction is not a number (thirty-third round: its own start pressure above the
    # refit's isotropic reach) is one the variant cannot predict: the variant is not compared, and says which
    unpredicted = {v: [p for p, (_, sc) in sorted(s.items()) if not np.isfinite(sc)] for v, s in every.items()}
    sets = {v: s for v, s in every.items() if not unpredicted[v]}
    names = sorted(set.intersection(*(set(s) for s in sets.values())))
    index = {p: i for i, p in enumerate(names)}
    scores = {v: {index[p]: s[p][1] for p in names} for v, s in sets.items()}
    sizes = {v: coefficients(os.path.join(d, "parameters.csv")) for v, d in runs.items()}
    chosen, beaten, means = model_variants.choose(scores, {v: sizes[v] for v in scores})
    md = [f"<!-- demkit/model_joint.py: mu = {mu}, the held-out test among the joint calibration's variants fitted on "
          "D2 + D3 and TC_s3 dense: each packing's own fitted curves (D2/D3 of a friction-study packing, TC_s3 of a "
          "laboratory packing) predicted by the refit without it (`dem model`'s jackknife over both sets, heldout.csv); "
          "b beats a when a - b, paired over the packings, exceeds t_{K-1,0.975} SE; chosen: the fewest coefficients "
          "that nothing beats (model_variants.choose) -->",
          "| variant | coefficients | χ²/dof | mean held-out score (all) | friction packings | laboratory packings | "
          "overlap − variant, mean ± SE (t SE) | beaten by | chosen |", "|---|---|---|---|---|---|---|---|---|"]
    lines = ["variant,coefficients,chi2_per_dof [-],heldout_mean [-],heldout_friction_mean [-],"
             "heldout_laboratory_mean [-],versus_overlap_mean [-],versus_overlap_se [-],versus_overlap_t_se [-],"
             "packings,beaten_by,chosen\n"]
    from demkit import model_state_limit
    for v in runs:
        chi = float(free_values(os.path.join(runs[v], "parameters.csv"))["chi2_per_dof"]["value"])
        part = {k: [sc for p, (st, sc) in every[v].items() if st == k and np.isfinite(sc)] for k in (0, 1)}
        f, lab = (sum(x) / len(x) if x else float("nan") for x in (part[0], part[1]))
        if unpredicted[v]:
            k = len(every[v]) - len(unpredicted[v])
            md.append(f"| {v} | {sizes[v]} | {chi:.4g} | not compared: the held-out predictions of "
                      f"{', '.join(unpredicted[v])} are not numbers | {f:.4g} (the {len(part[0])} predicted) | "
                      f"{lab:.4g} (the {len(part[1])} predicted) | – | – |  |")
            lines.append(f"{v},{sizes[v]},{chi!r},nan,{f!r},{lab!r},nan,nan,nan,{k},,"
                         f"not predicting {' '.join(unpredicted[v])}\n")
            continue
        dm, dse, tq, _, _ = (model_state_limit.paired_choice(scores["overlap"], scores[v]) if v != "overlap" and
                             "overlap" in scores else (float("nan"),) * 3 + (0, False))
        versus = f"{dm:.3g} ± {dse:.2g} ({tq * dse:.2g})" if dm == dm else "–"
        md.append(f"| {v} | {sizes[v]} | {chi:.4g} | {means[v]:.4g} | {f:.4g} | {lab:.4g} | {versus} | "
                  f"{', '.join(beaten[v]) or '–'} | {'yes' if v == chosen else ''} |")
        lines.append(f"{v},{sizes[v]},{chi!r},{means[v]!r},{f!r},{lab!r},{dm!r},{dse!r},{tq * dse!r},{len(names)},"
                     f"{' '.join(beaten[v])},{'yes' if v == chosen else 'no'}\n")
    for v, bad in failed.items():
        if bad:
            md.append(f"| {v} | | | not scored: its refits without {', '.join(bad)} failed | | | | | |")
            lines.append(f"{v},nan,nan,nan,nan,nan,nan,nan,nan,0,,not scored\n")
    write_md_csv(os.path.join(out, f"variants_mu_{mu}"), "heldout_choice", md, lines, show=False)
    return chosen


def refits_failed(jackknife_csv):
    """The packings whose jackknife refit is not usable (`dem model`'s jackknife.csv): their held-out scores are those
    of a fit that saw them."""
    with open(jackknife_csv, newline="") as fh:
        return [r["packing_left_out"] for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))
                if r["usable"] != "yes"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mu", nargs="+", default=[], help="friction coefficients to calibrate (0, 0.1, 0.3, 0.5, 1)")
    ap.add_argument("--out", default=OUT, help=f"where the tables go (default {OUT})")
    ap.add_argument("--work", default=os.path.join("runs", "model_joint"), help="working folder")
    ap.add_argument("--dem", default=os.path.join("build", "dem"), help="the dem binary")
    ap.add_argument("--no-jackknife", action="store_true", help="errors from the covariance only (faster)")
    ap.add_argument("--table-only", action="store_true", help="only rebuild OUT/joint from OUT/mu_MU")
    ap.add_argument("--jackknife", metavar="MU", help="the two-sample jackknife of OUT/mu_MU (12 refits, 2 at a time)")
    ap.add_argument("--choose", metavar="MU", help="the held-out test among OUT/mu_MU and its variants "
                    "(OUT/variants_mu_MU/heldout_choice.{md,csv})")
    ap.add_argument("--compare-jackknives", metavar="MU", help="OUT/mu_MU/jackknife_compare.{md,csv}: the covariance "
                    "errors, `dem model`'s jackknife over both sets and the two-sample jackknife of --jackknife")
    ap.add_argument("--compare-errors", nargs=3, metavar=("BEFORE", "AFTER", "STEM"),
                    help="STEM.{md,csv}: the quoted errors of two parameters.csv side by side")
    ap.add_argument("--comment", default="two calibrations' quoted errors", help="the comment of --compare-errors")
    ap.add_argument("--crosscheck", metavar="MU", help="OUT/mu_MU/jackknife_crosscheck.{md,csv}: two of `dem model`'s "
                    "jackknife refits against refits on ensembles rebuilt without the packing (the full weights kept)")
    a = ap.parse_args(argv)
    if a.crosscheck:
        crosscheck(a.crosscheck, a.out, a.work, a.dem)
        return 0
    if a.compare_jackknives:
        compare_jackknives(a.compare_jackknives, a.out)
        return 0
    if a.compare_errors:
        before, after, stem = a.compare_errors
        compare_errors(before, after, os.path.dirname(stem) or ".", os.path.basename(stem), a.comment)
        return 0
    if a.choose:
        print(f"model_joint: mu = {a.choose}: the held-out test chooses {heldout_choice(a.choose, a.out)}",
              file=sys.stderr)
        return 0
    if a.jackknife:
        two_sample_jackknife(a.jackknife, a.out, a.work, a.dem)
        return 0
    if not a.table_only:
        if not a.mu:
            ap.error("give --mu (or --table-only)")
        for mu in a.mu:
            if not os.path.exists(start_of(mu)):
                raise SystemExit(f"model_joint: no start {start_of(mu)} for mu = {mu}")
            rc = calibrate(mu, a.work, a.out, a.dem, not a.no_jackknife)
            print(f"model_joint: mu = {mu}: {'converged' if rc == 0 else 'not converged (tables written)'}",
                  file=sys.stderr)
    write(a.out)


if __name__ == "__main__":
    sys.exit(main())
