"""`dem model` end to end on the committed N = 9261 ensemble (data/figure3_n9261: 4 packings,
6 volume fractions, D2 and D3): calibrate on D2 + the isotropic branch, predict D3, tables,
curves and plots; and the refusals of bad input (exit 2, naming the problem and the fix)."""
import csv
import json
import math
import os
import shutil
import subprocess
import sys

import pytest

from conftest import DEM, ROOT

ENSEMBLE = os.path.join(ROOT, "data", "figure3_n9261")


def run(*args):
    return subprocess.run([DEM, "model", *args], capture_output=True, text=True, timeout=300)


def rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("model"))
    r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--force")
    assert r.returncode == 0, r.stderr
    return out, r


@pytest.fixture(scope="module")
def mu05_default(tmp_path_factory):
    """The mu = 0.5 ensemble of the friction study (a copy) and its default frictional-family calibration
    (--family extended, the overlap rule, no state limit; no jackknife, no plots): (work, out). Shared by the tests
    that compare a rule or an option with the default (each fit takes half a minute)."""
    from demkit import model_friction
    base = tmp_path_factory.mktemp("mu05")
    work, out = str(base / "mu_0.5"), str(base / "default")
    model_friction.copy_tree(os.path.join(ROOT, "data", "friction_n1000", "mu_0.5"), work)
    r = run(work, "--out", out, "--family", "extended", "--no-jackknife", "--no-plots")
    assert r.returncode == 0, r.stderr
    return work, out


def test_tables_curves_and_plots(result):
    out, r = result
    for stem in ("parameters", "correlations", "laws", "prediction"):
        for ext in ("csv", "json", "md", "tex"):
            assert os.path.exists(os.path.join(out, f"{stem}.{ext}")), stem + ext
    for q in ("p_star", "s_dev", "F_dev"):
        assert os.path.getsize(os.path.join(out, f"model_{q}.png")) > 10000
    assert os.path.exists(os.path.join(out, "model_paths.png"))
    params = {p["parameter"]: p for p in rows(os.path.join(out, "parameters.csv"))}
    assert len(params) == 19 + 2
    for name in ("s_max_a", "F_max_a", "a_A_a", "ln_beta_s_a"):
        assert math.isfinite(float(params[name]["value"])) and float(params[name]["se"]) > 0
    # The critical-state stress ratio of frictionless spheres: of order 0.1-0.2, falling with nu.
    assert 0.1 < float(params["s_max_a"]["value"]) < 0.25
    assert float(params["s_max_b"]["value"]) < 0


def test_every_d3_curve_is_predicted_and_judged_against_its_band(result):
    out, _ = result
    pred = rows(os.path.join(out, "prediction.csv"))
    d3 = [p for p in pred if p["mode"] == "D3"]
    assert {p["role"] for p in d3} == {"predicted"}
    assert {p["role"] for p in pred if p["mode"] == "D2"} == {"fitted"}
    assert len(d3) == 6 * 3
    for p in d3:
        rms, band = float(p["rms [quantity]"]), float(p["band_halfwidth [quantity]"])
        assert math.isclose(float(p["rms_over_band [-]"]), rms / band, rel_tol=1e-2)   # tables carry 3-4 digits
        # A prediction, not a fit, but of the same physics: within a few band widths everywhere.
        assert float(p["max_over_band [-]"]) < 5, p


def test_model_curve_starts_from_the_dem_start_state(result):
    out, _ = result
    with open(os.path.join(out, "curves", "D3_phi0.750.csv")) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    header = lines[0].strip().split(",")
    first = dict(zip(header, map(float, lines[1].split(","))))
    for q in ("p_star", "s_dev", "F_dev"):
        assert first[q + "_model"] == pytest.approx(first[q + "_mean"], rel=1e-6)


def test_bad_input_is_refused_with_the_fix(tmp_path, result):
    r = run(str(tmp_path / "nope"))
    assert r.returncode == 2 and "not a folder" in r.stderr
    r = run(str(tmp_path))
    assert r.returncode == 2 and "dem fit" in r.stderr, r.stderr
    out, _ = result
    r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--no-plots")
    assert r.returncode == 2 and "--force" in r.stderr
    # An ensemble curve lacking a column: named.
    bad = tmp_path / "bad"
    (bad / "ensemble").mkdir(parents=True)
    src = os.path.join(ENSEMBLE, "ensemble", "D2_phi0.750.csv")
    with open(src) as fh, open(bad / "ensemble" / "D2_phi0.750.csv", "w") as g:
        for ln in fh:
            g.write(ln.replace("F_dev_se", "F_dev_sx"))
    r = run(str(bad), "--no-plots", "--isotropic", os.path.join(ENSEMBLE, "members", "m000", "cycle_unloading.csv"))
    assert r.returncode == 2 and "F_dev_se" in r.stderr, r.stderr
    # No isotropic branch: says where it looked and how to pass one.
    shutil.copy(src, bad / "ensemble" / "D2_phi0.750.csv")
    r = run(str(bad), "--no-plots")
    assert r.returncode == 2 and "--isotropic" in r.stderr, r.stderr


# ---- Paths: the committed N = 1000 path ensembles (data/model_paths_qs16: 16 packings, nu = 0.69,
# 0.74, 0.80; reversal, isobaric, cyclic, triaxial; D2/D3 means, isotropic branches and D2 member curves) ----

PATHS = os.path.join(ROOT, "data", "model_paths_qs16")


@pytest.fixture(scope="module")
def paths_result(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("model_paths"))
    r = run(PATHS, "--out", out, "--no-jackknife", "--force", "--no-plots", "--calibrate-on", "D2,reversal")
    assert r.returncode == 0, r.stderr
    return out, r


def test_paths_are_fitted_or_predicted_and_judged(paths_result):
    out, r = paths_result
    assert "reversal" in r.stderr and "fitting 3 mode curves, 3 path curves (D2+reversal)" in r.stderr
    pred = rows(os.path.join(out, "prediction.csv"))
    by = {(p["mode"], p["nu"], p["quantity"]): p for p in pred}
    for nu in ("0.69", "0.74", "0.8"):
        assert by[("reversal", nu, "p_star")]["role"] == "fitted"
        assert by[("isobaric", nu, "eps_v")]["role"] == "predicted"
        assert ("isobaric", nu, "p_star") not in by   # p is held there: eps_v is judged instead
        for path in ("reversal", "cyclic", "isobaric"):
            for q in ("s_dev_signed", "F_dev_signed"):
                p = by[(path, nu, q)]
                assert int(p["n"]) > 90 and math.isfinite(float(p["rms_over_band [-]"]))
    # the model curve starts from the ensemble's signed start state, and holds p on isobaric rows
    with open(os.path.join(out, "curves", "paths", "isobaric_phi0.740.csv")) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    head = lines[0].strip().split(",")
    data = [dict(zip(head, map(float, ln.split(",")))) for ln in lines[1:]]
    assert data[0]["s_dev_model"] == pytest.approx(data[0]["s_dev_mean"], abs=1e-7)
    assert all(d["p_star_model"] == pytest.approx(data[0]["p_star_model"], rel=1e-9) for d in data)
    assert data[-1]["eps_v_model"] > 0   # the model dilates at nu = 0.74 (a_A > 0), as the DEM does


def test_triaxial_path_holds_the_side_stress_and_is_judged(paths_result):
    # constant side stress (docs/model.md): p* and eps_v are both free and both judged; the model
    # holds sigma_r = p (1 - s/3) at its start value; the mapped axial strain ends near the DEM's -0.15
    out, _ = paths_result
    by = {(p["mode"], p["nu"], p["quantity"]): p for p in rows(os.path.join(out, "prediction.csv"))}
    for nu in ("0.69", "0.74", "0.8"):
        for q in ("p_star", "eps_v", "s_dev_signed", "F_dev_signed"):
            p = by[("triaxial", nu, q)]
            assert p["role"] == "predicted" and int(p["n"]) > 70 and math.isfinite(float(p["rms_over_band [-]"]))
    with open(os.path.join(out, "curves", "paths", "triaxial_phi0.740.csv")) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    head = lines[0].strip().split(",")
    data = [dict(zip(head, map(float, ln.split(",")))) for ln in lines[1:]]
    assert all(d["isobaric"] == 2 for d in data)
    sr = [d["p_star_model"] * (1 - d["s_dev_model"] / 3) for d in data]
    assert all(v == pytest.approx(sr[0], rel=1e-6) for v in sr)   # 8 digits written
    assert data[-1]["p_star_model"] > 1.03 * data[0]["p_star_model"]   # the mean stress rises by q/3
    assert data[-1]["eps_zz_model"] == pytest.approx(data[-1]["eps_zz_dem"], abs=0.003)
    assert data[-1]["eps_zz_dem"] == pytest.approx(-0.15, abs=0.005)
    assert abs(data[-1]["sigma_r_p0_dem"] - 1) < 0.005   # the DEM servo held the side stress


def test_identifiability_table(paths_result):
    out, _ = paths_result
    t = rows(os.path.join(out, "identifiability.csv"))
    assert {r["calibrated_on"] for r in t} == {"D2+reversal"}
    assert len(t) == 4   # nu_ref and the three volume fractions
    for r in t:
        assert -1 <= float(r["corr_cov [-]"]) <= 1 and float(r["se_a_A_cov"]) > 0


def test_bad_path_options_are_refused(tmp_path):
    r = run(PATHS, "--out", str(tmp_path / "o"), "--no-plots", "--no-jackknife", "--calibrate-on", "D2,nope")
    assert r.returncode == 2 and "--calibrate-on nope" in r.stderr, r.stderr
    r = run(PATHS, "--out", str(tmp_path / "o"), "--no-plots", "--no-jackknife", "--paths", str(tmp_path / "none"))
    assert r.returncode == 2 and "--paths" in r.stderr and "not a folder" in r.stderr, r.stderr
    r = run(PATHS, "--out", str(tmp_path / "o"), "--no-plots", "--no-jackknife", "--calibrate-on", "reversal")
    assert r.returncode == 2 and "monotone mode" in r.stderr, r.stderr


# ---- The frictional family (docs/model.md, "The frictional extension") on a stored friction-study
# ensemble (data/friction_n1000/mu_0.5: K = 8, nu = 0.69, 0.74, 0.80) ----

def test_bad_family_and_surface_are_refused(tmp_path):
    r = run(ENSEMBLE, "--out", str(tmp_path / "f"), "--family", "cam-clay", "--no-plots")
    assert r.returncode == 2 and "--family" in r.stderr and "auto" in r.stderr, r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "s"), "--family", "extended", "--surface", "tresca", "--no-plots")
    assert r.returncode == 2 and "--surface" in r.stderr and "ld" in r.stderr, r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "l"), "--family", "extended", "--fabric-lode", "max", "--no-plots")
    assert r.returncode == 2 and "--fabric-lode max" in r.stderr and "principal" in r.stderr and "opening" in r.stderr, r.stderr
    assert "overlap" in r.stderr, r.stderr
    assert not os.path.exists(tmp_path / "l")
    r = run(ENSEMBLE, "--out", str(tmp_path / "p"), "--family", "extended", "--state-limit", "volumetric", "--no-plots")
    assert r.returncode == 2 and "--state-limit volumetric" in r.stderr and "pressure" in r.stderr, r.stderr
    assert not os.path.exists(tmp_path / "p")
    # the volume-form state parameter needs drained paths (its critical-state line is their end states)
    r = run(ENSEMBLE, "--out", str(tmp_path / "v"), "--family", "extended", "--state-limit", "volume", "--no-plots")
    assert r.returncode == 2 and "--state-limit volume" in r.stderr and "drained" in r.stderr, r.stderr
    assert not os.path.exists(tmp_path / "v")


def test_group_model_at_mu_0_ignores_the_fabric_rule(tmp_path):
    """mu = 0, where the held-out test keeps the group model (docs/model.md): its numbers, the
    whole summary, are the same bytes whatever --fabric-lode says (the rule lives in the extension)."""
    from demkit import model_friction
    src = os.path.join(ROOT, "data", "friction_n1000", "mu_0")
    work = str(tmp_path / "mu_0")
    model_friction.copy_tree(src, work)
    texts = []
    for rule in ("principal", "norm", "overlap", "extension"):
        out = str(tmp_path / rule)
        r = run(work, "--out", out, "--family", "group", "--fabric-lode", rule, "--no-jackknife", "--no-plots")
        assert r.returncode == 0, r.stderr
        with open(os.path.join(out, "summary.md")) as fh:
            texts.append(fh.read())
    assert texts[0] == texts[1] == texts[2] == texts[3]
    assert "group model" in texts[0] and "| D3 |" in texts[0]


def test_frictional_family_fits_the_mu_0_5_ensemble(tmp_path):
    from demkit import model_friction
    src = os.path.join(ROOT, "data", "friction_n1000", "mu_0.5")
    work = str(tmp_path / "mu_0.5")
    model_friction.copy_tree(src, work)
    model_friction.isobaric_paths(src, work)
    out = str(tmp_path / "model")
    r = run(work, "--out", out, "--family", "extended", "--fabric-lode", "principal", "--no-jackknife", "--no-plots")
    assert r.returncode == 0, r.stderr
    params = {p["parameter"]: p for p in rows(os.path.join(out, "parameters.csv"))}
    assert len(params) == 19 + 7 + 2
    assert float(params["chi2_per_dof"]["value"]) < 3
    summary = rows(os.path.join(out, "summary.csv"))
    roles = {(s["mode"], s["role"]) for s in summary}
    assert ("D2", "fitted") in roles and ("D3", "predicted") in roles and ("isobaric", "predicted") in roles
    # Every fitted D2 curve within a band half-width RMS (the group model: up to 31 here).
    for s in summary:
        if s["mode"] == "D2":
            assert float(s["worst [band]"]) < 1, s
    # The principal fabric rule: D2 (fitted, b = 1/2) is the same as without it, D3's fabric
    # plateau at nu = 0.69 is predicted within a band (2.7 band widths with the norm rule).
    out_n = str(tmp_path / "model_norm")
    r = run(work, "--out", out_n, "--family", "extended", "--fabric-lode", "norm", "--no-jackknife", "--no-plots")
    assert r.returncode == 0, r.stderr
    norm = {(s["mode"], s["nu [-]"]): s for s in rows(os.path.join(out_n, "summary.csv"))}
    for s in summary:
        key = (s["mode"], s["nu [-]"])
        if s["mode"] == "D2":
            assert s["F_dev [band]"] == norm[key]["F_dev [band]"]
        if s["mode"] == "D3" and float(s["nu [-]"]) < 0.7:
            assert float(s["F_dev [band]"]) < 1 < float(norm[key]["F_dev [band]"]), (s, norm[key])


def test_overlap_rule_predicts_the_late_d3_fabric_at_mu_0_5(mu05_default):
    """The overlap rule (docs/model.md, "The fabric's onset"; the default, so the shared default run): calibrated on
    D2 alone, every fitted D2 curve within a band, and the D3 fabric at nu = 0.80, 5.1 band widths off under the
    principal rule, within 2.5 (1.87 when stored)."""
    out = mu05_default[1]
    with open(os.path.join(out, "summary.md")) as fh:
        assert "fabric limit overlap" in fh.read()
    summary = {(s["mode"], float(s["nu [-]"])): s for s in rows(os.path.join(out, "summary.csv")) if s["mode"] != "calibration"}
    for (mode, nu), s in summary.items():
        if mode == "D2":
            assert float(s["worst [band]"]) < 1, s
    assert float(summary[("D3", 0.8)]["F_dev [band]"]) < 2.5, summary[("D3", 0.8)]


def test_extension_rule_keeps_d2_and_slows_the_dense_d3_fabric_at_mu_0_5(tmp_path, mu05_default):
    """The default rule is overlap (the shared default run's summary says so); the
    extension rule (docs/model.md, "The fabric's rate") changes nothing at b = 1/2, so every D2 row of
    the summary is the overlap rule's, and rates the D3 fabric per unit extension strain: at
    nu = 0.80, where the overlap rule's D3 fabric grows too fast (1.87 band widths when stored), it is
    predicted within a band (0.42 when stored)."""
    work, out_d = mu05_default
    out_x = str(tmp_path / "extension")
    r = run(work, "--out", out_x, "--family", "extended", "--fabric-lode", "extension", "--no-jackknife", "--no-plots")
    assert r.returncode == 0, r.stderr
    with open(os.path.join(out_d, "summary.md")) as fh:
        assert "fabric limit overlap" in fh.read()
    dflt = {(s["mode"], float(s["nu [-]"])): s for s in rows(os.path.join(out_d, "summary.csv")) if s["mode"] != "calibration"}
    ext = {(s["mode"], float(s["nu [-]"])): s for s in rows(os.path.join(out_x, "summary.csv")) if s["mode"] != "calibration"}
    for key, s in ext.items():
        if key[0] == "D2":
            assert s == dflt[key], (s, dflt[key])
    assert float(ext[("D3", 0.8)]["F_dev [band]"]) < 1 < float(dflt[("D3", 0.8)]["F_dev [band]"])


def test_fabric_onset_of_a_curve_stretched_by_the_extension_strain(tmp_path):
    """demkit.model_fabric_onset against curves built by hand: D3's fabric is D2's with the strain
    stretched by sqrt(3) (the same extension principal strain, eps/sqrt(3) against eps/3), so the
    onset ratio is sqrt(3) and the extension strain at the onsets over the overlap pi p*/(C nu)
    is the same; a D3 curve that never rises gives no onset (nan, counted out)."""
    import numpy as np
    from demkit import model_fabric_onset as mfo
    eps = np.linspace(0.0, 0.3, 101)
    rise = lambda e: 0.25 * (1 - np.exp(-(e / 0.05) ** 3))
    head = "eps_d,p_star,s_dev,F_dev,C\n"
    for k, d3_rises in enumerate((True, True, False)):
        m = tmp_path / "mu_0.5" / "members" / f"m00{k}" / "deviatoric"
        m.mkdir(parents=True)
        for mode, F in (("D2", 0.03 + rise(eps)), ("D3", 0.03 + (rise(eps / np.sqrt(3)) if d3_rises else 0 * eps))):
            text = head + "".join(f"{e},0.1,{0.5 + e},{f},8\n" for e, f in zip(eps, F))
            (m / f"{mode}_phi0.800.csv").write_text("# hand-built\n" + text)
    (rec,) = mfo.summary(str(tmp_path), 0.2, mus=("0.5",), nus=("0.800",))
    assert rec["ratio_on"][2] == 2                                   # the third packing never reaches it
    assert abs(rec["ratio_on"][0] - np.sqrt(3)) < 0.02, rec["ratio_on"]
    assert abs(rec["ext_D3_over_overlap"][0] / rec["ext_D2_over_overlap"][0] - 1) < 0.02
    assert abs(rec["overlap"][0] - np.pi * 0.1 / (8 * 0.8)) < 1e-12


def test_fabric_rate_and_stress_peak_of_curves_built_by_hand(tmp_path):
    """demkit.model_fabric_rate against curves built by hand: D3's fabric is D2's with the strain
    stretched by sqrt(3), so at equal extension strain the D3/D2 rise is 1 and at equal eps_d it is
    rise(0.3/sqrt(3))/rise(0.3); a stress ratio that peaks at 1 near eps_d = 0.15 and then loses
    0.1 per 0.15 of strain has a drop 0.1 x 0.9 against its mean over 0.27-0.3; p* = 0.1 (1 + eps)."""
    import numpy as np
    from demkit import model_fabric_rate as mfr
    eps = np.linspace(0.0, 0.3, 301)
    rise = lambda e: 0.25 * (1 - np.exp(-(e / 0.05) ** 3))
    s = 1 - np.exp(-eps / 0.005) - 0.1 * np.clip((eps - 0.15) / 0.15, 0, None)
    head = "eps_d,p_star,s_dev,F_dev,nu\n"
    for k in range(3):
        m = tmp_path / "mu_0.5" / "members" / f"m00{k}" / "deviatoric"
        m.mkdir(parents=True)
        for mode, F in (("D2", 0.03 + rise(eps)), ("D3", 0.03 + rise(eps / np.sqrt(3))), ("isobaric_D2", 0.03 + rise(eps))):
            text = head + "".join(f"{e},{0.1 * (1 + e)},{x},{f},0.8\n" for e, x, f in zip(eps, s, F))
            (m / f"{mode}_phi0.800.csv").write_text("# hand-built\n" + text)
    rate, peak = mfr.tables(str(tmp_path), mus=("0.5",), nus=("0.800",))
    (_, _, m, _), = rate
    assert abs(m[1] - 1) < 0.01, m
    assert abs(m[0] - rise(0.3 / np.sqrt(3)) / rise(0.3)) < 0.01, m
    for _, _, curve, pm, _ in peak:
        assert abs(pm[0] - 0.09) < 0.005 and abs(pm[1] - 0.15) < 0.01, (curve, pm)
        assert abs(pm[4] - (1 + 0.285)) < 0.002, (curve, pm)


def test_state_limit_fits_the_peak_at_mu_0_5_and_is_off_by_default(tmp_path, mu05_default):
    """The state-dependent stress-ratio limit (docs/model.md, "The state-dependent limit"): off by
    default (`--state-limit none` gives the default run's summary and parameters, the same bytes, compared on fits
    stopped after 3 iterations; the default's parameters table has no n_psi); switched on, the table lists n_psi_a and n_psi_b, every fitted D2 curve is
    within a band, and the D2 stress ratio at nu = 0.69, which peaks and softens in the DEM, is fitted
    within half a band (0.27 when stored; 0.68 without the state limit)."""
    work = mu05_default[0]
    # `none` is the default: the same bytes, compared on fits stopped after 3 iterations (returncode 1: not converged)
    short = {k: str(tmp_path / k) for k in ("short_default", "short_none")}
    for k, extra in (("short_default", []), ("short_none", ["--state-limit", "none"])):
        r = run(work, "--out", short[k], "--family", "extended", "--no-jackknife", "--no-plots", "--max-iterations",
                "3", *extra)
        assert r.returncode in (0, 1), r.stderr
    for name in ("summary.md", "parameters.md"):
        with open(os.path.join(short["short_default"], name)) as a, open(os.path.join(short["short_none"], name)) as b:
            assert a.read() == b.read(), name
    outs = {"none": mu05_default[1], "pressure": str(tmp_path / "pressure")}
    r = run(work, "--out", outs["pressure"], "--family", "extended", "--no-jackknife", "--no-plots", "--state-limit",
            "pressure")
    assert r.returncode == 0, r.stderr
    off = {p["parameter"]: p for p in rows(os.path.join(outs["none"], "parameters.csv"))}
    on = {p["parameter"]: p for p in rows(os.path.join(outs["pressure"], "parameters.csv"))}
    assert "n_psi_a" not in off and len(on) == len(off) + 2 and "n_psi_b" in on
    with open(os.path.join(outs["pressure"], "summary.md")) as fh:
        assert "state-dependent limit (pressure)" in fh.read()
    summary = {(s["mode"], float(s["nu [-]"])): s for s in rows(os.path.join(outs["pressure"], "summary.csv"))
               if s["mode"] != "calibration"}
    plain = {(s["mode"], float(s["nu [-]"])): s for s in rows(os.path.join(outs["none"], "summary.csv"))
             if s["mode"] != "calibration"}
    for (mode, nu), s in summary.items():
        if mode == "D2":
            assert float(s["worst [band]"]) < 1, s
    assert float(summary[("D2", 0.69)]["s_dev [band]"]) < 0.5 < float(plain[("D2", 0.69)]["s_dev [band]"])


def test_state_limit_choice_pairs_the_held_out_scores(tmp_path):
    """demkit.model_state_limit on hand-built selection files: the scores pair by left-out packing; a
    state-limit run better on every packing by 0.3 (spread 0.05) is chosen, one better by 0.01 with a
    spread of 0.2 is not (t_{7,0.975} = 2.365)."""
    from demkit import model_state_limit

    def write(folder, scores):
        os.makedirs(folder, exist_ok=True)
        with open(os.path.join(folder, "selection.csv"), "w") as fh:
            fh.write("# held-out\npacking_left_out,heldout_group [-],heldout_extended [-],difference [-]\n")
            for k, v in enumerate(scores):
                fh.write(f"{k},50,{v},{50 - v}\n")
            fh.write("mean,nan,nan,1\nchosen,extended,chi2/dof 1 / 1,nan\n")

    plain = [1.0 + 0.05 * ((-1) ** k) for k in range(8)]
    write(str(tmp_path / "plain" / "mu_1"), plain)
    write(str(tmp_path / "good" / "mu_1" / "model"), [v - 0.3 + 0.01 * k for k, v in enumerate(plain)])
    write(str(tmp_path / "noisy" / "mu_1" / "model"), [v - 0.01 + 0.2 * ((-1) ** (k // 2)) for k, v in enumerate(plain)])
    mean, se, t, K, chosen = model_state_limit.paired_choice(
        model_state_limit.extended_scores(str(tmp_path / "plain" / "mu_1")),
        model_state_limit.extended_scores(str(tmp_path / "good" / "mu_1" / "model")))
    assert K == 8 and chosen and abs(mean - (0.3 - 0.035)) < 1e-12 and abs(t - 2.3646) < 1e-3
    out = str(tmp_path / "choice.md")
    model_state_limit.main(["--plain", str(tmp_path / "plain"), "--state", str(tmp_path / "noisy"), "--mu", "1",
                            "--out", out])
    with open(out) as fh:
        text = fh.read()
    assert "| 1 | 8 |" in text and text.rstrip().endswith("plain limit |"), text


def test_a_fit_stopped_short_says_so_and_can_go_on(tmp_path):
    """Two iterations cannot converge: the tables are written with a `converged = no` row, the exit
    status is 1 with the way on, and --start from that table continues (no input error)."""
    from demkit import model_friction
    work = str(tmp_path / "mu_0.5")
    model_friction.copy_tree(os.path.join(ROOT, "data", "friction_n1000", "mu_0.5"), work)
    out = str(tmp_path / "short")
    r = run(work, "--out", out, "--family", "extended", "--no-jackknife", "--no-plots", "--max-iterations", "2")
    assert r.returncode == 1, r.stderr
    assert "did not converge" in r.stderr and "--start " + os.path.join(out, "parameters.csv") in r.stderr
    params = {p["parameter"]: p for p in rows(os.path.join(out, "parameters.csv"))}
    assert params["converged"]["law"].startswith("no: ") and "NO_CONVERGENCE" in params["converged"]["law"]
    on = run(work, "--out", str(tmp_path / "on"), "--family", "extended", "--no-jackknife", "--no-plots",
             "--start", os.path.join(out, "parameters.csv"), "--max-iterations", "2")
    assert on.returncode in (0, 1), on.stderr
    assert "converged" not in {p["parameter"] for p in rows(os.path.join(str(tmp_path / "on"), "parameters.csv"))} \
        or on.returncode == 1


def test_weighted_rule_needs_a_second_lode_angle_and_fits_both_at_mu_0_5(tmp_path):
    """The weighted fabric rule (docs/model.md, "The Lode weight"): on D2 alone it is refused (exit 2,
    naming the second Lode angle, nothing written); calibrated on D2 + D3 its table lists ln_delta_w and
    n_w and no n_psi (the state limit off), every D3 fabric curve is fitted within 0.9 band half-widths
    (0.76 when stored; the overlap rule's reaches 1.02) and its chi2/dof is below the overlap rule's on
    the same curves (1.42 against 1.75 when stored)."""
    from demkit import model_friction
    src = os.path.join(ROOT, "data", "friction_n1000", "mu_0.5")
    work = str(tmp_path / "mu_0.5")
    model_friction.copy_tree(src, work)
    r = run(work, "--out", str(tmp_path / "d2"), "--family", "extended", "--fabric-lode", "weighted", "--no-plots")
    assert r.returncode == 2 and "second Lode angle" in r.stderr and "--calibrate-on" in r.stderr, r.stderr
    assert not os.path.exists(str(tmp_path / "d2")), "the refused run left its output folder"
    os.makedirs(tmp_path / "empty")
    r = run(str(tmp_path / "empty"), "--out", str(tmp_path / "e"), "--no-plots")   # any refusal after the folder check
    assert r.returncode == 2 and "does not exist" in r.stderr and not os.path.exists(str(tmp_path / "e")), r.stderr
    chi = {}
    for rule in ("weighted", "overlap"):
        r = run(work, "--out", str(tmp_path / rule), "--family", "extended", "--fabric-lode", rule, "--calibrate-on",
                "D2,D3", "--no-jackknife", "--no-plots")
        assert r.returncode == 0, r.stderr
        summary = rows(os.path.join(str(tmp_path / rule), "summary.csv"))
        chi[rule] = next(float(s["role"].split()[-1]) for s in summary if s["mode"] == "calibration")
    names = [p["parameter"] for p in rows(os.path.join(str(tmp_path / "weighted"), "parameters.csv"))]
    assert "ln_delta_w" in names and "n_w" in names and not any(n.startswith("n_psi") for n in names), names
    for s in rows(os.path.join(str(tmp_path / "weighted"), "summary.csv")):
        if s["mode"] == "D3":
            assert s["role"] == "fitted" and float(s["F_dev [band]"]) < 0.9, s
    assert chi["weighted"] < chi["overlap"], chi


def test_held_out_scores_of_a_single_family_run_pair_like_the_selection(tmp_path):
    """A `--family extended` run with the jackknife writes heldout.csv (the per-packing scores that a
    `--family auto` run writes in selection.csv); demkit.model_state_limit reads either, and pairs them."""
    from demkit import model_state_limit
    a, b = tmp_path / "a", tmp_path / "b"
    os.makedirs(a)
    os.makedirs(b)
    with open(a / "selection.csv", "w") as fh:
        fh.write("packing_left_out,heldout_group [-],heldout_extended [-],difference [-]\n0,5,1.0,4\n1,5,1.2,3.8\n"
                 "2,5,0.9,4.1\nmean,nan,nan,1\n")
    with open(b / "heldout.csv", "w") as fh:
        fh.write("# held-out\npacking_left_out,heldout_extended [-]\n0,0.5\n1,0.8\n2,0.6\n")
    sb = model_state_limit.extended_scores(str(b))
    assert sb == {0: 0.5, 1: 0.8, 2: 0.6}
    mean, se, t, K, chosen = model_state_limit.paired_choice(model_state_limit.extended_scores(str(a)), sb)
    assert K == 3 and abs(mean - 0.4) < 1e-12 and chosen


def test_lode_weight_table_of_hand_built_runs(tmp_path):
    """demkit.model_lode_weight --table-only on two hand-built runs (summary, held-out scores, parameters):
    the worst curve of each kind with its quantity and nu, chi2/dof from the calibration row, and the rule
    the paired held-out test chooses (weighted better on every packing by 0.2: chosen); a coefficient's
    jackknife SE, or the covariance SE marked c where the jackknife gave none."""
    from demkit import model_lode_weight
    out = tmp_path / "out"
    head = "mode,nu [-],role,p_star [band],eps_v [band],s_dev [band],F_dev [band],worst [band]\n"
    for rule, f3, chi, shift in (("overlap", 1.4, 1.7, 0.0), ("weighted", 0.6, 1.3, 0.2)):
        d = out / rule / "mu_1"
        os.makedirs(d)
        (d / "summary.csv").write_text(head + f"D2,0.69,fitted,0.2,nan,0.8,0.5,0.8\nD3,0.74,fitted,0.3,nan,0.5,{f3},{f3}\n"
                                       "isobaric,0.8,predicted,nan,1.2,0.4,0.3,1.2\n"
                                       f"calibration,nan,chi2/dof {chi},nan,nan,nan,nan,{f3}\n")
        (d / "heldout.csv").write_text("packing_left_out,heldout_extended [-]\n" +
                                       "".join(f"{k},{1.0 + 0.01 * k - shift}\n" for k in range(8)))
        (d / "parameters.csv").write_text("parameter,law,value,se,se_method,lo95,hi95,se_covariance,se_jackknife,units\n"
                                          "n_w,w,5.0,0.5,jk,4,6,0.3,0.5,-\nchi_D,c,3.0,nan,cov,nan,nan,0.1,nan,-\n")
    model_lode_weight.main(["--work", str(tmp_path / "w"), "--out", str(out), "--mu", "1", "--table-only"])
    text = (out / "lode_weight.md").read_text()
    row = next(l for l in text.splitlines() if l.startswith("| 1 |"))
    assert "1.7 → 1.3" in row and "0.80 (s 0.69)" in row and "1.40 (F 0.74) → 0.60 (F 0.74)" in row, row
    assert "1.20 (ε_v 0.80)" in row and row.rstrip().endswith("| weighted |"), row
    params = (out / "parameters_weighted.md").read_text()
    assert "| n_w | 5 ± 0.5 |" in params and "| chi_D | 3 ± 0.1 c |" in params, params


def test_stored_lode_weight_tables_are_rebuilt_from_the_stored_runs(tmp_path):
    """data/friction_n1000/model_friction/lode_weight: its tables are what `--table-only` makes of its runs
    (byte for byte), every run carries its 8 held-out scores, and a missing run is named, not a traceback."""
    from demkit import model_lode_weight
    src = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "lode_weight")
    work = tmp_path / "lw"
    shutil.copytree(src, work)
    model_lode_weight.main(["--work", str(tmp_path / "w"), "--out", str(work), "--table-only"])
    for name in ("lode_weight.md", "lode_weight.csv", "parameters_overlap.md", "parameters_weighted.md"):
        with open(os.path.join(src, name)) as a, open(work / name) as b:
            assert a.read() == b.read(), name
    for rule in model_lode_weight.RULES:
        for mu in model_lode_weight.MUS:
            assert len(model_lode_weight.model_state_limit.extended_scores(str(work / rule / f"mu_{mu}"))) == 8
    with pytest.raises(SystemExit, match="does not exist"):
        model_lode_weight.main(["--work", str(tmp_path / "w"), "--out", str(tmp_path / "none"), "--table-only"])


def test_variant_choice_is_the_simplest_that_no_other_beats():
    """demkit.model_variants.choose: b beats a when a's held-out scores exceed b's by more than t_{K-1,0.975}
    paired SE; the chosen variant is the one with the fewest coefficients that nothing beats (a tie: the lower
    mean), so a richer variant is taken only when it beats every simpler one."""
    from demkit import model_variants
    noise = [0.01, -0.02, 0.015, -0.005, 0.02, -0.01, 0.0, 0.005]
    base = {k: 1.0 + 0.1 * k for k in range(8)}

    def shifted(d, flip=1):
        return {k: v - d + flip * noise[k] for k, v in base.items()}

    sizes = {"A": 7, "B": 9, "C": 9, "D": 11}
    # B and D below A on every packing, D below B: only D is not beaten.
    chosen, beaten, means = model_variants.choose(
        {"A": dict(base), "B": shifted(0.3), "C": shifted(0.0, -1), "D": shifted(0.6)}, sizes)
    assert chosen == "D" and beaten["D"] == [] and set(beaten["A"]) == {"B", "D"}, (chosen, beaten)
    # D only noise below B: B (fewer coefficients) is chosen, and D, not beaten either, is not.
    chosen, beaten, _ = model_variants.choose(
        {"A": dict(base), "B": shifted(0.3), "C": shifted(0.0, -1), "D": shifted(0.3, -1)}, sizes)
    assert chosen == "B" and beaten["B"] == [] and beaten["D"] == [], (chosen, beaten)
    # Nothing separates the four: the simplest.
    same = {n: shifted(0.0, s) for n, s in (("A", 1), ("B", -1), ("C", 1), ("D", -1))}
    assert model_variants.choose(same, sizes)[0] == "A"
    # B and C tie on size and are both unbeaten: the lower mean.
    chosen, _, means = model_variants.choose({"A": dict(base), "B": shifted(0.3), "C": shifted(0.31, -1),
                                              "D": shifted(0.3)}, sizes)
    assert chosen == "C" and means["C"] < means["B"], (chosen, means)


def test_holms_correction_keeps_strong_beats_and_drops_marginal_ones():
    """demkit.model_variants.holm_beats: with two variants Holm's correction is the uncorrected test; among six,
    a beat at p ~ 0.02 (t ~ 2.9, K = 8) is dropped (the smallest p must be below 0.05/15) while one at t ~ 15 is
    kept, and choose(holm=True) then takes the simpler variant."""
    from demkit import model_variants
    noise = [0.01, -0.02, 0.015, -0.005, 0.02, -0.01, 0.0, 0.005]
    base = {k: 1.0 + 0.1 * k for k in range(8)}
    marginal = {k: v - 0.016 + noise[k] for k, v in base.items()}
    strong = {k: v - 0.1 + 0.3 * noise[k] for k, v in base.items()}
    two = {"A": base, "B": marginal}
    assert model_variants.holm_beats(two) == {("A", "B"): True}
    assert model_variants.choose(two, {"A": 7, "B": 9}, holm=True)[0] == "B" == model_variants.choose(two, {"A": 7, "B": 9})[0]
    six = {"A": base, "B": marginal, "S": strong}
    for j, sign in enumerate((1, -1, 1)):   # three more, noise about A
        six[f"N{j}"] = {k: v + sign * noise[(k + j + 1) % 8] for k, v in base.items()}
    sizes = {"A": 7, "B": 9, "S": 11, "N0": 9, "N1": 9, "N2": 9}
    hb = model_variants.holm_beats(six)
    assert ("A", "S") in hb and ("A", "B") not in hb and ("B", "A") not in hb
    assert model_variants.choose(six, sizes)[1]["A"] == ["B", "S"]       # uncorrected: B beats A too
    chosen, beaten, _ = model_variants.choose(six, sizes, holm=True)
    assert chosen == "S" and "B" not in beaten["A"] and "S" in beaten["A"], (chosen, beaten)
    six.pop("S"), sizes.pop("S")
    assert model_variants.choose(six, sizes, holm=True)[0] == "A" and model_variants.choose(six, sizes)[0] == "B"


@pytest.mark.parametrize("where, K, mus", [
    (("friction_n1000", "model_friction", "lode_weight"), 8, ("0", "0.01", "0.1", "0.3", "0.5", "1")),
    (("friction_n1000_k12", "model"), 12, ("0", "0.1", "0.3", "0.5", "1"))])
def test_stored_variant_table_is_rebuilt_from_the_stored_runs(tmp_path, where, K, mus):
    """The stored variants.{md,csv} (the K = 8 study; the K = 12 ensembles, cross-started): what `demkit.model_variants
    --table-only` makes of the four variants' stored runs (byte for byte), and at K = 12 the two rules' tables
    (demkit.model_lode_weight) too; every run carries its K held-out scores, the choice is a variant that no
    other beats, and a start other than the default is named."""
    from demkit import model_lode_weight, model_variants
    src = os.path.join(ROOT, "data", *where)
    work = tmp_path / "lw"
    shutil.copytree(src, work)
    model_variants.main(["--work", str(tmp_path / "w"), "--out", str(work), "--mu", *mus, "--table-only"])
    names = ["variants.md", "variants.csv"]
    if K == 12:
        model_lode_weight.main(["--work", str(tmp_path / "w"), "--out", str(work), "--mu", *mus, "--table-only"])
        names += ["lode_weight.md", "lode_weight.csv", "parameters_overlap.md", "parameters_weighted.md"]
    for name in names:
        with open(os.path.join(src, name)) as a, open(work / name) as b:
            assert a.read() == b.read(), name
    rows = list(csv.DictReader(open(work / "variants.csv")))
    assert len(rows) == len(model_variants.VARIANTS) * len(mus)
    for r in rows:
        assert (r["chosen"] == "yes") <= (r["beaten_by"] == "none"), r
        assert (r["chosen_holm"] == "yes") <= (r["beaten_by_holm"] in ("none", "")), r
        # Holm's correction only removes beats
        assert set(r["beaten_by_holm"].split("; ")) - {"none", ""} <= set(r["beaten_by"].split("; ")), r
        assert r["start"] in ["default", "not run"] + [v[0] for v in model_variants.VARIANTS], r
        # only the eighth round's optional Lode-limit variants may be missing
        assert r["start"] != "not run" or r["variant"] in [v[0] for v in model_variants.LODE], r
    for _, folder, _, _, _ in model_variants.VARIANTS:
        for mu in mus:
            run = work / folder / f"mu_{mu}"
            if (run / "summary.csv").exists():
                assert len(model_variants.model_state_limit.extended_scores(str(run))) == K


def test_multi_start_run_names_its_start_variant(tmp_path):
    """start_of: a --cross-start run's start.txt, else the kept row of a multi-start run's starts.csv, whose path
    OUT/FOLDER/mu_MU/parameters.csv names the variant; 'default' when kept or absent."""
    from demkit import model_variants
    run = tmp_path / "run"
    run.mkdir()
    assert model_variants.start_of(str(run)) == "default"
    head = "start,chi2_per_dof [-],converged,kept,message\n"
    (run / "starts.csv").write_text(head + "default,2.4,yes,no,m\nOUT/weighted/mu_1/parameters.csv,2.3,yes,yes,m\n"
                                    "OUT/overlap/mu_1/parameters.csv,2.5,yes,no,m\n")
    assert model_variants.start_of(str(run)) == "weighted + limit"
    (run / "starts.csv").write_text(head + "default,2.2,yes,yes,m\nOUT/overlap/mu_1/parameters.csv,2.5,yes,no,m\n")
    assert model_variants.start_of(str(run)) == "default"
    (run / "start.txt").write_text("started from the calibrated parameters of the variant 'overlap' (...)\n")
    assert model_variants.start_of(str(run)) == "overlap"


def test_cross_start_keeps_the_lowest_minimum(tmp_path):
    """demkit.model_variants.cross_start with a stand-in `dem` (its chi2/dof set by the start's parameters.csv):
    each variant tried from the other three's parameters; the one whose default start ended higher is run again
    from the best start, with the jackknife, and says so in start.txt (the table's start column); one already at
    its lowest is left as it was."""
    from demkit import model_variants
    fake = tmp_path / "dem"
    fake.write_text("#!/usr/bin/env python3\n"
                    "import sys, os\n"
                    "a = sys.argv\n"
                    "out = a[a.index('--out') + 1]\n"
                    "chi = 2.0\n"
                    "if '--start' in a:\n"
                    "    chi = float(open(a[a.index('--start') + 1]).read().split(',')[-1])\n"
                    "os.makedirs(out, exist_ok=True)\n"
                    "open(os.path.join(out, 'summary.csv'), 'w').write('mode,nu [-],role,p_star [band],eps_v [band],"
                    "s_dev [band],F_dev [band],worst [band]\\ncalibration,nan,chi2/dof %g,nan,nan,nan,nan,1\\n' % chi)\n"
                    "open(os.path.join(out, 'parameters.csv'), 'w').write('parameter,value\\nchi,%g' % chi)\n"
                    "open(os.path.join(out, 'jack.txt'), 'w').write(str('--no-jackknife' not in a))\n")
    fake.chmod(0o755)
    out = tmp_path / "out"
    chis = {"overlap_no_limit": 1.5, "overlap": 1.2, "weighted_no_limit": 3.0, "weighted": 1.0}
    for folder, chi in chis.items():
        d = out / folder / "mu_1"
        os.makedirs(d)
        (d / "summary.csv").write_text("mode,nu [-],role,p_star [band],eps_v [band],s_dev [band],F_dev [band],"
                                       f"worst [band]\ncalibration,nan,chi2/dof {chi},nan,nan,nan,nan,1\n")
        (d / "parameters.csv").write_text(f"parameter,value\nchi,{chi}")
    model_variants.cross_start(str(fake), str(tmp_path / "work"), str(out), "1", str(tmp_path / "scratch"))
    for folder in ("overlap_no_limit", "overlap", "weighted_no_limit"):   # each reaches 1.0 from weighted's start
        assert model_variants.start_of(str(out / folder / "mu_1")) == "weighted + limit", folder
        assert (out / folder / "mu_1" / "jack.txt").read_text() == "True"
        assert "chi2/dof 1," in (out / folder / "mu_1" / "summary.csv").read_text()
    assert model_variants.start_of(str(out / "weighted" / "mu_1")) == "default"
    assert "chi2/dof 1.0" in (out / "weighted" / "mu_1" / "summary.csv").read_text()


def test_multi_start_keeps_the_best_of_the_single_starts(tmp_path, result):
    """`--start default,A`: the fit is made from each start and the result is, byte for byte, the single-start
    run with the lowest chi2/dof (converged before not converged); starts.csv lists both. Three iterations
    leave the default start short of the optimum that A (a converged run's parameters) starts at."""
    good = os.path.join(result[0], "parameters.csv")
    single = {}
    for name, start in (("default", "default"), ("good", good)):
        out = str(tmp_path / name)
        r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--no-plots", "--start", start, "--max-iterations", "3")
        assert r.returncode in (0, 1), r.stderr
        p = {q["parameter"]: q for q in rows(os.path.join(out, "parameters.csv"))}
        single[start] = (float(p["chi2_per_dof"]["value"]), "converged" not in p, out)
    multi = str(tmp_path / "multi")
    r = run(ENSEMBLE, "--out", multi, "--no-jackknife", "--no-plots", "--start", f"default,{good}", "--max-iterations", "3")
    assert r.returncode in (0, 1), r.stderr
    table = rows(os.path.join(multi, "starts.csv"))
    assert [t["start"] for t in table] == ["default", good]
    for t in table:
        chi, conv, _ = single[t["start"]]
        assert float(t["chi2_per_dof [-]"]) == pytest.approx(chi, rel=1e-5)
        assert (t["converged"] == "yes") == conv
    best = min(single, key=lambda s: (not single[s][1], single[s][0]))
    assert single[best][0] < max(v[0] for v in single.values())   # the two starts really differ
    assert [t["kept"] for t in table] == ["yes" if t["start"] == best else "no" for t in table]
    with open(os.path.join(multi, "parameters.csv")) as a, open(os.path.join(single[best][2], "parameters.csv")) as b:
        assert a.read() == b.read()
    # one start writes no starts table (the outputs of a single-start run are unchanged)
    assert not os.path.exists(os.path.join(single["default"][2], "starts.csv"))


def edited_parameters(src, dst, factors):
    """A copy of a parameters.csv with some values multiplied (a start elsewhere)."""
    table = rows(src)
    for t in table:
        if t["parameter"] in factors:
            t["value"] = repr(float(t["value"]) * factors[t["parameter"]])
    with open(dst, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    return dst


def test_multi_start_holds_the_first_starts_isotropic_values(tmp_path, result):
    """--hold-isotropic with several starts: every start's fit holds the named parameters at the
    first start's values, including a kept start that carries other values of them."""
    good = os.path.join(result[0], "parameters.csv")
    first = edited_parameters(good, str(tmp_path / "first.csv"), {"p0": 1.1, "s_max_a": 1.6, "ln_beta_s_a": 0.5})
    second = edited_parameters(good, str(tmp_path / "second.csv"), {"p0": 0.8})
    out = str(tmp_path / "multi")
    r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--no-plots", "--start", f"{first},{second}",
            "--hold-isotropic", "p0", "--max-iterations", "5")
    assert r.returncode in (0, 1), r.stderr
    assert [t["kept"] for t in rows(os.path.join(out, "starts.csv"))] == ["no", "yes"]   # the second start kept
    p = {q["parameter"]: float(q["value"]) for q in rows(os.path.join(out, "parameters.csv")) if q["parameter"] == "p0"}
    p_first = float(next(q["value"] for q in rows(first) if q["parameter"] == "p0"))
    assert p["p0"] == pytest.approx(p_first, rel=1e-5)   # held at the first start's 1.1 x, not the kept one's 0.8 x


def test_the_jackknife_records_its_refits_and_retries_an_unusable_one_from_the_other_starts(tmp_path, result):
    """jackknife.csv: one row per packing left out, with the refit's chi2/dof, whether it converged and was usable
    (converged, chi2/dof <= 3 max(1, the full fit's)), where it started and how many starts it took. From a converged
    optimum every refit is usable at once and the jackknife errors are quoted. Stopped after one iteration from two
    far starts, every refit is unusable, is run again from the other start (2 tries; 3 where the basin check ran it
    again), and the errors are the covariance's, with a warning that names the refits."""
    good = os.path.join(result[0], "parameters.csv")
    a = str(tmp_path / "a")
    r = run(ENSEMBLE, "--out", a, "--no-plots", "--start", good)
    assert r.returncode == 0, r.stderr
    params = {q["parameter"]: q for q in rows(os.path.join(a, "parameters.csv"))}
    full = float(params["chi2_per_dof"]["value"])
    table = rows(os.path.join(a, "jackknife.csv"))
    assert [t["packing_left_out"] for t in table] == ["m000", "m001", "m002", "m003"]
    for k, t in enumerate(table):
        chi = float(t["chi2_per_dof [-]"])
        assert t["converged"] == "yes" and t["usable"] == "yes" and t["tries"] == "1", t
        assert t["start"] == "the full fit's optimum" and 0 < chi <= 3 * max(1.0, full), t
        assert float(t["full_fit_chi2_per_dof [-]"]) == pytest.approx(full, rel=1e-5)
        line = next(l for l in r.stderr.splitlines() if l.startswith(f"dem model: jackknife {k + 1}/4"))
        assert float(line.split("chi2/dof = ")[1]) == pytest.approx(chi, rel=1e-3), line
    assert math.isfinite(float(params["s_max_a"]["se_jackknife"])) and "jackknife not used" not in r.stderr
    far = edited_parameters(good, str(tmp_path / "far.csv"), {"s_max_a": 1.8, "p0": 1.2})
    b = str(tmp_path / "b")
    r = run(ENSEMBLE, "--out", b, "--no-plots", "--start", f"default,{far}", "--max-iterations", "1")
    assert r.returncode == 1, r.stderr
    table = rows(os.path.join(b, "jackknife.csv"))
    assert len(table) == 4 and all(t["converged"] == "no" and t["usable"] == "no" for t in table)
    # 2 tries, and a third where the basin check found another refit's optimum lower on this one's data
    assert all(t["tries"] == "2" or (t["tries"] == "3" and "(basin check; from " in t["start"]) for t in table), table
    warning = next(l for l in r.stderr.splitlines() if "jackknife not used" in l)
    assert all(f"m00{k} left out" in warning for k in range(4)) and "jackknife.md" in warning, warning
    params = rows(os.path.join(b, "parameters.csv"))
    assert all(math.isnan(float(q["se_jackknife"])) for q in params)
    assert not os.path.exists(os.path.join(result[0], "jackknife.csv")), "--no-jackknife writes no refit table"


def test_bad_starts_are_refused(tmp_path, result):
    good = os.path.join(result[0], "parameters.csv")
    r = run(ENSEMBLE, "--out", str(tmp_path / "a"), "--no-plots", "--start", f"default,{tmp_path}/none.csv")
    assert r.returncode == 2 and "none.csv is not a file" in r.stderr and "`default`" in r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "b"), "--no-plots", "--start", f"default,{good}", "--hold-isotropic", "p0")
    assert r.returncode == 2 and "the first is `default`" in r.stderr and "parameters.csv first" in r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "c"), "--no-plots", "--start-isotropic", "branch")
    assert r.returncode == 2 and "no --start was given" in r.stderr and "--start PARAMETERS.csv" in r.stderr, r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "d"), "--no-plots", "--start", good, "--start-isotropic", "both")
    assert r.returncode == 2 and "--start-isotropic" in r.stderr, r.stderr
    for d in "abcd":
        assert not os.path.exists(tmp_path / d / "parameters.csv")


def test_parameter_values_carry_every_digit_in_the_machine_tables(result):
    """parameters.csv and .json carry each value to the last bit (--start and --predict-with read them back: a restart
    from six digits began up to 1.7 % above the optimum's cost, docs/model.md, sixteenth round), parameters.md the
    six digits a reader wants; the two agree."""
    out = result[0]
    table = {r["parameter"]: r for r in rows(os.path.join(out, "parameters.csv"))}
    with open(os.path.join(out, "parameters.json")) as fh:
        machine = {r["parameter"]: r["value"] for r in json.load(fh)["rows"]}
    with open(os.path.join(out, "parameters.md")) as fh:
        md = {c[0]: c[2] for c in ([x.strip() for x in ln.strip().strip("|").split("|")] for ln in fh if ln.startswith("| "))}
    longer = 0
    for name in ("p0", "nu_c", "C0", "C1", "s_max_a", "ln_beta_s_a", "F_max_a", "a_A_a"):
        text = table[name]["value"]
        v = float(text)
        assert machine[name] == v, name                        # the .json holds the same double
        assert md[name] == "%.6g" % v, (name, md[name], text)   # .md: six significant digits of it
        longer += len(text.lstrip("-").replace(".", "").lstrip("0")) > 6
    assert longer >= 6, table   # fitted values are not six-digit numbers


def test_cost_scan_reads_a_smooth_optimum_and_refuses_unknown_names(tmp_path, result):
    """demkit.model_cost_scan: the group model's optimum on figure3_n9261 is smooth (stepping s_max_a and p0 by
    relative 1e-7 leaves the initial cost's seven digits, spread below 1e-5), every point in --csv; a name that is not a
    coefficient is refused with the names it could have been, exit 2, nothing written."""
    good = os.path.join(result[0], "parameters.csv")
    out = str(tmp_path / "scan.csv")
    env = dict(os.environ, PYTHONPATH=ROOT)
    r = subprocess.run([sys.executable, "-m", "demkit.model_cost_scan", ENSEMBLE, good, "--scan", "s_max_a,p0",
                        "--steps", "1", "--dem", DEM, "--csv", out], capture_output=True, text=True, cwd=ROOT, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("(smooth)") == 2, r.stdout
    pts = rows(out)
    assert [p["name"] for p in pts] == ["s_max_a"] * 3 + ["p0"] * 3
    assert [int(p["k"]) for p in pts] == [-1, 0, 1, -1, 0, 1]
    v = [float(p["value"]) for p in pts[:3]]
    assert v[0] < v[1] < v[2] and v[2] / v[1] - 1 == pytest.approx(1e-7, rel=1e-3)
    bad = str(tmp_path / "bad.csv")
    r = subprocess.run([sys.executable, "-m", "demkit.model_cost_scan", ENSEMBLE, good, "--scan", "n_peak",
                        "--dem", DEM, "--csv", bad], capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert r.returncode == 2 and "n_peak not a coefficient" in r.stderr and "s_max_a" in r.stderr, r.stderr
    assert not os.path.exists(bad)


def test_predicting_with_a_law_that_has_the_isotropic_cusp_warns(tmp_path):
    """--predict-with a stored volume-form calibration whose nu_cC lies above its nu_c (the fourteenth round's mu = 1
    joint optimum, kept as a start) predicts, and warns with the cusp's pressure p*(nu_cC) = 1.92e-3, computed here from
    the file's isotropic law; a law without the cusp (the stored mu = 1 joint calibration) does not warn. A path whose
    pressure crosses p*(nu_cC) (the dense TC_s3 test at p* = 1e-3) is named."""
    sv = os.path.join(ROOT, "data", "geotech", "model", "state_volume")
    law = os.path.join(sv, "fourteenth_round", "three_pressures", "mu_1", "joint", "parameters.csv")
    v = {r["parameter"]: float(r["value"]) for r in rows(law) if r["parameter"] in
         ("p0", "nu_c", "gamma_p", "C0", "nu_cC")}
    x = math.log(v["nu_cC"] / v["nu_c"])
    p_cusp = v["p0"] * (v["nu_cC"] * v["C0"] / v["nu_c"]) * x * (1 + v["gamma_p"] * x)   # C = C0 at nu_cC
    friction = os.path.join(ROOT, "data", "friction_n1000", "mu_1")
    r = run(friction, "--predict-with", law, "--family", "extended", "--no-plots", "--out", str(tmp_path / "a"), "--force")
    assert r.returncode == 0, r.stderr
    line = next(l for l in r.stderr.splitlines() if "nu_cC above nu_c" in l)
    assert float(line.split("unbounded at p* = ")[1].split(",")[0]) == pytest.approx(p_cusp, rel=1e-5), line
    ok = os.path.join(sv, "three_pressures", "mu_1", "joint", "parameters.csv")
    r = run(friction, "--predict-with", ok, "--family", "extended", "--no-plots", "--out", str(tmp_path / "b"), "--force")
    assert r.returncode == 0 and "nu_cC above nu_c" not in r.stderr, r.stderr
    # seventeenth round: the dense TC_s3 test at p* = 1e-3 rises through that pressure, and is named
    g = subprocess.run([sys.executable, "-m", "demkit.geotech_model", "--curves", os.path.join(ROOT, "data", "geotech",
                        "curves"), "--mu", "1", "--out", str(tmp_path / "g"), "--levels", "iso_lo", "--joint", "--tests",
                        "TC_s3"], capture_output=True, text=True, cwd=ROOT)
    assert g.returncode == 0, g.stderr
    r = run(str(tmp_path / "g" / "ensemble_joint"), "--predict-with", law, "--family", "extended", "--no-plots", "--out",
            str(tmp_path / "c"), "--force")
    assert r.returncode == 0, r.stderr
    with open(tmp_path / "c" / "curves" / "paths" / "TC_s3_dense_phi0.658.csv") as fh:
        p = [float(x["p_star_model"]) for x in csv.DictReader(ln for ln in fh if not ln.startswith("#"))]
    assert min(p) < p_cusp < max(p)
    line = next(l for l in r.stderr.splitlines() if "TC_s3_dense (predicted) crosses the isotropic law's cusp" in l)
    assert float(line.split("(p* = ")[1].split(",")[0]) == pytest.approx(p_cusp, rel=1e-5) and "--jamming shared" in line


def _slope_jump_ratio(curve):
    """The largest jump of d eps_vol / d eps_d between rows of a model path, over the mean of the jumps two rows either
    side (1 on a smooth curve; large at a kink), away from the first rows."""
    with open(curve) as fh:
        r = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    ev, e = [float(x["eps_vol"]) for x in r], [float(x["eps_d"]) for x in r]
    d1 = [(ev[i + 1] - ev[i]) / (e[i + 1] - e[i]) for i in range(len(r) - 1)]
    d2 = [abs(d1[i + 1] - d1[i]) for i in range(len(d1) - 1)]
    return max(d2[i] / max(1e-15, (d2[i - 2] + d2[i + 2]) / 2) for i in range(5, len(d2) - 2))


def test_one_jamming_fraction_removes_the_isobaric_kink(tmp_path, result):
    """--jamming shared ties the coordination law's jamming fraction to the pressure law's: parameters.csv writes
    nu_cC = nu_c (every digit) with the tie named; the separate laws of figure3_n9261 (nu_cC 0.6670 above nu_c 0.6663)
    warn, and their isobaric model path at nu = 0.671 kinks where its nu crosses nu_cC (the slope of eps_vol jumps 24
    times its neighbours' jumps), the tied law's is smooth; a tie with nu_cC held, or an unknown word, is refused."""
    out = str(tmp_path / "shared")
    r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--jamming", "shared", "--force")
    assert r.returncode == 0, r.stderr
    table = {x["parameter"]: x for x in rows(os.path.join(out, "parameters.csv"))}
    assert table["nu_cC"]["value"] == table["nu_c"]["value"]
    assert "one jamming fraction" in table["nu_cC"]["law"] and "tied" in table["nu_cC"]["se_method"]
    assert "lies above nu_c" not in r.stderr
    sep = {x["parameter"]: float(x["value"]) for x in rows(os.path.join(result[0], "parameters.csv"))}
    assert sep["nu_cC"] > sep["nu_c"]
    assert "--jamming shared ties the two" in result[1].stderr
    assert _slope_jump_ratio(os.path.join(result[0], "curves", "isobaric_phi0.671.csv")) > 10
    assert _slope_jump_ratio(os.path.join(out, "curves", "isobaric_phi0.671.csv")) < 2
    good = os.path.join(result[0], "parameters.csv")
    r = run(ENSEMBLE, "--out", str(tmp_path / "a"), "--no-plots", "--jamming", "shared", "--start", good,
            "--hold-isotropic", "nu_cC")
    assert r.returncode == 2 and "leave nu_cC out of --hold-isotropic" in r.stderr, r.stderr
    r = run(ENSEMBLE, "--out", str(tmp_path / "b"), "--no-plots", "--jamming", "one")
    assert r.returncode == 2 and "--jamming" in r.stderr, r.stderr
    for d in "ab":
        assert not os.path.exists(tmp_path / d / "parameters.csv")


def test_jamming_table_reads_the_laws_as_dem_model_writes_them(tmp_path, result):
    """demkit.model_jamming's isotropic laws are the C++ ones: at each nu of laws.csv its p*(nu) and C(nu) equal the
    table's p_iso and C_iso (six digits) for the separate and for the tied law; its row for figure3_n9261 quotes each
    run's chi2/dof as parameters.csv does, the tied nu_c, and the separate laws' cusp p*(nu_cC) (C = C0 there) where
    nu_cC lies above nu_c; a folder that is not a tied run is refused."""
    from demkit import model_jamming as mj
    out = str(tmp_path / "shared")
    r = run(ENSEMBLE, "--out", out, "--no-jackknife", "--no-plots", "--jamming", "shared", "--force")
    assert r.returncode == 0, r.stderr
    dirs = {"separate": result[0], "shared": out}
    for d in dirs.values():
        L = mj.read_law(os.path.join(d, "parameters.csv"))
        for x in rows(os.path.join(d, "laws.csv")):
            nu = float(x["nu [-]"])
            assert float("%.6g" % mj.pressure(L, nu)) == pytest.approx(float(x["p_iso [p*]"]), rel=1e-9), (d, nu)
            assert float("%.6g" % mj.coordination(L, nu)) == pytest.approx(float(x["C_iso [-]"]), rel=1e-9), (d, nu)
    row = mj.row("figure3", "group", ENSEMBLE, dirs)
    chi = {w: float(next(x for x in rows(os.path.join(d, "parameters.csv")) if x["parameter"] == "chi2_per_dof")["value"])
           for w, d in dirs.items()}
    assert row[2] == pytest.approx(chi["separate"], rel=1e-4) and row[3] == pytest.approx(chi["shared"], rel=1e-4)
    A, B = (mj.read_law(os.path.join(d, "parameters.csv")) for d in dirs.values())
    assert row[11] == B["nu_c"] == B["nu_cC"]
    x = math.log(A["nu_cC"] / A["nu_c"])
    assert row[21] == pytest.approx(A["p0"] * A["nu_cC"] * A["C0"] / A["nu_c"] * x * (1 + A["gamma_p"] * x), rel=1e-12)
    # the relaxed static packings of data/isostatic_n1000 at mu = 0: 18 stops, 2 of them unjammed (E_kin/E_pot > 1)
    relaxed = os.path.join(ROOT, "data", "isostatic_n1000", "isostatic.json")
    pts = mj.relaxed_points(relaxed, 0.0)
    assert len(pts) == 16 and min(p for _, p in pts) == pytest.approx(2.61e-4, rel=1e-2)
    full = mj.row("figure3", "group", ENSEMBLE, dirs, mu=0.0, relaxed=relaxed)
    assert full[:22] == row[:22] and row[24] == row[25] == 0   # without the relaxed points: none
    for law, rms, n in ((A, full[22], full[24]), (B, full[23], full[25])):
        above = [(nu, p) for nu, p in pts if nu > law["nu_c"]]
        assert n == len(above) > 0
        assert rms == pytest.approx(math.sqrt(sum((mj.pressure(law, nu) / p - 1) ** 2 for nu, p in above) / n))
    with pytest.raises(SystemExit, match="not a --jamming shared run"):
        mj.row("figure3", "group", ENSEMBLE, {"separate": result[0], "shared": result[0]})


def test_profile_intervals_end_where_the_cost_rises_by_the_scale(tmp_path):
    """Twenty-fourth round: `--profile NAMES` holds each named coefficient at trial values and refits the rest until
    chi2 rises by s = max(1, chi2/dof) (profile.csv). Checked here on the N = 9261 group calibration from its stored
    optimum: every end is found with its rise within 0.05 of s; no end lies nearer than the error-scale check's
    linearised profile allows (the profile minimises over the others, so it rises no faster: t >= 1/sqrt(rise) of
    error_scale.csv, less the 0.05 tolerance); the stderr counts are the csv's; and an independent fit with C0 held at
    its lower end by `--hold-isotropic` (another code path) does not go below the profile's chi2 there. parameters.csv
    carries the ends as profile_lo68/hi68 (twenty-seventh round), a run without --profile does not. An unknown
    name is refused with the fix."""
    out = str(tmp_path / "p")
    stored = os.path.join(ENSEMBLE, "model", "parameters.csv")
    names = ["C0", "alpha", "ln_beta_s_b"]
    r = run(ENSEMBLE, "--start", stored, "--out", out, "--no-jackknife", "--no-plots", "--profile", ",".join(names))
    assert r.returncode == 0, r.stderr
    chi2 = 2 * float(r.stderr.split("Final cost: ")[1].split(",")[0])
    prof = {x["parameter"]: x for x in rows(os.path.join(out, "profile.csv"))}
    scale = {x["parameter"]: x for x in rows(os.path.join(out, "error_scale.csv"))}
    s = max(1.0, float(next(x for x in rows(os.path.join(out, "parameters.csv")) if x["parameter"] == "chi2_per_dof")["value"]))
    assert sorted(prof) == sorted(names)
    for n, x in prof.items():
        assert x["end_lower"] == x["end_upper"] == "found", x
        for side, rise in (("lower", "chi2_rise_minus [-]"), ("upper", "chi2_rise_plus [-]")):
            assert abs(float(x["rise_" + side + " [-]"]) - 1) <= 0.05 + 5e-3, x
            t = float(x[side + "_over_se [-]"])
            assert t >= (1 - 0.03) / math.sqrt(float(scale[n][rise])), (n, side, t, scale[n])
        assert x["chi2_below_fit"] == "nan"
    line = next(l for l in r.stderr.splitlines() if "profile intervals:" in l)
    outside = sum(1 for x in prof.values() if any(not (2 ** -0.5 <= float(x[k]) <= 2 ** 0.5)
                                                  for k in ("lower_over_se [-]", "upper_over_se [-]")))
    assert line.split("of ")[1].startswith("3 coefficients, %d have an end beyond" % outside), line
    assert "no refit went below the fit's chi2" in line, line

    # parameters.csv carries the same ends (profile_lo68/hi68) on the profiled rows, nan on the others
    params = {x["parameter"]: x for x in rows(os.path.join(out, "parameters.csv"))}
    for n, x in params.items():
        want = (prof[n]["profile_lower"], prof[n]["profile_upper"]) if n in prof else ("nan", "nan")
        assert (x["profile_lo68"], x["profile_hi68"]) == want, (n, x)

    lower = float(prof["C0"]["profile_lower"])
    with open(os.path.join(out, "parameters.csv"), newline="") as fh:
        table = list(csv.reader(fh))
    for row in table:
        if row and row[0] == "C0":
            row[2] = repr(lower)
    held = str(tmp_path / "held.csv")
    with open(held, "w", newline="") as fh:
        csv.writer(fh).writerows(table)
    h = run(ENSEMBLE, "--start", held, "--hold-isotropic", "C0", "--out", str(tmp_path / "h"), "--no-jackknife",
            "--no-plots")
    assert h.returncode == 0, h.stderr
    assert "profile_lo68" not in open(os.path.join(str(tmp_path / "h"), "parameters.csv")).readline()   # not profiled
    final = [2 * float(x.split(",")[0]) for x in h.stderr.split("Final cost: ")[1:]]
    face = [float(l.split("held there to ")[1].split(" ")[0]) for l in h.stderr.splitlines() if "held there to" in l]
    chi2_held = min(final + face)
    rise = float(prof["C0"]["rise_lower [-]"])
    assert chi2_held >= chi2 + (rise - 0.01) * s - 0.05, (chi2_held, chi2, rise, s)

    bad = run(ENSEMBLE, "--out", str(tmp_path / "bad"), "--profile", "C0,bogus", "--no-jackknife", "--no-plots")
    assert bad.returncode == 2 and "'bogus' is not a coefficient" in bad.stderr and "give `all`" in bad.stderr, bad.stderr


def test_the_jackknife_over_two_sets_of_packings(tmp_path, result):
    """Fitted curves from two sets of packings (thirty-second round): D2 at nu = 0.671-0.720 reduced by `dem fit` from
    m000, m001 alone, at 0.750-0.819 from m002, m003 alone, in one ensemble folder. The jackknife leaves each packing
    out of its own set's means only (4 refits, set 0, 0, 1, 1), writes each packing's set beside its held-out score, and
    the 95 % intervals take Welch-Satterthwaite's t (between t_1 and t_2 with two packings per set), not t_3."""
    from scipy import stats
    nus = {0: ("0.671", "0.690", "0.720"), 1: ("0.750", "0.780", "0.819")}
    joint = tmp_path / "joint"
    (joint / "ensemble").mkdir(parents=True)
    for s, members in ((0, ("m000", "m001")), (1, ("m002", "m003"))):
        part = tmp_path / f"set{s}"
        for m in members:
            (part / "members" / m).mkdir(parents=True)
            for f in [f"D2_phi{nu}.csv" for nu in nus[s]] + ["cycle_unloading.csv"]:
                shutil.copy2(os.path.join(ENSEMBLE, "members", m, f), part / "members" / m / f)
        r = subprocess.run([DEM, "fit", str(part), "--no-plots"], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        for nu in nus[s]:
            shutil.copy2(part / "ensemble" / f"D2_phi{nu}.csv", joint / "ensemble")
        shutil.copytree(part / "members", joint / "members", dirs_exist_ok=True)
    out = str(tmp_path / "out")
    r = run(str(joint), "--out", out, "--no-plots", "--start", os.path.join(result[0], "parameters.csv"))
    assert r.returncode == 0, r.stderr
    table = rows(os.path.join(out, "jackknife.csv"))
    assert [(t["packing_left_out"], t["set"], t["usable"]) for t in table] == [
        ("m000", "0", "yes"), ("m001", "0", "yes"), ("m002", "1", "yes"), ("m003", "1", "yes")]
    held = rows(os.path.join(out, "heldout.csv"))
    assert [(h["packing"], h["set"]) for h in held] == [("m000", "0"), ("m001", "0"), ("m002", "1"), ("m003", "1")]
    assert all(math.isfinite(float(h["heldout_extended [-]"])) for h in held)
    params = {q["parameter"]: q for q in rows(os.path.join(out, "parameters.csv"))}
    quoted = [q for q in params.values() if q["se_method"] == "jackknife over packings" and
              math.isfinite(float(q["se"])) and float(q["se"]) > 0]
    assert len(quoted) >= 10
    lo, hi = stats.t.ppf(0.975, 2), stats.t.ppf(0.975, 1)
    for q in quoted:
        t = (float(q["hi95"]) - float(q["value"])) / float(q["se"])
        rounding = 1e-6 * abs(float(q["hi95"])) / float(q["se"])   # hi95 is printed to six digits
        assert lo * (1 - 1e-4) - rounding <= t <= hi * (1 + 1e-4) + rounding, (q["parameter"], t)
    assert any("only 2 packings in a set" in l for l in r.stderr.splitlines())
    # the errors again from the refits' own estimates (jackknife_estimates.csv), each set about its own mean
    est = rows(os.path.join(out, "jackknife_estimates.csv"))
    assert [(e["packing_left_out"], e["set"]) for e in est] == [(t["packing_left_out"], t["set"]) for t in table]
    for q in quoted:
        parts = 0.0
        for s in ("0", "1"):
            x = [float(e[q["parameter"]]) for e in est if e["set"] == s]
            m = sum(x) / len(x)
            parts += (len(x) - 1) / len(x) * sum((v - m) ** 2 for v in x)
        assert float(q["se_jackknife"]) == pytest.approx(math.sqrt(parts), rel=1e-5), q["parameter"]
        pooled = [float(e[q["parameter"]]) for e in est]
        m = sum(pooled) / 4
        one = math.sqrt(3 / 4 * sum((v - m) ** 2 for v in pooled))   # as if one set: not what is quoted
        assert one != pytest.approx(float(q["se_jackknife"]), rel=1e-3), q["parameter"]


def test_the_basin_check_restarts_a_refit_and_names_a_lower_start_for_the_fit(tmp_path):
    """The jackknife's basin check (thirty-fifth round) on the N = 9261 ensemble stopped after one iteration: each
    refit, beaten on its own data by another refit's optimum, is run again from it and ends lower (jackknife.csv's
    start and tries say so); the fit's own data score lower at a refit's optimum, so the run warns and writes it to
    basin_start/parameters.csv, at which a fit from there starts (Ceres' own initial cost) below the first fit's
    chi2; a rerun into the folder that finds no lower optimum leaves no basin_start/ behind (nor, without the
    jackknife, the former jackknife tables; a file of the user's stays); --no-basin-check keeps every refit where it
    ended."""
    import re
    out = tmp_path / "short"
    r = run(ENSEMBLE, "--out", str(out), "--no-plots", "--max-iterations", "1")
    assert r.returncode == 1, r.stderr   # not converged
    refits = rows(out / "jackknife.csv")
    assert len(refits) == 4
    for t in refits:
        was = re.search(r"basin check; from the full fit's optimum it ended at chi2/dof ([0-9.]+)\)", t["start"])
        assert t["start"].startswith("the refit without m00") and was, t["start"]
        assert t["tries"] == "2" and float(t["chi2_per_dof [-]"]) < float(was.group(1))
    chi2 = float(next(p for p in rows(out / "parameters.csv") if p["parameter"] == "chi2_per_dof")["value"])
    warned = [ln for ln in r.stderr.splitlines() if "the fit's own data score chi2/dof" in ln]
    assert len(warned) == 1 and "the fit had not converged" in warned[0] and "basin_start/parameters.csv" in warned[0]
    start = out / "basin_start" / "parameters.csv"
    basin = next(p for p in rows(start) if p["parameter"] == "chi2_per_dof")
    assert float(basin["value"]) < chi2
    again = run(ENSEMBLE, "--out", str(tmp_path / "again"), "--no-plots", "--no-jackknife", "--start", str(start),
                "--max-iterations", "1")
    initial = float(re.search(r"Initial cost: ([0-9.e+-]+)", again.stderr).group(1))
    dof = 2 * float(re.search(r"Final cost: ([0-9.e+-]+)", r.stderr).group(1)) / chi2   # the first fit's
    assert 2 * initial / dof == pytest.approx(float(basin["value"]), rel=2e-3)
    (out / "notes.txt").write_text("a file of the user's")
    r2 = run(ENSEMBLE, "--out", str(out), "--no-plots", "--force", "--no-jackknife")
    assert r2.returncode == 0, r2.stderr
    assert not (out / "basin_start").exists()
    # nor the former run's jackknife tables beside the new ones (clear_former_results); the user's file stays
    assert not any((out / f"{stem}.{ext}").exists() for stem in ("jackknife", "jackknife_estimates", "heldout")
                   for ext in ("csv", "md", "json", "tex"))
    assert (out / "notes.txt").read_text() == "a file of the user's" and (out / "parameters.csv").exists()
    off = tmp_path / "off"   # --no-basin-check: every refit where it ended, no warning
    r3 = run(ENSEMBLE, "--out", str(off), "--no-plots", "--max-iterations", "1", "--no-basin-check")
    assert r3.returncode == 1 and "basin check" not in r3.stderr and "own data score" not in r3.stderr, r3.stderr
    assert all(t["tries"] == "1" and t["start"] == "the full fit's optimum" for t in rows(off / "jackknife.csv"))
    assert not (off / "basin_start").exists()
