"""demkit.geotech (issue 31, docs/geotech.md) on synthetic data with known answers: friction and
dilatancy angles of Mohr-Coulomb stress states under the Mohr-Coulomb flow rule, the closed-form
properties of the Matsuoka-Nakai and Lade-Duncan surfaces, and intervals over packings."""
import math

import numpy as np
import pytest

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
