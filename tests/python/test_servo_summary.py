"""The servo's hold on its targets (issue 32, "Also"; issue 31's low-pressure lag) and the per-component
summary written after a path curve's rows (docs/control.md, "The servo's summary"): the side stress of
a constant-side-stress test on the 400-sphere packings is held tightly after the start-up (today's
main: rows up to 1.5-3 %), and the summary's numbers equal a recomputation from the curve's columns."""
import json

import numpy as np
import pytest

from conftest import SMALL_SCENE, run_dem
from demkit.curves import read_curve

PATHS = """
[paths]
triaxial = [ { name = "compress", rate = [0, 0, -1], sigma_p0 = { x = 1.0, y = 1.0 }, until = { eps_zz = -0.08 } } ]
tt_b05 = [ { rate = [0, 0, -1], pressure_p0 = 1.0, lode_b = 0.5, until = { eps_zz = -0.05 } } ]
D2_plain = [ { rate = "D2", until = { eps_d = 0.03 } } ]
"""
STARTUP = 0.02   # the summary's start-up window in eps_d_accumulated past the stage start


@pytest.fixture(scope="module")
def scene(small_run, tmp_path_factory):
    f = tmp_path_factory.mktemp("servo") / "servo.toml"
    f.write_text(SMALL_SCENE + PATHS)
    return f


def run_path(scene, small_run, tmp_path, mode, phi):
    out = tmp_path / f"{mode}_{phi}.csv"
    r = run_dem("mode", "--scene", scene, "--packing", small_run["dir"] / "checkpoints" / f"unloading_phi{phi}.ckpt",
                "--mode", mode, "--out", out, "--threads", "1", "--quiet")
    assert r.returncode == 0, r.stderr
    return out


def summary(path):
    lines = [ln for ln in path.read_text().splitlines() if ln.startswith("# servo_summary: ")]
    assert len(lines) == 1, "one summary line after the rows"
    return json.loads(lines[0][len("# servo_summary: "):])


def recomputed(c):
    """Per-component errors from the columns alone: sigma_ii and p relative to their targets, the
    lode_b row sigma_2 - sigma_3 - b (sigma_1 - sigma_3) relative to the p target."""
    e = {}
    for a in "xx", "yy", "zz":
        t = c[f"target_{a}_Pa"]
        if np.isfinite(t).any():
            e[f"sigma_{a}"] = np.abs(c[f"sigma_{a}_Pa"] / t - 1)
    tp = c["target_p_Pa"]
    if np.isfinite(tp).any():
        e["p"] = np.abs(c["p_Pa"] / tp - 1)
    return e


def windows(c):
    # each row's eps_d_accumulated past its stage's start (the last row of the previous stage, 0 at first)
    acc, stage = c["eps_d_accumulated"], c["stage"]
    start = np.zeros_like(acc)
    for k in range(1, len(acc)):
        start[k] = start[k - 1] if stage[k] == stage[k - 1] else acc[k - 1]
    return acc - start >= STARTUP


@pytest.mark.parametrize("phi", ["0.690", "0.780"])
def test_the_servo_holds_the_side_stress_after_the_start_up(scene, small_run, tmp_path, phi):
    path = run_path(scene, small_run, tmp_path, "triaxial", phi)
    c = read_curve(path)
    after = windows(c)
    assert after.sum() > 15
    p0 = c["p_Pa"][0]
    err = np.maximum(np.abs(c["sigma_xx_Pa"] / p0 - 1), np.abs(c["sigma_yy_Pa"] / p0 - 1))[after]
    # dead-beat servo, rate limit 4x: one row of 1.5 % seen at N = 400, nu = 0.78 (a plastic event);
    # main's PI: rows up to 3 % (docs/control.md). The RMS is the sharper witness.
    assert err.max() < 0.025, err
    assert np.sqrt(np.mean(err ** 2)) < 0.005, err
    assert c["eps_xx"][-1] > 0.01 and c["eps_yy"][-1] > 0.01   # the side axes gave way


def test_the_summary_equals_a_recomputation_from_the_columns(scene, small_run, tmp_path):
    path = run_path(scene, small_run, tmp_path, "triaxial", "0.690")
    c, s = read_curve(path), summary(path)
    assert s["startup_eps_d"] == STARTUP
    e, after = recomputed(c), windows(c)
    assert set(s["components"]) == {"sigma_xx", "sigma_yy"} == set(e)
    for name, v in e.items():
        got = s["components"][name]
        assert got["rows"] == after.sum() and got["startup_rows"] == (~after).sum()
        assert got["max_rel"] == pytest.approx(v[after].max(), rel=1e-4, abs=1e-8)
        assert got["rms_rel"] == pytest.approx(np.sqrt(np.mean(v[after] ** 2)), rel=1e-4, abs=1e-8)
        assert got["startup_max_rel"] == pytest.approx(v[~after].max(), rel=1e-4, abs=1e-8)
        # control_error_rel is the largest component, row by row
    worst = np.maximum(e["sigma_xx"], e["sigma_yy"])
    assert np.allclose(worst, c["control_error_rel"], atol=1e-7)


def test_a_true_triaxial_summary_has_p_and_b(scene, small_run, tmp_path):
    path = run_path(scene, small_run, tmp_path, "tt_b05", "0.780")
    c, s = read_curve(path), summary(path)
    after = windows(c)
    p_err = np.abs(c["p_Pa"] / c["target_p_Pa"] - 1)
    s1, s2, s3 = c["sigma_zz_Pa"], c["sigma_yy_Pa"], c["sigma_xx_Pa"]   # sigma_1 on z, sigma_3 on x
    b_err = np.abs(s2 - s3 - 0.5 * (s1 - s3)) / c["target_p_Pa"]
    assert list(s["components"]) == ["p", "b"]
    for name, v in (("p", p_err), ("b", b_err)):
        assert s["components"][name]["max_rel"] == pytest.approx(v[after].max(), rel=1e-4, abs=1e-8)
        assert s["components"][name]["rms_rel"] == pytest.approx(np.sqrt(np.mean(v[after] ** 2)), rel=1e-4, abs=1e-8)


def test_a_strain_controlled_path_writes_no_summary(scene, small_run, tmp_path):
    path = run_path(scene, small_run, tmp_path, "D2_plain", "0.690")
    assert "servo_summary" not in path.read_text()
