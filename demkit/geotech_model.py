"""The laboratory element tests of data/geotech as the path ensembles `dem model --paths` reads
(issue 31; docs/model.md, "Calibrated on drained triaxial tests").

    python3 -m demkit.geotech_model --curves data/geotech/curves --mu 0.5 --out DIR [--tests T1,T2] [--force]
    python3 -m demkit.geotech_model --collect ROOT      # ROOT/{blind,lab}_PREP/summary.csv -> ROOT/comparison.{md,csv}

CURVES/mu_MU/PREP/LEVEL/TEST/mS.csv   the stored test curves (docs/geotech.md), one per packing
DIR/ensemble_PREP/paths/TEST_PREP_phiX.csv          ensemble of the K packings, the format of
                                                    demkit.path_ensemble (X: the mean start nu, 3 decimals)
DIR/ensemble_PREP/members/mS/paths/TEST_PREP_phiX.csv   each packing on the ensemble's grid (jackknife)
DIR/ensemble_PREP/ensemble/D[23]_phiX.csv          with --friction FDIR: FDIR's D2/D3 ensemble means (trimmed)
DIR/ensemble_joint/                                 with --joint: the dense and loose paths and members in one
                                                    folder (the dense isotropic states and D2/D3 means)
DIR/ensemble_PREP/members/mS/prep/cycle_unloading.csv   the packing's isotropic states: the start row
                                                    of its TC_s3 curve at each pressure level (nu, p_star,
                                                    C_nonrattler = the curve's C), what a laboratory's
                                                    isotropic compression gives

Every test here is monotone, so the grid is eps_d since the start (its running maximum), not the
accumulated |d eps_d|, which counts the servo-held axes' back-and-forth (as demkit.path_ensemble
does for the constant-side-stress path). Signs along the first loading direction of D2 (x
stretched, z compressed): eps_d_signed = eps_d sign(eps_xx - eps_zz), s_dev_signed = s_dev
sign(sigma_zz - sigma_xx). The stored curves keep F_dev but not its components, so F_dev_signed =
F_dev times the test's loading sign (the sign of sigma_zz - sigma_xx at the end): exact once the
fabric has turned with the load, biased at the start, where the packing's own anisotropy (F_dev
about 0.02) has a random direction (docs/model.md says so). Controls per row: `triaxial` (side
stresses held, z strain prescribed: TC_s3, TE_s3), `isobaric` (p held: TC_p, TT_b*, TE_p).
The intermediate-stress ratio b of each test is read from its name by `dem model` (lode_b_of).
SS_cns (simple shear: the principal axes rotate) is not converted: the model has fixed axes.
"""
import argparse
import glob
import os
import shutil
import sys

import numpy as np

from demkit.atomic import write_atomic
from demkit.curves import CurveError, read_text
from demkit.path_ensemble import reduce_path, trim

TESTS = ("TC_s3", "TE_s3", "TC_p", "TT_b025", "TT_b050", "TT_b075", "TE_p")
LEVELS = ("iso_lo", "iso_hi")   # the default; --levels adds iso_vhi (p* = 5e-2) or iso_vlo (1e-4)
ALL_LEVELS = ("iso_vlo", "iso_lo", "iso_hi", "iso_vhi")
NEED = ("eps_xx", "eps_zz", "eps_d", "eps_v", "nu", "p_star", "s_dev", "F_dev", "C", "sigma_xx_Pa", "sigma_yy_Pa",
        "sigma_zz_Pa", "p_Pa", "target_xx_Pa", "target_yy_Pa", "target_zz_Pa", "target_p_Pa")


def read_columns(path):
    try:
        _, head, body = read_text(path)
    except CurveError as e:
        raise SystemExit(f"geotech_model: {e}")
    cols = {h: np.array([float(r[i]) for r in body]) for i, h in enumerate(head) if h in NEED}
    for n in NEED:
        if n not in cols:
            raise SystemExit(f"geotech_model: {path} has no column {n}: give the curves of data/geotech/curves "
                             "(demkit.geotech analyse --store writes them)")
    if len(cols["nu"]) < 3:
        raise SystemExit(f"geotech_model: {path} has {len(cols['nu'])} rows; a test curve needs at least 3")
    return cols


def member(path):
    """One test curve as the member dict of demkit.path_ensemble.signed_member."""
    c = read_columns(path)
    d_sz = c["sigma_zz_Pa"] - c["sigma_xx_Pa"]
    load_sign = 1.0 if d_sz[-1] >= 0 else -1.0
    tx, ty, tz, tp = (np.isfinite(c[k]) for k in ("target_xx_Pa", "target_yy_Pa", "target_zz_Pa", "target_p_Pa"))
    acc = np.maximum.accumulate(c["eps_d"])
    return {
        "acc": acc,
        "e": c["eps_xx"] - c["eps_zz"],
        "eps_d_signed": c["eps_d"] * np.sign(c["eps_xx"] - c["eps_zz"]),
        "nu": c["nu"], "eps_v": c["eps_v"], "p_star": c["p_star"], "s_dev": c["s_dev"], "F_dev": c["F_dev"],
        "s_dev_signed": c["s_dev"] * np.sign(d_sz),
        "F_dev_signed": c["F_dev"] * load_sign,
        "isobaric": tp.astype(int),
        "triaxial": (tx & ty & ~tz & ~tp).astype(int),
        "eps_zz": c["eps_zz"],
        "sigma_r_p0": 0.5 * (c["sigma_xx_Pa"] + c["sigma_yy_Pa"]) / c["p_Pa"][0],
    }


def write_isotropic(root, prep, out, seeds, levels=LEVELS):
    """Per packing: its start states at every pressure level (the TC_s3 curves' first rows)."""
    for s in seeds:
        lines = ["# dem geotech isotropic states: the first row of TC_s3 at each pressure level (relaxed "
                 "isotropic checkpoints of the preparation, docs/geotech.md); C_nonrattler is the curve's C\n",
                 "nu,p_star,C_nonrattler\n"]
        for level in levels:
            f = os.path.join(root, prep, level, "TC_s3", f"{s}.csv")
            if not os.path.exists(f):
                raise SystemExit(f"geotech_model: {f} is missing: the isotropic states come from TC_s3 at every level")
            c = read_columns(f)
            lines.append(f"{c['nu'][0]:.10g},{c['p_star'][0]:.10g},{c['C'][0]:.10g}\n")
        write_atomic(os.path.join(out, "members", s, "prep", "cycle_unloading.csv"), "".join(lines))


def copy_friction(friction, dest):
    """The friction study's D2/D3 ensemble means (`dem fit`'s columns `dem model` reads), to be predicted."""
    import re
    keep = re.compile(r"^(eps_d|n_packings|(nu|p_star|s_dev|F_dev)_(mean|sd|se|lo95|hi95))$")
    files = sorted(glob.glob(os.path.join(friction, "ensemble", "D[23]_phi*.csv")))
    if not files:
        raise SystemExit(f"geotech_model: no {friction}/ensemble/D2_phiX.csv: --friction must be a friction-study "
                         "ensemble folder (data/friction_n1000/mu_MU)")
    for f in files:
        trim(f, os.path.join(dest, "ensemble", os.path.basename(f)), lambda h: bool(keep.match(h)))


def convert(curves, mu, out, tests, force=False, friction=None, levels=LEVELS):
    root = os.path.join(curves, f"mu_{mu}")
    if not os.path.isdir(root):
        raise SystemExit(f"geotech_model: {root} is not a folder: give --curves data/geotech/curves and a --mu it holds")
    made = []
    for prep in sorted(os.listdir(root)):
        dest = os.path.join(out, f"ensemble_{prep}")
        if os.path.exists(dest) and not force:
            raise SystemExit(f"geotech_model: {dest} exists: pass --force to replace it")
        if os.path.exists(dest):
            shutil.rmtree(dest)
        seeds = sorted(os.path.splitext(os.path.basename(f))[0]
                       for f in glob.glob(os.path.join(root, prep, levels[0], "TC_s3", "m*.csv")))
        if len(seeds) < 2:
            raise SystemExit(f"geotech_model: {root}/{prep}/{levels[0]}/TC_s3 holds {len(seeds)} curves; need >= 2")
        write_isotropic(root, prep, dest, seeds, levels)
        if friction:
            copy_friction(friction, dest)
        for level in levels:
            for test in tests:
                files = sorted(glob.glob(os.path.join(root, prep, level, test, "m*.csv")))
                if len(files) < 2:
                    print(f"geotech_model: {prep}/{level}/{test}: {len(files)} curves, skipped", file=sys.stderr)
                    continue
                mem = [member(f) for f in files]
                nu_tag = f"{np.mean([m['nu'][0] for m in mem]):.3f}"
                name = f"{test}_{prep}"
                K, n = reduce_path(files, name, nu_tag, os.path.join(dest, "paths"), os.path.join(dest, "members"), mem=mem)
                made.append((prep, level, test, nu_tag, K, n))
                print(f"geotech_model: {prep}/{level}/{test} -> {name}_phi{nu_tag}.csv ({K} packings, {n} rows)",
                      file=sys.stderr)
    return made


def write_joint(out, made):
    """ensemble_joint: the dense and the loose ensembles' paths side by side (their names differ by the preparation),
    each packing's members of both, the dense preparation's isotropic states and D2/D3 means: a laboratory's
    calibration on dense and loose samples at once (`--calibrate-on TC_s3_dense,TC_s3_loose`)."""
    preps = sorted({m[0] for m in made})
    if preps != ["dense", "loose"]:
        raise SystemExit(f"geotech_model: --joint needs a dense and a loose preparation; this mu has {', '.join(preps)}")
    dense, loose, joint = (os.path.join(out, f"ensemble_{p}") for p in ("dense", "loose", "joint"))
    seeds_d = sorted(os.listdir(os.path.join(dense, "members")))
    seeds_l = sorted(os.listdir(os.path.join(loose, "members")))
    if seeds_d != seeds_l:
        raise SystemExit(f"geotech_model: --joint: the dense packings {seeds_d} are not the loose ones {seeds_l}")
    if os.path.exists(joint):
        shutil.rmtree(joint)
    shutil.copytree(dense, joint)
    for src, dst in [(os.path.join(loose, "paths"), os.path.join(joint, "paths"))] + [
            (os.path.join(loose, "members", m, "paths"), os.path.join(joint, "members", m, "paths")) for m in seeds_l]:
        for f in sorted(glob.glob(os.path.join(src, "*.csv"))):
            shutil.copy2(f, os.path.join(dst, os.path.basename(f)))
    print(f"geotech_model: {joint}: dense and loose paths, the dense isotropic states", file=sys.stderr)


def read_summary(path):
    """{(mode, nu): row} of a `dem model` summary.csv."""
    import csv
    with open(path, newline="") as fh:
        return {(r["mode"], r["nu [-]"]): r for r in csv.DictReader(fh) if r["mode"] != "calibration"}


def chi2_of(path):
    import csv
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["mode"] == "calibration":
                return r["role"].replace("chi2/dof ", "")
    return "nan"


def collect(root):
    """ROOT/{blind,lab}_PREP/summary.csv -> ROOT/comparison.{md,csv}: per curve the RMS error over the
    band half-width (p*, eps_v, s_dev, F_dev, worst) of the blind prediction (friction-study calibration)
    and of the laboratory calibration (TC_s3 + the isotropic states), side by side."""
    q = ("p_star [band]", "eps_v [band]", "s_dev [band]", "F_dev [band]", "worst [band]")
    head = ["prep", "mode", "nu [-]"] + [f"blind {c}" for c in q] + ["lab role"] + [f"lab {c}" for c in q]
    rows, chi = [], {}
    for prep in ("dense", "loose"):
        b_path, l_path = (os.path.join(root, f"{k}_{prep}", "summary.csv") for k in ("blind", "lab"))
        if not (os.path.exists(b_path) and os.path.exists(l_path)):
            raise SystemExit(f"geotech_model: --collect needs {b_path} and {l_path} (the README's `dem model` runs)")
        b, lab = read_summary(b_path), read_summary(l_path)
        chi[prep] = (chi2_of(b_path), chi2_of(l_path))
        for key in list(lab) + [k for k in b if k not in lab]:
            rb, rl = b.get(key, {}), lab.get(key, {})
            rows.append([prep, key[0], key[1]] + [rb.get(c, "") or "" for c in q] + [rl.get("role", "")]
                        + [rl.get(c, "") for c in q])
    write_comparison(root, head, rows,
                     "RMS of model - DEM mean over the mean 95 % band half-width per curve: blind = the friction study's "
                     "mu = 0.5 calibration (constant-volume D2, nu = 0.69-0.80), lab = calibrated on TC_s3 at both pressures + "
                     "the isotropic states of the same preparation; nan: not a quantity of that curve; empty: not in that run; "
                     f"chi2/dof blind / lab: dense {chi['dense'][0]} / {chi['dense'][1]}, loose {chi['loose'][0]} / {chi['loose'][1]}")
    return rows


def write_comparison(folder, head, rows, comment):
    """FOLDER/comparison.csv and .md (the comment in an HTML comment above the table), each written atomically."""
    write_atomic(os.path.join(folder, "comparison.csv"), ",".join(head) + "\n" + "".join(",".join(r) + "\n" for r in rows))
    md = [f"<!-- {comment} -->\n", "| " + " | ".join(head) + " |\n", "|" + "---|" * len(head) + "\n"]
    md += ["| " + " | ".join(r) + " |\n" for r in rows]
    write_atomic(os.path.join(folder, "comparison.md"), "".join(md))


STATE_RUNS = (("dense", "dense", "loose_predicts_dense"), ("loose", "dense_predicts_loose", "loose"))   # prep, its dense-state and loose-state runs


def collect_state(root):
    """ROOT/state_volume/{dense,loose,dense_predicts_loose,loose_predicts_dense}/summary.csv and ROOT/lab_PREP/summary.csv
    -> ROOT/state_volume/comparison.{md,csv}: per laboratory curve the worst RMS error over the band half-width of the
    stored laboratory calibration of its own preparation (no state parameter), of the dense calibration with the
    volume-form state parameter and of the loose one (fitted where the curve is its calibration, else predicted)."""
    sv = os.path.join(root, "state_volume")
    need = [os.path.join(root, f"lab_{p}", "summary.csv") for p in ("dense", "loose")]
    need += [os.path.join(sv, d, "summary.csv") for d in ("dense", "loose", "dense_predicts_loose", "loose_predicts_dense")]
    missing = [n for n in need if not os.path.exists(n)]
    if missing:
        raise SystemExit(f"geotech_model: --collect-state needs {', '.join(missing)} (the README's `dem model` runs, step 7)")
    head = ["prep", "mode", "nu [-]", "lab role", "lab worst [band]", "dense-state role", "dense-state worst [band]",
            "loose-state role", "loose-state worst [band]"]
    rows, chi = [], {}
    for prep, dense_dir, loose_dir in STATE_RUNS:
        lab = read_summary(os.path.join(root, f"lab_{prep}", "summary.csv"))
        ds = read_summary(os.path.join(sv, dense_dir, "summary.csv"))
        ls = read_summary(os.path.join(sv, loose_dir, "summary.csv"))
        chi[prep] = chi2_of(os.path.join(sv, prep, "summary.csv"))
        for key in [k for k in ds if k[0].endswith("_" + prep)]:
            rows.append([prep, key[0], key[1], lab.get(key, {}).get("role", ""), lab.get(key, {}).get("worst [band]", ""),
                         ds[key]["role"], ds[key]["worst [band]"], ls.get(key, {}).get("role", ""),
                         ls.get(key, {}).get("worst [band]", "")])
    write_comparison(sv, head, rows,
                     "worst RMS of model - DEM mean over the mean 95 % band half-width per laboratory curve (mu = 0.5): lab = "
                     "the stored calibration of the curve's own preparation (lab_PREP, no state parameter); dense-state / "
                     "loose-state = calibrated on TC_s3 of that preparation with --state-limit volume, the other preparation "
                     "predicted with --predict-with; inf: the model diverged along it; nan: not a quantity; chi2/dof dense-state "
                     f"{chi['dense']}, loose-state {chi['loose']}")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--curves", default="data/geotech/curves", help="folder of the stored geotech curves")
    ap.add_argument("--mu", default="0.5", help="friction coefficient as in the folder name mu_MU")
    ap.add_argument("--out", help="output folder (ensemble_PREP/ written in it)")
    ap.add_argument("--collect", help="instead: write ROOT/comparison.{md,csv} from ROOT/{blind,lab}_{dense,loose}/summary.csv")
    ap.add_argument("--collect-state", help="instead: write ROOT/state_volume/comparison.{md,csv} from the volume-form "
                    "state parameter's runs and ROOT/lab_{dense,loose}")
    ap.add_argument("--tests", default=",".join(TESTS), help="comma-separated tests (default: every monotone test)")
    ap.add_argument("--force", action="store_true", help="replace existing ensemble_PREP folders")
    ap.add_argument("--joint", action="store_true", help="also write ensemble_joint/: the dense and loose paths in one "
                    "ensemble (with the dense isotropic states), to calibrate on both preparations at once")
    ap.add_argument("--levels", default=",".join(LEVELS), help="comma-separated pressure levels to convert (default "
                    "iso_lo,iso_hi: p* = 1e-3, 1e-2; also iso_vhi, 5e-2, and iso_vlo, 1e-4, where the curves have them)")
    ap.add_argument("--friction", help="also copy this friction-study folder's D2/D3 ensemble means into "
                    "ensemble_PREP/ensemble/ (predicted by `dem model`), e.g. data/friction_n1000/mu_0.5")
    a = ap.parse_args(argv)
    if a.collect:
        collect(a.collect)
        return 0
    if a.collect_state:
        collect_state(a.collect_state)
        return 0
    if not a.out:
        print("geotech_model: give --out DIR (or --collect ROOT, --collect-state ROOT)", file=sys.stderr)
        return 2
    tests = [t for t in a.tests.split(",") if t]
    bad = [t for t in tests if t not in TESTS]
    if bad:
        print(f"geotech_model: --tests {','.join(bad)}: not a monotone test the model can integrate; give some of "
              f"{','.join(TESTS)} (SS_cns rotates the principal axes, which the model does not have)", file=sys.stderr)
        return 2
    levels = [lv for lv in a.levels.split(",") if lv]
    bad = [lv for lv in levels if lv not in ALL_LEVELS]
    if bad or not levels:
        print(f"geotech_model: --levels {','.join(bad) or '(none)'}: give some of {','.join(ALL_LEVELS)}", file=sys.stderr)
        return 2
    made = convert(a.curves, a.mu, a.out, tests, a.force, a.friction, tuple(levels))
    if a.joint:
        write_joint(a.out, made)
    return 0


if __name__ == "__main__":
    sys.exit(main())
