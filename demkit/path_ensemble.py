"""Ensemble averages of loading-path curves (reversal, isobaric, cyclic) on a common grid of the
accumulated deviatoric strain, with signed deviatoric quantities, for `dem model --paths`
(docs/model.md). The ensemble reduce of `dem fit` leaves paths out (docs/control.md): averaging
through a reversal needs the accumulated strain as the grid and a sign for the deviators.

    python3 -m demkit.path_ensemble --members RAW --out DIR [--source RUN] [--force]

RAW/mNNN/PATH_phiX.csv   path curves of `dem mode --mode PATH` (one per packing, the same path
                         and start volume fraction for every packing)
DIR/paths/PATH_phiX.csv  ensemble (grid: eps_d_accumulated; for a path held at constant side stress
                         throughout (triaxial), eps_d since the start, see signed_member): for X in nu, eps_v, p_star, s_dev_signed, F_dev_signed, s_dev,
                         F_dev: X_mean, X_sd, X_se, X_lo95, X_hi95 (mean -/+ t_{K-1,0.975} se, the
                         band `dem fit` writes); eps_d_accumulated, eps_d_signed, direction
                         (+1/-1: the sign of the strain increment that reaches the row),
                         isobaric (1 where the path held p), triaxial (1 where the side stresses
                         sigma_xx, sigma_yy were held and the axial z strain prescribed), n_packings;
                         also eps_zz (the axial strain) and sigma_r_p0 = (sigma_xx + sigma_yy)/2 / p(row 0)
                         (the side stress over the path's start pressure: 1 where a triaxial servo holds it)
DIR/members/mNNN/paths/PATH_phiX.csv   each member resampled on that grid (for the jackknife)
--source RUN             also copy, trimmed to the columns `dem model` reads, RUN/ensemble/{D2,D3}_phiX.csv,
                         RUN/members/*/prep/cycle_unloading.csv and RUN/members/*/deviatoric/D2_phiX.csv

Signs (docs/definitions.md: s_dev, F_dev and eps_d are magnitudes, compression positive):
eps_d_signed = eps_d sign(eps_xx - eps_zz), s_dev_signed = s_dev sign(sigma_zz - sigma_xx),
F_dev_signed = F_dev sign(F_zz - F_xx): positive along the first loading direction (D2 =
[1, 0, -1] stretches x and compresses z), negative after a reversal has turned the deviator.
A signed magnitude jumps by 2|s_dev| at the crossing when sigma_yy is not halfway between
sigma_xx and sigma_zz; the mean over packings smooths that.
"""
import argparse
import glob
import os
import re
import sys

import numpy as np
from scipy import stats

from demkit.atomic import write_atomic
from demkit.curves import CurveError, read_text

QUANTITIES = ("nu", "eps_v", "p_star", "s_dev_signed", "F_dev_signed", "s_dev", "F_dev", "eps_zz", "sigma_r_p0")
NAME_RE = re.compile(r"([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv$")


def read_csv(path):
    """Comment lines (#..., with their line ends) and {column: list of str} (demkit.curves.read_text)."""
    try:
        comments, head, body = read_text(path)
    except CurveError as e:
        raise SystemExit(f"path_ensemble: {e}")
    return [c + "\n" for c in comments], {h: [r[i] for r in body] for i, h in enumerate(head)}


def fnum(col):
    return np.array([float(v) for v in col])


def fmt(v):
    return "nan" if not np.isfinite(v) else f"{v:.7g}"   # 7 digits: far below the packings' spread


def signed_member(path):
    _, c = read_csv(path)
    need = ("eps_d_accumulated", "eps_xx", "eps_zz", "eps_d", "eps_v", "nu", "p_star", "s_dev", "sigma_xx_Pa",
            "sigma_zz_Pa", "sigma_yy_Pa", "p_Pa", "F_dev", "F_xx", "F_zz", "target_p_Pa")
    for n in need:
        if n not in c:
            raise SystemExit(f"path_ensemble: {path} has no column {n} (a path curve of `dem mode --mode PATH` is needed)")
    acc = fnum(c["eps_d_accumulated"])
    m = {
        "acc": acc,
        "e": fnum(c["eps_xx"]) - fnum(c["eps_zz"]),
        "eps_d_signed": fnum(c["eps_d"]) * np.sign(fnum(c["eps_xx"]) - fnum(c["eps_zz"])),
        "nu": fnum(c["nu"]), "eps_v": fnum(c["eps_v"]), "p_star": fnum(c["p_star"]),
        "s_dev": fnum(c["s_dev"]), "F_dev": fnum(c["F_dev"]),
        "s_dev_signed": fnum(c["s_dev"]) * np.sign(fnum(c["sigma_zz_Pa"]) - fnum(c["sigma_xx_Pa"])),
        "F_dev_signed": fnum(c["F_dev"]) * np.sign(fnum(c["F_zz"]) - fnum(c["F_xx"])),
        "isobaric": np.isfinite(fnum(c["target_p_Pa"])).astype(int),
        "eps_zz": fnum(c["eps_zz"]),
        "sigma_r_p0": 0.5 * (fnum(c["sigma_xx_Pa"]) + fnum(c["sigma_yy_Pa"])) / fnum(c["p_Pa"])[0],
    }
    tx = fnum(c["target_xx_Pa"]) if "target_xx_Pa" in c else np.full(len(acc), np.nan)
    ty = fnum(c["target_yy_Pa"]) if "target_yy_Pa" in c else np.full(len(acc), np.nan)
    tz = fnum(c["target_zz_Pa"]) if "target_zz_Pa" in c else np.full(len(acc), np.nan)
    # constant side stress: x and y stress controlled, z strain controlled, no pressure servo
    m["triaxial"] = (np.isfinite(tx) & np.isfinite(ty) & ~np.isfinite(tz) & ~np.isfinite(fnum(c["target_p_Pa"]))).astype(int)
    if len(acc) > 1 and np.all(m["triaxial"][1:] == 1):
        # Constant side stress: the side axes are servo-driven, and their back-and-forth (the two
        # sides are held separately) adds to the accumulated sum |d eps_d| without being loading
        # (0.246 against eps_d = 0.225 at eps_zz = -0.15). The path is monotone, so its abscissa is
        # eps_d since the start itself (its running maximum, for the last digits of the noise).
        m["acc"] = acc = np.maximum.accumulate(fnum(c["eps_d"]))
    if np.any(np.diff(acc) < 0):
        raise SystemExit(f"path_ensemble: {path}: eps_d_accumulated decreases")
    return m


def member_name(f, by_stem=False):
    """RAW/mNNN/PATH_phiX.csv -> mNNN; with by_stem, DIR/mS.csv -> mS (demkit.geotech_model)."""
    return os.path.splitext(os.path.basename(f))[0] if by_stem else os.path.basename(os.path.dirname(f))


def interp(acc, y, grid):
    return np.interp(grid, acc, y)


def reduce_path(files, name, nu_tag, out_dir, members_out, mem=None):
    """Reduce the member curves `files` (or, when given, the member dicts `mem` built from them, with
    the keys of signed_member; the member name is the file's folder, or its stem when `mem` is given)."""
    named_by_stem = mem is not None
    mem = [signed_member(f) for f in files] if mem is None else mem
    K = len(mem)
    if K < 2:
        raise SystemExit(f"path_ensemble: {name}_phi{nu_tag}: {K} member curve(s); an ensemble needs >= 2")
    # Grid: the rows of the first member (the path is strain controlled in eps_d, so every member
    # is sampled at the same accumulated strains up to the last step), cut at the shortest member.
    top = min(m["acc"][-1] for m in mem)
    grid = mem[0]["acc"][mem[0]["acc"] <= top + 1e-12]
    for m in mem[1:]:
        common = min(len(m["acc"]), len(grid))
        if np.max(np.abs(m["acc"][:common] - grid[:common])) > 1e-6:
            print(f"path_ensemble: note: {name}_phi{nu_tag}: member rows differ from the grid by up to "
                  f"{np.max(np.abs(m['acc'][:common] - grid[:common])):.2g}; resampled linearly", file=sys.stderr)
            break
    e = np.mean([interp(m["acc"], m["e"], grid) for m in mem], axis=0)
    direction = np.zeros(len(grid), dtype=int)
    direction[1:] = np.sign(np.diff(e)).astype(int)
    direction[0] = direction[1] if len(grid) > 1 else 1
    # Reversals must fall on rows (the DEM lands its strain stops exactly and writes the row), so
    # that every interval between rows is monotone: a turning row is a strict extremum of e.
    for i in range(1, len(grid) - 1):
        if direction[i] * direction[i + 1] < 0 and not (abs(e[i]) >= max(abs(e[i - 1]), abs(e[i + 1])) - 1e-12
                                                       or abs(e[i]) <= min(abs(e[i - 1]), abs(e[i + 1])) + 1e-12):
            raise SystemExit(f"path_ensemble: {name}_phi{nu_tag}: the reversal near row {i} is not on a row")
    iso = np.max([interp(m["acc"], m["isobaric"].astype(float), grid) for m in mem], axis=0)
    isobaric = (iso > 0.5).astype(int)
    isobaric[0] = isobaric[1] if len(grid) > 1 else 0
    tri = np.max([interp(m["acc"], m["triaxial"].astype(float), grid) for m in mem], axis=0)
    triaxial = (tri > 0.5).astype(int)
    triaxial[0] = triaxial[1] if len(grid) > 1 else 0
    tq = stats.t.ppf(0.975, K - 1)
    cols = {}
    res = {q: np.array([interp(m["acc"], m[q], grid) for m in mem]) for q in QUANTITIES}
    for q in QUANTITIES:
        x = res[q]
        mean = x.mean(axis=0)
        sd = x.std(axis=0, ddof=1)
        se = sd / np.sqrt(K)
        cols[q] = (mean, sd, se, mean - tq * se, mean + tq * se)
    eps_signed = np.mean([interp(m["acc"], m["eps_d_signed"], grid) for m in mem], axis=0)
    head = ["eps_d_accumulated", "eps_d_signed", "direction", "isobaric", "triaxial", "n_packings"]
    for q in QUANTITIES:
        head += [f"{q}_{s}" for s in ("mean", "sd", "se", "lo95", "hi95")]
    lines = [
        f"# dem path ensemble: {name} from nu = {nu_tag}, {K} packings "
        f"({' '.join(member_name(f, named_by_stem) for f in files)})\n",
        "# each member resampled (linear) on the common eps_d_accumulated grid; X_mean, X_sd (sample), "
        "X_se = X_sd/sqrt(K), X_lo95/X_hi95 = X_mean -/+ t_{K-1,0.975} X_se (95% band of the mean)\n",
        "# signed along the first loading direction: eps_d_signed = eps_d sign(eps_xx - eps_zz), "
        "s_dev_signed = s_dev sign(sigma_zz - sigma_xx), F_dev_signed = F_dev sign(F_zz - F_xx); "
        "s_dev, F_dev: magnitudes; direction: sign of the strain increment into the row; isobaric: 1 where p was held; "
        "triaxial: 1 where sigma_xx, sigma_yy were held (constant side stress, axial z strain prescribed); "
        "sigma_r_p0 = (sigma_xx + sigma_yy)/2 / p(row 0)\n",
        ",".join(head) + "\n",
    ]
    for i in range(len(grid)):
        r = [fmt(grid[i]), fmt(eps_signed[i]), str(direction[i]), str(isobaric[i]), str(triaxial[i]), str(K)]
        for q in QUANTITIES:
            r += [fmt(v[i]) for v in cols[q]]
        lines.append(",".join(r) + "\n")
    write_atomic(os.path.join(out_dir, f"{name}_phi{nu_tag}.csv"), "".join(lines))
    if members_out:
        for f, m in zip(files, mem):
            member = member_name(f, named_by_stem)
            q_out = ("nu", "eps_v", "p_star", "s_dev_signed", "F_dev_signed")
            text = [f"# dem path member curve: {name} from nu = {nu_tag}, {member}, resampled on the ensemble grid; "
                    "signs as in the ensemble file\n", "eps_d_accumulated," + ",".join(q_out) + "\n"]
            ys = [interp(m["acc"], m[q], grid) for q in q_out]
            for i in range(len(grid)):
                text.append(fmt(grid[i]) + "," + ",".join(fmt(y[i]) for y in ys) + "\n")
            write_atomic(os.path.join(members_out, member, "paths", f"{name}_phi{nu_tag}.csv"), "".join(text))
    return K, len(grid)


def trim(src, dst, keep):
    comments, c = read_csv(src)
    head = [h for h in c if keep(h)]
    if not head:
        raise SystemExit(f"path_ensemble: {src}: none of the needed columns")
    n = len(c[head[0]])
    text = comments + [",".join(head) + "\n"] + [",".join(c[h][i] for h in head) + "\n" for i in range(n)]
    write_atomic(dst, "".join(text))


def copy_source(run, out):
    ens_keep = re.compile(r"^(eps_d|n_packings|(nu|p_star|s_dev|F_dev)_(mean|sd|se|lo95|hi95))$")
    files = sorted(glob.glob(os.path.join(run, "ensemble", "D[23]_phi*.csv")))
    if not files:
        raise SystemExit(f"path_ensemble: no {run}/ensemble/D2_phiX.csv: --source must be an ensemble run reduced by `dem fit`")
    for f in files:
        trim(f, os.path.join(out, "ensemble", os.path.basename(f)), lambda h: bool(ens_keep.match(h)))
    for m in sorted(glob.glob(os.path.join(run, "members", "m*"))):
        name = os.path.basename(m)
        trim(os.path.join(m, "prep", "cycle_unloading.csv"), os.path.join(out, "members", name, "prep", "cycle_unloading.csv"),
             lambda h: h in ("nu", "p_star", "C_nonrattler"))
        for f in sorted(glob.glob(os.path.join(m, "deviatoric", "D2_phi*.csv"))):
            trim(f, os.path.join(out, "members", name, "deviatoric", os.path.basename(f)),
                 lambda h: h in ("eps_d", "nu", "p_star", "s_dev", "F_dev"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--members", required=True, help="folder with one sub-folder of path curves per packing")
    ap.add_argument("--out", required=True, help="output folder (paths/ and members/ are written in it)")
    ap.add_argument("--source", help="ensemble run whose D2/D3 means, isotropic branches and D2 member curves are copied (trimmed)")
    ap.add_argument("--no-members", action="store_true", help="do not write the resampled member curves")
    a = ap.parse_args(argv)
    groups = {}
    for f in sorted(glob.glob(os.path.join(a.members, "*", "*_phi*.csv"))):
        m = NAME_RE.search(os.path.basename(f))
        if m:
            groups.setdefault((m.group(1), m.group(2)), []).append(f)
    if not groups:
        print(f"path_ensemble: no PATH_phiX.csv under {a.members}/*/", file=sys.stderr)
        return 2
    sizes = {len(v) for v in groups.values()}
    if len(sizes) != 1:
        print(f"path_ensemble: warning: paths have different numbers of members: "
              f"{ {k: len(v) for k, v in groups.items()} }", file=sys.stderr)
    for (name, nu), files in sorted(groups.items()):
        K, n = reduce_path(files, name, nu, os.path.join(a.out, "paths"), None if a.no_members else os.path.join(a.out, "members"))
        print(f"path_ensemble: {name}_phi{nu}: {K} packings, {n} rows", file=sys.stderr)
    if a.source:
        copy_source(a.source, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
