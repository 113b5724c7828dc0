"""Bad input: clear message, non-zero exit, nothing lost."""
import os

from conftest import run_dem, ROOT

PACKING = os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt")


def test_unknown_key_names_the_key(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[contact]\nstifness_N_m = 1e8\n")
    p = run_dem("run", scene, "--out", tmp_path / "o")
    assert p.returncode == 2
    assert "contact.stifness_N_m" in p.stderr and "stiffness_N_m" in p.stderr
    assert not (tmp_path / "o").exists(), "nothing may be written for a bad scene"


def test_bad_override_and_unstable_time_step(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[particles]\ncount = 300\n")
    p = run_dem("run", scene, "--out", tmp_path / "o", "--set", "integration.dt_over_tc=0.8")
    assert p.returncode == 2 and "stability limit" in p.stderr
    p = run_dem("info", scene, "--set", "particles.radius_min_m=-1")
    assert p.returncode == 2 and "radius_min_m must be positive" in p.stderr


def test_finished_results_are_not_overwritten(small_run):
    before = (small_run["dir"] / "deviatoric" / "D2_phi0.720.csv").read_bytes()
    p = run_dem("run", small_run["scene"], "--out", small_run["dir"], "--quiet")
    assert p.returncode != 0 and "--force" in p.stderr
    assert (small_run["dir"] / "deviatoric" / "D2_phi0.720.csv").read_bytes() == before
    p = run_dem("fit", small_run["dir"])
    assert p.returncode != 0 and "--force" in p.stderr


def test_blow_up_is_detected_and_the_last_good_state_kept(tmp_path):
    # A dense packing with a time step near the single-contact limit: in a packing the
    # effective stiffness is several contacts', so the integration diverges (without damping,
    # which would hold the growth to a transient).
    scene = tmp_path / "s.toml"
    scene.write_text(f'[particles]\npacking_file = "{PACKING}"\n[integration]\ndt_over_tc = 0.6\n'
                     "check_every_steps = 20\n[contact]\ndamping_kg_s = 0\nbackground_damping_kg_s = 0\n"
                     "[protocol]\ntarget_phi = 0.65\ncheckpoints_unloading = [0.7]\n")
    p = run_dem("run", scene, "--out", tmp_path / "o", "--quiet", timeout=300)
    assert p.returncode == 3, p.stderr[-2000:]
    assert "blew up" in p.stderr and "dt_over_tc" in p.stderr
    assert "near the stability limit" in p.stderr      # warned before it ran
    assert (tmp_path / "o" / "failed_relax.ckpt").exists()
    assert not (tmp_path / "o" / "prep" / "relax.csv").exists(), "a failed stage must not look complete"


def test_packing_outside_the_cell_is_refused(tmp_path):
    pack = tmp_path / "p.txt"
    pack.write_text("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.02 0.001\n0.005 0.005 0.005 0.001\n")
    scene = tmp_path / "s.toml"
    scene.write_text(f'[particles]\npacking_file = "{pack}"\n')
    p = run_dem("run", scene, "--out", tmp_path / "o", "--quiet")
    assert p.returncode == 1 and "outside the periodic cell" in p.stderr


def test_fast_shear_is_flagged_as_not_quasi_static(small_run, tmp_path):
    # Crossing the quasi-static boundary: at rate*t_c = 1e-3 the inertial number of the
    # nu = 0.69 packing exceeds 1e-3 and the runner says so; at 1e-5 it stays silent.
    packing = small_run["dir"] / "checkpoints" / "unloading_phi0.690.txt"
    fast = run_dem("mode", "--packing", packing, "--mode", "D2", "--rate-tc", 1e-3, "--eps-max", 0.01,
                   "--quiet", "--out", tmp_path / "fast.csv", check=True)
    assert "not quasi-static" in fast.stderr and "deviatoric_rate_tc" in fast.stderr
    slow = run_dem("mode", "--packing", packing, "--mode", "D2", "--rate-tc", 1e-5, "--eps-max", 0.01,
                   "--quiet", "--out", tmp_path / "slow.csv", check=True)
    assert "not quasi-static" not in slow.stderr


def test_fit_map_writes_one_row_per_cell_and_never_overwrites(tmp_path):
    out = tmp_path / "map.csv"
    args = ("fit-map", "--out", out, "--lengths", "1", "8", "--noises", "0.01", "--correlations", "0", "0.5",
            "--trials", "10")
    run_dem(*args, check=True)
    rows = [r for r in out.read_text().splitlines() if not r.startswith("#")]
    assert rows[0].startswith("length_beta_eps,noise_over_amplitude,noise_correlation,beta_rel_error_median")
    assert len(rows) == 1 + 2 * 2
    # the saturated, low-noise cell recovers beta to a few percent
    cells = {tuple(r.split(",")[:3]): r.split(",") for r in rows[1:]}
    assert float(cells[("8", "0.01", "0")][3]) < 0.05
    p = run_dem(*args)
    assert p.returncode == 1 and "exists" in p.stderr
    p = run_dem("fit-map", "--out", tmp_path / "bad.csv", "--correlations", "1.0", "--trials", "5")
    assert p.returncode == 1 and "correlation must be in [0, 1)" in p.stderr
    assert not (tmp_path / "bad.csv").exists()
