"""demkit.geotech_rate (issue 31, docs/geotech.md "The mu(I) law") on synthetic data with known
answers: the mu(I) law of Jop, Forterre & Pouliquen and nu = nu_max - a I recovered from
per-packing points, with jackknife intervals over the packings that cover the truth; the steady
state read from a hand-built simple-shear curve."""
import math
import os

import numpy as np
import pytest

from demkit import geotech_rate as gr

TRUE = (0.38, 0.64, 0.28)                     # mu_s, mu_2, I_0 (Jop et al.'s glass beads)
RATES_I = np.geomspace(1e-4, 1.0, 9)


def packings(k, noise, seed=7, law=TRUE):
    """{packing: (I, mu)}: each packing's steady points on the law plus its own noise."""
    rng = np.random.default_rng(seed)
    return {f"m{j}": (RATES_I * (1 + 0.02 * rng.standard_normal(RATES_I.size)),
                      gr.mu_of_i(RATES_I, *law) + noise * rng.standard_normal(RATES_I.size)) for j in range(k)}


def test_exact_points_give_the_law_back():
    pts = packings(4, 0.0)
    i = np.concatenate([v[0] for v in pts.values()])
    mu = gr.mu_of_i(i, *TRUE)
    assert np.allclose(gr.fit_mu_i(i, mu), TRUE, rtol=1e-5)


def test_noisy_packings_recover_the_law_within_the_jackknife_interval():
    # 20 synthetic ensembles of 4 packings: the 95 % intervals cover the truth in about 19 of 20
    # (measured 0.96-0.99 over 80 ensembles of 6); at least 17 of 20 here
    cover, halves = np.zeros(3), []
    for seed in range(20):
        est, half = gr.jackknife(packings(4, 0.01, seed), gr.fit_mu_i)
        assert np.all(np.isfinite(half)) and np.all(half > 0)
        cover += np.abs(est - np.array(TRUE)) <= half
        halves.append(half)
    assert np.all(cover >= 17), cover
    # and the intervals are informative: a few hundredths on mu, a fraction of I_0
    med = np.median(halves, axis=0)
    assert med[0] < 0.03 and med[1] < 0.1 and med[2] < 0.5 * TRUE[2], med


def test_a_law_whose_plateau_is_not_reached_leaves_i0_not_determined():
    # all points far below I_0 = 1e3: mu is flat, mu_2 and I_0 cannot be told apart
    i = np.geomspace(1e-4, 1e-2, 8)
    mu = gr.mu_of_i(i, 0.38, 0.64, 1e3)
    p = gr.fit_mu_i(i, mu)
    assert all(math.isnan(v) for v in p) or abs(p[0] - 0.38) < 1e-3


def test_fewer_than_three_packings_have_no_interval():
    est, half = gr.jackknife(packings(2, 0.01), gr.fit_mu_i)
    assert np.all(np.isnan(half)) and np.all(np.isfinite(est))


def test_dilatancy_law_recovered():
    rng = np.random.default_rng(3)
    pts = {f"m{j}": (RATES_I, 0.62 - 0.35 * RATES_I + 0.002 * rng.standard_normal(RATES_I.size)) for j in range(5)}
    (nu_max, a), half = gr.jackknife(pts, gr.fit_nu_i)
    assert abs(nu_max - 0.62) <= half[0] and abs(a - 0.35) <= half[1]
    assert half[0] < 0.005 and half[1] < 0.02


def test_steady_state_of_a_hand_built_shear_curve(tmp_path):
    # tau/sigma_n = 0.4 after the transient, gamma_dot = 100/s, sigma_n = 1e6 Pa, d = 2 mm,
    # rho = 2000: I = 100 * 2e-3 * sqrt(2000 / 1e6) = 8.944e-3
    n = 101
    x = np.linspace(0, 0.6, n)
    mu = np.where(x < 0.2, 2 * x, 0.4)
    cols = {"eps_d": x, "eps_v": np.zeros(n), "nu": np.full(n, 0.6), "p_Pa": np.full(n, 1.1e6),
            "sigma_zz_Pa": np.full(n, 1e6), "sigma_xz_Pa": -mu * 1e6, "rate_xz_1_s": np.full(n, 100.0),
            "control_error_rel": np.zeros(n)}
    path = os.path.join(tmp_path, "m1.csv")
    with open(path, "w") as fh:
        fh.write("# physics: particles.radius_min_m=0.0005 particles.radius_max_m=0.0015 particles.density_kg_m3=2000\n")
        fh.write(",".join(cols) + "\n")
        for k in range(n):
            fh.write(",".join(repr(float(v[k])) for v in cols.values()) + "\n")
    s = gr.steady_state(path)
    assert s["tau_over_sigma_n"] == pytest.approx(0.4)
    assert s["inertial"] == pytest.approx(100 * 2e-3 * math.sqrt(2000 / 1e6))
    assert s["p_over_sigma_n"] == pytest.approx(1.1)
    assert s["dilatancy_end"] == pytest.approx(0.0, abs=1e-12)


def test_a_curve_without_the_physics_line_is_refused(tmp_path):
    path = os.path.join(tmp_path, "m1.csv")
    with open(path, "w") as fh:
        fh.write("eps_d,eps_v,nu,sigma_zz_Pa,sigma_xz_Pa,rate_xz_1_s\n0,0,0.6,1,0,1\n")
    with pytest.raises(ValueError, match="radius_min_m"):
        gr.steady_state(path)


def test_unsteady_rates_are_left_out_of_the_fits():
    # exact points on the law at 8 rates, plus a ninth whose volume is still changing and whose
    # tau/sigma_n is far off: with it left out the law comes back exactly
    rates = [f"r{k}" for k in range(9)]
    i_values = np.append(RATES_I[:8], 2.0)
    members = [{"mu": "0.5", "prep": "loose", "level": "iso_hi", "test": "SS_cns", "rate_tc": r, "packing": f"m{j}",
                "inertial": i, "tau_over_sigma_n": (gr.mu_of_i(i, *TRUE) if r != "r8" else 5.0),
                "nu": 0.62 - 0.3 * i} for j in range(3) for r, i in zip(rates, i_values)]
    means = [{"mu": "0.5", "prep": "loose", "level": "iso_hi", "test": "SS_cns", "rate_tc": r,
              "volume_stationary": "no" if r == "r8" else "yes"} for r in rates]
    skip = gr.unsteady(means)
    assert skip == {("0.5", "loose", "iso_hi", "SS_cns", "r8")}
    (fit,) = gr.law_fits(members, skip)
    assert fit["rates"] == 8
    assert (fit["mu_s"], fit["mu_2"], fit["I_0"]) == pytest.approx(TRUE, rel=1e-5)
    assert (fit["nu_max"], fit["a"]) == pytest.approx((0.62, 0.3))
    (with_it,) = gr.law_fits(members)
    assert with_it["rates"] == 9 and with_it["mu_s"] != pytest.approx(TRUE[0], rel=1e-3)


def test_the_stop_override_is_the_scene_path_with_only_its_end_changed(tmp_path):
    """--eps-d's `--set paths.TEST=...` parses (as TOML, the way `dem` reads a --set) to the scene's own
    stages with the last one's `until` replaced, every other key and value kept."""
    import tomllib
    scene = tmp_path / "s.toml"
    scene.write_text('[paths]\nT = [ { rate = "SS_xz", sigma_p0 = { z = 1.0 }, until = { eps_d = 1.2 } },\n'
                     '      { rate = [0, 0, -1], pressure_p0 = 0.5, lode_b = 0.25, until = { eps_zz = -0.4 } } ]\n')
    flag, value = gr.stop_override(str(scene), "T", 0.6)
    key, text = value.split("=", 1)
    assert flag == "--set" and key == "paths.T"
    got = tomllib.loads("T = " + text)["T"]
    want = tomllib.loads(scene.read_text())["paths"]["T"]
    want[-1]["until"] = {"eps_d": 0.6}
    assert got == want
