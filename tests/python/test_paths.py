"""Loading paths and stress control ([paths], issue 11) on the 400-sphere packings of small_run:
a path that spells out a mode gives its curve bit for bit, the servo holds its targets, a
reversal behaves as it must, bad control input is refused before anything runs, and `dem run`
+ `dem fit` + `dem plot` handle paths beside the plain modes."""
import shutil

import numpy as np
import pytest

from conftest import SMALL_SCENE, run_dem
from demkit.curves import read_curve

PATHS = """
[paths]
D2_as_path = [ { rate = "D2", until = { eps_d = 0.1 } } ]
triaxial = [ { name = "compress", rate = [0, 0, -1], sigma_p0 = { x = 1.0, y = 1.0 }, until = { eps_zz = -0.1 } } ]
isobaric_D2 = [ { rate = "D2", pressure_p0 = 1.0, until = { eps_d = 0.15 } } ]
reversal = [ { name = "load", rate = "D2", until = { eps_d = 0.12 } },
             { name = "reverse", rate = "-D2", until = { eps_d = 0.24 } } ]
"""
# Rows before this eps_d are the servo's transient (the targets are p0 while the prescribed axis
# starts loading); after it the error is judged.
TRANSIENT_EPS_D = 0.03


@pytest.fixture(scope="module")
def scene(small_run, tmp_path_factory):
    f = tmp_path_factory.mktemp("paths") / "paths.toml"
    f.write_text(SMALL_SCENE + PATHS)
    return f


def run_path(scene, small_run, tmp_path, mode, phi, *extra):
    out = tmp_path / f"{mode}_{phi}.csv"
    r = run_dem("mode", "--scene", scene, "--packing", small_run["dir"] / "checkpoints" / f"unloading_phi{phi}.ckpt",
                "--mode", mode, "--out", out, "--threads", "1", "--quiet", *extra)
    assert r.returncode == 0, r.stderr
    return out


def data_rows(path):
    return [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]


def test_a_path_spelling_out_a_mode_gives_its_curve_bit_for_bit(scene, small_run, tmp_path):
    path = run_path(scene, small_run, tmp_path, "D2_as_path", "0.720")
    mode = run_path(scene, small_run, tmp_path, "D2", "0.720", "--eps-max", "0.1")
    a, b = data_rows(path), data_rows(mode)
    assert len(a) == len(b) > 30
    n = len(b[0].split(",")) - 1   # the mode's columns without its stage name
    for ra, rb in zip(a, b):
        assert ra.split(",")[:n] == rb.split(",")[:n]


@pytest.mark.parametrize("phi", ["0.690", "0.780"])
def test_constant_side_stress_compression_holds_the_side_stress(scene, small_run, tmp_path, phi):
    c = read_curve(run_path(scene, small_run, tmp_path, "triaxial", phi))
    p0 = c["p_Pa"][0]
    assert np.allclose(c["target_xx_Pa"], p0, rtol=1e-8) and np.allclose(c["target_yy_Pa"], p0, rtol=1e-8)
    assert np.all(np.isnan(c["target_zz_Pa"]))
    after = c["eps_d"] >= TRANSIENT_EPS_D
    err = np.maximum(np.abs(c["sigma_xx_Pa"][after] / p0 - 1), np.abs(c["sigma_yy_Pa"][after] / p0 - 1))
    # Measured at N = 400: mean 0.4-1.0 % (no bias: the signed mean is 0.1 %; the rest is the
    # packing's own stress noise, ~1/sqrt(N)), single rows after a plastic event up to 3 %.
    assert err.mean() < 0.015, err
    assert err.max() < 0.05, err
    assert np.allclose(err, np.maximum(c["control_error_rel"][after], 0), atol=1e-6)
    # The axial stress rises (the test loads), the side axes expand (the servo gives way).
    assert c["sigma_zz_Pa"][after].mean() > 1.05 * p0
    assert c["eps_xx"][-1] > 0.02 and c["eps_yy"][-1] > 0.02
    assert c["eps_zz"][-1] == pytest.approx(-0.1, abs=1e-4)


def test_isobaric_D2_holds_the_pressure_and_lets_the_volume_change(scene, small_run, tmp_path):
    c = read_curve(run_path(scene, small_run, tmp_path, "isobaric_D2", "0.690"))
    p0 = c["p_Pa"][0]
    after = c["eps_d"] >= TRANSIENT_EPS_D
    err = np.abs(c["p_Pa"][after] / p0 - 1)
    assert err.mean() < 0.01 and err.max() < 0.05, err   # measured: mean 0.25 %, max 1.1 %
    # The deviatoric direction is the prescribed one: eps_yy = eps_v (only the servo moves it), and
    # the volume is free: it changes by more than rounding.
    assert np.allclose(c["eps_yy"], c["eps_v"], atol=1e-9)
    assert np.abs(c["eps_v"]).max() > 1e-4
    assert c["s_dev"][-10:].mean() > 0.1   # sheared to the critical state


def test_strain_reversal_crosses_zero_and_reaches_the_opposite_asymptote(scene, small_run, tmp_path):
    c = read_curve(run_path(scene, small_run, tmp_path, "reversal", "0.720"))
    ratio = (c["sigma_xx_Pa"] - c["sigma_zz_Pa"]) / c["p_Pa"]
    load, rev = c["stage"] == "load", c["stage"] == "reverse"
    acc = c["eps_d_accumulated"]
    plateau = ratio[load & (acc > 0.08)].mean()
    assert plateau < -0.08   # D2 extends x, compresses z: sigma_zz > sigma_xx
    end = ratio[rev & (acc > 0.32)].mean()
    assert end > 0.08 and abs(end + plateau) < 0.5 * abs(plateau)   # the opposite asymptote
    assert np.any(np.diff(np.sign(ratio[rev])) != 0)                 # passes through zero
    s_load = c["s_dev"][load & (acc > 0.08)].mean()
    assert c["s_dev"][rev].min() < 0.35 * s_load                      # s_dev dips ...
    assert c["s_dev"][rev & (acc > 0.32)].mean() > 0.6 * s_load      # ... and recovers
    # Strains count from the path start: eps_d returns to ~0 half-way through the reversal.
    assert c["eps_d"][rev].min() < 0.005 and acc[-1] == pytest.approx(0.36, abs=2e-3)


def run_bad_path(small_run, tmp_path, path):
    """`dem mode` on a scene whose [paths] entry `bad` is `path`: (CompletedProcess, output CSV)."""
    f = tmp_path / "bad.toml"
    f.write_text(SMALL_SCENE + f"\n[paths]\nbad = {path}\n")
    out = tmp_path / "bad.csv"
    r = run_dem("mode", "--scene", f, "--packing", small_run["dir"] / "checkpoints" / "unloading_phi0.720.ckpt",
                "--mode", "bad", "--out", out, "--quiet")
    return r, out


@pytest.mark.parametrize("path,needle", [
    ('[{ rate = [0, 0, 0], constant_volume = true, sigma_p0 = { x = 1, y = 1, z = 1 }, until = { time_tc = 100 } }]',
     "over-constrained"),
    ('[{ rate = "D2", pressure_Pa = -1e5, until = { eps_d = 0.1 } }]', "positive"),
    ('[{ rate = [0, 0, -1], until = { eps_zz = 0.1 } }]', "behind"),
    ('[{ rate = [1, 1, 1], until = { eps_d = 0.1 } }]', "never grows"),
])
def test_bad_control_input_is_refused_before_anything_runs(small_run, tmp_path, path, needle):
    r, out = run_bad_path(small_run, tmp_path, path)
    assert r.returncode == 2 and needle in r.stderr, r.stderr
    assert not out.exists() and not (tmp_path / "bad.csv.part").exists()


def test_run_fit_and_plot_handle_paths_beside_modes(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run["dir"], run)
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL_SCENE.replace('modes = ["D2", "D3"]', 'modes = ["D2", "D3", "short_reversal"]') + """
[paths]
short_reversal = [ { rate = "D2", until = { eps_d = 0.03 } }, { rate = "-D2", until = { eps_d = 0.06 } } ]
""")
    r = run_dem("run", scene, "--out", run, "--stages", "deviatoric", "--quiet")
    assert r.returncode == 0, r.stderr
    for phi in ("0.690", "0.720", "0.780"):
        c = read_curve(run / "deviatoric" / f"short_reversal_phi{phi}.csv")
        assert list(dict.fromkeys(c["stage"])) == ["D2", "-D2"]
    assert "short_reversal_phi0.720.csv" in (run / "manifest.json").read_text()
    fit = run_dem("fit", run, "--force")
    assert fit.returncode == 0, fit.stderr
    assert "is a loading path" in fit.stderr
    assert "short_reversal" not in (run / "fit" / "parameters.csv").read_text()
    assert (run / "plots" / "path_short_reversal_phi0.720.png").stat().st_size > 1000
