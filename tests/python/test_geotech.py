"""demkit.geotech (issue 31, docs/geotech.md) on synthetic data with known answers: friction and
dilatancy angles of Mohr-Coulomb stress states under the Mohr-Coulomb flow rule, the closed-form
properties of the Matsuoka-Nakai and Lade-Duncan surfaces, and intervals over packings."""
import csv
import glob
import math
import os
import tomllib

import numpy as np
import pytest

from conftest import ROOT
from demkit import geotech

# ------------------------------------------------------------------------------------------
# The analysis on synthetic data with known answers


def synthetic_triaxial(phi_deg, psi_deg, sigma3=1e6, n=201):
    """A drained triaxial compression curve on the Mohr-Coulomb surface (sigma_1/sigma_3 =
    (1 + sin phi)/(1 - sin phi)) that dilates by the Mohr-Coulomb flow rule at the TC corner,
    eps_v' = -2 sin psi eps_1' / (1 - sin psi) (compression positive)."""
    s, sp = math.sin(math.radians(phi_deg)), math.sin(math.radians(psi_deg))
    a = np.linspace(0, 0.3, n)                      # axial compression
    ev = -2 * sp * a / (1 - sp)                     # volumetric compression
    lat = (ev - a) / 2                              # each lateral axis, compression positive
    one = np.ones(n)
    c = {"eps_zz": -a, "eps_xx": -lat, "eps_yy": -lat, "eps_v": -(ev / 3), "eps_d": a - lat,
         "nu": 0.6 * np.exp(-ev), "p_Pa": sigma3 * (2 + (1 + s) / (1 - s)) / 3 * one,
         "sigma_xx_Pa": sigma3 * one, "sigma_yy_Pa": sigma3 * one, "sigma_zz_Pa": sigma3 * (1 + s) / (1 - s) * one,
         "sigma_xy_Pa": 0 * one, "sigma_xz_Pa": 0 * one, "sigma_yz_Pa": 0 * one,
         "control_error_rel": 0 * one, "time_s": a}
    c["sigma_dev_Pa"] = c["sigma_zz_Pa"] - c["sigma_xx_Pa"]
    return c


def test_the_analysis_recovers_phi_and_psi_of_a_mohr_coulomb_triaxial_test():
    v = geotech.curve_values(synthetic_triaxial(32.0, 8.0))
    assert v["phi_peak_deg"] == pytest.approx(32.0, abs=1e-9)
    assert v["phi_cs_deg"] == pytest.approx(32.0, abs=1e-9)
    assert v["psi_max_deg"] == pytest.approx(8.0, abs=1e-6)
    assert v["q_over_p_cs"] == pytest.approx(6 * math.sin(math.radians(32)) / (3 - math.sin(math.radians(32))))
    assert v["b_cs"] == pytest.approx(0.0, abs=1e-12)
    # Rowe: sigma_1/sigma_3 = K D; with psi = 0 (no dilation) D = 1 and K is the stress ratio
    w = geotech.curve_values(synthetic_triaxial(30.0, 0.0))
    assert w["rowe_phi_f_deg"] == pytest.approx(30.0, abs=1e-6) and w["psi_max_deg"] == pytest.approx(0, abs=1e-6)


def test_simple_shear_dilatancy_is_tan_psi_equals_minus_deps_zz_over_dgamma():
    n, tan_psi = 101, 0.1
    gamma = np.linspace(0, 0.5, n)
    ezz = tan_psi * gamma                           # extension positive: the sample dilates
    zero, one = np.zeros(n), np.ones(n)
    c = {"eps_xx": zero, "eps_yy": zero, "eps_zz": ezz, "eps_v": ezz / 3, "eps_d": gamma, "nu": 0.6 * one,
         "p_Pa": one, "sigma_xx_Pa": one, "sigma_yy_Pa": one, "sigma_zz_Pa": one, "sigma_xy_Pa": zero,
         "sigma_xz_Pa": -0.4 * one, "sigma_yz_Pa": zero, "control_error_rel": zero, "time_s": gamma,
         "rate_xz_1_s": one}
    v = geotech.curve_values(c)
    assert v["psi_max_deg"] == pytest.approx(math.degrees(math.atan(tan_psi)), abs=1e-6)


def test_failure_criteria_closed_forms():
    s = math.sin(math.radians(30))
    for name in ("MC", "MN", "LD"):   # calibrated on TC, each returns TC's friction at b = 0
        assert geotech.predicted_sin_phi(name, geotech.constant_from_sin_phi(name, s), 0.0) == pytest.approx(s)
    mn = geotech.constant_from_sin_phi("MN", s)
    # Matsuoka-Nakai passes through the Mohr-Coulomb corners in compression and extension alike
    assert geotech.predicted_sin_phi("MN", mn, 1.0) == pytest.approx(s, rel=1e-9)
    # and lies outside Mohr-Coulomb in between; Lade-Duncan is stronger in extension than in compression
    assert geotech.predicted_sin_phi("MN", mn, 0.5) > s + 0.01
    assert geotech.predicted_sin_phi("LD", geotech.constant_from_sin_phi("LD", s), 1.0) > s + 0.01
    # the isotropic state: MN = 9, LD = 27
    assert geotech.criterion("MN", 1.0, 1.0, 1.0) == pytest.approx(9) and geotech.criterion("LD", 1, 1, 1) == 27


def test_the_ensemble_recovers_a_mohr_coulomb_material_against_b():
    """Packings on a Mohr-Coulomb surface (phi = 28 deg, scatter 0.5 deg) at five b: the family's
    phi is b-independent within its intervals, and Matsuoka-Nakai (calibrated on b = 0) misses it
    at b = 0.5 by more than the interval."""
    rng = np.random.default_rng(1)
    results = {}
    for b in (0.0, 0.25, 0.5, 0.75, 1.0):
        members = []
        for _ in range(6):
            phi = 28.0 + rng.normal(0, 0.5)
            v = geotech.curve_values(synthetic_triaxial(phi, 0.0))
            v["b_cs"] = b
            members.append(v)
        results[("0.5", "dense", "iso_lo", f"TT_b{round(100 * b):03d}")] = {"members": members, "summary": geotech.summarise(members)}
    rows = geotech.failure_surface(results)
    assert len(rows) == 5
    for r in rows:
        assert abs(r["phi_deg"] - 28.0) < r["phi_ci95_deg"] + 0.3
        assert r["MC_phi_deg"] == pytest.approx(rows[0]["phi_deg"])
    mid = [r for r in rows if r["b_target"] == 0.5][0]
    assert mid["MN_phi_deg"] - mid["phi_deg"] > mid["phi_ci95_deg"]
    assert geotech.summarise(results[("0.5", "dense", "iso_lo", "TT_b000")]["members"])["critical_state"] == "yes"


def test_fewer_than_two_packings_give_no_interval():
    m, h, k = geotech.mean_ci([1.0])
    assert m == 1.0 and math.isnan(h) and k == 1
    s = geotech.summarise([{q: 0.0 for q in geotech.SCALARS}])
    assert s["volume_stationary"] == "not determined" and s["critical_state"] == "not determined"


def test_the_critical_state_flag_says_yes_no_or_not_determined():
    assert geotech.stationary(0.01, 0.02, 0.05) == "yes"
    assert geotech.stationary(0.2, 0.05, 0.05) == "no"          # still dilating, surely
    assert geotech.stationary(0.04, 0.05, 0.05) == "not determined"
    assert geotech.critical_state_reached({"volume_stationary": "yes", "stress_stationary": "no"}) == "no"
    assert geotech.critical_state_reached({"volume_stationary": "yes", "stress_stationary": "not determined"}) == \
        "not determined"


def synthetic_csl_results(nu_of_p, levels=(5e6, 5e7, 5e8), tests=("TC_s3", "TC_p"), packings=4, noise=2e-4, seed=3):
    """results[(mu, prep, level, test)] of analyse_groups' shape: end states on nu_of_p(p) with
    Gaussian noise, each curve at p scattered by a few per cent about its level."""
    rng = np.random.default_rng(seed)
    results = {}
    for i, p0 in enumerate(levels):
        for test in tests:
            ps = p0 * (1 + 0.05 * rng.standard_normal(packings))
            members = [{"nu_cs": nu_of_p(p) + noise * rng.standard_normal(), "p_cs_Pa": p} for p in ps]
            results[("0.5", "dense", f"L{i}", test)] = {"members": members, "summary": {"volume_stationary": "yes"}}
    return results


def test_the_critical_state_line_shape_recovers_a_soft_sphere_line_and_its_curvature():
    """Three pressure decades: nu = nu_0 + c p gives back nu_0 and c within 3 SE; a straight line
    e(ln p) gives kappa = 0 within 3 SE, a curved one its kappa; a test missing at one level is left
    out of the shape fits; two levels give no shape rows."""
    nu0, c = 0.585, 0.04 / 500                      # nu rises by 0.04 at 500 MPa
    rows = geotech.critical_state_line(synthetic_csl_results(lambda p: nu0 + c * p / 1e6))
    rigid, = [r for r in rows if r["level"] == "rigid"]
    assert abs(rigid["nu_cs"] - nu0) < 3 * rigid["nu_0_se"] and rigid["nu_0_se"] < 2e-4
    assert abs(rigid["c_per_MPa"] - c) < 3 * rigid["c_per_MPa_se"]
    assert rigid["tests"] == "TC_p+TC_s3" and rigid["n_curves"] == 24
    for kappa in (0.0, 0.002):
        e = lambda p: 0.7 - 0.02 * math.log(p / 1e6) + kappa * math.log(p / 1e6) ** 2
        res = synthetic_csl_results(lambda p: 1 / (1 + e(p)))
        res[("0.5", "loose", "L0", "TE_s3")] = {"members": [{"nu_cs": 0.5, "p_cs_Pa": 5e6}] * 4,
                                                "summary": {"volume_stationary": "yes"}}   # at one level only
        curv, = [r for r in geotech.critical_state_line(res) if r["level"] == "curvature"]
        assert abs(curv["kappa"] - kappa) < 3 * curv["kappa_se"] and curv["kappa_se"] < 5e-4
        assert abs(curv["lambda"] - 0.02) < 3 * curv["lambda_se"] and curv["tests"] == "TC_p+TC_s3"
    two = geotech.critical_state_line(synthetic_csl_results(lambda p: nu0 + c * p / 1e6, levels=(5e7, 5e8)))
    assert not [r for r in two if r["level"] in ("curvature", "rigid")] and [r for r in two if r["level"] == "line"]


def test_the_low_pressure_level_has_its_own_preparation_and_rate():
    """iso_vlo (p* = 1e-4): the scene's gas stage, then its iso_lo stage at a tenth of the target, as
    `--set` values that TOML reads back; the test rate sqrt(10) below the scene's, the servo's limit
    in the scene's ratio to it; the scene's levels keep the scene's rate."""
    scene = os.path.join(ROOT, "data", "scenes", "geotech.toml")
    with open(scene, "rb") as fh:
        sc = tomllib.load(fh)
    args = geotech.low_level_overrides(scene)
    assert args[0] == "--set" and args[2:] == ["--set", "protocol.modes_from=iso_vlo"]
    key, value = args[1].split("=", 1)
    stages = tomllib.loads(f"v = {value}")["v"]
    lo = next(st for st in sc["protocol"]["preparation"] if st.get("checkpoint_name") == "iso_lo")
    assert key == "protocol.preparation" and stages[0] == sc["protocol"]["preparation"][0]
    assert stages[1] == dict(lo, name="iso_vlo", checkpoint_name="iso_vlo", target_Pa=lo["target_Pa"] / 10)
    rate = geotech.level_rate_args(scene, "iso_vlo")
    assert float(rate[1]) == pytest.approx(sc["protocol"]["deviatoric_rate_tc"] / math.sqrt(10), rel=1e-5)
    ratio = sc["servo"]["rate_max_tc"] / sc["protocol"]["deviatoric_rate_tc"]
    assert rate[2:] == ["--set", f"servo.rate_max_tc={float(rate[1]) * ratio:.6g}"]
    assert geotech.level_rate_args(scene, "iso_lo") == [] == geotech.level_rate_args(scene, "iso_hi")
    for v in ({"a": [1, 2.5e-7, "x\"y"], "b": {"c": True}}, ["q"]):
        assert tomllib.loads(f"v = {geotech.toml_inline(v)}")["v"] == v
    with pytest.raises(SystemExit):
        geotech.main(["run", "--out", "/nonexistent", "--levels", "iso_low"])


def test_the_high_pressure_level_has_its_own_preparation_at_the_scene_rate():
    """iso_vhi (p* = 5e-2): the scene's gas stage, then its iso_hi stage at 5x the target, in a folder
    of its own (the stored iso_lo/iso_hi preparations untouched); its tests at the scene's rate; a run
    and the model's converter both accept it, an unknown level is refused."""
    scene = os.path.join(ROOT, "data", "scenes", "geotech.toml")
    with open(scene, "rb") as fh:
        sc = tomllib.load(fh)
    args = geotech.level_overrides(scene, "iso_vhi")
    assert args[2:] == ["--set", "protocol.modes_from=iso_vhi"]
    stages = tomllib.loads(f"v = {args[1].split('=', 1)[1]}")["v"]
    hi = next(st for st in sc["protocol"]["preparation"] if st.get("checkpoint_name") == "iso_hi")
    assert stages == [sc["protocol"]["preparation"][0],
                      dict(hi, name="iso_vhi", checkpoint_name="iso_vhi", target_Pa=hi["target_Pa"] * 5)]
    assert geotech.level_rate_args(scene, "iso_vhi") == []
    assert geotech.prep_dir("R", "dense", "0.5", 1, "iso_vhi") == os.path.join("R", "prep_vhi", "dense", "m1")
    assert geotech.prep_dir("R", "loose", "0.5", 1, "iso_hi") == os.path.join("R", "prep", "loose_mu0.5", "m1")
    assert geotech.checked_levels("iso_lo,iso_vhi") == "iso_lo,iso_vhi"
    from demkit import geotech_model
    assert geotech_model.main(["--out", "/nonexistent", "--levels", "iso_xhi"]) == 2


# ------------------------------------------------------------------------------------------
# The stored runs (data/geotech) against the scene that made them and against each other

DATA = os.path.join(ROOT, "data", "geotech")


def data_rows(path):
    """(header, rows) of a curve, comment lines skipped."""
    with open(path) as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))
    return rows[0], rows[1:]


def test_every_stored_curve_runs_to_the_end_its_scene_path_sets():
    """Each curve in data/geotech/curves ends where data/scenes/geotech.toml's `until` stops its test
    (a curve left from a shorter version of the scene fails here)."""
    with open(os.path.join(ROOT, "data", "scenes", "geotech.toml"), "rb") as fh:
        paths = tomllib.load(fh)["paths"]
    curves = glob.glob(os.path.join(DATA, "curves", "mu_*", "*", "*", "*", "m*.csv"))
    assert len(curves) >= 8 * 4 * 4
    for path in curves:
        (key, target), = paths[path.split(os.sep)[-2]][-1]["until"].items()
        header, rows = data_rows(path)
        end = float(rows[-1][header.index(key)])
        assert abs(end) >= abs(target) and abs(end) - abs(target) < 0.01, (path, key, end, target)


def test_the_failure_surface_has_five_b_values_at_every_mu_and_preparation():
    """Every (mu, prep, level) of the scene's two levels with curves has the whole constant-p family,
    b = 0 ... 1, over 4 packings; the p* = 1e-4 level (iso_vlo) has TC_p (b = 0) at every mu and the whole
    family at mu = 0.5."""
    with open(os.path.join(DATA, "failure_surface_cs.csv")) as fh:
        rows = list(csv.DictReader(fh))
    cells = {(r["mu"], r["prep"], r["level"]) for r in rows}
    on_disk = {tuple(p.split(os.sep)[-3:]) for p in glob.glob(os.path.join(DATA, "curves", "mu_*", "*", "*"))}
    assert {(m[3:], p, lv) for m, p, lv in on_disk} == cells
    assert {c[0] for c in cells} == {"0", "0.1", "0.3", "0.5", "1"}   # the friction study's mu but 0.01
    for cell in cells:
        rs = [r for r in rows if (r["mu"], r["prep"], r["level"]) == cell]
        b = [0] if cell[2] == geotech.LOW_LEVEL and cell[0] != "0.5" else [0, 0.25, 0.5, 0.75, 1]
        assert sorted(float(r["b_target"]) for r in rs) == b, cell
        assert all(r["K"] == "4" for r in rs), cell


def test_the_rate_series_at_the_scene_rate_is_a_prefix_of_the_stored_curves():
    """data/geotech/rate's curves at the scene's rate (3e-5/t_c; at p* = 1e-4 the level's own,
    geotech.level_rate_args) and their twins in curves/ are one deterministic run: equal in every column
    both keep, row for row, over the rate curve's length but its last row (the row written where the rate
    series stops, which a longer test passes without a row)."""
    scene = os.path.join(ROOT, "data", "scenes", "geotech.toml")
    low = float(geotech.level_rate_args(scene, geotech.LOW_LEVEL)[1])
    twins = glob.glob(os.path.join(DATA, "rate", "curves", "mu_*", "*", "iso_[lh]*", "*", "r3e-5", "m*.csv"))
    twins += [p for p in glob.glob(os.path.join(DATA, "rate", "curves", "mu_*", "*", geotech.LOW_LEVEL, "*", "r*", "m*.csv"))
              if float(p.split(os.sep)[-2][1:]) == pytest.approx(low, rel=1e-5)]
    assert len(twins) == 24
    for path in twins:
        parts = path.split(os.sep)
        h1, a = data_rows(path)
        h2, b = data_rows(os.path.join(DATA, "curves", *parts[-6:-2], parts[-1]))
        common = [c for c in h1 if c in h2 and c != "stage"]
        assert len(common) >= 8
        pick = lambda h, rows: [[r[h.index(c)] for c in common] for r in rows]
        assert len(b) >= len(a) - 1
        assert pick(h1, a[:-1]) == pick(h2, b[:len(a) - 1]), path
        if len(b) == len(a):                       # same length: the same test, the stop row too
            assert pick(h1, a[-1:]) == pick(h2, b[-1:]), path
        if parts[-3] == "SS_cns":                  # the series stops at eps_d = 0.6 (--eps-d), its twin runs on
            end = lambda h, rows: float(rows[-1][h.index("eps_d")])
            assert abs(end(h1, a) - 0.6) < 0.01 and end(h2, b) > 1.5 and len(b) > 2 * len(a), path
