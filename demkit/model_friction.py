"""`dem model` on the friction study's stored ensembles (data/friction_n1000/mu_*): the before/after
table of issue 31 (docs/model.md, "The frictional extension"; docs/friction.md).

    python3 -m demkit.model_friction --out WORK [--dem build/dem] [--mu 0 0.5 ...] [--no-jackknife] [--surface ld]
        [--fabric-lode overlap|principal|norm|opening|extension]

For every mu: WORK/mu_MU/ is a working copy of data/friction_n1000/mu_MU (ensemble means, isotropic
branches, member D2/D3 curves) plus WORK/mu_MU/paths/isobaric_phiX.csv, the ensemble of the
members' isobaric D2 curves (deviatoric/isobaric_D2_phiX.csv) on the first member's
eps_d_accumulated grid. The stored member curves are trimmed (no strain or stress components),
so their signs cannot be recovered: the path is monotone forward shear, and s_dev, F_dev (magnitudes)
stand for the signed values, as for the D2/D3 curves the model is calibrated on (at the start, where
the anisotropy is the packing's random initial one, a magnitude is biased up by its noise).
Then `dem model WORK/mu_MU --family auto` (both families; the held-out test chooses) writes
WORK/mu_MU/model/ (the chosen family) and WORK/mu_MU/model/FAMILY/ (the other), and this script
collects their summary.csv into WORK/before_after.{md,csv}: the RMS error per curve in band
half-widths, group model (before) and frictional family (after), fitted (D2) and predicted (D3,
isobaric D2), with the calibrations' chi2/dof.
"""
import argparse
import csv
import glob
import os
import shutil
import subprocess
import sys

import numpy as np
from scipy import stats

from demkit.atomic import write_atomic

MUS = ("0", "0.01", "0.1", "0.3", "0.5", "1")
PATH_Q = ("nu", "eps_v", "p_star", "s_dev", "F_dev")


def read_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#") and ln.strip()))
    if not rows:
        raise SystemExit(f"model_friction: {path} has no header")
    head = rows[0]
    return {h: [r[i] for r in rows[1:]] for i, h in enumerate(head)}


def fnum(col):
    return np.array([float(v) for v in col])


def fmt(v):
    return "nan" if not np.isfinite(v) else f"{v:.7g}"


def copy_tree(src, dst):
    """The ensemble means, the members' isotropic branches and D2/D3 curves."""
    for f in glob.glob(os.path.join(src, "ensemble", "D[23]_phi*.csv")):
        os.makedirs(os.path.join(dst, "ensemble"), exist_ok=True)
        shutil.copy(f, os.path.join(dst, "ensemble"))
    for m in sorted(glob.glob(os.path.join(src, "members", "m*"))):
        name = os.path.basename(m)
        for sub, pat in (("prep", "cycle_unloading.csv"), ("deviatoric", "D[23]_phi*.csv")):
            for f in glob.glob(os.path.join(m, sub, pat)):
                os.makedirs(os.path.join(dst, "members", name, sub), exist_ok=True)
                shutil.copy(f, os.path.join(dst, "members", name, sub))


def working_copy(store, work, mu, who):
    """WORK/mu_MU, a working copy of STORE/mu_MU (copy_tree and isobaric_paths) made when it has no paths/ yet;
    a missing STORE/mu_MU is refused, naming WHO's --store."""
    src, dst = os.path.join(store, f"mu_{mu}"), os.path.join(work, f"mu_{mu}")
    if not os.path.isdir(src):
        raise SystemExit(f"{who}: {src} does not exist (--store: the friction study's folder)")
    if not os.path.isdir(os.path.join(dst, "paths")):
        copy_tree(src, dst)
        isobaric_paths(src, dst)
    return dst


def isobaric_paths(src, dst):
    """paths/isobaric_phiX.csv and members/mNNN/paths/isobaric_phiX.csv from the members' isobaric D2 curves."""
    members = sorted(glob.glob(os.path.join(src, "members", "m*")))
    tags = sorted({os.path.basename(f)[len("isobaric_D2_"):-4]
                   for m in members for f in glob.glob(os.path.join(m, "deviatoric", "isobaric_D2_phi*.csv"))})
    for tag in tags:
        files = [os.path.join(m, "deviatoric", f"isobaric_D2_{tag}.csv") for m in members]
        files = [f for f in files if os.path.exists(f)]
        if len(files) < 2:
            continue
        mem = []
        for f in files:
            c = read_csv(f)
            mem.append({"acc": fnum(c["eps_d_accumulated"]), **{q: fnum(c[q]) for q in PATH_Q}})
        top = min(m["acc"][-1] for m in mem)
        grid = mem[0]["acc"][mem[0]["acc"] <= top + 1e-12]
        K = len(mem)
        tq = stats.t.ppf(0.975, K - 1)
        res = {q: np.array([np.interp(grid, m["acc"], m[q]) for m in mem]) for q in PATH_Q}
        out_q = {"nu": "nu", "eps_v": "eps_v", "p_star": "p_star", "s_dev": "s_dev_signed", "F_dev": "F_dev_signed"}
        head = ["eps_d_accumulated", "eps_d_signed", "direction", "isobaric", "triaxial", "n_packings"]
        cols = {}
        for q, name in out_q.items():
            x = res[q]
            mean, sd = x.mean(axis=0), x.std(axis=0, ddof=1)
            se = sd / np.sqrt(K)
            cols[name] = (mean, sd, se, mean - tq * se, mean + tq * se)
            head += [f"{name}_{s}" for s in ("mean", "sd", "se", "lo95", "hi95")]
        lines = [f"# isobaric D2 from nu = {tag[3:]}, {K} packings: members' curves resampled on the first member's "
                 "eps_d_accumulated grid (demkit/model_friction.py); s_dev, F_dev magnitudes taken as signed (monotone "
                 "forward path); X_lo95/X_hi95 = X_mean -/+ t_{K-1,0.975} X_se\n", ",".join(head) + "\n"]
        for i in range(len(grid)):
            r = [fmt(grid[i]), fmt(grid[i]), "1", "1", "0", str(K)]
            for name in out_q.values():
                r += [fmt(v[i]) for v in cols[name]]
            lines.append(",".join(r) + "\n")
        write_atomic(os.path.join(dst, "paths", f"isobaric_{tag}.csv"), "".join(lines))
        for f, m in zip(files, mem):
            name = os.path.basename(os.path.dirname(os.path.dirname(f)))
            text = ["# member isobaric D2 curve resampled on the ensemble grid (signs as the ensemble file)\n",
                    "eps_d_accumulated,nu,eps_v,p_star,s_dev_signed,F_dev_signed\n"]
            ys = [np.interp(grid, m["acc"], m[q]) for q in PATH_Q]
            for i in range(len(grid)):
                text.append(fmt(grid[i]) + "," + ",".join(fmt(y[i]) for y in ys) + "\n")
            write_atomic(os.path.join(dst, "members", name, "paths", f"isobaric_{tag}.csv"), "".join(text))


def family_dirs(model_dir):
    """(group summary folder, extended summary folder, chosen family) of a `--family auto` output."""
    sel = read_csv(os.path.join(model_dir, "selection.csv"))
    chosen = sel[list(sel)[1]][list(sel[list(sel)[0]]).index("chosen")]
    other = "group" if chosen == "extended" else "extended"
    dirs = {chosen: model_dir, other: os.path.join(model_dir, other)}
    return dirs["group"], dirs["extended"], chosen


def summary_rows(folder):
    c = read_csv(os.path.join(folder, "summary.csv"))
    keys = list(c)
    rows = {}
    chi2 = float("nan")
    for i in range(len(c[keys[0]])):
        mode, nu, role = c[keys[0]][i], c[keys[1]][i], c[keys[2]][i]
        if mode == "calibration":
            chi2 = float(role.split()[-1])
            continue
        vals = [float(c[k][i]) for k in keys[3:7]]
        rows[(mode, float(nu))] = (role, vals)
    return rows, chi2


def table(work, mus, norm_work=None, middle="norm"):
    """WORK/before_after.{md,csv}: per curve the group model (before) and the extended family (after);
    with norm_work (a run with --fabric-lode norm) also the extended family under the norm rule (the
    first round's), between them; `middle` names that column (the rule it was run with)."""
    head = ["mu", "mode", "nu", "role", "quantity", "group_rms_over_band [-]"]
    if norm_work:
        head.append(f"extended_{middle}_rms_over_band [-]")
    head.append("extended_rms_over_band [-]")
    arrow = f"before → {middle} rule → after" if norm_work else "before → after"
    out_rows = []
    md = [f"| μ | curve | ν | role | p* (ε_v isobaric): {arrow} | s_dev | F_dev |", "|---|---|---|---|---|---|---|"]
    chis = []
    d2_moves = False   # does the after rule change D2 (the overlap rule does; norm/principal/opening do not)
    nan4 = [float("nan")] * 4
    for mu in mus:
        g_dir, x_dir, chosen = family_dirs(os.path.join(work, f"mu_{mu}", "model"))
        g, g_chi = summary_rows(g_dir)
        x, x_chi = summary_rows(x_dir)
        n, n_chi = summary_rows(family_dirs(os.path.join(norm_work, f"mu_{mu}", "model"))[1]) if norm_work else (None, None)
        if n is not None and any(not np.array_equal(n.get(k, (r, nan4))[1], v, equal_nan=True)
                                 for k, (r, v) in x.items() if k[0] == "D2"):
            d2_moves = True
        chis.append((mu, g_chi, x_chi, chosen, n_chi))
        for key in sorted(g, key=lambda k: ({"D2": 0, "D3": 1}.get(k[0], 2), k[1])):
            role, gv = g[key]
            cols = [gv] + ([n.get(key, (role, nan4))[1]] if n is not None else []) + [x.get(key, (role, nan4))[1]]
            for q, name in ((0, "p_star"), (1, "eps_v"), (2, "s_dev"), (3, "F_dev")):
                if any(np.isfinite(c[q]) for c in cols):
                    out_rows.append([mu, key[0], f"{key[1]:.2f}", role, name] + [fmt(c[q]) for c in cols])
            first = 1 if key[0] == "isobaric" else 0
            cells = [" → ".join(f"{c[q]:.2f}" for c in cols) for q in (first, 2, 3)]
            md.append(f"| {mu} | {key[0]} | {key[1]:.2f} | {role} | " + " | ".join(cells) + " |")
    md += ["", "| μ | χ²/dof group | χ²/dof extended | held-out test chooses |", "|---|---|---|---|"]
    md += [f"| {mu} | {gc:.3g} | {xc:.3g} | {ch} |" for mu, gc, xc, ch, _ in chis]
    # Compact: per mu the worst curve of each kind, before -> (norm rule ->) after.
    d3_role = next((r[3] for r in out_rows if r[1] == "D3"), "predicted")   # fitted with --calibrate-on D2,D3
    if d2_moves:
        md += ["", f"| μ | χ²/dof ({arrow}) | worst fitted D2 | worst {d3_role} D3 | worst predicted isobaric "
               "| chosen |", "|---|---|---|---|---|---|"]
    else:
        md += ["", f"| μ | χ²/dof before → after | worst fitted D2 | worst {d3_role} D3 ({arrow}) | worst predicted "
               "isobaric | chosen |", "|---|---|---|---|---|---|"]
    for mu, gc, xc, ch, nc in chis:
        cells = []
        for mode in ("D2", "D3", "isobaric"):
            sel = [r for r in out_rows if r[0] == mu and r[1] == mode]
            worst = []
            for c in range(5, len(head)):
                v = [float(r[c]) for r in sel if np.isfinite(float(r[c]))]
                worst.append(max(v) if v else float("nan"))
            if mode != "D3" and not d2_moves:
                worst = [worst[0], worst[-1]]   # the rule changes D3 only
            cells.append(" → ".join(f"{w:.2f}" for w in worst) if sel else "–")
        chi = f"{gc:.3g} → {nc:.3g} → {xc:.3g}" if d2_moves else f"{gc:.3g} → {xc:.3g}"
        md.append(f"| {mu} | {chi} | " + " | ".join(cells) + f" | {ch} |")
    text = [",".join(head) + "\n"] + [",".join(r) + "\n" for r in out_rows]
    write_atomic(os.path.join(work, "before_after.csv"), "".join(text))
    write_atomic(os.path.join(work, "before_after.md"), "\n".join(md) + "\n")
    print("\n".join(md))


def parameter_table(work, mus):
    """WORK/parameters_all.md: every coefficient of the extended family per mu, value +- its
    jackknife SE (the covariance SE where no jackknife ran, marked c)."""
    cols, names = [], []
    for mu in mus:
        x_dir = family_dirs(os.path.join(work, f"mu_{mu}", "model"))[1]
        c = read_csv(os.path.join(x_dir, "parameters.csv"))
        vals = {}
        for i, n in enumerate(c["parameter"]):
            v, jk, cov = (float(c[k][i]) for k in ("value", "se_jackknife", "se_covariance"))
            se, mark = (jk, "") if np.isfinite(jk) else (cov, " c")
            vals[n] = f"{v:.4g} ± {se:.2g}{mark}" if np.isfinite(se) else f"{v:.4g}"
            if n not in names:
                names.append(n)
        cols.append(vals)
    md = ["| parameter | " + " | ".join(f"μ = {mu}" for mu in mus) + " |", "|---|" + "---|" * len(mus)]
    md += [f"| {n} | " + " | ".join(c.get(n, "") for c in cols) + " |" for n in names]
    write_atomic(os.path.join(work, "parameters_all.md"),
                 "<!-- the extended family's coefficients per mu, value ± jackknife SE over the packings (c: covariance "
                 "SE); demkit/model_friction.py -->\n" + "\n".join(md) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="working folder (copies of the stored ensembles and the model results)")
    ap.add_argument("--store", default="data/friction_n1000", help="the friction study's stored ensembles")
    ap.add_argument("--dem", default="build/dem")
    ap.add_argument("--mu", nargs="+", default=list(MUS))
    ap.add_argument("--no-jackknife", action="store_true")
    ap.add_argument("--surface", default="ld")
    ap.add_argument("--fabric-lode", default="overlap", choices=("principal", "norm", "opening", "overlap", "extension", "weighted"),
                    help="the extended family's fabric-limit rule (norm: the first round's numbers)")
    ap.add_argument("--state-limit", default="none", choices=("none", "pressure"),
                    help="the extended family's stress-ratio limit (pressure: the state-dependent limit of issue 31's "
                         "fifth round, n_psi fitted)")
    ap.add_argument("--calibrate-on", default="D2",
                    help="the modes fitted, passed to `dem model --calibrate-on` (D2,D3 for the weighted rule, which needs "
                         "a second Lode angle; the others are predicted)")
    ap.add_argument("--max-iterations", type=int, default=None,
                    help="`dem model --max-iterations` (its default, 1000, when not given)")
    ap.add_argument("--jamming", default="separate", choices=("separate", "shared"),
                    help="the isotropic laws' jamming fractions (dem model --jamming; shared: nu_cC = nu_c)")
    ap.add_argument("--table-only", action="store_true", help="only collect the existing results")
    ap.add_argument("--middle-rule", default="norm", help="the --fabric-lode of --norm-work's run (its column name)")
    ap.add_argument("--norm-work", default=None,
                    help="a WORK folder of the same command with --fabric-lode norm: its extended family is put "
                         "between before and after in the table")
    a = ap.parse_args(argv)
    for mu in a.mu:
        src = os.path.join(a.store, f"mu_{mu}")
        dst = os.path.join(a.out, f"mu_{mu}")
        if a.table_only:
            continue
        if not os.path.isdir(src):
            raise SystemExit(f"model_friction: {src} does not exist (--store: the friction study's folder)")
        copy_tree(src, dst)
        isobaric_paths(src, dst)
        cmd = [a.dem, "model", dst, "--family", "auto", "--surface", a.surface, "--fabric-lode", a.fabric_lode, "--force",
               "--no-plots"]
        if a.no_jackknife:
            cmd.append("--no-jackknife")
        if a.state_limit != "none":
            cmd += ["--state-limit", a.state_limit]
        if a.calibrate_on != "D2":
            cmd += ["--calibrate-on", a.calibrate_on]
        if a.jamming != "separate":
            cmd += ["--jamming", a.jamming]
        if a.max_iterations:
            cmd += ["--max-iterations", str(a.max_iterations)]
        print("model_friction:", " ".join(cmd), file=sys.stderr)
        with open(os.path.join(dst, "model.log"), "w") as log:
            if subprocess.call(cmd, stderr=log) not in (0, 1):
                raise SystemExit(f"model_friction: {' '.join(cmd)} failed (see {dst}/model.log)")
    table(a.out, a.mu, a.norm_work, a.middle_rule)
    parameter_table(a.out, a.mu)


if __name__ == "__main__":
    main()
