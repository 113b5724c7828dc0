"""Friction end to end: a frictional scene through the protocol, its columns and physics record,
and what friction must do to the response (independent expectations, not stored outputs)."""
import os

import numpy as np
import pytest

from conftest import ROOT, run_dem
from demkit.curves import read_curve

SCENE = os.path.join(ROOT, "data", "scenes", "friction_example.toml")
SMALL = ["--set", "particles.count=300", "--set", "protocol.checkpoints_unloading=[0.72]",
         "--set", 'protocol.modes=["D2"]', "--set", "protocol.eps_d_max=0.25"]
FRICTION_COLUMNS = ["sliding_fraction", "E_rot_J", "omega_mean_rad_s", "E_t_J", "W_friction_J", "sigma_antisym_rel"]


@pytest.fixture(scope="module")
def rough_and_smooth(tmp_path_factory):
    d = tmp_path_factory.mktemp("friction")
    rough, smooth = d / "rough", d / "smooth"
    run_dem("run", SCENE, "--out", rough, "--quiet", *SMALL, "--set", "output.vtk=true", check=True)
    run_dem("run", SCENE, "--out", smooth, "--quiet", *SMALL, "--set", "contact.friction=0",
            "--set", 'contact.tangential="none"', check=True)
    return rough, smooth


def test_frictional_curves_have_the_friction_columns_and_record(rough_and_smooth):
    rough, smooth = rough_and_smooth
    c = read_curve(rough / "deviatoric" / "D2_phi0.720.csv")
    for name in FRICTION_COLUMNS:
        assert name in c, name
    text = (rough / "deviatoric" / "D2_phi0.720.csv").read_text()
    assert "contact.friction=0.5" in text and "# contact tangential: cundall_strack, Cundall-Strack" in text
    assert 0 <= c["sliding_fraction"].min() and c["sliding_fraction"].max() <= 1
    assert np.all(np.diff(c["W_friction_J"]) >= 0)          # dissipation only accumulates
    assert c["W_friction_J"][-1] > c["W_friction_J"][0]      # shear slides contacts
    assert np.all(c["E_t_J"] <= c["E_pot_J"] + 1e-12)        # the springs are part of E_pot
    # Quasi-static: the torques balance, the contact stress is symmetric to a small fraction of p.
    assert np.median(c["sigma_antisym_rel"]) < 1e-2
    s = read_curve(smooth / "deviatoric" / "D2_phi0.720.csv")
    for name in FRICTION_COLUMNS:
        assert name not in s, name                           # frictionless columns unchanged
    physics = [l for l in (smooth / "deviatoric" / "D2_phi0.720.csv").read_text().splitlines() if l.startswith("# physics")]
    assert physics and "friction" not in physics[0]          # a frictionless record keeps its old keys


def test_friction_raises_the_stress_ratio_and_lowers_the_coordination(rough_and_smooth):
    """Frictional packs carry more shear (macroscopic friction grows with mu) and need fewer
    contacts per particle (isostatic: 6 frictionless, towards 4 with friction)."""
    rough, smooth = rough_and_smooth
    r = read_curve(rough / "deviatoric" / "D2_phi0.720.csv")
    s = read_curve(smooth / "deviatoric" / "D2_phi0.720.csv")
    late_r = r["s_dev"][r["eps_d"] > 0.15].mean()
    late_s = s["s_dev"][s["eps_d"] > 0.15].mean()
    assert late_r > 1.5 * late_s, (late_r, late_s)
    assert r["C_nonrattler"][0] < s["C_nonrattler"][0]


def test_a_frictional_run_resumes_and_fits(rough_and_smooth, tmp_path):
    rough, _ = rough_and_smooth
    fit = run_dem("fit", rough)
    assert fit.returncode == 0, fit.stderr[-2000:]
    assert (rough / "fit" / "parameters.csv").exists()
    # The deviatoric stage again from the same checkpoint gives the same bytes (history and
    # rotations are in the checkpoint).
    again = tmp_path / "again.csv"
    run_dem("mode", "--packing", rough / "checkpoints" / "unloading_phi0.720.ckpt", "--scene", rough / "scene.toml",
            "--mode", "D2", "--out", again, "--threads", "1", check=True)
    def rows(path):   # every column but the stage label (D2_phi0.720 in a run, D2 in dem mode)
        return [l.rsplit(",", 1)[0] for l in path.read_text().splitlines() if not l.startswith("#")]
    ref, got = rows(rough / "deviatoric" / "D2_phi0.720.csv"), rows(again)
    assert len(got) == len(ref) > 10 and got == ref


def test_friction_keys_are_checked():
    bad = run_dem("info", SCENE, "--set", "contact.friction=-1")
    assert bad.returncode == 2 and "contact.friction" in bad.stderr
    bad = run_dem("info", SCENE, "--set", 'contact.tangential="none"')
    assert bad.returncode == 2 and "cundall_strack" in bad.stderr
    ok = run_dem("info", SCENE, check=True)
    assert "Cundall-Strack" in ok.stdout


def test_the_vtk_contact_network_carries_the_tangential_forces(rough_and_smooth):
    rough, _ = rough_and_smooth
    nets = sorted((rough / "vtk").glob("D2_phi0.720_contacts_*.vtu"))
    assert nets, sorted(p.name for p in (rough / "vtk").iterdir())[:10]
    head = nets[-1].read_bytes().split(b"<AppendedData")[0].decode()
    assert 'Name="tangential_force_N"' in head and 'Name="sliding"' in head


def test_python_views_of_the_spins_and_the_frictional_contact_forces(rough_and_smooth):
    import sys
    sys.path.insert(0, os.path.join(ROOT, "build", "python"))
    import demtk
    rough, _ = rough_and_smooth
    scene = demtk.load_scene(str(rough / "scene.toml"), set={"integration.threads": 1})
    state = demtk.read_checkpoint(str(rough / "checkpoints" / "unloading_phi0.720.ckpt")).state
    eng = demtk.Engine(scene, state)
    w = state.angular_velocities
    assert w.shape == (state.count, 3) and np.isfinite(w).all() and np.abs(w).max() > 0
    eng.step(10)
    assert np.shares_memory(w, state.angular_velocities)
    c = eng.contacts()
    tangential = c["force"] - c["normal"] * c["force_normal"][:, None]
    assert np.abs(tangential).max() > 1e-3 * np.abs(c["force_normal"]).max()   # friction carries load
