"""The ensemble workflow end to end on a tiny scene: averages against hand computation, member 0
against the single-packing run, resume after a killed workflow, reported (not dropped) failures,
and the same results through a real single-node Slurm."""
import base64
import csv
import glob
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import DEM, ROOT, kill_group, run_dem
from demkit.curves import read_curve

TINY = """
[particles]
count = 250
seed = 5
[protocol]
target_phi = 0.64
compress_rate_tc = 2e-4
cycle_rate_tc = 1e-4
checkpoints_unloading = [0.74]
modes = ["D2", "D3"]
deviatoric_rate_tc = 4e-5
eps_d_max = 0.06
[integration]
dt_over_tc = 0.1
[output]
sample_strain = 0.003
vtk = false
[ensemble]
packings = 3
"""
T2_975 = 4.302652729911275   # Student's t quantile, 2 degrees of freedom (tables)


def ensemble(scene, out, *extra, env=None, check=True):
    return run_dem("ensemble", scene, "--out", out, *extra, check=check, timeout=600, env=env)


@pytest.fixture(scope="session")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("ens")
    scene = d / "tiny.toml"
    scene.write_text(TINY)
    t0 = time.time()
    p = ensemble(scene, d / "run", "--cores", "2")
    return {"dir": d / "run", "scene": scene, "stderr": p.stderr, "wall": time.time() - t0}


def member_curves(run, name):
    return [read_curve(f) for f in sorted(glob.glob(str(run / "members" / "m*" / "deviatoric" / f"{name}.csv")))]


def strictly_increasing(curve):
    """Rows whose eps_d the next row exceeds (the last row lands on eps_d_max right after a
    sampled row and can print as the same number): keep the later of equal strains."""
    e = curve["eps_d"]
    keep = np.append(e[1:] > e[:-1], True)
    return {k: v[keep] for k, v in curve.items()}


def test_averages_and_bands_equal_hand_computation(tiny):
    run = tiny["dir"]
    for name in ("D2_phi0.740", "D3_phi0.740"):
        members = [strictly_increasing(m) for m in member_curves(run, name)]
        assert len(members) == 3
        ens = read_curve(run / "ensemble" / f"{name}.csv")
        n = len(ens["eps_d"])
        for m in members:   # members share the sampling: the grid is their strain column
            np.testing.assert_allclose(m["eps_d"][:n], ens["eps_d"], rtol=0, atol=1e-12)
        for col in ("s_dev", "F_dev", "p_Pa", "C", "eps_v"):
            y = np.array([m[col][:n] for m in members])
            mean, sd = y.mean(axis=0), y.std(axis=0, ddof=1)
            scale = np.abs(y).max() + 1e-300
            np.testing.assert_allclose(ens[col + "_mean"], mean, rtol=1e-9, atol=1e-9 * scale)
            np.testing.assert_allclose(ens[col + "_sd"], sd, rtol=1e-8, atol=1e-9 * scale)
            np.testing.assert_allclose(ens[col + "_se"], sd / np.sqrt(3), rtol=1e-8, atol=1e-9 * scale)
            np.testing.assert_allclose(ens[col + "_hi95"], mean + T2_975 * sd / np.sqrt(3), rtol=1e-8, atol=1e-9 * scale)
        assert (ens["n_packings"] == 3).all()


def test_member_zero_is_the_single_packing_run_and_members_differ(tiny, tmp_path):
    run = tiny["dir"]
    single = tmp_path / "single"
    run_dem("run", tiny["scene"], "--out", single, "--set", "ensemble.packings=1", "--threads", "1", "--quiet", check=True)
    for name in ("D2_phi0.740", "D3_phi0.740"):
        a = (single / "deviatoric" / f"{name}.csv").read_bytes()
        b = (run / "members" / "m000" / "deviatoric" / f"{name}.csv").read_bytes()
        assert a == b, f"{name}: member 0 differs from `dem run` of the same seed"
    seeds = set()
    for scene in sorted(glob.glob(str(run / "members" / "m*" / "scene.toml"))):
        seeds.update(ln for ln in open(scene) if ln.startswith("seed"))
    assert len(seeds) == 3, f"members must have distinct seeds: {seeds}"
    a, b = member_curves(run, "D2_phi0.740")[:2]
    assert np.abs(a["s_dev"] - b["s_dev"]).max() > 1e-4, "members are not independent packings"


def test_fit_tables_carry_errors_between_packings(tiny):
    run = tiny["dir"]
    with open(run / "fit" / "parameters.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {(r["mode"], r["quantity"]) for r in rows} == {(m, q) for m in ("D2", "D3") for q in ("s_dev", "F_dev")}
    for r in rows:
        assert r["packings"] == "3" and r["error_method"] == "jackknife over packings"
        lo, x, hi, se = (float(r[k]) for k in ("x_max_lo95", "x_max", "x_max_hi95", "se_x_max"))
        assert lo < x < hi
        assert hi - x == pytest.approx(T2_975 * se, rel=1e-4)
    with open(run / "fit" / "shared_path.csv", newline="") as fh:
        shared = list(csv.DictReader(fh))
    assert len(shared) == 2 and all(s["packings"] == "3" for s in shared)
    with open(run / "ensemble" / "members.csv", newline="") as fh:
        assert [m["status"] for m in csv.DictReader(fh)] == ["complete"] * 6
    for png in ("ensemble_s_dev", "fit_D2_phi0.740", "isotropic"):
        assert (run / "plots" / f"{png}.png").stat().st_size > 1000
    # one volume fraction: no parameters-against-nu figure (it would be empty panels), a note instead
    assert not (run / "plots" / "fit_parameters.png").exists()
    assert "done in" in tiny["stderr"] and "% of the work" in tiny["stderr"]


def test_fit_tables_append_the_chosen_model(tiny):
    """docs/model_selection.md: the earlier columns first and unchanged in order, the model columns after."""
    run = tiny["dir"]
    with open(run / "fit" / "parameters.csv", newline="") as fh:
        header = next(csv.reader(fh))
        fh.seek(0)
        rows = list(csv.DictReader(fh))
    assert header.index("warnings") == 27 and header[28] == "model" and header[-3] == "peak_warnings"
    assert header[-2:] == ["usable", "not_usable_because"]   # the one usable rule (issue 33), last
    for r in rows:
        assert r["model"] in ("saturating", "peak", "two-rate"), r["model"]
        p = float(r["selection_p"])
        # no test where a fit failed (here: ill-conditioned saturating fits of the short tiny curves), said so
        assert 0 <= p <= 1 or (np.isnan(p) and "failed" in r["selection_reason"]), r["selection_reason"]
        if r["model"] == "saturating":
            assert r["x_crit"] == r["x_max"] and r["x_crit_lo95"] == r["x_max_lo95"]
        else:
            assert float(r["selection_p"]) < 0.01
    md = (run / "fit" / "parameters.md").read_text()
    assert "Model:" in md


def finished_tasks(out, stage):
    """Status files of the tasks Snakemake had registered as finished. A status file written in the
    instant before a kill still carries Snakemake's "incomplete" marker: that task was running, and
    rerunning it is what a resume should do. A marker caught being written is a temporary file
    `tmpXXXX.NAME` (base64 has no dot; seen under load, twenty-fifth round): its NAME counts too."""
    inc = out / ".snakemake" / "incomplete"
    marked = ({base64.urlsafe_b64decode(m.name.rsplit(".", 1)[-1]).decode() for m in inc.glob("*")}
              if inc.is_dir() else set())
    return [f for f in glob.glob(str(out / "members" / "*" / stage / "*.json"), recursive=True)
            if not f.endswith("manifest.json") and os.path.relpath(f, out) not in marked]


def test_breakdown_adds_up_to_the_wall_time(tiny):
    """The parts printed at the end and stored in run.json add up to the wall time measured here,
    and the task parts are the tasks' own intervals (status files) over the cores."""
    run = tiny["dir"]
    bd = json.loads((run / "run.json").read_text())["breakdown"]
    parts = bd["parts_s"]
    assert sum(parts.values()) == pytest.approx(tiny["wall"], rel=0.03)
    assert bd["wall_s"] == pytest.approx(tiny["wall"], rel=0.03) and bd["cores"] == 2

    def seconds(pattern):
        return sum(s["t_end"] - s["t_start"] for s in (json.loads(open(f).read()) for f in glob.glob(str(run / pattern))))
    assert parts["preparations"] == pytest.approx(seconds("members/*/prep.json") / 2, abs=0.01)
    assert parts["mode tasks"] + parts["rebuilds"] == pytest.approx(seconds("members/*/deviatoric/*.json") / 2, abs=0.01)
    assert parts["reduction"] + parts["plots"] == pytest.approx(seconds("logs/reduce.json") / 2, abs=0.01)
    assert 0 < parts["plots"] and 0 < parts["rebuilds"] < parts["mode tasks"]
    assert "where the" in tiny["stderr"] and "scheduler overhead" in tiny["stderr"]
    print(next(ln for ln in tiny["stderr"].splitlines() if "where the" in ln), f"(measured here: {tiny['wall']:.2f} s)")


@pytest.mark.parametrize("group", ["member", "task"])
def test_killed_workflow_resumes_and_loses_only_running_tasks(tiny, tmp_path, group):
    """One Snakemake job per packing (group member: its tasks in sequence) or per task: a kill
    loses only the running task, and the resumed run gives the bytes of an uninterrupted one."""
    out = tmp_path / "killed"
    p = subprocess.Popen([DEM, "ensemble", str(tiny["scene"]), "--out", str(out), "--cores", "1", "--group", group],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and not finished_tasks(out, "deviatoric"):
        time.sleep(0.2)
    kill_group(p)   # the driver, Snakemake and the running tasks, at once; then every one of them gone
    finished = {f: os.stat(f).st_mtime_ns for f in finished_tasks(out, "**")}
    assert finished, "nothing finished before the kill"
    assert not (out / "fit" / "parameters.csv").exists()
    r = ensemble(tiny["scene"], out, "--cores", "2", "--group", group)
    for f, t in finished.items():
        assert os.stat(f).st_mtime_ns == t, f"{f} was recomputed after the resume"
    for name in ("D2_phi0.740", "D3_phi0.740"):
        assert (out / "ensemble" / f"{name}.csv").read_bytes() == (tiny["dir"] / "ensemble" / f"{name}.csv").read_bytes()
        for m in ("m000", "m001", "m002"):
            curve = f"members/{m}/deviatoric/{name}.csv"
            assert (out / curve).read_bytes() == (tiny["dir"] / curve).read_bytes(), curve
    assert "done in" in r.stderr
    assert len(glob.glob(str(out / "members" / "*" / "member.json"))) == (3 if group == "member" else 0)


def test_deleted_task_result_reruns_its_group(tiny, tmp_path):
    """A packing's group marker does not stand for a task result deleted since: that task reruns."""
    out = tmp_path / "copy"
    shutil.copytree(tiny["dir"], out)
    assert (out / "members" / "m001" / "member.json").exists()   # the tiny scene's tasks are short: grouped
    victim = out / "members" / "m001" / "deviatoric" / "D3_phi0.740.json"
    keep = out / "members" / "m001" / "deviatoric" / "D2_phi0.740.json"
    t_keep = keep.stat().st_mtime_ns
    victim.unlink()
    ensemble(tiny["scene"], out, "--cores", "2")
    assert json.loads(victim.read_text())["status"] == "complete"
    assert keep.stat().st_mtime_ns == t_keep
    curve = out / "members" / "m002" / "deviatoric" / "D2_phi0.740.csv"   # a curve alone, its status kept
    curve.unlink()
    ensemble(tiny["scene"], out, "--cores", "2")
    assert curve.read_bytes() == (tiny["dir"] / "members" / "m002" / "deviatoric" / "D2_phi0.740.csv").read_bytes()
    assert keep.stat().st_mtime_ns == t_keep


def test_blown_up_member_is_reported_not_dropped(tiny, tmp_path):
    # The task wrapper turns a blow-up (exit 3) into a status, not a failed workflow ...
    status = tmp_path / "x.json"
    rc = subprocess.run([sys.executable, "-m", "demkit.task", "--status", str(status), "--log", str(tmp_path / "x.log"),
                         "--", "sh", "-c", "echo 'dem: simulation blew up: overlap' >&2; exit 3"],
                        env={**os.environ, "PYTHONPATH": ROOT}).returncode
    assert rc == 0
    st = json.loads(status.read_text())
    assert st["status"] == "blew_up" and "blew up" in st["message"]
    # ... and the reduce leaves that member out of the averages, saying so.
    run = tmp_path / "copy"
    shutil.copytree(tiny["dir"], run)
    (run / "members" / "m001" / "deviatoric" / "D2_phi0.740.json").write_text(status.read_text())
    fit = run_dem("fit", run, "--force", "--no-plots")
    assert fit.returncode == 0, fit.stderr
    assert "member m001 left out (blew_up" in fit.stderr
    ens = read_curve(run / "ensemble" / "D2_phi0.740.csv")
    assert (ens["n_packings"] == 2).all()
    with open(run / "ensemble" / "members.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["status"] != "complete"]
    assert [(r["member"], r["mode"], r["status"]) for r in rows] == [("m001", "D2", "blew_up")]
    with open(run / "fit" / "parameters.csv", newline="") as fh:
        d2 = [r for r in csv.DictReader(fh) if r["mode"] == "D2"]
    assert all(r["packings"] == "2" and "m001 left out" in r["warnings"] for r in d2)


def test_other_scene_in_the_folder_and_ensembles_in_dem_run_are_refused(tiny, tmp_path):
    r = ensemble(tiny["scene"], tiny["dir"], "--set", "contact.stiffness_N_m=5e7", check=False)
    assert r.returncode == 1 and "holds the results of another scene" in r.stderr and "stiffness" in r.stderr
    r = run_dem("run", tiny["scene"], "--out", tmp_path / "x")
    assert r.returncode == 2 and "dem ensemble" in r.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("sbatch") is None,
                    reason="needs root and Debian's slurm-wlm + munge (scripts/install-deps.sh) to start a Slurm")
def test_slurm_profile_gives_the_local_results(tiny, tmp_path):
    cluster = tmp_path / "slurm"
    start = subprocess.run(["bash", os.path.join(ROOT, "scripts", "slurm-local.sh"), "start", str(cluster)],
                           capture_output=True, text=True, timeout=120)
    assert start.returncode == 0, start.stderr
    try:
        env = {**os.environ, "SLURM_CONF": str(cluster / "slurm.conf"), "CI": "true"}   # CI: poll every 1 s, not 10 s
        out = tmp_path / "run"
        ensemble(tiny["scene"], out, "--profile", "slurm", env=env)
        # grouped (the tiny scene's tasks are short): one sbatch job per packing and one for the reduce
        assert len(glob.glob(str(out / "logs" / "slurm" / "*.out"))) >= 4, "tasks did not go through sbatch"
        assert len(glob.glob(str(out / "members" / "*" / "member.json"))) == 3
        for f in sorted(glob.glob(str(tiny["dir"] / "ensemble" / "*.csv"))):
            assert (out / "ensemble" / os.path.basename(f)).read_bytes() == open(f, "rb").read(), f
        a = (tiny["dir"] / "fit" / "parameters.csv").read_text()
        assert (out / "fit" / "parameters.csv").read_text() == a
    finally:
        subprocess.run(["bash", os.path.join(ROOT, "scripts", "slurm-local.sh"), "stop", str(cluster)], timeout=60)
