"""`dem model` end to end on the committed N = 9261 ensemble (data/figure3_n9261: 4 packings,
6 volume fractions, D2 and D3): calibrate on D2 + the isotropic branch, predict D3, tables,
curves and plots; and the refusals of bad input (exit 2, naming the problem and the fix)."""
import csv
import math
import os
import shutil
import subprocess

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
