"""Issue 22: nothing lost, nothing silently wrong, part two. One test (or a few) per numbered
case of the issue; each failed on main before the fix. Small scenes (N = 200), few steps."""
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import time

import pytest

from conftest import DEM, ROOT, run_dem

TINY = """
[particles]
count = 200
seed = 5
[integration]
threads = 1
[protocol]
target_phi = 0.64
compress_rate_tc = 1e-3
cycle_rate_tc = 2e-5
cycle_phi_max = 0.74
checkpoints_unloading = [0.72, 0.69]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.02
relax_max_time_tc = 2e3
[output]
sample_strain = 0.002
vtk = false
"""


def scene(tmp_path, extra="", name="s.toml"):
    f = tmp_path / name
    f.write_text(TINY + extra)
    return f


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """A prepared tiny run (checkpoints only): a packing for `dem mode`."""
    d = tmp_path_factory.mktemp("i22prep")
    s = d / "tiny.toml"
    s.write_text(TINY)
    run_dem("run", s, "--out", d / "run", "--stages", "prep", "--quiet", check=True)
    return d


# ---- 3: NaN and overflowing stress targets never switch the servo off -----------------------

@pytest.mark.parametrize("stage", [
    '{ rate = [0, 0, -1], sigma_p0 = { x = nan, y = 1 }, until = { eps_zz = -0.01 } }',
    '{ rate = [0, 0, -1], sigma_p0 = { x = 1e300, y = 1 }, until = { eps_zz = -0.01 } }',
    '{ rate = [0, 0, -1], sigma_p0 = { x = inf, y = 1 }, until = { eps_zz = -0.01 } }',
    '{ rate = [0, 0, -1], sigma_Pa = { x = -inf, y = 1e5 }, until = { eps_zz = -0.01 } }',
    '{ rate = [1, 0, -1], pressure_p0 = nan, until = { eps_d = 0.01 } }',
    '{ rate = [1, 0, -1], pressure_p0 = 1e300, until = { eps_d = 0.01 } }',
    '{ rate = [1, 0, -1], pressure_Pa = nan, until = { eps_d = 0.01 } }',
    '{ rate = [nan, 0, 0], until = { eps_xx = 0.01 } }',
    '{ rate = [1e300, 0, -1e300], until = { eps_d = 0.01 } }',
    '{ rate = [1, 0, -1], until = { p_p0 = 1e300 } }',
])
def test_non_finite_or_overflowing_targets_and_rates_are_refused(tmp_path, stage):
    s = scene(tmp_path, f'[paths]\nP = [ {stage} ]\n').read_text().replace('modes = ["D2"]', 'modes = ["P"]')
    (tmp_path / "s.toml").write_text(s)
    p = run_dem("info", tmp_path / "s.toml")
    assert p.returncode == 2, (stage, p.stdout, p.stderr)
    assert "paths.P" in p.stderr or "P" in p.stderr, p.stderr


def test_non_finite_mode_rates_are_refused(tmp_path):
    for spelling in ("[nan, 0, 0]", "[[0, nan, 0], [0, 0, 0], [0, 0, 0]]", "[1e300, 0, -1e300]"):
        s = scene(tmp_path, f'[modes]\nM = {spelling}\n').read_text().replace('modes = ["D2"]', 'modes = ["M"]')
        (tmp_path / "s.toml").write_text(s)
        p = run_dem("info", tmp_path / "s.toml")
        assert p.returncode == 2, (spelling, p.stdout, p.stderr)


# ---- 6: names never escape the run folder ---------------------------------------------------

@pytest.mark.parametrize("section,name", [
    ("paths", '"../../../X"'), ("modes", '"../../../X"'), ("paths", '"a;b"'), ("modes", '"a b"'),
    ("paths", '""'), ("modes", '""'), ("paths", '"D2"'), ("paths", '"SS_xz"'), ("paths", '"x/y"'),
])
def test_names_that_become_file_names_are_checked(tmp_path, section, name):
    entry = '[ { rate = "D2", until = { eps_d = 0.01 } } ]' if section == "paths" else "[1, 0, -1]"
    s = scene(tmp_path, f"[{section}]\n{name} = {entry}\n").read_text().replace(
        'modes = ["D2"]', f'modes = [{name}]')
    (tmp_path / "s.toml").write_text(s)
    p = run_dem("info", tmp_path / "s.toml")
    assert p.returncode == 2, (name, p.stdout, p.stderr)
    assert "letters, digits" in p.stderr or "built-in mode" in p.stderr, p.stderr


def test_path_stage_names_with_csv_breaking_characters_are_refused(tmp_path):
    s = scene(tmp_path, '[paths]\nP = [ { name = "a,b", rate = "D2", until = { eps_d = 0.01 } } ]\n').read_text()
    (tmp_path / "s.toml").write_text(s.replace('modes = ["D2"]', 'modes = ["P"]'))
    p = run_dem("info", tmp_path / "s.toml")
    assert p.returncode == 2 and "letters, digits" in p.stderr, p.stderr


def test_dem_mode_refuses_an_escaping_name(prepared, tmp_path):
    ck = prepared / "run" / "checkpoints" / "unloading_phi0.690.ckpt"
    p = run_dem("mode", "--scene", prepared / "tiny.toml", "--packing", ck, "--mode", "D2", "--name", "a,b\nc",
                "--out", tmp_path / "o.csv", "--quiet")
    assert p.returncode == 2 and "--name" in p.stderr, p.stderr
    assert not (tmp_path / "o.csv").exists()


# ---- 7: no write follows a planted symlink --------------------------------------------------

def test_curve_writer_does_not_follow_a_planted_part_link(prepared, tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "o.csv"
    os.symlink(victim, str(out) + ".part")
    ck = prepared / "run" / "checkpoints" / "unloading_phi0.690.ckpt"
    run_dem("mode", "--scene", prepared / "tiny.toml", "--packing", ck, "--mode", "D2", "--eps-max", "0.002",
            "--out", out, "--quiet", check=True)
    assert victim.read_text() == "precious\n"
    assert not os.path.islink(out) and out.read_text().startswith("#")


def test_atomic_writers_do_not_follow_planted_links(prepared, tmp_path):
    """write_file_atomic (scene.toml, checkpoints), the fit tables and the task status JSON."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "run"
    out.mkdir()
    os.symlink(victim, out / "scene.toml.part")
    s = prepared / "tiny.toml"
    run_dem("run", s, "--out", out, "--quiet", "--set", "protocol.checkpoints_unloading=[0.69]", check=True)
    assert victim.read_text() == "precious\n" and not os.path.islink(out / "scene.toml")
    os.symlink(victim, out / "fit" / "parameters.csv.part") if (out / "fit").is_dir() else None
    (out / "fit").mkdir(exist_ok=True)
    if not os.path.lexists(out / "fit" / "parameters.csv.part"):
        os.symlink(victim, out / "fit" / "parameters.csv.part")
    run_dem("fit", out, "--force", "--no-plots")
    assert victim.read_text() == "precious\n"
    assert not os.path.islink(out / "fit" / "parameters.csv")
    # the Python status writer of the workflow tasks
    st = tmp_path / "st.json"
    os.symlink(victim, str(st) + ".part")
    r = subprocess.run([sys.executable, "-m", "demkit.task", "--status", st, "--log", tmp_path / "l.log", "--",
                        "true"], cwd=ROOT, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=ROOT))
    assert r.returncode == 0, r.stderr
    assert victim.read_text() == "precious\n" and json.loads(st.read_text())["status"] == "complete"


# ---- 8: non-regular input files are refused at once ------------------------------------------

def test_device_and_fifo_inputs_are_refused(prepared, tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for f in ("/dev/zero", str(fifo)):
        p = run_dem("run", scene(tmp_path), "--out", tmp_path / "r", "--quiet", "--set",
                    f'particles.packing_file="{f}"', timeout=30)
        assert p.returncode == 1 and "not a regular file" in p.stderr, p.stderr
        p = run_dem("mode", "--packing", f, "--mode", "D2", "--out", tmp_path / "m.csv", timeout=30)
        assert p.returncode in (1, 2) and "regular file" in p.stderr, p.stderr
        p = run_dem("info", f, timeout=30)
        assert p.returncode == 2 and "not a regular file" in p.stderr, p.stderr
        p = run_dem("mode", "--packing", f + ".ckpt" if False else f, "--mode", "D2", "--out", tmp_path / "m.csv",
                    timeout=30)
        assert p.returncode != 0
    # a checkpoint path that is a FIFO
    fifo2 = tmp_path / "x.ckpt"
    os.mkfifo(fifo2)
    p = run_dem("mode", "--packing", fifo2, "--mode", "D2", "--out", tmp_path / "m.csv", timeout=30)
    assert p.returncode in (1, 2) and "regular file" in p.stderr, p.stderr


def test_absurd_packing_line_is_refused(tmp_path):
    f = tmp_path / "p.txt"
    f.write_text("##PERIODIC:: 1 1 1\n" + "0" * 100000 + "\n")
    p = run_dem("run", scene(tmp_path), "--out", tmp_path / "r", "--quiet", "--set", f'particles.packing_file="{f}"',
                timeout=30)
    assert p.returncode == 1 and "bytes" in p.stderr, p.stderr
