"""YADE cross-checks: live runs (YADE is installed by scripts/setup.sh) and stored references."""
import json
import os
import shutil
import subprocess

import pytest

from conftest import run_dem, ROOT
from demkit.compare import compare
from demkit.curves import read_curve

YADE = shutil.which("yade")
needs_yade = pytest.mark.skipif(YADE is None, reason="yade is not installed (scripts/install-deps.sh installs it)")


def run_yade(script, *args, timeout=600):
    p = subprocess.run([YADE, "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", script), *map(str, args)],
                       capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p


@needs_yade
@pytest.mark.parametrize("r2", [0.5e-3, 1.5e-3])
def test_two_sphere_collision_yade_equals_ours(r2):
    # Both codes clamp the normal force at zero (YADE 2023.02a's ViscElPhys law does too, which
    # is why its restitution exceeds the analytic e of the unclamped law); same leapfrog scheme.
    p = run_yade("collision.py", "--r2", r2, "--dt-over-tc", 5e-4)
    yade = json.loads([ln for ln in p.stdout.splitlines() if ln.startswith("{")][-1])
    ours = json.loads(run_dem("collide", "--r2", r2, "--set", "integration.dt_over_tc=0.0005",
                              "--set", "integration.integrator=symplectic_euler", check=True).stdout)
    assert abs(yade["t_contact_s"] / ours["t_contact_s"] - 1) < 1e-3
    assert abs(yade["restitution"] / ours["restitution"] - 1) < 1e-3
    assert abs(ours["t_contact_s"] / ours["t_contact_analytic_s"] - 1) < 1e-3
    assert yade["restitution"] > yade["restitution_analytic"] + 1e-3   # the clamp, measurably


@needs_yade
def test_live_small_d2_run_agrees_with_yade(small_run, tmp_path):
    packing = small_run["dir"] / "checkpoints" / "unloading_phi0.720.txt"
    ours, yade = tmp_path / "ours.csv", tmp_path / "yade.csv"
    run_dem("mode", "--packing", packing, "--mode", "D2", "--rate-tc", 4e-5, "--eps-max", 0.06, "--quiet",
            "--set", "integration.integrator=symplectic_euler", "--set", "contact.background_damping_kg_s=0",
            "--set", "output.sample_strain=0.002", "--out", ours, check=True)
    run_yade("run_mode.py", "--packing", packing, "--mode", "D2", "--rate-tc", 4e-5, "--eps-max", 0.06,
             "--sample-strain", 0.002, "--out", yade)
    a, b = read_curve(ours), read_curve(yade)
    # Same packing, same definitions: the elastic energy agrees to round-off; p to 1e-5 (the
    # dashpot part of the first row sees each code's start-up velocity field, ~1e-4 of p).
    assert abs(a["E_pot_J"][0] / b["E_pot_J"][0] - 1) < 1e-9
    assert abs(a["p_Pa"][0] / b["p_Pa"][0] - 1) < 1e-5
    assert abs(a["F_dev"][0] - b["F_dev"][0]) < 1e-9 and a["C"][0] == b["C"][0]
    res, _ = compare(a, b)
    # 400 spheres are chaotic: two codes (or two integrators) follow different trajectories
    # from the first step, and the curves differ by the sample-to-sample spread of this small
    # packing (YADE vs ours on the three packings of this fixture: 0.007-0.031 in s_dev RMS,
    # 2-4 % in p). The tolerance is calibrated here, on this packing, by our own code with the
    # other integrator (velocity Verlet: as decorrelated as YADE's leapfrog is), times 4, with
    # floors. The physics itself is pinned by the first-row identities above.
    other = tmp_path / "ours_verlet.csv"
    run_dem("mode", "--packing", packing, "--mode", "D2", "--rate-tc", 4e-5, "--eps-max", 0.06, "--quiet",
            "--set", "integration.integrator=velocity_verlet", "--set", "contact.background_damping_kg_s=0",
            "--set", "output.sample_strain=0.002", "--out", other, check=True)
    self_res, _ = compare(a, read_curve(other))
    assert res["p_Pa"]["max_rel"] < max(0.03, 4 * self_res["p_Pa"]["max_rel"]), (res["p_Pa"], self_res["p_Pa"])
    assert res["s_dev"]["rms_abs"] < max(0.02, 4 * self_res["s_dev"]["rms_abs"]), (res["s_dev"], self_res["s_dev"])
    assert res["C"]["rms_abs"] < max(0.3, 4 * self_res["C"]["rms_abs"]), (res["C"], self_res["C"])


REF = os.path.join(ROOT, "data", "yade")


@pytest.mark.parametrize("mode,phi", [("D2", "0.690"), ("D2", "0.740"), ("D2", "0.800"), ("D3", "0.740")])
def test_current_runner_against_stored_yade_reference(mode, phi, tmp_path):
    # Our current code on the stored N = 9261 packing (first eps_d = 0.04, about 5 s), against
    # the stored YADE curve of the same packing and physics.
    stored = os.path.join(REF, f"yade_{mode}_phi{phi}.csv")
    if not os.path.exists(stored):
        pytest.skip(f"{stored} not generated (bash yade_ref/make_reference.sh)")
    ours = tmp_path / "ours.csv"
    run_dem("mode", "--packing", os.path.join(REF, f"packing_phi{phi}.txt"), "--mode", mode, "--rate-tc", 1e-4,
            "--eps-max", 0.04, "--quiet", "--set", "integration.integrator=symplectic_euler",
            "--set", "contact.background_damping_kg_s=0", "--set", "output.sample_strain=0.003",
            "--out", ours, check=True)
    a, b = read_curve(ours), read_curve(stored)
    assert abs(a["E_pot_J"][0] / b["E_pot_J"][0] - 1) < 1e-9
    assert abs(a["p_Pa"][0] / b["p_Pa"][0] - 1) < 1e-5
    res, _ = compare(a, b)
    assert res["p_Pa"]["max_rel"] < 0.01, res["p_Pa"]
    assert res["s_dev"]["rms_abs"] < 0.01, res["s_dev"]
    assert res["F_dev"]["rms_abs"] < 0.01, res["F_dev"]
    assert res["C"]["rms_abs"] < 0.05, res["C"]
