import os
import signal
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
DEM = os.path.join(ROOT, "build", "dem")

# The small scene of the integration test: the paper's protocol on 400 spheres, fast rates.
SMALL_SCENE = """
[particles]
count = 400
seed = 3
[protocol]
target_phi = 0.64
compress_rate_tc = 2e-4
cycle_rate_tc = 1e-4
cycle_phi_max = 0.82
checkpoints_unloading = [0.78, 0.72, 0.69]
modes = ["D2", "D3"]
deviatoric_rate_tc = 4e-5
eps_d_max = 0.3
[output]
sample_strain = 0.003
vtk = true
"""


# The modules that start a single-node Slurm (scripts/slurm-local.sh): one daemon at a time on this machine.
SLURM_MODULES = {"test_ensemble.py", "test_sweep.py"}


@pytest.hookimpl(tryfirst=True)   # before xdist's own hook, which turns the marks into the node ids' @group
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (scripts/test.sh runs `-n N --dist loadgroup` where it is installed): every module's tests on
    one worker, so a module-scoped fixture (a fit, a run) is computed once; the modules that start Slurm on the same
    worker, one after another. Without xdist nothing changes."""
    if not config.pluginmanager.hasplugin("xdist"):
        return
    for item in items:
        name = os.path.basename(str(item.fspath))
        item.add_marker(pytest.mark.xdist_group("slurm" if name in SLURM_MODULES else name))


def run_dem(*args, check=False, timeout=900, env=None):
    """Run build/dem with args (environment `env`, default ours); return CompletedProcess (text)."""
    if not os.path.exists(DEM):
        pytest.fail(f"{DEM} is missing: run scripts/setup.sh first")
    p = subprocess.run([DEM, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)
    if check and p.returncode != 0:
        raise AssertionError(f"dem {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    return p


def kill_group(proc, wait=30.0):
    """SIGKILL the process group of the Popen `proc` (a `dem ensemble` started with start_new_session), reap it, and
    wait until every process of it is gone, at most `wait` s: the leader's exit is not the group's, and a worker that
    inherited the ensemble's lock can outlive the leader by a moment under load (the resumed run then found the folder
    locked: test_killed_workflow_resumes_and_loses_only_running_tasks on a loaded machine, nineteenth round)."""
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    gone = time.time() + wait
    while time.time() < gone:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)


@pytest.fixture(scope="session")
def small_run(tmp_path_factory):
    """One whole-protocol run of SMALL_SCENE plus its fit, shared by the pipeline tests."""
    d = tmp_path_factory.mktemp("small")
    scene = d / "small.toml"
    scene.write_text(SMALL_SCENE)
    out = d / "run"
    run_dem("run", scene, "--out", out, "--quiet", check=True)
    fit = run_dem("fit", out, check=True)
    return {"dir": out, "scene": scene, "fit_stderr": fit.stderr}
