"""The laboratory tests of data/geotech as path ensembles for `dem model` (demkit.geotech_model),
on hand-built curves; and the refusals of the paths-only calibration options (--start,
--hold-isotropic, --max-iterations). docs/model.md, "Calibrated on drained triaxial tests"."""
import csv
import math
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from conftest import DEM, ROOT

COLS = ["eps_xx", "eps_yy", "eps_zz", "eps_v", "eps_d", "nu", "p_Pa", "p_star", "sigma_xx_Pa", "sigma_yy_Pa",
        "sigma_zz_Pa", "s_dev", "F_dev", "C", "target_xx_Pa", "target_yy_Pa", "target_zz_Pa", "target_p_Pa", "stage"]


def write_curve(path, test, nu0, p0, scale):
    """A monotone axisymmetric test: TC (z compressed) or TE (z extended) at constant side stress."""
    sign = -1.0 if test.startswith("TC") else 1.0
    n = 21
    ezz = sign * np.linspace(0.0, 0.2, n)
    exx = -0.45 * ezz
    epsd = np.abs(exx - ezz)
    s = scale * 0.8 * (1 - np.exp(-20 * epsd)) + 0.02
    F = scale * 0.3 * (1 - np.exp(-10 * epsd)) + 0.02
    # side stress held at p0: sigma_a = p0 + q, q = s p, p = p0 (1 + s/3) for TC; extension: sigma_a below
    p = p0 / (1 - (-sign) * s / 3)
    q = (-sign) * s * p
    sxx = np.full(n, p0)
    szz = sxx + q
    rows = []
    for i in range(n):
        ev = (2 * exx[i] + ezz[i]) / 3
        rows.append([exx[i], exx[i], ezz[i], ev, epsd[i], nu0 * np.exp(-3 * ev), p[i], p[i] * 1e-3 / p0, sxx[i], sxx[i],
                     szz[i], s[i], F[i], 6.0, p0, p0, "nan", "nan", "s1"])
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        fh.write("# dem curve: hand-built\n" + ",".join(COLS) + "\n")
        for r in rows:
            fh.write(",".join(x if isinstance(x, str) else repr(float(x)) for x in r) + "\n")


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    root = tmp_path_factory.mktemp("geo")
    for level, nu0, p0 in (("iso_lo", 0.60, 5e7), ("iso_hi", 0.62, 5e8)):
        for test in ("TC_s3", "TE_s3"):
            for k, scale in (("m1", 0.9), ("m2", 1.1)):
                write_curve(str(root / "curves" / "mu_0.5" / "loose" / level / test / f"{k}.csv"), test, nu0 + (0.001 if k == "m2" else 0), p0, scale)
    out = root / "model"
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", str(root / "curves"), "--mu", "0.5",
                        "--out", str(out), "--tests", "TC_s3,TE_s3"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return root, out / "ensemble_loose"


def scaled_copy(parameters, name, factor, dst):
    """A copy of a parameters.csv with coefficient `name`'s value times `factor`, at dst (returned)."""
    with open(parameters, newline="") as fh:
        table = list(csv.reader(fh))
    for row in table:
        if row[0] == name:
            row[2] = repr(float(row[2]) * factor)
    with open(dst, "w", newline="") as fh:
        csv.writer(fh).writerows(table)
    return dst


def read(path):
    with open(path) as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def test_ensembles_are_the_means_with_signs_and_controls(tree):
    _, ens = tree
    names = sorted(os.listdir(ens / "paths"))
    assert names == ["TC_s3_loose_phi0.601.csv", "TC_s3_loose_phi0.621.csv", "TE_s3_loose_phi0.601.csv",
                     "TE_s3_loose_phi0.621.csv"], names
    tc = read(ens / "paths" / "TC_s3_loose_phi0.601.csv")
    te = read(ens / "paths" / "TE_s3_loose_phi0.601.csv")
    last = tc[-1]
    eps = float(last["eps_d_accumulated"])
    assert eps == pytest.approx(0.29, abs=1e-9)   # |e_xx - e_zz| = 1.45 x 0.2
    s_mean = 0.8 * (1 - np.exp(-20 * eps)) + 0.02   # the mean of scales 0.9 and 1.1 is 1
    assert float(last["s_dev_signed_mean"]) == pytest.approx(s_mean, rel=1e-6)
    assert float(last["F_dev_signed_mean"]) == pytest.approx(0.3 * (1 - np.exp(-10 * eps)) + 0.02, rel=1e-6)
    assert all(r["triaxial"] == "1" and r["isobaric"] == "0" for r in tc)
    assert all(r["direction"] == "1" for r in tc)
    # extension: the deviators and the strain against D2's first loading direction
    assert all(r["direction"] == "-1" for r in te[1:])
    assert float(te[-1]["s_dev_signed_mean"]) == pytest.approx(-s_mean, rel=1e-6)
    assert float(te[-1]["F_dev_signed_mean"]) < -0.2
    assert float(te[-1]["eps_d_signed_mean"] if "eps_d_signed_mean" in te[-1] else te[-1]["eps_d_signed"]) < 0
    assert float(tc[0]["nu_mean"]) == pytest.approx(0.6005, abs=1e-9)
    # members on the grid, and the isotropic states at both levels
    m1 = read(ens / "members" / "m1" / "paths" / "TC_s3_loose_phi0.601.csv")
    assert len(m1) == len(tc)
    iso = read(ens / "members" / "m2" / "prep" / "cycle_unloading.csv")
    assert [float(r["nu"]) for r in iso] == pytest.approx([0.601, 0.621])
    assert [float(r["p_star"]) for r in iso] == pytest.approx([1e-3 / (1 - 0.02 / 3)] * 2)   # row 0: s = 0.02


def test_converter_refuses_what_the_model_cannot_integrate(tree, tmp_path):
    root, _ = tree
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", str(root / "curves"), "--out",
                        str(tmp_path / "o"), "--tests", "SS_cns"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "SS_cns" in r.stderr and "rotates" in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", str(root / "curves"), "--out",
                        str(root / "model"), "--tests", "TC_s3"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "--force" in r.stderr, r.stderr


def test_joint_ensemble_holds_both_preparations_at_every_level_asked(tmp_path):
    """--joint: ensemble_joint has the dense and the loose paths (at the levels --levels names, iso_vhi included)
    and each packing's members of both, with the dense isotropic states; a mu without a dense preparation, or an
    unknown level, is refused."""
    curves = tmp_path / "curves"
    for prep, dnu in (("dense", 0.05), ("loose", 0.0)):
        for level, nu0, p0 in (("iso_lo", 0.60, 5e7), ("iso_hi", 0.62, 5e8), ("iso_vhi", 0.70, 2.5e9)):
            for k in ("m1", "m2"):
                write_curve(str(curves / "mu_0.5" / prep / level / "TC_s3" / f"{k}.csv"), "TC_s3",
                            nu0 + dnu + (0.001 if k == "m2" else 0), p0, 1.0 if k == "m1" else 1.1)
    out = tmp_path / "model"
    cmd = [sys.executable, "-m", "demkit.geotech_model", "--curves", str(curves), "--mu", "0.5", "--out", str(out),
           "--tests", "TC_s3", "--levels", "iso_lo,iso_hi,iso_vhi", "--joint"]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    joint = out / "ensemble_joint"
    names = sorted(os.listdir(joint / "paths"))
    assert names == sorted(f"TC_s3_{p}_phi{np.mean([nu + d, nu + d + 0.001]):.3f}.csv"
                           for p, d in (("dense", 0.05), ("loose", 0.0)) for nu in (0.60, 0.62, 0.70)), names
    for m in ("m1", "m2"):
        assert sorted(os.listdir(joint / "members" / m / "paths")) == names
        iso = read(joint / "members" / m / "prep" / "cycle_unloading.csv")
        assert len(iso) == 3 and float(iso[0]["nu"]) > 0.64, "the dense preparation's three isotropic states"
    r = subprocess.run(cmd[:-3] + ["iso_lo,iso_xhi", "--joint", "--force"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "iso_xhi" in r.stderr, r.stderr
    import shutil
    shutil.rmtree(curves / "mu_0.5" / "dense")
    r = subprocess.run(cmd + ["--force"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "--joint needs a dense and a loose" in r.stderr, r.stderr


def test_paths_only_calibration_options_are_refused_with_the_fix(tree, tmp_path):
    _, ens = tree
    start = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "mu_0.5", "parameters.csv")
    base = [DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--family", "extended", "--calibrate-on", "TC_s3_loose"]
    r = subprocess.run(base + ["--out", str(tmp_path / "a")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "monotone mode" in r.stderr and "--start" in r.stderr, r.stderr
    r = subprocess.run(base + ["--out", str(tmp_path / "b"), "--start", str(tmp_path / "none.csv")], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "--start" in r.stderr and "parameters.csv" in r.stderr, r.stderr
    r = subprocess.run(base + ["--out", str(tmp_path / "c"), "--start", start, "--hold-isotropic", "gamma_p,kappa"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--hold-isotropic kappa" in r.stderr and "nu_cC" in r.stderr, r.stderr
    r = subprocess.run(base + ["--out", str(tmp_path / "d"), "--hold-isotropic", "gamma_p"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "--start" in r.stderr, r.stderr
    r = subprocess.run(base + ["--out", str(tmp_path / "e"), "--start", start, "--max-iterations", "0"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--max-iterations" in r.stderr, r.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("parameter,law,value\np0,law,0.04\n")
    r = subprocess.run(base + ["--out", str(tmp_path / "f"), "--start", str(bad)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "nu_c" in r.stderr, r.stderr


def test_collect_puts_blind_and_lab_side_by_side(tmp_path):
    head = "mode,nu [-],role,p_star [band],eps_v [band],s_dev [band],F_dev [band],worst [band]\n"
    for kind, v in (("blind", "5.5"), ("lab", "0.5")):
        for prep in ("dense", "loose"):
            d = tmp_path / f"{kind}_{prep}"
            d.mkdir()
            (d / "summary.csv").write_text(head + f"TC_s3_{prep},0.66,{'predicted' if kind == 'blind' else 'fitted'},"
                                           f"1,{v},2,3,{v}\ncalibration,nan,chi2/dof 7.5,nan,nan,nan,nan,{v}\n")
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--collect", str(tmp_path)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    rows = read(tmp_path / "comparison.csv")
    assert [(x["prep"], x["mode"], x["blind eps_v [band]"], x["lab eps_v [band]"], x["lab role"]) for x in rows] == [
        ("dense", "TC_s3_dense", "5.5", "0.5", "fitted"), ("loose", "TC_s3_loose", "5.5", "0.5", "fitted")]
    assert "chi2/dof blind / lab: dense 7.5 / 7.5" in (tmp_path / "comparison.md").read_text()
    (tmp_path / "lab_loose" / "summary.csv").unlink()
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--collect", str(tmp_path)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode != 0 and "lab_loose" in r.stderr, r.stderr


def summary_rows(path):
    return {(r["mode"], r["nu [-]"]): r for r in read(path) if r["mode"] != "calibration"}


def test_volume_state_parameters_round_trip_through_predict_with(tmp_path):
    """On the stored mu = 0.5 loose TC_s3/TE_s3 curves: `--state-limit volume` writes nu_cs, lambda_cs, n_peak, n_dil;
    `--predict-with` its parameters.csv gives every curve the numbers the calibration's own evaluation gave (the
    fitted TC_s3 now 'predicted'); the option refused with the group family, and --predict-with refused with the
    family its file does not hold."""
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech", "curves"),
                        "--mu", "0.5", "--out", str(tmp_path / "m"), "--tests", "TC_s3,TE_s3"], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    ens = tmp_path / "m" / "ensemble_loose"
    start = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "mu_0.5", "parameters.csv")
    cal = tmp_path / "cal"
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--family", "extended", "--calibrate-on",
                        "TC_s3_loose", "--start", start, "--state-limit", "volume", "--max-iterations", "5",
                        "--hold-isotropic", "gamma_p,nu_cC,alpha", "--out",
                        str(cal)], capture_output=True, text=True, timeout=300)
    assert r.returncode in (0, 1), r.stderr   # 5 iterations: converged or not, the tables are written
    names = [x["parameter"] for x in read(cal / "parameters.csv")]
    for n in ("nu_cs", "lambda_cs", "c_cs", "n_peak", "n_dil", "chi_D"):
        assert n in names, names
    values = {x["parameter"]: float(x["value"]) for x in read(cal / "parameters.csv")}
    assert values["lambda_cs"] == 0.0 and values["c_cs"] > 0, values   # --csl linear, the default
    assert "n_psi_a" not in names and "lambda_psi" not in names
    laws = read(cal / "laws.csv")   # laws of psi: at the critical state and at each calibration path's start
    assert laws[0]["state"] == "critical state" and float(laws[0]["psi [-]"]) == 0.0, laws[0]
    assert len(laws) == 3 and all(r["state"].startswith("TC_s3_loose start") for r in laws[1:]), laws
    pred = tmp_path / "pred"
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--family", "extended", "--predict-with",
                        str(cal / "parameters.csv"), "--out", str(pred)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    a, b = summary_rows(cal / "summary.csv"), summary_rows(pred / "summary.csv")
    assert set(a) == set(b) and len(a) == 4, (a.keys(), b.keys())   # TC_s3, TE_s3 at two pressures
    for key in a:
        assert b[key]["role"] == "predicted"
        for q in ("p_star [band]", "eps_v [band]", "s_dev [band]", "F_dev [band]"):
            assert a[key][q] == b[key][q], (key, q, a[key][q], b[key][q])
    assert "chi2/dof nan" in (pred / "summary.md").read_text()
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--family", "group", "--predict-with",
                        str(cal / "parameters.csv"), "--out", str(tmp_path / "g")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--family extended" in r.stderr, r.stderr
    assert not (tmp_path / "g").exists()   # the refused file leaves no empty folder behind (eighteenth round)
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--family", "group", "--calibrate-on",
                        "TC_s3_loose", "--start", start, "--state-limit", "volume", "--out", str(tmp_path / "h")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--family extended" in r.stderr, r.stderr
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--family", "extended", "--calibrate-on",
                        "TC_s3_loose", "--start", start, "--state-limit", "volume", "--csl", "cubic", "--out",
                        str(tmp_path / "c")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--csl cubic" in r.stderr and "linear" in r.stderr, r.stderr
    assert not (tmp_path / "c").exists()
    # --hold: an extension coefficient held at its start (the start file has no n_rate: the default 1), no error
    # quoted; the free fit above moved it; an unknown name, or the group family, refused before anything is written
    free = {x["parameter"]: x for x in read(cal / "parameters.csv")}
    assert float(free["n_rate"]["value"]) != 1.0 and free["lambda_cs"]["se"] == "nan", free["n_rate"]
    held = tmp_path / "held"
    base = [DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--calibrate-on", "TC_s3_loose", "--start", start,
            "--state-limit", "volume", "--max-iterations", "5", "--hold-isotropic", "gamma_p,nu_cC,alpha"]
    r = subprocess.run(base + ["--family", "extended", "--hold", "n_rate", "--out", str(held)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode in (0, 1), r.stderr
    got = {x["parameter"]: x for x in read(held / "parameters.csv")}
    assert float(got["n_rate"]["value"]) == 1.0 and got["n_rate"]["se"] == "nan", got["n_rate"]
    for extra, want in ((["--family", "extended", "--hold", "n_ratee"], "n_rate"), (["--family", "group", "--hold", "n_rate"],
                                                                                  "--family extended")):
        r = subprocess.run(base + extra + ["--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and want in r.stderr, r.stderr
        assert not (tmp_path / "x").exists()
    # a coefficient the chosen law does not carry (n_rate without the volume-form state parameter) is refused too
    no_volume = [a for a in base if a not in ("--state-limit", "volume")]
    r = subprocess.run(no_volume + ["--family", "extended", "--hold", "n_rate", "--out", str(tmp_path / "x")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--hold n_rate" in r.stderr and "--state-limit volume" in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()


def test_collect_state_puts_the_state_parameters_runs_beside_the_lab_calibrations(tmp_path):
    head = "mode,nu [-],role,p_star [band],eps_v [band],s_dev [band],F_dev [band],worst [band]\n"
    def summary(d, rows, chi):
        d.mkdir(parents=True)
        (d / "summary.csv").write_text(head + "".join(f"{m},{nu},{role},1,1,1,1,{w}\n" for m, nu, role, w in rows)
                                       + f"calibration,nan,chi2/dof {chi},nan,nan,nan,nan,9\n")
    summary(tmp_path / "lab_dense", [("TC_s3_dense", "0.66", "fitted", "2.1"), ("TC_p_dense", "0.66", "predicted", "nan")], 24)
    summary(tmp_path / "lab_loose", [("TC_s3_loose", "0.59", "fitted", "0.5")], 0.7)
    sv = tmp_path / "state_volume"
    summary(sv / "dense", [("TC_s3_dense", "0.66", "fitted", "1.2"), ("TC_p_dense", "0.66", "predicted", "2.0"),
                           ("D2", "0.74", "predicted", "30")], 16.3)
    summary(sv / "dense_predicts_loose", [("TC_s3_loose", "0.59", "predicted", "1.1")], "nan")
    summary(sv / "loose", [("TC_s3_loose", "0.59", "fitted", "0.35")], 1.15)
    summary(sv / "loose_predicts_dense", [("TC_s3_dense", "0.66", "predicted", "nan")], "nan")
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--collect-state", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    rows = [(x["prep"], x["mode"], x["lab worst [band]"], x["dense-state role"], x["dense-state worst [band]"],
             x["loose-state role"], x["loose-state worst [band]"]) for x in read(sv / "comparison.csv")]
    assert rows == [("dense", "TC_s3_dense", "2.1", "fitted", "1.2", "predicted", "nan"),
                    ("dense", "TC_p_dense", "nan", "predicted", "2.0", "", ""),
                    ("loose", "TC_s3_loose", "0.5", "predicted", "1.1", "fitted", "0.35")], rows
    assert "chi2/dof dense-state 16.3, loose-state 1.15" in (sv / "comparison.md").read_text()
    (sv / "loose" / "summary.csv").unlink()
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--collect-state", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "state_volume/loose/summary.csv" in r.stderr, r.stderr


def test_d2_lode_sets_the_stress_lode_parameter_of_d2_curves_and_round_trips(tmp_path):
    """`--d2-lode` (thirteenth round) on the stored mu = 0.5 dense calibration predicting the friction study's D2/D3:
    a number moves the D2 and isobaric D2 predictions only (D3 and the laboratory tests keep their numbers), is written
    as b_D2 and read back by --predict-with; `normal` gives the plane-strain b of the Lade-Duncan surface through the
    file's s_max_a, which demkit.geotech_cv's independent root agrees with; bad values, and `normal` with D2 curves
    in the calibration, are refused before anything is written."""
    from demkit import geotech, geotech_cv
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech", "curves"),
                        "--mu", "0.5", "--out", str(tmp_path / "m"), "--tests", "TC_s3", "--friction",
                        os.path.join(ROOT, "data", "friction_n1000", "mu_0.5")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    ens = tmp_path / "m" / "ensemble_dense"
    params = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "dense", "parameters.csv")
    base = [DEM, "model", str(ens), "--no-plots", "--family", "extended", "--predict-with"]

    def predict(name, *extra, p=params):
        r = subprocess.run(base + [str(p), "--out", str(tmp_path / name), *extra], capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr
        with open(tmp_path / name / "prediction.csv") as fh:
            return {(x["mode"], x["nu"], x["quantity"]): float(x["rms_over_band [-]"]) for x in csv.DictReader(fh)}

    half, num, normal = predict("half"), predict("num", "--d2-lode", "0.33"), predict("normal", "--d2-lode", "normal")
    assert set(half) == set(num) and any(k[0] == "D2" for k in half) and any(k[0] == "D3" for k in half)
    for k in half:
        if k[0] in ("D2", "isobaric_D2") and k[2] == "s_dev":
            assert num[k] != half[k], k
        elif k[0] not in ("D2", "isobaric_D2"):
            assert num[k] == half[k], k
    got = {x["parameter"]: x["value"] for x in read(tmp_path / "num" / "parameters.csv")}
    assert float(got["b_D2"]) == 0.33 and "b_D2" not in {x["parameter"] for x in read(tmp_path / "half" / "parameters.csv")}
    assert predict("again", p=tmp_path / "num" / "parameters.csv") == num   # the file's b_D2 read back
    values = {x["parameter"]: float(x["value"]) for x in read(tmp_path / "normal" / "parameters.csv")}
    s = values["s_max_a"]   # the surface through q/p = s at b = 1/2, as its triaxial-compression friction
    k = 1 / math.sqrt(0.75)
    const = geotech.criterion("LD", 1 + s * 0.5 * k, 1.0, 1 - s * 0.5 * k)
    b = geotech_cv.plane_strain_b("LD", geotech.predicted_sin_phi("LD", const, 0.0))
    assert values["b_D2"] == pytest.approx(b, abs=1e-5)
    assert 0.25 < values["b_D2"] < 0.45
    for bad, want in ((["--d2-lode", "1.5"], "--d2-lode 1.5"), (["--d2-lode", "half"], "--d2-lode half")):
        r = subprocess.run(base + [params, "--out", str(tmp_path / "x")] + bad, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and want in r.stderr, r.stderr
        assert not (tmp_path / "x").exists()
    r = subprocess.run([DEM, "model", str(ens), "--no-plots", "--no-jackknife", "--family", "extended", "--calibrate-on",
                        "D2", "--d2-lode", "normal", "--out", str(tmp_path / "y")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--d2-lode normal" in r.stderr and "give --d2-lode a number" in r.stderr, r.stderr
    assert not (tmp_path / "y").exists()


def test_a_curve_the_model_diverges_along_is_inf_and_counts_in_the_worst(tmp_path):
    """Thirteenth round: a curve the model diverges along is "inf" in its cells and in the calibration row's worst
    (it was nan and left out of the worst). The stored three-pressure mu = 0.1 calibration diverged so until the
    fourteenth round's shape cap; here a copy of it with a steep psi-law of the anisotropy modulus (a_A_b = -200,
    stored -16: a_A turns negative on the dense side) read with unbounded laws (--no-psi-range) diverges along the
    dense tests. With the file's psi range the same file gives every curve a finite number, none silently nan."""
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech", "curves"),
                        "--mu", "0.1", "--out", str(tmp_path / "m"), "--levels", "iso_lo,iso_hi,iso_vhi", "--joint",
                        "--tests", "TC_s3,TC_p"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    stored = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "three_pressures", "mu_0.1", "joint",
                          "parameters.csv")
    with open(stored, newline="") as f:
        table = list(csv.reader(f))
    steep = [row[:2] + ["-200"] + row[3:] if row[0] == "a_A_b" else row for row in table]
    assert steep != table
    params = tmp_path / "steep.csv"
    with open(params, "w", newline="") as f:
        csv.writer(f).writerows(steep)
    base = [DEM, "model", str(tmp_path / "m" / "ensemble_joint"), "--no-plots", "--family", "extended", "--predict-with",
            str(params)]
    r = subprocess.run(base + ["--no-psi-range", "--out", str(tmp_path / "free")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    rows = {(x["mode"], x["nu [-]"]): x for x in read(tmp_path / "free" / "summary.csv")}
    bad = [k for k, x in rows.items() if x["worst [band]"] == "inf"]
    assert ("TC_p_dense", "0.6576") in bad, rows
    assert rows[("calibration", "nan")]["worst [band]"] == "inf"
    assert "not finite" in r.stderr
    r = subprocess.run(base + ["--out", str(tmp_path / "range")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    for x in read(tmp_path / "range" / "summary.csv"):
        assert x["worst [band]"] not in ("nan", "inf") or x["mode"] == "calibration", x   # every curve a number
    assert "not finite" not in r.stderr


def test_no_stored_state_calibration_quotes_a_coefficient_as_exact():
    """A covariance error of 0 to rounding is a direction the curves do not see (thirteenth round): every stored
    volume-state parameters.csv of README step 8 on (the starts of earlier rounds kept as they were) quotes such a
    coefficient as nan, never as an error below 1e-9 of its value."""
    import glob
    files = [f for f in glob.glob(os.path.join(ROOT, "data", "geotech", "model", "state_volume", "**", "parameters.csv"),
                                  recursive=True)
             if not any(old in f for old in ("tenth_round", "eleventh_round"))]   # earlier rounds' starts, as they were
    assert len(files) >= 10
    for f in files:
        for x in read(f):
            se = float(x["se_covariance"]) if x.get("se_covariance") not in (None, "", "nan") else math.nan
            if math.isfinite(se):
                assert se > 1e-9 * max(1.0, abs(float(x["value"]))), (f, x["parameter"], se)


def test_a_path_the_laws_cannot_start_is_not_determined_not_diverged(tmp_path):
    """Seventeenth round: the friction study's mu = 0.5 laws (nu_c = 0.5990) predicting the loose TC_s3 tests: the one
    at p* = 1e-3 starts at nu = 0.5928, below nu_c, so the laws cannot start it. Its summary row says so in its role and
    is "nan" (not determined) in every cell, it does not make the calibration row's worst "inf", and no curve is called
    diverged; the p* = 1e-2 test (nu = 0.6185) is predicted and judged, and is the worst. That one crosses the law's
    cusp at nu_cC, and is said to; with the fractions tied it is not."""
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech", "curves"),
                        "--mu", "0.5", "--out", str(tmp_path / "m"), "--tests", "TC_s3"], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    law = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "mu_0.5", "parameters.csv")
    r = subprocess.run([DEM, "model", str(tmp_path / "m" / "ensemble_loose"), "--no-plots", "--family", "extended",
                        "--predict-with", law, "--out", str(tmp_path / "p")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "cannot be integrated" in r.stderr and "not finite" not in r.stderr
    rows = {(x["mode"], x["nu [-]"]): x for x in read(tmp_path / "p" / "summary.csv")}
    low, high = rows[("TC_s3_loose", "0.5928")], rows[("TC_s3_loose", "0.6185")]
    assert "not integrable" in low["role"]
    assert [low[k] for k in ("p_star [band]", "eps_v [band]", "s_dev [band]", "F_dev [band]", "worst [band]")] == ["nan"] * 5
    worst = float(high["worst [band]"])
    assert math.isfinite(worst) and float(rows[("calibration", "nan")]["worst [band]"]) == worst
    # the p* = 1e-2 path dilates through nu_cC = 0.6100 (above nu_c): the law's cusp, named with the fix; a copy of the
    # law with the two fractions tied (nu_cC = nu_c) predicts it without the warning
    with open(tmp_path / "p" / "curves" / "paths" / "TC_s3_loose_phi0.618.csv") as fh:
        nu = [float(x["nu_model"]) for x in csv.DictReader(ln for ln in fh if not ln.startswith("#"))]
    law_rows = read(law)
    v = {x["parameter"]: x["value"] for x in law_rows}
    assert min(nu) < float(v["nu_cC"]) < max(nu) and float(v["nu_c"]) < float(v["nu_cC"])
    cusp = f"TC_s3_loose (predicted) crosses the isotropic law's cusp (nu = nu_cC = {float(v['nu_cC']):.6g}"
    assert cusp in r.stderr, r.stderr
    assert "--jamming shared" in r.stderr
    with open(law, newline="") as fh:
        table = list(csv.reader(fh))
    tied = tmp_path / "tied.csv"
    with open(tied, "w", newline="") as fh:
        csv.writer(fh).writerows([row[:2] + [v["nu_c"]] + row[3:] if row[0] == "nu_cC" else row for row in table])
    r = subprocess.run([DEM, "model", str(tmp_path / "m" / "ensemble_loose"), "--no-plots", "--family", "extended",
                        "--predict-with", str(tied), "--out", str(tmp_path / "t")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0 and "cusp" not in r.stderr, r.stderr


def stored_lab_ensemble(tmp_path, mu, test, prep):
    """The stored laboratory curves of one test at friction mu as a path ensemble (demkit.geotech_model) in TMP/m;
    returns its ensemble_PREP folder."""
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech", "curves"),
                        "--mu", mu, "--out", str(tmp_path / "m"), "--tests", test], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return str(tmp_path / "m" / f"ensemble_{prep}")


def test_a_relaxing_anisotropic_pressure_ends_the_constant_p_runaway(tmp_path):
    """Eighteenth round: the stored mu = 0.5 loose calibration (README step 8, the anisotropy's pressure permanent)
    predicting the loose constant-p triaxial compression at p* = 1e-3: the model's nu still moves at the end (over the
    last 0.1 of strain more than 100 times the DEM's drift) and ends far from its own critical-state line; its restart
    with `--anisotropy-pressure relaxing` (step 11; parameters.csv carries the row anisotropy_excess) ends on the line
    and as still as the DEM. demkit.model_excess reads the ends as computed here by hand; the written parameters.csv
    round-trips through --predict-with; the flag overrides the file's law (permanent brings the drift back); the flag
    without the volume-form state parameter, or unknown, is refused."""
    from demkit import model_excess as mx
    ens = stored_lab_ensemble(tmp_path, "0.5", "TC_p", "loose")
    sv = os.path.join(ROOT, "data", "geotech", "model", "state_volume")
    laws = {"permanent": os.path.join(sv, "loose", "parameters.csv"),
            "relaxing": os.path.join(sv, "relaxing_excess", "loose", "parameters.csv")}
    assert "anisotropy_excess" in [x["parameter"] for x in read(laws["relaxing"])]
    assert "anisotropy_excess" not in [x["parameter"] for x in read(laws["permanent"])]

    def predict(law, out, *extra):
        r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", law, *extra,
                            "--out", str(tmp_path / out)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        predict.stderr = r.stderr
        return str(tmp_path / out)

    ends = {}
    for way, law in laws.items():
        out = predict(law, way)
        # the permanent law's runaway is named on stderr, with the fix; the relaxing law's paths are not
        named = "TC_p_loose nu=0.5928 (predicted) still moves at its end" in predict.stderr
        assert named == (way == "permanent") and ("--anisotropy-pressure relaxing" in predict.stderr) == named, predict.stderr
        P = mx.values(law)
        with open(os.path.join(out, "curves", "paths", "TC_p_loose_phi0.593.csv")) as fh:
            c = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
        eps = [float(x["eps_d_accumulated"]) for x in c]
        nu = [float(x["nu_model"]) for x in c]
        dem = [nu[0] * math.exp(-3 * float(x["eps_v_mean"])) for x in c]
        i = max(j for j in range(len(eps)) if eps[j] <= eps[-1] - 0.1)
        p_end = float(c[-1]["p_star_model"])
        psi = nu[-1] - (P["nu_cs"] + P["lambda_cs"] * math.log(p_end / 1e-3) + P["c_cs"] * (p_end - 1e-3))
        drift, drift_dem = (abs(v[-1] - v[i]) / (eps[-1] - eps[i]) for v in (nu, dem))
        got = {n: (x, m, d) for n, x, m, d in mx.path_ends(out, P)}["TC_p_loose_phi0.593"]
        assert got == pytest.approx((psi, drift, drift_dem), rel=1e-12)
        ends[way] = (psi, drift, drift_dem)
    psi, drift, drift_dem = ends["permanent"]
    assert drift > 100 * drift_dem and drift > 0.01 and abs(psi) > 0.01, ends
    psi, drift, drift_dem = ends["relaxing"]
    assert drift < 10 * drift_dem + 1e-3 and abs(psi) < 1e-3, ends
    again = predict(os.path.join(str(tmp_path / "relaxing"), "parameters.csv"), "again")
    assert summary_rows(os.path.join(again, "summary.csv")) == summary_rows(str(tmp_path / "relaxing" / "summary.csv"))
    back = predict(laws["relaxing"], "back", "--anisotropy-pressure", "permanent")
    assert "anisotropy_excess" not in [x["parameter"] for x in read(os.path.join(back, "parameters.csv"))]
    assert mx.path_ends(back, mx.values(laws["relaxing"]))[0][2] > 0.01
    # step 11's extra starts: each stored file with ln_beta_p_a set to ln 30 and ln 200, every other cell the same
    mx.make_starts(sv, str(tmp_path / "starts"))
    for name in mx.LAB:
        orig = list(csv.reader(open(os.path.join(sv, name, "parameters.csv"))))
        for b in mx.BETA_P_STARTS:
            new = list(csv.reader(open(tmp_path / "starts" / name / f"beta_p_{b:g}.csv")))
            assert len(new) == len(orig)
            for x, y in zip(orig, new):
                assert x == y if x[0] != "ln_beta_p_a" else (x[:2] + x[3:] == y[:2] + y[3:] and float(y[2]) == math.log(b))
    bad = [([DEM, "model", ens, "--no-plots", "--family", "extended", "--calibrate-on", "TC_p_loose", "--start",
             laws["permanent"], "--anisotropy-pressure", "relaxing"], "add --state-limit volume"),
           ([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with",
             os.path.join(ROOT, "data", "friction_n1000", "model_friction", "mu_0.5", "parameters.csv"),
             "--anisotropy-pressure", "relaxing"], "no volume-form state parameter"),
           ([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", laws["permanent"],
             "--anisotropy-pressure", "elastic"], "--anisotropy-pressure")]
    for k, (cmd, want) in enumerate(bad):
        r = subprocess.run(cmd + ["--out", str(tmp_path / f"x{k}")], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and want in r.stderr, r.stderr
        assert not (tmp_path / f"x{k}").exists()


def test_a_relaxing_excess_above_the_pressure_is_named_and_written(tmp_path):
    """Nineteenth round: with the relaxing law the elastic state sits at p* - q. The stored mu = 1 dense relaxing
    calibration (README step 11) predicting the dense drained compression at p* = 1e-3 carries an excess q above p*
    (its elastic state below the isotropic law's jamming fraction): the path curve's column q_star_model holds q, the
    largest q/p* computed here from it is above 1, and dem model names the path with that ratio. The permanent
    calibration it restarted from has no such column and no such warning."""
    ens = stored_lab_ensemble(tmp_path, "1", "TC_s3", "dense")
    sv = os.path.join(ROOT, "data", "geotech", "model", "state_volume")
    out = {}
    for way, law in (("relaxing", os.path.join(sv, "relaxing_excess", "mu_1", "dense", "parameters.csv")),
                     ("permanent", os.path.join(sv, "mu_1", "dense", "parameters.csv"))):
        r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", law,
                            "--out", str(tmp_path / way)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        out[way] = r.stderr
    curve = tmp_path / "relaxing" / "curves" / "paths" / "TC_s3_dense_phi0.658.csv"
    c = read(curve)
    ratio = max(float(x["q_star_model"]) / float(x["p_star_model"]) for x in c)
    assert ratio > 1
    line = next(l for l in out["relaxing"].splitlines() if l.startswith("dem model: warning: TC_s3_dense") and "times p*" in l)
    assert float(line.split("excess q up to ")[1].split(" times")[0]) == pytest.approx(ratio, rel=5e-3), line
    assert "below the isotropic law's jamming fraction" in line
    assert "times p*" not in out["permanent"]
    assert "q_star_model" not in read(tmp_path / "permanent" / "curves" / "paths" / "TC_s3_dense_phi0.658.csv")[0]
    # the same law with its excess bounded (--anisotropy-pressure bounded overrides the file's): q below p* on every
    # row, not named; the written parameters.csv says so (anisotropy_excess = 2) and predicts the same again
    law = os.path.join(sv, "relaxing_excess", "mu_1", "dense", "parameters.csv")
    r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", law,
                        "--anisotropy-pressure", "bounded", "--out", str(tmp_path / "bounded")], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and "times p*" not in r.stderr, r.stderr
    c = read(tmp_path / "bounded" / "curves" / "paths" / "TC_s3_dense_phi0.658.csv")
    assert max(float(x["q_star_model"]) / float(x["p_star_model"]) for x in c) < 1
    written = {x["parameter"]: x["value"] for x in read(tmp_path / "bounded" / "parameters.csv")}
    assert float(written["anisotropy_excess"]) == 2
    r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with",
                        str(tmp_path / "bounded" / "parameters.csv"), "--out", str(tmp_path / "again")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert summary_rows(str(tmp_path / "again" / "summary.csv")) == summary_rows(str(tmp_path / "bounded" / "summary.csv"))
    r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--calibrate-on", "TC_s3_dense",
                        "--start", law, "--anisotropy-pressure", "bounded", "--out", str(tmp_path / "refused")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--anisotropy-pressure bounded" in r.stderr and "add --state-limit volume" in r.stderr
    assert not (tmp_path / "refused").exists()


def test_a_drained_path_that_reaches_the_control_pole_is_named_and_stopped(tmp_path):
    """Twentieth round: a drained triaxial path whose anisotropy modulus A = a_A B F comes within 10 % of 3B (the pole
    of the constant-side-stress control) is not continued. The stored tenth-round loose calibration reaches it on the
    loose TC_s3 test at nu = 0.6185: its model curve is a number up to a row and nan from the next on, dem model names
    the path with the strain of the last row reached, and that curve's error is inf in summary.csv. The other
    pressure's curve is not named and is a number throughout."""
    ens = stored_lab_ensemble(tmp_path, "0.5", "TC_s3", "loose")
    law = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "tenth_round", "loose", "parameters.csv")
    r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", law,
                        "--out", str(tmp_path / "p")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    named = [l for l in r.stderr.splitlines() if "cannot hold its side stress" in l]
    assert len(named) == 1 and named[0].startswith("dem model: warning: TC_s3_loose nu=0.6185"), r.stderr
    assert "came within 10 % of 3B" in named[0]
    at = float(named[0].split("after eps_d_accumulated = ")[1].split(":")[0])
    curves = sorted((tmp_path / "p" / "curves" / "paths").glob("TC_s3_loose_*.csv"))
    assert len(curves) == 2
    for path in curves:
        p = [float(x["p_star_model"]) for x in read(path)]
        acc = [float(x["eps_d_accumulated"]) for x in read(path)]
        finite = [math.isfinite(v) for v in p]
        if "0.618" in path.name:
            k = finite.index(False)
            assert all(finite[:k]) and not any(finite[k:]), path
            assert acc[k - 1] == pytest.approx(at, rel=2e-3)
        else:
            assert all(finite), path
    worst = {(x["mode"], x["nu [-]"]): x["worst [band]"] for x in read(tmp_path / "p" / "summary.csv")}
    assert [w for (m, nu), w in worst.items() if m == "TC_s3_loose" and nu.startswith("0.618")] == ["inf"]
    assert [w for (m, nu), w in worst.items() if m == "TC_s3_loose" and nu.startswith("0.593")] != ["inf"]


def test_the_excess_tables_print_beta_p_with_its_interval_or_its_bound(tmp_path):
    """Twenty-first round: the excess tables (comparison.md, excess_size.md, bounded.md) print beta_p with the 95 %
    interval of ln beta_p from its parameters.csv, the bound where the fit ends within 1 % of one (1e-3 or 300, the
    interval saying nothing there), and 'interval not determined' where the file has none; the interval ends to two
    significant digits without an exponent."""
    from demkit import model_excess as mx
    head = "parameter,law,value,se,se_method,lo95,hi95,se_covariance,se_jackknife,units\n"
    cases = {"inside": (math.log(37.2), 3.0863, 4.14426, "37.2 (22–63)"),
             "wide": (math.log(0.389), -5.62628, 3.73726, "0.389 (0.0036–42)"),
             "lower": (math.log(1.0026e-3), -6.9049, -6.9045, "0.001 (lower bound)"),
             "upper": (math.log(299.9), "nan", "nan", "300 (upper bound)"),
             "none": (math.log(5.0), "nan", "nan", "5 (interval not determined)")}
    for name, (ln_b, lo, hi, want) in cases.items():
        f = tmp_path / f"{name}.csv"
        f.write_text(head + f"a_A_a,a,1.0,0.1,c,0.8,1.2,0.1,nan,-\nln_beta_p_a,b,{ln_b!r},1,c,{lo},{hi},1,nan,-\n")
        bp = math.exp(mx.values(str(f))["ln_beta_p_a"])
        lo_b, hi_b = mx.beta_p_interval(str(f))
        assert mx.beta_p_cell(bp, lo_b, hi_b) == want, name
        if isinstance(lo, float):
            assert (lo_b, hi_b) == pytest.approx((math.exp(lo), math.exp(hi)), rel=1e-12)
    assert [mx.plain(v) for v in (0.0065, 42.4, 166.0, 1e-6 * 5.67, 4400.0)] == ["0.0065", "42", "170", "0.0000057", "4400"]
    # the stored tables carry the new column and print the same cells as made here from the stored parameters
    sv = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "bounded_excess")
    with open(os.path.join(sv, "bounded.csv"), newline="") as fh:
        rows = {r["calibration"]: r for r in csv.DictReader(fh)}
    lo_b, hi_b = mx.beta_p_interval(os.path.join(sv, "loose", "parameters.csv"))
    assert float(rows["loose"]["beta_p_lo95_bounded [1/eps_d]"]) == pytest.approx(lo_b, rel=1e-12)
    cell = mx.beta_p_cell(float(rows["loose"]["beta_p_bounded [1/eps_d]"]), lo_b, hi_b)
    assert f"| {cell} |" in open(os.path.join(sv, "bounded.md")).read()


def test_a_calibration_against_the_control_margin_is_named_and_a_last_digit_loses_it(tmp_path):
    """Twenty-first round: the bounded three-pressure mu = 0.1 joint calibration (README step 12) takes the dense TC_s3
    test at nu = 0.6816 to a_A F/3 = 0.8999989, 1e-6 below 0.9 where the drained control is given up: its optimum sits
    against that margin. The path curve's pole_ratio_model equals a_A(psi) F/3 recomputed here from the curve's own
    columns and the parameters (a_A = a_A_a + a_A_b psi, psi = nu - nu_cs(p*) clamped to [psi_min, psi_max]); dem model
    names that path, with its largest ratio, and no other; a_A_a larger by twice the ratio's distance to the margin
    loses the path (2 parts in 10^6 before the thirty-sixth round, 8 parts in 10^5 since its graded start)."""
    from demkit import model_excess as mx
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech",
                        "curves"), "--mu", "0.1", "--out", str(tmp_path / "m"), "--tests", "TC_s3", "--levels",
                        "iso_lo,iso_hi,iso_vhi"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    ens = str(tmp_path / "m" / "ensemble_dense")
    law = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "bounded_excess", "three_pressures", "mu_0.1",
                       "joint", "parameters.csv")

    def predict(parameters, out):
        r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", "--predict-with", parameters,
                            "--out", str(tmp_path / out)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        return r.stderr

    err = predict(law, "p")
    named = [l for l in err.splitlines() if "of where its drained control is lost" in l]
    assert len(named) == 1 and named[0].startswith("dem model: warning: TC_s3_dense nu=0.6816 (predicted)"), err
    said = float(named[0].split("a_A F/3 = ")[1].split(" ")[0])
    P = mx.values(law)
    for path in sorted((tmp_path / "p" / "curves" / "paths").glob("TC_s3_dense_*.csv")):
        rows = read(path)
        ratios = []
        for x in rows[1:]:
            nu, p, F = float(x["nu_model"]), float(x["p_star_model"]), float(x["F_dev_model"])
            psi = min(max(nu - mx.nu_cs(P, p), P["psi_min"]), P["psi_max"])
            want = (P["a_A_a"] + P["a_A_b"] * psi) * F / 3
            assert float(x["pole_ratio_model"]) == pytest.approx(want, rel=1e-6, abs=1e-9), (path.name, x)
            ratios.append(float(x["pole_ratio_model"]))
        if "0.682" in path.name:
            assert max(ratios) == pytest.approx(said, abs=1e-8) and 0.899 <= said < 0.9
        else:
            assert max(ratios) < 0.899, path.name
    # a_A_a raised by twice the ratio's distance to the margin (1 + 2e-6 until the thirty-sixth round's graded start
    # moved the largest ratio from 0.8999989 to 0.8999632)
    edited = scaled_copy(law, "a_A_a", 1 + 2 * (0.9 - said) / said + 2e-6, tmp_path / "edited.csv")
    err = predict(str(edited), "q")
    assert "TC_s3_dense nu=0.6816 (predicted) cannot hold its side stress" in err, err
    # a calibration from the stored optimum (one iteration, on the dense and loose tests it was calibrated on) names the
    # fitted path and says that its errors describe the margin
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech",
                        "curves"), "--mu", "0.1", "--out", str(tmp_path / "j"), "--tests", "TC_s3", "--levels",
                        "iso_lo,iso_hi,iso_vhi", "--joint"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([DEM, "model", str(tmp_path / "j" / "ensemble_joint"), "--start", law, "--calibrate-on",
                        "TC_s3_dense,TC_s3_loose", "--family", "extended", "--state-limit", "volume", "--hold-isotropic",
                        "gamma_p,nu_cC,alpha", "--anisotropy-pressure", "bounded", "--max-iterations", "1",
                        "--no-jackknife", "--no-plots", "--out", str(tmp_path / "fit")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode in (0, 1), r.stderr
    assert "TC_s3_dense nu=0.6816 (fitted) comes within" in r.stderr and "optimum sits against that margin" in r.stderr
    pinned = [l for l in r.stderr.splitlines() if "the optimum sits against the drained control's margin on" in l]
    assert len(pinned) == 1 and "TC_s3_dense nu=0.6816" in pinned[0] and "not how the data determine" in pinned[0]
    for x in read(tmp_path / "fit" / "parameters.csv"):
        if x["parameter"] in ("p0", "a_A_a", "s_max_a", "n_dil"):   # quoted as not determined, the numbers kept beside
            assert math.isnan(float(x["se"])) and math.isnan(float(x["lo95"])), x
            assert x["se_method"].startswith("not determined: the optimum sits against the drained control's margin")
            assert float(x["se_covariance"]) > 0, x


def test_a_cost_that_is_not_smooth_at_its_optimum_quotes_no_errors(tmp_path):
    """Twenty-second round: the relaxing three-pressure mu = 0.5 dense calibration (README step 11) takes its fitted
    dense TC_s3 test at nu = 0.6576 to an excess q above p*, so that the elastic state falls below the law's jamming
    fraction and through the coordination law's nu_cC, where the bulk modulus is unbounded ((nu/nu_cC - 1)^(alpha - 1),
    alpha < 1). The fixed-step path moved by more than 10^-3 in s_dev when nu_c changed in its twelfth digit; since
    the thirty-sixth round's step control it does not move (seen here from two predictions, outside the check). dem
    model's Jacobian check still finds nu_c's column off (every column before), names the cusp's elastic pressure p_iso(nu_cC) (computed here
    from the law its one iteration ended at), and quotes no error (se nan, the covariance's number kept in
    se_covariance). The bounded calibration of the same data is smooth and quotes them."""
    from demkit import model_excess as mx
    r = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech",
                        "curves"), "--mu", "0.5", "--out", str(tmp_path / "m"), "--tests", "TC_s3", "--levels",
                        "iso_lo,iso_hi,iso_vhi"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    ens = str(tmp_path / "m" / "ensemble_dense")
    sv = os.path.join(ROOT, "data", "geotech", "model", "state_volume")
    law = os.path.join(sv, "relaxing_excess", "three_pressures", "dense", "parameters.csv")

    def dem(*args, out):
        r = subprocess.run([DEM, "model", ens, "--no-plots", "--family", "extended", *args, "--out", str(tmp_path / out)],
                           capture_output=True, text=True, timeout=300)
        return r

    edited = scaled_copy(law, "nu_c", 1 + 1e-12, tmp_path / "edited.csv")
    s = {}
    for name, parameters in (("stored", law), ("edited", str(edited))):
        p = dem("--predict-with", parameters, out=name)
        assert p.returncode == 0, p.stderr
        s[name] = [float(x["s_dev_model"]) for x in read(tmp_path / name / "curves" / "paths" / "TC_s3_dense_phi0.658.csv")]
    # until the thirty-sixth round's step control the fixed-step path moved by more than 1e-3 here; now RK4's steps are
    # halved where the cusp makes the law stiff, and the path does not move
    assert max(abs(a - b) for a, b in zip(s["stored"], s["edited"])) < 1e-6, "a last digit of nu_c moves the path"

    fit = ["--calibrate-on", "TC_s3_dense", "--state-limit", "volume", "--hold-isotropic", "gamma_p,nu_cC,alpha",
           "--max-iterations", "1", "--no-jackknife"]
    r = dem("--start", law, "--anisotropy-pressure", "relaxing", *fit, out="rough")
    assert r.returncode == 1, r.stderr   # one iteration: not converged, its tables written
    assert "the cost is not smooth at the optimum" in r.stderr, r.stderr
    line = next(l for l in r.stderr.splitlines() if "largest disagreement" in l)
    assert float(line.split("largest disagreement ")[1].split(" ")[0]) > 0.1 and "not smooth" in line, line
    P = mx.values(str(tmp_path / "rough" / "parameters.csv"))   # the law the one iteration ended at, which it names
    x = math.log(P["nu_cC"] / P["nu_c"])
    p_cusp = P["p0"] * (P["nu_cC"] * P["C0"] / P["nu_c"]) * x * (1 + P["gamma_p"] * x)   # C = C0 at nu_cC
    cusp = next(l for l in r.stderr.splitlines() if "TC_s3_dense (fitted) crosses the isotropic law's cusp" in l)
    assert float(cusp.split("elastic p* - q = ")[1].split(",")[0]) == pytest.approx(p_cusp, rel=1e-5), cusp
    assert p_cusp < 0 and "below the law's jamming fraction" in cusp
    from demkit import model_smoothness as ms   # the stored table's reader, on this log
    (tmp_path / "rough.log").write_text(r.stderr)
    got = ms.parse(str(tmp_path / "rough.log"))
    assert got["smooth"] is False and got["largest"] == float(line.split("largest disagreement ")[1].split(" ")[0])
    # every column was off with the fixed step; with the step control nu_c's, the law's cusp itself, still is
    assert 1 <= got["above"] <= got["checked"] and got["checked"] > 10, got
    assert got["cusp"] == "TC_s3_dense" and got["margin"] == "" and got["coefficient"] == "nu_c", got
    assert got["coefficient"] == line.split("(")[1].split(";")[0] and math.isfinite(got["chi2"]), got
    rows_ = {x["parameter"]: x for x in read(tmp_path / "rough" / "parameters.csv")}
    for name in ("p0", "C0", "a_A_a", "ln_beta_p_a", "n_peak"):
        assert rows_[name]["se"] == "nan" and rows_[name]["lo95"] == "nan", rows_[name]
        assert rows_[name]["se_method"].startswith("not determined: the cost is not smooth at the optimum"), rows_[name]
        assert math.isfinite(float(rows_[name]["se_covariance"])), rows_[name]

    bounded = os.path.join(sv, "bounded_excess", "three_pressures", "dense", "parameters.csv")
    r = dem("--start", bounded, "--anisotropy-pressure", "bounded", *fit, out="smooth")
    assert "not smooth" not in r.stderr, r.stderr
    line = next(l for l in r.stderr.splitlines() if "largest disagreement" in l)
    assert float(line.split("largest disagreement ")[1].split(" ")[0]) < 1e-4 and "; smooth;" in line, line
    (tmp_path / "smooth.log").write_text(r.stderr)
    got = ms.parse(str(tmp_path / "smooth.log"))
    assert got["smooth"] is True and got["above"] == 0 < got["checked"] and got["cusp"] == "" and got["largest"] < 1e-4, got
    rows_ = {x["parameter"]: x for x in read(tmp_path / "smooth" / "parameters.csv")}
    assert float(rows_["a_A_a"]["se"]) > 0 and rows_["a_A_a"]["se_method"].startswith("covariance"), rows_["a_A_a"]
    # the cost over one quoted error (twenty-third round): a row per quoted coefficient, the worst pair on stderr
    scale = {x["parameter"]: x for x in read(tmp_path / "smooth" / "error_scale.csv")}
    quoted = [n for n, x in rows_.items() if x["se"] not in ("nan", "") and x["se_method"].startswith("covariance")]
    assert sorted(n for n, x in scale.items() if x["quoted"] == "yes") == sorted(quoted)
    assert got["quoted"] == len(quoted) and got["rise_coefficient"] in quoted, got
    worst = scale[got["rise_coefficient"]]
    assert float(worst["chi2_rise_minus [-]"]) == pytest.approx(got["rise_minus"], rel=1e-2, nan_ok=True), (worst, got)
    rises = [(float(scale[n]["chi2_rise_minus [-]"]), float(scale[n]["chi2_rise_plus [-]"])) for n in quoted]
    assert got["rise_below"] == sum(1 for m, p in rises if m < 0.5 or p < 0.5), (rises, got)
    assert got["rise_above"] == sum(1 for m, p in rises if m > 2 or p > 2), (rises, got)
    assert got["rise_bound"] == sum(1 for m, p in rises if math.isnan(m) or math.isnan(p)), (rises, got)
    assert ms.parse(str(tmp_path / "rough.log"))["quoted"] == 0   # no error quoted on the rough cost


def test_a_start_pressure_above_the_isotropic_laws_reach_is_named(tmp_path):
    """Twenty-second round: the bounded mu = 1 dense calibration of that round (README step 12 with --coordination
    free, kept in bounded_excess/twenty_second_round/) has a
    coordination law that falls with the density (C1 < 0), so its isotropic pressure peaks below nu = 1 (the peak
    found here on a fine grid from the file's law). The friction study's D2 and D3 at nu = 0.80 start above that peak:
    no elastic state holds their pressure. dem model names both, with the law's largest pressure and where it lies,
    and no curve that starts below it."""
    from demkit import model_excess as mx
    law = os.path.join(ROOT, "data", "geotech", "model", "state_volume", "bounded_excess", "twenty_second_round",
                       "mu_1", "dense", "parameters.csv")
    P = mx.values(law)

    def p_iso(nu):
        base = nu / P["nu_cC"] - 1
        C = P["C0"] + (P["C1"] * base ** P["alpha"] if base > 0 else 0)
        x = math.log(nu / P["nu_c"])
        return P["p0"] * (nu * C / P["nu_c"]) * x * (1 + P["gamma_p"] * x)

    grid = [P["nu_c"] + (1 - P["nu_c"]) * i / 20000 for i in range(20001)]
    top = max(p_iso(nu) for nu in grid)
    assert P["C1"] < 0 and top > p_iso(1.0)
    friction = os.path.join(ROOT, "data", "friction_n1000", "mu_1")
    r = subprocess.run([DEM, "model", friction, "--predict-with", law, "--family", "extended", "--no-plots", "--out",
                        str(tmp_path / "p")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    named = [l for l in r.stderr.splitlines() if "above the isotropic law's reach" in l]
    starts = {}
    for f in sorted((tmp_path / "p" / "curves").glob("D*_phi*.csv")):
        first = read(f)[0]
        starts[f.name] = float(first["p_star_mean"])
    above = sorted(n for n, p in starts.items() if p > top)
    assert above == ["D2_phi0.800.csv", "D3_phi0.800.csv"], starts
    assert len(named) == 2 and all("nu=0.8 (predicted)" in l for l in named), named
    said = float(named[0].split("its largest p* on [nu_c, 1] is ")[1].split(" ")[0])
    assert said == pytest.approx(top, rel=1e-3), (said, top)
    for f in above:
        rows_ = read(tmp_path / "p" / "curves" / f)
        assert all(math.isnan(float(x["p_star_model"])) for x in rows_[1:]), f


def test_the_smoothness_table_restarts_each_calibration_with_its_own_options(tmp_path):
    """demkit.model_smoothness restarts each stored calibration with the options of the README step that made it
    (steps 8, 11, 12; with --tied steps 10-12's one-fraction ones), one iteration, and writes what parse reads."""
    from demkit import model_smoothness as ms
    c = ms.command("dem", "S", "relaxing", "loose", "out")
    assert c[c.index("--start") + 1] == os.path.join("S", "relaxing_excess", "loose", "parameters.csv")
    assert c[c.index("--calibrate-on") + 1] == "TC_s3_loose" and c[-2:] == ["--hold", "n_rate"]
    assert c[c.index("--anisotropy-pressure") + 1] == "relaxing" and c[c.index("--max-iterations") + 1] == "1"
    assert c[c.index("--hold-isotropic") + 1] == "gamma_p,nu_cC,alpha" and "--jamming" not in c
    c = ms.command("dem", "S", "permanent", "three_pressures/mu_1/joint", "out", tied=True)
    assert c[c.index("--start") + 1] == os.path.join("S", "jamming_shared", "three_pressures/mu_1/joint", "parameters.csv")
    assert c[c.index("--calibrate-on") + 1] == "TC_s3_dense,TC_s3_loose" and "--anisotropy-pressure" not in c
    assert c[c.index("--hold-isotropic") + 1] == "gamma_p,alpha" and c[c.index("--jamming") + 1] == "shared"
    assert c[2] == ms.ENSEMBLE["three_pressures/mu_1/joint"]
    assert c[c.index("--coordination") + 1] == "free"   # as every fit before the twenty-third round
    assert "--coordination" not in ms.command("dem", "S", "bounded", "dense", "out", free=False)
    for c1, free in (("-7.07", True), ("3.2", True), ("0", False)):
        f = tmp_path / f"p{c1}.csv"
        f.write_text(f"parameter,law,value\np0,x,0.05\nC1,x,{c1}\n")
        assert ms.coordination_free(str(f)) is free, c1
    rows_ = [["bounded", "mu_1/dense", float("inf"), "p0", 20, 20, "no", 17.0, "", "TC_s3_dense", 0, 0, 0, 0, "",
              float("nan"), float("nan")],
             ["relaxing", "dense", 3e-7, "n_F_b", 0, 21, "yes", 7.58, "TC_s3_dense", "", 19, 1, 5, 2, "C0", 0.31, 15.7]]
    ms.write(rows_, str(tmp_path))
    md = (tmp_path / "smoothness.md").read_text()
    assert ("| bounded | mu_1/dense | inf (a stepped point not evaluated) (p0) | 20 of 20 | no | 17 | — | TC_s3_dense "
            "| 0 | — | — | — | — |") in md
    assert ("| relaxing | dense | 3e-07 (n_F_b) | 0 of 21 | yes | 7.58 | TC_s3_dense | — | 19 | 1 | 5 | 2 | "
            "0.31, 15.7 (C0) |") in md
    back = read(tmp_path / "smoothness.csv")
    assert back[0]["largest_disagreement [-]"] == "inf" and back[1]["smooth"] == "yes"


def mirrored_coordination(src, dst, factor):
    """A copy of the friction study's ensemble directory src at dst whose isotropic branch's C_nonrattler falls with the
    density: each jammed point's C mirrored about the branch's mid-range m and scaled (C' = m - factor (C - m), m over
    every member's jammed rows), pressures untouched."""
    import shutil
    shutil.copytree(src, dst)
    files = sorted(dst.glob("members/*/prep/cycle_unloading.csv"))
    tables = []
    for f in files:
        lines = f.read_text().splitlines()
        head = [l for l in lines if l.startswith("#")]
        rows = list(csv.DictReader(l for l in lines if not l.startswith("#")))
        tables.append((f, head, rows))
    jammed = [float(r["C_nonrattler"]) for _, _, rows in tables for r in rows if float(r["p_star"]) > 1e-7]
    top, bottom = max(jammed), min(jammed)
    for f, head, rows in tables:
        for r in rows:
            if float(r["p_star"]) > 1e-7:
                middle = (top + bottom) / 2
                r["C_nonrattler"] = repr(middle - factor * (float(r["C_nonrattler"]) - middle))
        with open(f, "w", newline="") as fh:
            fh.write("\n".join(head) + "\n")
            w = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)
    return dst


def test_the_coordination_law_rises_unless_told_otherwise(tmp_path):
    """Twenty-third round: a fitted coordination law C(nu) = C0 + C1 (nu/nu_cC - 1)^alpha keeps C1 >= 0 by default
    (--coordination rising). On the friction study's mu = 0.1 ensemble, whose branch's C rises, the bound is not
    reached and the fit is bit for bit the one without it (--coordination free). With the branch's C mirrored so that it
    falls with the density (mirrored about its mid-range, at half the slope), the free fit follows it (C1 < 0), and
    the default stops at C1 = 0 exactly, names the bound with the branch's C at its ends, and quotes no error for C1,
    nu_cC and alpha. (mu = 0.5 until the thirty-seventh round: its group fit's excess pressure relaxes stiffly there,
    beta_p up to 4e5, and under the step control the four fits took 16 times as long; the coordination law is
    fitted the same way at either.)"""
    src = os.path.join(ROOT, "data", "friction_n1000", "mu_0.1")
    falling = mirrored_coordination(pathlib.Path(src), tmp_path / "falling", 0.5)

    def fit(data, name, *extra, converged=True):
        out = tmp_path / name
        # the group family: the coordination law is in the isotropic block both families fit, and the group's fit is
        # the faster (the extended one starts from it)
        r = subprocess.run([DEM, "model", str(data), "--family", "group", "--no-jackknife", "--no-plots", "--out",
                            str(out), *extra], capture_output=True, text=True, timeout=600)
        assert r.returncode in ((0,) if converged else (0, 1)), r.stderr   # 1: not converged, its tables written
        return {x["parameter"]: x for x in read(out / "parameters.csv")}, r.stderr

    # 30 iterations, converged or not: the two stop at the same point bit for bit, C1 well above 0 by then
    rising, _ = fit(src, "rising", "--max-iterations", "30", converged=False)
    free, _ = fit(src, "free", "--coordination", "free", "--max-iterations", "30", converged=False)
    assert float(rising["C1"]["value"]) > 0.5
    assert (tmp_path / "rising" / "parameters.csv").read_bytes() == (tmp_path / "free" / "parameters.csv").read_bytes()

    # the mirrored branch is not data a law was made for: these two stop at an iteration limit, where the sign of C1 is
    # settled already
    free_f, _ = fit(falling, "falling_free", "--coordination", "free", "--max-iterations", "40", converged=False)
    bound_f, err = fit(falling, "falling_rising", "--max-iterations", "40", converged=False)
    assert float(free_f["C1"]["value"]) < -0.5, free_f["C1"]
    assert float(bound_f["C1"]["value"]) == 0.0, bound_f["C1"]
    for name in ("C1", "nu_cC", "alpha"):
        assert bound_f[name]["se"] == "nan", bound_f[name]
    said = [l for l in err.splitlines() if "C1 sits on its bound 0 (--coordination rising)" in l]
    assert len(said) == 1, err
    branch = [r for f in sorted(falling.glob("members/*/prep/cycle_unloading.csv")) for r in read(f)
              if float(r["p_star"]) > 1e-7]
    lo = min(branch, key=lambda r: float(r["nu"]))
    hi = max(branch, key=lambda r: float(r["nu"]))
    assert float(lo["C_nonrattler"]) > float(hi["C_nonrattler"])   # the mirrored branch falls
    words = said[0].split("goes from ")[1].split()
    assert float(words[0]) == pytest.approx(float(lo["C_nonrattler"]), rel=1e-3), said[0]
    assert float(words[6]) == pytest.approx(float(hi["C_nonrattler"]), rel=1e-3), said[0]
