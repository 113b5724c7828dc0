"""The neighbour list's run summary: `dem mode` prints it, demkit.task puts it in the status JSON."""
import json
import os
import subprocess
import sys

from conftest import ROOT, run_dem


def test_mode_summary_reaches_the_task_status(tmp_path):
    # A few hundred steps of the shared packing at t_c/5: rebuilds happen, and their counts
    # add up in the status JSON next to the curve.
    status, curve = tmp_path / "D2.json", tmp_path / "D2.csv"
    cmd = [os.path.join(ROOT, "build", "dem"), "mode", "--packing", os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt"),
           "--scene", os.path.join(ROOT, "data", "scenes", "quickstart.toml"), "--mode", "D2", "--eps-max", "0.03",
           "--rate-tc", "3e-4", "--out", str(curve), "--quiet", "--threads", "1"]
    rc = subprocess.run([sys.executable, "-m", "demkit.task", "--status", str(status), "--log", str(tmp_path / "D2.log"),
                         "--", *cmd], env={**os.environ, "PYTHONPATH": ROOT}).returncode
    assert rc == 0
    st = json.loads(status.read_text())
    assert st["status"] == "complete"
    nl = st["neighbor_list"]
    assert nl["steps"] > 0 and nl["rebuilds"] > 0, nl
    assert nl["rebuilds"] == nl["trigger_displacement"] + nl["trigger_deformation"] + nl["trigger_flip"]
    assert nl["trigger_rattler"] + nl["trigger_packing"] <= nl["trigger_displacement"]
    assert 0 <= nl["rebuild_share"] < 1
    assert abs(nl["rebuilds_per_1e4_steps"] - 1e4 * nl["rebuilds"] / nl["steps"]) < 1e-3 * nl["rebuilds_per_1e4_steps"]


def test_bench_prints_the_rebuild_summary():
    r = run_dem("bench", "--steps", "300", "--set", "integration.dt_over_tc=0.2", "--rate-tc", "1e-3", check=True)
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("neighbor_list="))
    nl = json.loads(line[len("neighbor_list="):])
    assert nl["steps"] == 300 and nl["skin_m"] > 0
    assert "list rebuilds:" in r.stdout and "of the wall time" in r.stdout


def _preamble(curve):
    return [ln for ln in curve.read_text().splitlines() if ln.startswith("#")]


def test_the_skin_is_recorded_and_is_not_physics(tmp_path):
    # The quickstart scene (t_c/5) gets the auto skin, 0.4 (dt/t_c / 0.02)^0.4 = 1.005 r_min; the
    # same run with the skin set by hand has the same physics record (hash and keys) and says so.
    packing = os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt")
    scene = os.path.join(ROOT, "data", "scenes", "quickstart.toml")
    curves = {}
    for name, extra in (("auto", []), ("set", ["--set", "integration.skin_over_rmin=0.4"])):
        curves[name] = tmp_path / f"{name}.csv"
        run_dem("mode", "--packing", packing, "--scene", scene, "--mode", "D2", "--eps-max", "0.01", "--rate-tc", "3e-4",
                "--out", curves[name], "--quiet", "--threads", "1", *extra, check=True)
    pre = {k: _preamble(c) for k, c in curves.items()}
    skin = {k: next(ln for ln in p if ln.startswith("# neighbour list: skin=")) for k, p in pre.items()}
    r_min = 0.5e-3
    auto = float(skin["auto"].split("skin=")[1].split()[0])
    assert abs(auto / r_min - 0.4 * 10 ** 0.4) < 1e-4 and "auto, from dt/t_c" in skin["auto"], skin["auto"]
    assert "skin=0.0002 m = 0.4 r_min (set in the scene)" in skin["set"], skin["set"]
    physics = {k: next(ln for ln in p if ln.startswith("# physics:")) for k, p in pre.items()}
    assert physics["auto"] == physics["set"]
    info = run_dem("info", scene, check=True).stdout
    assert "neighbour list     skin = 0.0005024 m = 1 r_min (auto" in info, info
