"""Issue 10: nothing lost, nothing silently wrong. Killed runs resume, a full disk and a corrupt
checkpoint end in a clear error and a clean rerun, outputs of different physics never mix.

All on a 200-sphere scene (one thread: bit-exact reruns), a few seconds in all."""
import json
import os
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest

from conftest import DEM, ROOT, run_dem
from demkit.curves import read_curve

TINY_SCENE = """
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
modes = ["D2", "D3"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.03
relax_max_time_tc = 2e3
[output]
sample_strain = 0.002
vtk = false
"""


def files_of(d):
    return sorted(os.path.relpath(os.path.join(r, f), d) for r, _, fs in os.walk(d) for f in fs)


def same_results(a, b):
    """Every curve, checkpoint and packing of run a equals b's byte for byte."""
    names = [f for f in files_of(a) if f.endswith((".csv", ".ckpt", ".txt"))]
    assert names, a
    for f in names:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def manifest(d):
    return json.loads((d / "manifest.json").read_text())


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiny")
    (d / "tiny.toml").write_text(TINY_SCENE)
    run_dem("run", d / "tiny.toml", "--out", d / "ref", "--quiet", check=True)
    return d


def copy_run(tiny, dest):
    shutil.copytree(tiny / "ref", dest)
    return dest


def kill_when(args, path, timeout=60):
    """Start dem, SIGKILL it as soon as `path` exists; return the exit status."""
    p = subprocess.Popen([DEM, *map(str, args)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while not os.path.exists(path) and p.poll() is None and time.time() - t0 < timeout:
        time.sleep(0.002)
    p.send_signal(signal.SIGKILL)
    return p.wait()


# ---- killed runs -----------------------------------------------------------------------

def test_killed_preparation_resumes_from_the_last_stage_bit_for_bit(tiny, tmp_path):
    out = tmp_path / "run"
    rc = kill_when(["run", tiny / "tiny.toml", "--out", out, "--quiet"], out / "prep" / "after_relax.ckpt")
    assert rc == -signal.SIGKILL, "the run ended before it could be killed"
    assert manifest(out)["complete"] is False
    assert not (out / "checkpoints" / "unloading_phi0.690.ckpt").exists()
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--quiet", check=True)
    assert "resuming after the finished stage relax" in p.stderr
    assert "already exist" not in p.stderr
    same_results(tiny / "ref", out)
    assert manifest(out)["complete"] is True
    assert not [f for f in files_of(out) if f.endswith(".part")]


def test_interrupted_preparation_of_other_physics_is_not_resumed(tiny, tmp_path):
    out = tmp_path / "run"
    kill_when(["run", tiny / "tiny.toml", "--out", out, "--quiet"], out / "prep" / "after_relax.ckpt")
    before = files_of(out)
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--quiet", "--set", "contact.stiffness_N_m=5e7")
    assert p.returncode == 2 and "contact.stiffness_N_m" in p.stderr and "--force" in p.stderr
    assert files_of(out) == before


def test_killed_deviatoric_stage_resumes_and_keeps_finished_curves(tiny, tmp_path):
    slow = ["--set", "protocol.deviatoric_rate_tc=2e-5", "--set", 'protocol.modes=["D2"]']
    ref, out = tmp_path / "ref", tmp_path / "run"
    for d in (ref, out):
        shutil.copytree(tiny / "ref" / "checkpoints", d / "checkpoints")
    run_dem("run", tiny / "tiny.toml", "--out", ref, "--stages", "deviatoric", "--quiet", *slow, check=True)
    args = ["run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", *slow]
    assert kill_when(args, out / "deviatoric" / "D2_phi0.720.csv") == -signal.SIGKILL
    assert manifest(out)["complete"] is False
    p = run_dem(*args[:-len(slow) - 1], *slow, check=True)
    assert "D2_phi0.720: finished earlier, kept" in p.stderr
    same_results(ref / "deviatoric", out / "deviatoric")
    assert manifest(out)["complete"] is True


# ---- full disk -------------------------------------------------------------------------

def mounted_disk(tmp_path, size):
    """A tmpfs of `size` (e.g. "256k") under tmp_path; needs root (CI runs the tests as root)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root: the full-disk tests run as root in CI")
    d = tmp_path / "disk"
    d.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)]).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (no CAP_SYS_ADMIN)")
    return d


@pytest.fixture
def small_disk(tmp_path):
    """A 256 kB tmpfs."""
    d = mounted_disk(tmp_path, "256k")
    yield d
    subprocess.run(["umount", "-l", str(d)])


@pytest.fixture
def run_sized_disk(tmp_path):
    """A 1 MB tmpfs: room for a whole 200-sphere run once the filler is gone."""
    d = mounted_disk(tmp_path, "1m")
    yield d
    subprocess.run(["umount", "-l", str(d)])


def fill(disk, leave):
    """Fill the file system of `disk` up to `leave` free bytes."""
    free = shutil.disk_usage(disk).free
    with open(disk / "filler", "wb") as fh:
        fh.write(b"\0" * max(free - leave, 0))


def test_full_disk_dem_mode_leaves_only_part_and_fails(tiny, small_disk):
    fill(small_disk, 8192)
    out = small_disk / "D2.csv"
    p = run_dem("mode", "--packing", tiny / "ref" / "checkpoints" / "unloading_phi0.720.txt", "--mode", "D2",
                "--rate-tc", 2e-4, "--eps-max", 0.05, "--set", "output.sample_strain=0.0002", "--set",
                "integration.threads=1", "--quiet", "--out", out)
    assert p.returncode == 1 and "disk full" in p.stderr, p.stderr
    assert not out.exists() and (small_disk / "D2.csv.part").exists()


def test_full_disk_deviatoric_stage_fails_then_reruns_cleanly(tiny, small_disk):
    out = small_disk / "run"
    shutil.copytree(tiny / "ref" / "checkpoints", out / "checkpoints")
    for f in (out / "checkpoints").glob("*.txt"):
        f.unlink()   # room for the curves
    fill(small_disk, 12000)
    args = ("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet")
    p = run_dem(*args)
    assert p.returncode == 1 and "disk full" in p.stderr, p.stderr
    for f in (out / "deviatoric").glob("*.csv"):          # what was renamed into place is whole
        assert f.read_bytes() == (tiny / "ref" / "deviatoric" / f.name).read_bytes(), f.name
    assert manifest(out)["complete"] is False
    (small_disk / "filler").unlink()
    run_dem(*args, check=True)
    same_results(tiny / "ref" / "deviatoric", out / "deviatoric")
    assert manifest(out)["complete"] is True


def test_full_disk_dem_fit_fails_and_writes_no_table(tiny, small_disk):
    out = small_disk / "run"
    shutil.copytree(tiny / "ref" / "deviatoric", out / "deviatoric")
    fill(small_disk, 6000)
    p = run_dem("fit", out, "--no-plots")
    assert p.returncode == 1 and "disk full" in p.stderr, p.stderr
    assert not (out / "fit" / "parameters.csv").exists()
    (small_disk / "filler").unlink()
    run_dem("fit", out, "--no-plots", "--force", check=True)
    assert (out / "fit" / "parameters.csv").exists()


# ---- corrupt checkpoint ----------------------------------------------------------------

def test_corrupt_checkpoint_is_refused_and_a_rerun_restores_everything(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    ck = out / "checkpoints" / "unloading_phi0.720.ckpt"
    b = bytearray(ck.read_bytes())
    b[len(b) // 2] ^= 0x04          # one flipped bit in the middle of the particle data
    ck.write_bytes(bytes(b))
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--force", "--quiet")
    assert p.returncode == 1 and "unloading_phi0.720.ckpt" in p.stderr and "checksum" in p.stderr, p.stderr
    assert "rerun the preparation" in p.stderr
    same_results(tiny / "ref" / "deviatoric", out / "deviatoric")      # nothing was removed
    run_dem("run", tiny / "tiny.toml", "--out", out, "--force", "--quiet", check=True)
    same_results(tiny / "ref", out)


# ---- physics of the outputs ------------------------------------------------------------

def test_deviatoric_stage_refuses_checkpoints_of_other_physics_before_writing(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    scene_before = (out / "scene.toml").read_bytes()
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet",
                "--set", "contact.stiffness_N_m=5e7")
    assert p.returncode == 2 and "contact.stiffness_N_m = 100000000 (checkpoint) vs 50000000" in p.stderr, p.stderr
    assert (out / "scene.toml").read_bytes() == scene_before
    assert manifest(out)["complete"] is True


def test_kept_curves_of_another_rate_are_refused_and_force_replaces_them(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    run_dem("fit", out, "--no-plots", check=True)
    args = ("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet",
            "--set", "protocol.deviatoric_rate_tc=1e-4", "--set", 'protocol.modes=["D2"]')
    p = run_dem(*args)
    assert p.returncode == 2 and "protocol.deviatoric_rate_tc" in p.stderr and "--force" in p.stderr
    p = run_dem(*args, "--force", check=True)
    assert "removed" in p.stderr and "deviatoric/" in p.stderr and "fit/" in p.stderr
    assert sorted(f.name for f in (out / "deviatoric").iterdir()) == ["D2_phi0.690.csv", "D2_phi0.720.csv"]
    assert not (out / "fit").exists()
    rates = {o["physics"] for o in manifest(out)["outputs"] if o["file"].startswith("deviatoric/")}
    assert len(rates) == 1


def test_force_with_other_checkpoints_leaves_no_stale_outputs(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    run_dem("run", tiny / "tiny.toml", "--out", out, "--force", "--quiet",
            "--set", "protocol.checkpoints_unloading=[0.70]", "--set", 'protocol.modes=["D3"]', check=True)
    assert sorted(f.name for f in (out / "checkpoints").iterdir()) == ["unloading_phi0.700.ckpt", "unloading_phi0.700.txt"]
    assert sorted(f.name for f in (out / "deviatoric").iterdir()) == ["D3_phi0.700.csv"]
    assert [o["file"] for o in manifest(out)["outputs"] if o["file"].startswith("deviatoric")] == \
        ["deviatoric/D3_phi0.700.csv"]


def test_fit_reads_the_manifest_and_refuses_mixed_physics(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    # A stale curve of another stiffness, not in the manifest: not fitted.
    text = (out / "deviatoric" / "D2_phi0.690.csv").read_text()
    stale = text.replace("contact.stiffness_N_m=100000000", "contact.stiffness_N_m=50000000")
    assert stale != text
    (out / "deviatoric" / "D2_phi0.650.csv").write_text(stale)
    p = run_dem("fit", out, "--no-plots", check=True)
    assert "D2_phi0.650.csv is not listed in manifest.json" in p.stderr
    rows = (out / "fit" / "parameters.csv").read_text().splitlines()[1:]
    assert len(rows) == 8 and not [r for r in rows if r.startswith("D2,0.65,")]
    # A folder of curves assembled by hand (no manifest): every curve, but one physics only.
    hand = tmp_path / "hand"
    shutil.copytree(out / "deviatoric", hand / "deviatoric")
    p = run_dem("fit", hand, "--no-plots")
    assert p.returncode == 1 and "different physics" in p.stderr
    assert "contact.stiffness_N_m=100000000 vs 50000000" in p.stderr, p.stderr
    (hand / "deviatoric" / "D2_phi0.650.csv").unlink()
    run_dem("fit", hand, "--no-plots", check=True)


# ---- the fitter says when nothing was fitted --------------------------------------------

def synthetic_curve(path, e, s, f):
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = "\n".join(f"{a!r},{b!r},{c!r}" for a, b, c in zip(e, s, f))
    path.write_text("eps_d,s_dev,F_dev\n" + rows + "\n")


def test_fit_exit_code_says_when_nothing_was_fitted(tmp_path):
    # Two curves whose s_dev is flat (nothing to fit) and whose F_dev is a short straight line
    # (a slope, not the law's three parameters): no fit is usable. Used to exit 0, "4 fits written".
    e = np.linspace(0, 0.03, 11)
    for phi in ("0.700", "0.720"):
        synthetic_curve(tmp_path / "run" / "deviatoric" / f"D2_phi{phi}.csv", e, np.full_like(e, 0.1), 0.02 + 0.5 * e)
    p = run_dem("fit", tmp_path / "run", "--no-plots")
    assert p.returncode == 1 and "no curve could be fitted" in p.stderr, p.stderr
    assert "0 of 4 fits usable" in p.stderr


# ---- bad input: refused before running ----------------------------------------------------

def test_mode_parses_rates_exactly_and_refuses_impossible_ones(tiny, tmp_path):
    pack = tiny / "ref" / "checkpoints" / "unloading_phi0.720.txt"
    for rate, eps in ((2.4e-6, 0.0005), (4e-7, 0.0001)):
        out = tmp_path / f"m{rate}.csv"
        run_dem("mode", "--packing", pack, "--mode", "D2", "--rate-tc", rate, "--eps-max", eps,
                "--threads", 1, "--quiet", "--out", out, "--set", f"output.sample_strain={eps / 5}", check=True)
        c = read_curve(out)
        tc = float([ln for ln in out.read_text().splitlines() if ln.startswith("# t_c=")][0].split()[1][4:])
        # D2: eps_d = sqrt(3) * rate * t for the rate shape (1, 0, -1); not the last row, whose
        # step is shortened to land on eps_max; t_c is printed to 6 digits
        measured = c["eps_d"][-2] / (np.sqrt(3) * c["time_s"][-2]) * tc
        assert abs(measured / rate - 1) < 1e-5, (rate, measured)
    for bad in (("--rate-tc", 0), ("--rate-tc", -1), ("--rate-tc", "nan"), ("--eps-max", -1)):
        p = run_dem("mode", "--packing", pack, "--mode", "D2", *bad, "--out", tmp_path / "x.csv")
        assert p.returncode == 2 and bad[0] in p.stderr, (bad, p.stderr)
        assert not (tmp_path / "x.csv").exists()


def test_mode_checks_out_first_and_keeps_its_failed_state_next_to_it(tiny, tmp_path):
    pack = tiny / "ref" / "checkpoints" / "unloading_phi0.720.txt"
    p = run_dem("mode", "--packing", pack, "--out", tmp_path)
    assert p.returncode == 2 and "is a folder" in p.stderr
    p = run_dem("mode", "--packing", pack, "--out", tmp_path / "no" / "c.csv")
    assert p.returncode == 2 and "does not exist" in p.stderr
    out = tmp_path / "sub" / "c.csv"
    out.parent.mkdir()
    p = run_dem("mode", "--packing", pack, "--out", out, "--quiet", "--threads", 1, "--set", "integration.dt_over_tc=0.6",
                "--set", "contact.damping_kg_s=0", "--set", "contact.background_damping_kg_s=0",
                "--set", "integration.check_every_steps=10", "--rate-tc", 1e-5, "--eps-max", 0.5)
    assert p.returncode == 3, p.stderr
    assert (tmp_path / "sub" / "c.csv.failed.ckpt").exists() and "c.csv.failed.ckpt" in p.stderr
    assert not list(tmp_path.glob("failed_*")) and not out.exists()


def test_run_refuses_packings_that_do_not_belong_to_the_scene(tmp_path):
    def run_with(lines):
        pack = tmp_path / "p.txt"
        pack.write_text("##PERIODIC:: 0.01 0.01 0.01\n" + "".join(f"{x} {y} {z} {r}\n" for x, y, z, r in lines))
        scene = tmp_path / "s.toml"
        scene.write_text(f'[particles]\npacking_file = "{pack}"\n')
        return run_dem("run", scene, "--out", tmp_path / "o", "--quiet")
    p = run_with([(0.002, 0.005, 0.005, 1e-4), (0.006, 0.005, 0.005, 1e-4)])     # 10x smaller
    assert p.returncode == 1 and "particles.radius_min_m" in p.stderr
    p = run_with([(0.002, 0.005, 0.005, 1e-3), (0.00247, 0.005, 0.005, 1e-3)])   # overlap 1.53 r
    assert p.returncode == 1 and "overlap by 1.53" in p.stderr
    p = run_with([(0.002, 0.005, 0.005, 1e-3), (0.002, 0.005, 0.005, 1e-3)])     # coincident
    assert p.returncode == 1 and "same centre" in p.stderr
    assert not (tmp_path / "o").exists()


def test_scene_gaps_are_refused_before_anything_runs(tmp_path):
    scene = tmp_path / "s.toml"
    for text, key in (("", "data/scenes/"), ("[contact]\nstiffness_N_m = inf\n", "stiffness_N_m"),
                      ("[particles]\ncount = 4294967596\n", "out of range"),
                      ("[protocol]\ncheckpoints_unloading = [0.7001, 0.6999]\n", "phi0.700"),
                      ("[output]\nprogress_seconds = -1\n", "progress_seconds")):
        scene.write_text(text)
        p = run_dem("run", scene, "--out", tmp_path / "o")
        assert p.returncode == 2 and key in p.stderr, (text, p.stderr)
        assert not (tmp_path / "o").exists()
    scene.write_text("[particles]\ncount = 2000000000\n")
    p = run_dem("run", scene, "--out", tmp_path / "o")
    assert p.returncode == 2 and "GB" in p.stderr and not (tmp_path / "o").exists()


def test_collide_refuses_impossible_input_at_once(tmp_path):
    t0 = time.time()
    for args in (("--v0", 0), ("--v0", -1), ("--r1", -1e-3), ("--v0", 1e6)):
        p = run_dem("collide", *args, timeout=20)
        assert p.returncode == 2, (args, p.stderr)
    assert time.time() - t0 < 10
    assert "--v0 is too large" in run_dem("collide", "--v0", 1e6).stderr
    # A sphere smaller than the scene's radius_min (which sets dt) is named as the cause, not --v0.
    p = run_dem("collide", "--r1", 1e-5)
    assert p.returncode == 2 and "--r1" in p.stderr and "particles.radius_min_m" in p.stderr, p.stderr


def test_exit_codes_follow_the_readme(tmp_path):
    assert run_dem().returncode == 2                                          # no subcommand
    assert run_dem("run", tmp_path / "missing.toml", "--out", tmp_path / "o").returncode == 2
    assert run_dem("info", "--frobnicate").returncode == 2
    assert run_dem("--help").returncode == 0


def test_compare_refuses_partial_overlap_and_unordered_strain(tmp_path):
    ours = os.path.join(ROOT, "data", "yade", "ours_D2_phi0.740.csv")
    lines = open(ours).read().splitlines()
    head = [ln for ln in lines if ln.startswith("#")] + [lines[len([ln for ln in lines if ln.startswith("#")])]]
    data = lines[len(head):]
    short = tmp_path / "short.csv"
    short.write_text("\n".join(head + data[: len(data) // 10]) + "\n")      # 10 % of the range
    p = run_dem("compare", ours, short)
    assert p.returncode == 4 and "coverage" in p.stdout, p.stdout
    shuffled = tmp_path / "shuffled.csv"
    shuffled.write_text("\n".join(head + data[:5] + [data[7], data[6]] + data[8:]) + "\n")
    p = run_dem("compare", ours, shuffled)
    assert p.returncode == 1 and "does not increase" in p.stderr, p.stderr


# ---- what a rerun keeps must be what the scene says (issue 10, found in the audit) ---------

def test_kept_curves_of_another_extent_or_mode_definition_are_refused(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    scene_before = (out / "scene.toml").read_bytes()
    for change in (["--set", "protocol.eps_d_max=0.04"], ["--set", "protocol.eps_d_max=0.06"]):
        p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", *change)
        assert p.returncode == 2, p.stderr
        assert "as an earlier scene defined it" in p.stderr and "--force" in p.stderr, p.stderr
        assert (out / "scene.toml").read_bytes() == scene_before
    # A built-in mode cannot be redefined at all any more (issue 32): refused before the curves are compared.
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet",
                "--set", "modes.D2=[1.0, -1.0, 0.0]")
    assert p.returncode == 2 and "is a built-in mode" in p.stderr, p.stderr
    assert (out / "scene.toml").read_bytes() == scene_before
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", "--force",
                "--set", "protocol.eps_d_max=0.04", check=True)
    eps = [float(r.split(",")[6]) for r in (out / "deviatoric" / "D2_phi0.690.csv").read_text().splitlines()
           if r and not r.startswith(("#", "step"))]
    assert eps[-1] == pytest.approx(0.04, abs=1e-9)


def test_deviatoric_stage_refuses_checkpoints_of_another_preparation(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    scene_before = (out / "scene.toml").read_bytes()
    p = run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet",
                "--set", "protocol.cycle_rate_tc=1e-5")
    assert p.returncode == 2 and "protocol.preparation" in p.stderr and "cycle_loading" in p.stderr, p.stderr
    assert (out / "scene.toml").read_bytes() == scene_before
    # What a deviatoric rerun may change: the modes and their rate.
    run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", "--force",
            "--set", "protocol.deviatoric_rate_tc=1e-4", check=True)


def test_fit_force_leaves_no_table_of_the_earlier_fit(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    run_dem("fit", out, "--no-plots", check=True)
    assert (out / "fit" / "shared_path.csv").exists()
    run_dem("run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", "--force",
            "--set", 'protocol.modes=["D2"]', check=True)
    (out / "fit").mkdir(exist_ok=True)
    (out / "fit" / "shared_path.csv").write_text("mode,stale\n")   # as an earlier fit of D2 and D3 left it
    (out / "fit" / "parameters.csv").write_text("stale\n")
    run_dem("fit", out, "--no-plots", "--force", check=True)
    assert not (out / "fit" / "shared_path.csv").exists()
    assert "D2" in (out / "fit" / "parameters.csv").read_text()


def test_interrupted_deviatoric_rerun_of_a_finished_run_is_marked_incomplete(tiny, tmp_path):
    out = copy_run(tiny, tmp_path / "run")
    assert manifest(out)["complete"] is True
    args = ["run", tiny / "tiny.toml", "--out", out, "--stages", "deviatoric", "--quiet", "--force",
            "--set", "protocol.deviatoric_rate_tc=2e-5", "--set", 'protocol.modes=["D2"]']
    # Killed while the second curve is being written (the copied folder holds finished ones).
    assert kill_when(args, out / "deviatoric" / "D2_phi0.690.csv.part") == -signal.SIGKILL
    assert manifest(out)["complete"] is False
    run_dem(*args, check=True)
    assert manifest(out)["complete"] is True


def test_full_disk_during_the_preparation_fails_then_resumes_to_the_same_bytes(tiny, run_sized_disk):
    small_disk = run_sized_disk
    out = small_disk / "run"
    prep_bytes = sum(f.stat().st_size for f in (tiny / "ref").rglob("*") if f.is_file() and "deviatoric" not in f.parts)
    fill(small_disk, prep_bytes // 2)
    args = ("run", tiny / "tiny.toml", "--out", out, "--quiet")
    p = run_dem(*args)
    assert p.returncode == 1 and "disk full" in p.stderr, p.stderr
    assert manifest(out)["complete"] is False
    for f in files_of(out):   # whatever was renamed into place is whole
        if f.endswith((".csv", ".ckpt", ".txt")) and not f.startswith("prep/after_"):
            assert (out / f).read_bytes() == (tiny / "ref" / f).read_bytes(), f
    (small_disk / "filler").unlink()
    p = run_dem(*args, check=True)
    assert "resuming" in p.stderr
    same_results(tiny / "ref", out)
    assert not [f for f in files_of(out) if f.endswith(".part")]


# ---- thread-count independence (issue 12) -------------------------------------------------

def test_fixed_blocks_give_the_same_curve_bytes_for_1_to_4_threads(tiny, tmp_path):
    curves = []
    for threads in (1, 2, 3, 4):
        out = tmp_path / f"D2_t{threads}.csv"
        run_dem("mode", "--packing", tiny / "ref" / "checkpoints" / "unloading_phi0.720.ckpt", "--mode", "D2",
                "--rate-tc", 2e-4, "--eps-max", 0.05, "--threads", threads, "--set", "integration.blocks=12",
                "--quiet", "--out", out, check=True)
        curves.append(out.read_bytes())
    assert all(c == curves[0] for c in curves[1:])
