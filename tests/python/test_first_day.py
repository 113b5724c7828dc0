"""The traps of a first session: --help of the Python-backed commands, `dem mode`'s physics
without --scene, `dem info`'s wall-time estimate, the Slurm preflight of `dem ensemble`."""
import re
import shutil

import pytest

from conftest import run_dem

SCENE = """
[particles]
count = 200
seed = 5
[protocol]
target_phi = 0.64
compress_rate_tc = 1e-3
cycle_rate_tc = 5e-4
cycle_phi_max = 0.75
checkpoints_unloading = [0.72]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.01
[integration]
dt_over_tc = 0.1
[output]
vtk = false
"""


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("firstday")
    (d / "s.toml").write_text(SCENE)
    run_dem("run", d / "s.toml", "--out", d / "run", "--quiet", "--stages", "prep", check=True)
    return d


@pytest.mark.parametrize("command,options", [("compare", ["--plot", "--labels", "--tol-p", "--min-coverage"]),
                                              ("plot", ["--fits", "run_dir"])])
def test_python_backed_commands_have_a_real_help(command, options):
    for flag in ("--help", "-h"):
        p = run_dem(command, flag)
        assert p.returncode == 0, p.stderr
        for o in options:
            assert o in p.stdout, (command, o, p.stdout)


def physics_line(csv):
    return next(ln for ln in csv.read_text().splitlines() if ln.startswith("# physics:"))


def test_mode_without_scene_takes_the_physics_of_the_packings_run(run_folder, tmp_path):
    ckpt = run_folder / "run" / "checkpoints" / "unloading_phi0.720.ckpt"
    args = ("--mode", "D2", "--eps-max", 0.005, "--quiet", "--threads", 1)
    inferred = run_dem("mode", "--packing", ckpt, *args, "--out", tmp_path / "a.csv", check=True)
    assert f"physics from {run_folder / 'run' / 'scene.toml'}" in inferred.stderr, inferred.stderr
    explicit = run_dem("mode", "--scene", run_folder / "run" / "scene.toml", "--packing", ckpt, *args,
                       "--out", tmp_path / "b.csv", check=True)
    assert "physics from" not in explicit.stderr and "defaults" not in explicit.stderr
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert "dt_over_tc=0.1" in physics_line(tmp_path / "a.csv")
    # the same checkpoint outside its run folder: the built-in defaults, said on stderr
    shutil.copy(ckpt, tmp_path / "loose.ckpt")
    loose = run_dem("mode", "--packing", tmp_path / "loose.ckpt", *args, "--out", tmp_path / "c.csv", check=True)
    assert "built-in defaults" in loose.stderr and "--scene" in loose.stderr, loose.stderr
    m = re.search(r"dt = t_c/([0-9.]+)", loose.stderr)
    assert m and float(m.group(1)) != 10.0, loose.stderr       # the defaults' dt, not the run's t_c/10
    assert physics_line(tmp_path / "c.csv") != physics_line(tmp_path / "a.csv")


def test_info_estimates_the_wall_time_from_a_timed_probe(run_folder):
    p = run_dem("info", run_folder / "s.toml", check=True)
    m = re.search(r"wall time +about ([0-9.]+) (s|min|h) for ([0-9.e+]+) particle-steps.* at ([0-9.]+) M particle-steps/s",
                  p.stdout)
    assert m, p.stdout
    assert float(m.group(4)) > 0.05          # a measured speed, not a constant
    seconds = float(m.group(1)) * {"s": 1, "min": 60, "h": 3600}[m.group(2)]
    assert abs(seconds - float(m.group(3)) / (float(m.group(4)) * 1e6)) <= max(1.0, 0.1 * seconds)
    assert "wall time" not in run_dem("info", run_folder / "s.toml", "--no-probe", check=True).stdout


def test_slurm_profile_without_a_controller_is_refused_naming_slurm_conf(run_folder, tmp_path):
    if shutil.which("sbatch") is None:
        pytest.skip("slurm-wlm not installed")
    scene = tmp_path / "e.toml"
    scene.write_text(SCENE + "[ensemble]\npackings = 2\n")
    import os
    env = {**os.environ, "SLURM_CONF": str(tmp_path / "missing" / "slurm.conf")}
    p = run_dem("ensemble", scene, "--out", tmp_path / "ens", "--profile", "slurm", env=env, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "SLURM_CONF=" + str(tmp_path / "missing" / "slurm.conf") in p.stderr
    assert 'eval "$(bash scripts/slurm-local.sh start' in p.stderr
    assert not (tmp_path / "ens").exists()       # nothing written: no scene.toml, no lock, so a later run may use it


def test_compare_json_is_valid_for_non_finite_values():
    import json
    import numpy as np
    from demkit.compare import finite_or_null
    obj = {"a": float("nan"), "b": np.float64(1.5), "c": [np.inf, -np.inf, 2], "d": np.array([np.nan, 3.0]),
           "e": np.bool_(True), "f": {"g": np.int64(7)}}
    text = json.dumps(finite_or_null(obj), allow_nan=False)      # raises on a bare NaN
    assert json.loads(text) == {"a": None, "b": 1.5, "c": [None, None, 2], "d": [None, 3.0], "e": True, "f": {"g": 7}}


def test_help_shows_defaults_and_flags_as_typed():
    bench = run_dem("bench", "--help")
    assert bench.returncode == 0
    assert re.search(r"--steps\s+INT[^\n]*20000", bench.stdout), bench.stdout   # the default beside the option
    model = run_dem("model", "--help")
    assert "--no-jackknife" in model.stdout and "{false}" not in model.stdout, model.stdout


def test_set_before_the_scene_leaves_the_scene_to_the_positional(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    p = run_dem("info", "--set", "protocol.eps_d_max=0.02", "--set", "particles.seed=6", scene, "--no-probe")
    assert p.returncode == 0, p.stderr
    assert "scene is required" not in p.stderr
