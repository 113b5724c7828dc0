"""The powder engineer's analysis (demkit/powders.py, issue 35): the yield-locus construction on
synthetic Mohr circles with known sigma_c and sigma_1 recovers them, the flowability classes, the
averaging over packings, and the closed forms of Luding's pull-off force and Rumpf's estimate."""
import math
import os

import numpy as np
import pytest

from demkit import powders
from demkit.luding import Luding


def synthetic(c, phi_deg, centre, theta_deg, sigma_n=(0.25, 0.5, 0.75)):
    """Failure points on the line tau = c + sigma tan(phi) and a pre-shear point on the circle of
    centre `centre` tangent to that line, at the angle theta from the circle's right end (the
    tangent point is at 180 - (90 - phi) degrees: theta below it puts the point right of it)."""
    phi = math.radians(phi_deg)
    radius = c * math.cos(phi) + centre * math.sin(phi)
    th = math.radians(theta_deg)
    pre = (centre + radius * math.cos(th), radius * math.sin(th))
    pts = [(s * pre[0], c + s * pre[0] * math.tan(phi)) for s in sigma_n]
    return pts, pre, centre + radius, 2 * c * math.cos(phi) / (1 - math.sin(phi))


@pytest.mark.parametrize("c,phi_deg,centre,theta", [(1.0, 30, 10.0, 60), (0.3, 20, 5.0, 80), (2.0, 40, 12.0, 45),
                                                   (0.5, 35, 3.0, 120)])
def test_mohr_circles_of_a_known_locus_are_recovered(c, phi_deg, centre, theta):
    pts, pre, sigma_1, sigma_c = synthetic(c, phi_deg, centre, theta)
    r = powders.analyse_locus(pts, pre)
    assert r["c_Pa"] == pytest.approx(c, rel=1e-10)
    assert r["phi_lin_deg"] == pytest.approx(phi_deg, rel=1e-10)
    assert r["sigma_c_Pa"] == pytest.approx(sigma_c, rel=1e-10)
    assert r["sigma_1_Pa"] == pytest.approx(sigma_1, rel=1e-9)
    assert r["ffc"] == pytest.approx(sigma_1 / sigma_c, rel=1e-9)
    # phi_e: the line through the origin tangent to the steady-state circle
    radius = (sigma_1 - r["sigma_2_Pa"]) / 2
    assert math.sin(math.radians(r["phi_e_deg"])) == pytest.approx(radius / (sigma_1 - radius), rel=1e-9)
    assert r["phi_e_deg"] > phi_deg   # a cohesive locus: the effective angle exceeds the locus's


def test_unconfined_circle_touches_the_locus_and_passes_through_the_origin():
    c, phi = 0.7, math.radians(28)
    sc = powders.unconfined_yield_strength(c, phi)
    # distance from the centre (sc/2, 0) to the line sin(phi) sigma - cos(phi) tau + c cos(phi) = 0
    dist = abs(math.sin(phi) * sc / 2 + c * math.cos(phi))
    assert dist == pytest.approx(sc / 2, rel=1e-12)


def test_cohesionless_locus_is_free_flowing_with_phi_e_equal_to_phi():
    pts, pre, sigma_1, _ = synthetic(0.0, 25, 8.0, 70)
    r = powders.analyse_locus(pts, pre)
    assert r["sigma_c_Pa"] < 1e-12 * sigma_1 and r["ffc"] > 1e12 and r["class"] == "free-flowing"
    assert r["phi_e_deg"] == pytest.approx(25, rel=1e-9)
    assert r["sigma_1_Pa"] == pytest.approx(sigma_1, rel=1e-9)
    negative = powders.analyse_locus([(1.0, 0.4), (2.0, 0.85)], (3.0, 1.2))   # c < 0: no strength
    assert negative["sigma_c_Pa"] == 0 and negative["ffc"] == math.inf


def test_a_preshear_point_above_the_locus_gives_the_circle_through_it_with_the_locus_slope():
    pts, pre, _, _ = synthetic(1.0, 30, 10.0, 60)
    sp, tp = pre[0], pre[1] + 5.0
    centre, radius = powders.steady_state_circle(1.0, math.radians(30), sp, tp)
    assert math.hypot(sp - centre, tp) == pytest.approx(radius, rel=1e-12)        # through the point
    assert (centre - sp) / tp == pytest.approx(math.tan(math.radians(30)), rel=1e-12)   # slope of the YL there


@pytest.mark.parametrize("ffc,name", [(0.5, "not flowing"), (1.5, "very cohesive"), (3.0, "cohesive"),
                                      (7.0, "easy-flowing"), (12.0, "free-flowing"), (math.inf, "free-flowing"),
                                      (2.0, "cohesive"), (4.0, "easy-flowing")])
def test_flowability_classes(ffc, name):
    assert powders.flow_class(ffc) == name


def test_summary_averages_ffc_through_its_inverse():
    members = []
    for inv in (0.2, 0.25, 0.3):
        members.append({q: 1.0 for q in powders.QUANTITIES} | {"inv_ffc": inv})
    s = powders.summarise(members, "x")
    assert s["ffc"] == pytest.approx(4.0)
    half = s["inv_ffc_ci95"]
    assert half == pytest.approx(4.303 * 0.05 / math.sqrt(3), rel=1e-3)
    assert s["ffc_lo"] == pytest.approx(1 / (0.25 + half)) and s["ffc_hi"] == pytest.approx(1 / (0.25 - half))
    members[0]["inv_ffc"] = 0.0   # one cohesionless packing: the upper end becomes infinite
    members[1]["inv_ffc"] = 0.01
    s = powders.summarise(members, "x")
    assert s["ffc_hi"] == math.inf and math.isfinite(s["ffc"])


@pytest.mark.parametrize("dmax_over_star", [0.05, 0.3, 0.8, 1.5])
@pytest.mark.parametrize("kc", [0.0, 0.2e8, 1e8, 5e8])
def test_pull_off_force_equals_the_least_force_of_the_law_along_an_unloading(dmax_over_star, kc):
    law = Luding(k1=1e8, kp=5e8, kc=kc, phi_f=0.01, a12=0.25e-3)
    dmax = dmax_over_star * law.delta_star
    down = np.linspace(dmax, 0, 20001)[1:]
    forces = [f for f, _ in law.path(np.concatenate([np.linspace(0, dmax, 200), down]))]
    expected = powders.luding_pull_off(1e8, 5e8, kc, 0.01, 0.25e-3, dmax)
    assert -min(min(forces), 0.0) == pytest.approx(expected, rel=2e-3, abs=1e-12)


def test_rumpf_and_bond_number_closed_forms():
    assert powders.rumpf_tensile_strength(0.6, 6.0, 1e-3, 2e-3) == pytest.approx(0.6 * 6 * 1e-3 / (math.pi * 4e-6))
    assert powders.bond_number(2.0, 1e6, 1e-3) == pytest.approx(2.0)


@pytest.mark.parametrize("dmax_over_star,kc_over_k1", [(0.3, 0.5), (0.7, 5.0), (1.3, 2.0)])
def test_two_particle_pull_off_through_the_engine_equals_the_closed_form(dmax_over_star, kc_over_k1):
    """Two spheres pressed to delta_max and pulled apart by a prescribed overlap rate through our
    engine (bench/luding_pair.py's loop, demtk): the most tensile force is the closed-form pull-off
    force kc (k2 - k1) delta_max / (k2 + kc) (written from the law, not from the engine)."""
    pytest.importorskip("demtk")
    import sys
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                    "bench"))
    import luding_pair as lp
    phi_f, kc = 0.01, kc_over_k1 * lp.K1
    rows = lp.run_loop(lp.scene(kc, phi_f), [0.0, dmax_over_star, 0.0], 4000)
    f_min = min(f for _, _, f in rows)
    law = lp.law(kc, phi_f)
    expected = powders.luding_pull_off(lp.K1, lp.KP, kc, phi_f, law.a12, dmax_over_star * law.delta_star)
    # the overlap moves delta*/4000 per step: the discrete minimum misses the corner by < kc of that
    assert -f_min == pytest.approx(expected, rel=0, abs=kc * law.delta_star / 4000 + 1e-9 * expected)
    assert max(d for _, d, _ in rows) == pytest.approx(dmax_over_star * law.delta_star, rel=1e-6)


def test_welch_interval_matches_scipys_welch_test():
    """The half-width h of the difference's 95 % Welch interval: a difference of exactly h is
    significant at 5 % by scipy's Welch t-test (ttest_ind, equal_var=False)."""
    from scipy import stats
    a, b = [1.0, 1.4, 0.8, 1.3, 1.1], [0.5, 0.9, 0.2, 1.6, 0.7, 0.4, 1.1, 0.6]
    d, h = powders.welch_diff(a, b)
    assert d == pytest.approx(np.mean(a) - np.mean(b))
    shifted = np.asarray(a) - d + h   # the difference moved to the interval's end
    assert stats.ttest_ind(shifted, b, equal_var=False).pvalue == pytest.approx(0.05, rel=1e-9)
    assert math.isnan(powders.welch_diff([1.0], b)[1])


def _fake_level(tmp_path, name, dt, values, monkeypatch_store):
    """A level folder of runs whose analysis gives `values` (inv_ffc per packing, others fixed)."""
    runs = []
    for k, v in enumerate(values):
        run = tmp_path / name / f"s{k + 1}"
        run.mkdir(parents=True)
        (run / "scene.toml").write_text(f"[integration]\ndt_over_tc = {dt}\n[particles]\ncount = 100\n")
        (run / "manifest.json").write_text('{"complete": true}')
        monkeypatch_store[str(run)] = v
        runs.append(str(run))
    return runs


def test_dt_rows_take_the_finest_dt_as_reference_and_flag_means_outside_its_interval(tmp_path, monkeypatch):
    store = {}
    levels = {"fine": _fake_level(tmp_path, "fine", 0.05, [0.30, 0.32, 0.28, 0.31], store),
              "mid": _fake_level(tmp_path, "mid", 0.2, [0.31, 0.29, 0.30, 0.33], store),
              "coarse": _fake_level(tmp_path, "coarse", 0.5, [0.45, 0.47, 0.44, 0.46], store)}
    base = {q: 1.0 for q, _, _ in powders.DT_QUANTITIES} | {"steps": 1000.0, "wall_s": 1.0}
    monkeypatch.setattr(powders, "analyse_run", lambda r: base | {"inv_ffc": store[r]})
    rows, ref = powders.dt_rows(levels)
    assert ref == "fine"
    by = {r["label"]: r for r in rows}
    assert [r["label"] for r in rows] == ["coarse", "mid", "fine"]   # coarsest first
    assert by["fine"]["reference"] and not by["fine"]["inv_ffc_outside"]
    assert not by["mid"]["inv_ffc_outside"] and by["coarse"]["inv_ffc_outside"]
    assert by["coarse"]["inv_ffc_diff"] == pytest.approx(0.455 - 0.3025)
    assert by["mid"]["N"] == 100
