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
