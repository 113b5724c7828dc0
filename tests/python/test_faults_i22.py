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
    # the curve readers: the fitter's and Python's (dem compare, dem plot)
    p = run_dem("compare", fifo, "/dev/zero", timeout=30)
    assert p.returncode == 1 and "not a regular file" in p.stderr, p.stderr
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


# ---- ensembles: 1, 2, 5, 9, 10 --------------------------------------------------------------

ENS = TINY.replace("deviatoric_rate_tc = 2e-4", "deviatoric_rate_tc = 2e-3").replace(
    "checkpoints_unloading = [0.72, 0.69]", "checkpoints_unloading = [0.69]") + "[ensemble]\npackings = 2\n"


def ensemble(scene_file, out, *extra, check=False, env=None):
    return run_dem("ensemble", scene_file, "--out", out, "--cores", "2", *extra, check=check, timeout=600, env=env)


@pytest.fixture(scope="module")
def ens(tmp_path_factory):
    """A finished 2-packing ensemble, D2 from one checkpoint at a rate far from quasi-static."""
    d = tmp_path_factory.mktemp("i22ens")
    s = d / "ens.toml"
    s.write_text(ENS)
    p = ensemble(s, d / "run", check=True)
    return {"dir": d / "run", "scene": s, "stderr": p.stderr}


def copy_ens(ens, dst):
    shutil.copytree(ens["dir"], dst, ignore=shutil.ignore_patterns(".dem-ensemble.lock"))
    return dst


def fit_rows(run):
    import csv
    with open(run / "fit" / "parameters.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_resumed_ensemble_never_reports_partial_results_as_done(ens, tmp_path):
    run = copy_ens(ens, tmp_path / "run")
    for f in ("D2_phi0.690.json", "D2_phi0.690.csv"):
        (run / "members" / "m001" / "deviatoric" / f).unlink()
    # something else wrote fit tables into the partial folder (a `dem fit --partial`, a copy): newest of all
    (run / "fit" / "parameters.csv").write_text((ens["dir"] / "fit" / "parameters.csv").read_text())
    p = ensemble(ens["scene"], run)
    assert p.returncode == 0, p.stderr
    assert (run / "members" / "m001" / "deviatoric" / "D2_phi0.690.json").exists(), p.stderr
    assert all(r["packings"] == "2" for r in fit_rows(run))
    assert (run / "ensemble" / "D2_phi0.690.csv").read_bytes() == (ens["dir"] / "ensemble" / "D2_phi0.690.csv").read_bytes()
    # a member whose preparation is gone entirely
    shutil.rmtree(run / "members" / "m000")
    p = ensemble(ens["scene"], run)
    assert p.returncode == 0 and "done in" in p.stderr, p.stderr
    assert (run / "members" / "m000" / "prep.json").exists() and all(r["packings"] == "2" for r in fit_rows(run))


def test_fit_of_a_half_finished_ensemble_is_refused_or_marked(ens, tmp_path):
    run = copy_ens(ens, tmp_path / "run")
    before = (run / "fit" / "parameters.csv").read_bytes()
    (run / "members" / "m001" / "deviatoric" / "D2_phi0.690.json").unlink()
    p = run_dem("fit", run, "--force", "--no-plots")
    assert p.returncode == 1 and "incomplete" in p.stderr and "dem ensemble" in p.stderr, p.stderr
    assert (run / "fit" / "parameters.csv").read_bytes() == before   # nothing lost
    p = run_dem("fit", run, "--force", "--no-plots", "--partial")
    assert p.returncode == 0 and "incomplete" in p.stderr, p.stderr
    assert all("ensemble incomplete" in r["warnings"] for r in fit_rows(run))
    # a whole member missing (never prepared)
    shutil.rmtree(run / "members" / "m001")
    p = run_dem("fit", run, "--force", "--no-plots")
    assert p.returncode == 1 and "incomplete" in p.stderr, p.stderr


def test_far_from_quasi_static_is_said_where_it_is_read(ens):
    assert "inertial number" in ens["stderr"], ens["stderr"]
    assert all("inertial number" in r["warnings"] for r in fit_rows(ens["dir"]))


def test_force_does_not_break_a_running_ensemble(ens, tmp_path):
    out = tmp_path / "run"
    first = subprocess.Popen([DEM, "ensemble", str(ens["scene"]), "--out", str(out), "--cores", "1"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline and not (out / "logs").is_dir():
        time.sleep(0.1)
    p = ensemble(ens["scene"], out, "--force")
    assert p.returncode == 1 and "another `dem ensemble` is running" in p.stderr, p.stderr
    _, err = first.communicate(timeout=600)
    assert first.returncode == 0, err
    assert all(r["packings"] == "2" for r in fit_rows(out))


def test_all_preparations_blowing_up_is_named_with_exit_3(tmp_path):
    s = tmp_path / "bad.toml"
    s.write_text(ENS.replace("threads = 1", "threads = 1\nmax_overlap_fraction = 1e-3"))
    p = ensemble(s, tmp_path / "run")
    assert p.returncode == 3, p.stderr
    assert "every preparation blew up" in p.stderr and "--force" in p.stderr, p.stderr
    assert "run the same command again to continue" not in p.stderr


def test_slurm_without_a_controller_is_named(ens, tmp_path):
    env = dict(os.environ, SLURM_CONF=str(tmp_path / "no-such-slurm.conf"))
    p = ensemble(ens["scene"], tmp_path / "run", "--profile", "slurm", env=env)
    # The preflight (before any task): exit 2 naming SLURM_CONF and how to get a controller.
    assert p.returncode == 2 and "SLURM_CONF" in p.stderr and "slurm-local.sh" in p.stderr, p.stderr
    assert "run the same command again" not in p.stderr
    assert not (tmp_path / "run" / "members").exists()


def test_full_disk_during_the_preparations_is_named(ens, tmp_path):
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root: the full-disk tests run as root in CI")
    d = tmp_path / "disk"
    d.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(d)]).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        p = ensemble(ens["scene"], d / "run")
        assert p.returncode == 1, p.stderr
        assert "is full" in p.stderr and "Free space" in p.stderr, p.stderr
    finally:
        subprocess.run(["umount", "-l", str(d)])


# ---- 4: dem model never invents nu-slopes, warns at small K, refuses NaN rows -----------------

def test_model_on_one_volume_fraction_and_two_packings_says_so(ens, tmp_path):
    run = copy_ens(ens, tmp_path / "run")
    p = subprocess.run([DEM, "model", run, "--no-plots", "--out", tmp_path / "model"], capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    assert "one start volume fraction" in p.stderr and "only 2 packings" in p.stderr, p.stderr
    import csv
    with open(tmp_path / "model" / "parameters.csv", newline="") as fh:
        params = {r["parameter"]: r for r in csv.DictReader(fh)}
    for name, r in params.items():
        if name.endswith("_b"):
            assert r["se"] == "nan" and r["lo95"] == "nan", (name, r)


def test_model_refuses_nan_rows_by_name(ens, tmp_path):
    run = copy_ens(ens, tmp_path / "run")
    f = run / "ensemble" / "D2_phi0.690.csv"
    lines = f.read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln.startswith("eps_d,")][0]
    cols = lines[head].split(",")
    row = lines[head + 3].split(",")
    row[cols.index("s_dev_mean")] = "nan"
    lines[head + 3] = ",".join(row)
    f.write_text("\n".join(lines) + "\n")
    p = subprocess.run([DEM, "model", run, "--no-plots", "--out", tmp_path / "model"], capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 2 and "s_dev_mean is not a finite number" in p.stderr, (p.returncode, p.stderr)


# ---- 11: a stop that never comes ends in the stop error ---------------------------------------

def test_stop_that_never_comes_gives_the_stop_error(prepared, tmp_path):
    s = prepared / "tiny.toml"
    txt = s.read_text().replace('modes = ["D2"]', 'modes = ["P"]') + \
        '[paths]\nP = [ { rate = "D2", until = { s_dev = 5 } } ]\n'
    (tmp_path / "p.toml").write_text(txt)
    ck = prepared / "run" / "checkpoints" / "unloading_phi0.690.ckpt"
    p = run_dem("mode", "--scene", tmp_path / "p.toml", "--packing", ck, "--mode", "P", "--out", tmp_path / "p.csv",
                "--quiet", timeout=300)
    assert p.returncode == 1 and "stop condition was not met" in p.stderr, p.stderr
    assert not (tmp_path / "p.csv").exists()


# ---- 12: absurd rates are bounded before running, and dem info gives the steps --------------

@pytest.mark.parametrize("override", [
    'protocol.preparation=[{ name = "c", kind = "compress", rate_tc = 1e-300, until = { phi = 0.72 }, checkpoints = [0.70], checkpoint_name = "loading" }]',
    'protocol.preparation=[{ name = "c", kind = "compress", rate_tc = 1e-320, until = { phi = 0.72 }, checkpoints = [0.70], checkpoint_name = "loading" }]',
    "protocol.compress_rate_tc=1e-300",
    "protocol.deviatoric_rate_tc=1e-300",
    "protocol.relax_max_time_tc=1e300",
])
def test_absurd_work_is_refused_with_a_step_estimate(tmp_path, override):
    s = scene(tmp_path)
    if override.startswith("protocol.preparation"):
        txt = s.read_text()
        for k in ("target_phi", "compress_rate_tc", "cycle_rate_tc", "cycle_phi_max", "checkpoints_unloading",
                  "relax_max_time_tc"):
            txt = "\n".join(ln for ln in txt.splitlines() if not ln.startswith(k)) + "\n"
        s.write_text(txt.replace("[protocol]", "[protocol]\nmodes_from = \"loading\"", 1))
    p = run_dem("info", s, "--set", override, timeout=30)
    assert p.returncode == 2 and "steps" in p.stderr, (override, p.stderr)
    p = run_dem("run", s, "--out", tmp_path / "r", "--set", override, timeout=30)
    assert p.returncode == 2 and not (tmp_path / "r").exists(), p.stderr


def test_info_gives_the_steps_of_every_preparation_stage(tmp_path):
    p = run_dem("info", scene(tmp_path), check=True)
    prep = [ln for ln in p.stdout.splitlines() if ln.startswith("prep ")]
    assert prep and all("steps" in ln for ln in prep), p.stdout


# ---- 13: a sheared (version-4) packing_file runs, without the .txt export, saying so --------

def test_sheared_packing_file_runs_without_txt_checkpoints(prepared, tmp_path):
    ck = prepared / "run" / "checkpoints" / "unloading_phi0.690.ckpt"
    # a sheared state: the last good state of a simple shear stopped by a tight overlap limit
    from demkit.curves import read_curve
    free = tmp_path / "free.csv"
    run_dem("mode", "--scene", prepared / "tiny.toml", "--packing", ck, "--mode", "SS_xz", "--eps-max", "0.05",
            "--out", free, "--quiet", check=True)
    ov = read_curve(free)["overlap_max_rel"]
    limit = ov[0] + 0.5 * (ov.max() - ov[0])
    over = tmp_path / "ss.csv"
    p = run_dem("mode", "--scene", prepared / "tiny.toml", "--packing", ck, "--mode", "SS_xz", "--eps-max", "0.05",
                "--out", over, "--quiet", "--set", f"integration.max_overlap_fraction={limit:.6g}",
                "--set", "integration.check_every_steps=1", timeout=300)
    sheared = str(over) + ".failed.ckpt"
    if p.returncode != 3 or open(sheared, "rb").read(8) != b"DEMCKPT4":
        pytest.skip(f"could not make a sheared checkpoint here: {p.stderr[-300:]}")
    out = tmp_path / "run"
    p = run_dem("run", scene(tmp_path), "--out", out, "--quiet", "--set", f'particles.packing_file="{sheared}"',
                timeout=300)
    assert p.returncode == 0, p.stderr
    assert "tilted" in p.stderr and ".txt" in p.stderr, p.stderr
    assert (out / "checkpoints" / "unloading_phi0.690.ckpt").exists()
    assert not (out / "checkpoints" / "unloading_phi0.690.txt").exists()
    assert (out / "deviatoric" / "D2_phi0.690.csv").exists()


# ---- 14: checkpoints do not depend on the thread count; --threads must be >= 1 ----------------

def test_checkpoints_are_the_same_bytes_for_any_thread_count(tmp_path):
    s = scene(tmp_path)
    for t in ("1", "2"):
        run_dem("run", s, "--out", tmp_path / f"t{t}", "--stages", "prep", "--quiet", "--threads", t, check=True)
    for f in sorted((tmp_path / "t1").glob("**/*.ckpt")):
        other = tmp_path / "t2" / f.relative_to(tmp_path / "t1")
        assert f.read_bytes() == other.read_bytes(), f


def test_resumed_with_another_thread_count_gives_the_same_checkpoints(tmp_path):
    s = scene(tmp_path)
    ref = tmp_path / "ref"
    run_dem("run", s, "--out", ref, "--stages", "prep", "--quiet", "--threads", "1", check=True)
    out = tmp_path / "resumed"
    shutil.copytree(ref, out)
    m = json.loads((out / "manifest.json").read_text())
    m["complete"] = False
    (out / "manifest.json").write_text(json.dumps(m))
    for f in ("prep/after_cycle_unloading.ckpt", "checkpoints/unloading_phi0.690.ckpt", "checkpoints/unloading_phi0.720.ckpt"):
        (out / f).unlink()
    p = run_dem("run", s, "--out", out, "--stages", "prep", "--quiet", "--threads", "2")
    assert p.returncode == 0, p.stderr
    for f in sorted(ref.glob("**/*.ckpt")):
        assert f.read_bytes() == (out / f.relative_to(ref)).read_bytes(), f


@pytest.mark.parametrize("threads", ["0", "-1", "-8"])
def test_threads_below_one_are_refused(tmp_path, threads):
    for cmd in (["run", scene(tmp_path), "--out", tmp_path / "r"], ["bench", "--steps", "1"]):
        p = run_dem(*cmd, "--threads", threads, timeout=30)
        assert p.returncode == 2 and "--threads" in p.stderr, p.stderr
    assert not (tmp_path / "r").exists()


def test_more_than_four_threads_say_their_bits_differ(tmp_path):
    p = run_dem("info", scene(tmp_path), "--set", "integration.threads=8", check=True)
    assert "integration.blocks=4" in p.stderr, p.stderr
    p = run_dem("info", scene(tmp_path), "--set", "integration.threads=8", "--set", "integration.blocks=4", check=True)
    assert "blocks" not in p.stderr


# ---- and keep it so: the README's exit-code table, walked ------------------------------------

def test_every_exit_code_of_the_readme_table_is_what_dem_returns(prepared, tmp_path):
    import re
    text = open(os.path.join(ROOT, "README.md")).read()
    table = text[text.index("**Errors.**"):text.index("Checkpoints (format version")]
    codes = sorted(int(c) for c in re.findall(r"^\| (\d) \|", table, re.M))
    assert codes == [0, 1, 2, 3, 4], codes
    s = scene(tmp_path)
    ck = prepared / "run" / "checkpoints" / "unloading_phi0.690.ckpt"
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for f, rate in ((a, "2e-4"), (b, "2e-3")):
        run_dem("mode", "--scene", prepared / "tiny.toml", "--packing", ck, "--mode", "D2", "--eps-max", "0.01",
                "--rate-tc", rate, "--out", f, "--quiet", check=True)
    cases = {
        0: ["info", s],
        1: ["run", s, "--out", tmp_path / "r1", "--quiet", "--set", 'particles.packing_file="/dev/zero"'],
        2: ["run", s, "--out", tmp_path / "r2", "--quiet", "--set", "contact.no_such_key=1"],
        3: ["run", s, "--out", tmp_path / "r3", "--quiet", "--set", "integration.max_overlap_fraction=1e-3"],
        4: ["compare", a, b],
    }
    for code in codes:
        p = run_dem(*cases[code], timeout=300)
        assert p.returncode == code, (code, p.stderr[-2000:])
        if code:
            assert (p.stderr + p.stdout).strip(), code   # every error is said
