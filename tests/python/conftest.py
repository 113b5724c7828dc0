import os
import subprocess
import sys

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


def run_dem(*args, check=False, timeout=900, env=None):
    """Run build/dem with args (environment `env`, default ours); return CompletedProcess (text)."""
    if not os.path.exists(DEM):
        pytest.fail(f"{DEM} is missing: run scripts/setup.sh first")
    p = subprocess.run([DEM, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)
    if check and p.returncode != 0:
        raise AssertionError(f"dem {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    return p


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
