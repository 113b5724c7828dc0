"""YADE cross-checks: live runs (YADE is installed by scripts/setup.sh) and stored references."""
import glob
import itertools
import json
import os
import shutil
import subprocess

import numpy as np
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


SHEAR = os.path.join(ROOT, "data", "yade_shear")


@needs_yade
def test_live_simple_shear_start_agrees_with_yade(tmp_path):
    # SS_xz (v_x = 2 r z) from the stored N = 1000 packing, in both codes, for the first ~3500
    # steps: an off-diagonal O.cell.velGrad in YADE, our tilted cell. Same first row (the packing
    # as loaded), the same strain path (eps_d = sqrt(3) asinh(gamma/2), gamma = 2 r t), the same
    # sign convention for the shear stress, and early curves within a few % (before chaos).
    packing = os.path.join(SHEAR, "packing_phi0.740.txt")
    ours, yade = tmp_path / "ours.csv", tmp_path / "yade.csv"
    run_dem("mode", "--scene", os.path.join(SHEAR, "scene.toml"), "--packing", packing, "--mode", "SS_xz",
            "--eps-max", 0.012, "--quiet", "--out", ours, check=True)
    # --r-min: t_c (so dt and the rate) from the scene's radius_min_m, as ours, not the packing's smallest
    run_yade("run_mode.py", "--packing", packing, "--mode", "SS_xz", "--rate-tc", 1e-4, "--eps-max", 0.012,
             "--r-min", 5e-4, "--sample-strain", 0.002, "--out", yade)
    a, b = read_curve(ours), read_curve(yade)
    assert abs(a["E_pot_J"][0] / b["E_pot_J"][0] - 1) < 1e-9
    assert abs(a["p_Pa"][0] / b["p_Pa"][0] - 1) < 1e-5
    assert abs(a["F_dev"][0] - b["F_dev"][0]) < 1e-9 and a["C"][0] == b["C"][0]
    # Both strains are the log strain of F = [[1, 0, gamma], [0, 1, 0], [0, 0, 1]] (YADE's O.cell.trsf):
    # eps_d = sqrt(3) asinh(gamma/2), eps_xz = asinh(gamma/2) / sqrt(1 + gamma^2/4), eps_v = 0
    t_c = float([ln for ln in open(yade) if ln.startswith("# t_c=")][0].split("=")[1].split()[0])
    # (ours' last row lands on eps_max exactly, not on a whole step: rows before it)
    for c in (a, b):
        gamma = 2 * 1e-4 / t_c * c["time_s"][:-1]
        beta = np.arcsinh(gamma / 2)
        assert abs(c["eps_d"][:-1] - 3 ** 0.5 * beta).max() < 1e-8
        assert abs(c["eps_xz"][:-1] - beta / np.sqrt(1 + gamma ** 2 / 4)).max() < 1e-8
        assert abs(c["eps_v"]).max() < 1e-12
    # the shear stress builds up with the same sign (compression positive: sigma_xz < 0 for v_x = 2 r z)
    assert a["sigma_xz_Pa"][-1] < 0 and b["sigma_xz_Pa"][-1] < 0
    assert abs(a["sigma_xz_Pa"][-1] / b["sigma_xz_Pa"][-1] - 1) < 0.1
    res, _ = compare(a, b)
    assert res["p_Pa"]["max_rel"] < 0.01, res["p_Pa"]
    assert res["s_dev"]["rms_abs"] < 0.01, res["s_dev"]


def test_current_runner_against_stored_yade_simple_shear(tmp_path):
    # Our current code on the stored packing, SS_xz to eps_d = 0.04, against the stored YADE curve
    # (data/yade_shear/README.md): same start, and the start of the curves (before the trajectories
    # separate) within a few times what our own dt x 1.001 rerun gives there.
    stored = os.path.join(SHEAR, "yade_SS_xz_phi0.740.csv")
    ours = tmp_path / "ours.csv"
    run_dem("mode", "--scene", os.path.join(SHEAR, "scene.toml"), "--packing", os.path.join(SHEAR, "packing_phi0.740.txt"),
            "--mode", "SS_xz", "--eps-max", 0.04, "--quiet", "--out", ours, check=True)
    a, b = read_curve(ours), read_curve(stored)
    assert abs(a["E_pot_J"][0] / b["E_pot_J"][0] - 1) < 1e-9
    assert abs(a["p_Pa"][0] / b["p_Pa"][0] - 1) < 1e-5
    res, _ = compare(a, b)
    # measured when stored: p 3e-4, s_dev 4e-4, F_dev 3.4e-3, C 0.006 (dt x 1.001 of ours: 1e-4, 1e-4, 2e-3, 0.005)
    assert res["p_Pa"]["max_rel"] < 0.003, res["p_Pa"]
    assert res["s_dev"]["rms_abs"] < 0.003, res["s_dev"]
    assert res["F_dev"]["rms_abs"] < 0.01, res["F_dev"]
    assert res["C"]["rms_abs"] < 0.03, res["C"]


def test_compare_reads_sheared_curves_and_writes_json(tmp_path):
    # The sheared curves of both codes carry the objective forms in eps_d, s_dev, F_dev, so
    # `dem compare` takes them as they are; --json used to fail on numpy bools in the verdict.
    a = os.path.join(SHEAR, "ours_SS_xz_dt0.02.csv")
    b = os.path.join(SHEAR, "yade_SS_xz_phi0.740.csv")
    out = tmp_path / "cmp.json"
    p = run_dem("compare", a, b, "--json", out)
    assert p.returncode in (0, 4), p.stderr
    res = json.loads(out.read_text())
    assert res["eps_d_range"][1] > 0.29 and res["coverage"] > 0.99
    assert all(isinstance(v["ok"], bool) for v in res["verdict"].values())
    assert (p.returncode == 0) == all(v["ok"] for v in res["verdict"].values())
    p = run_dem("compare", a, b, "--json", out, "--tol-p", 1e-9)       # a failing verdict is written too
    assert p.returncode == 4 and json.loads(out.read_text())["verdict"]["p_Pa"]["ok"] is False


FRIC = os.path.join(ROOT, "data", "yade_friction")


@needs_yade
@pytest.mark.parametrize("angle,r2", [(30, 5e-4), (80, 5e-4), (45, 1.5e-3)])
def test_oblique_impact_with_friction_yade_equals_ours(angle, r2):
    # Two spheres meet at `angle` from the line of centres, mu = 0.5, k_t = 2/7 k: ViscElMat with
    # ks = 2 k_t, frictionAngle = atan(mu) in YADE (a free pair: no periodic shift velocity), `dem collide
    # --angle-deg` in ours, the same dt and leapfrog. Measured when written: the same e_n, e_t and spins to
    # 12 digits at 10-80 deg and w = 1, 3 (data/yade_friction/oblique*.csv). 30 and 45 deg stick (Maw's
    # regime, e_t near 3/7 at k_t/k = 2/7), 80 deg slides (e_t = 1 - mu (1 + e_n) / tan(theta)).
    ours = json.loads(run_dem("collide", "--angle-deg", angle, "--r2", r2, "--set", "contact.friction=0.5",
                              "--set", "integration.integrator=symplectic_euler", "--set", "integration.dt_over_tc=0.002",
                              check=True).stdout)
    p = run_yade("collision.py", "--angle-deg", angle, "--r2", r2, "--friction", 0.5, "--dt", repr(ours["dt_s"]))
    yade = json.loads([ln for ln in p.stdout.splitlines() if ln.startswith("{")][-1])
    assert yade["pair_checked"]
    for k in ("normal_restitution", "tangential_restitution", "omega0_y_rad_s", "omega1_y_rad_s", "tangential_impulse_Ns"):
        assert abs(yade[k] / ours[k] - 1) < 1e-8, (k, yade[k], ours[k])
    e_n, e_t = ours["normal_restitution"], ours["tangential_restitution"]
    t = np.tan(np.radians(angle))
    if t > 3.5 * 0.5 * (1 + e_n):                       # gross sliding: rigid-body theory (finite stiffness: 0.1 %)
        assert abs(e_t - (1 - 0.5 * (1 + e_n) / t)) < 2e-3
    else:
        assert 0.3 < e_t < 0.75 and ours["omega1_y_rad_s"] > 0


# `dem compare`'s checked measures, and YADE's distance allowed in units of the largest ours-ours distance:
# about 1.2x the ratio measured when stored (data/yade_friction/summary.md; ours regenerated in December 2026
# with the dead-beat servo). Below 1.5: within our chaos floor (D2: p, F_dev, C, sliding fraction; triax:
# F_dev, C, sliding fraction). Above: the systematic offsets docs/yade.md reports (YADE's s_dev +0.8 % in D2
# (2.65x), p +0.5 % and s_dev +1.5 % under constant side stress (10x, 7x), where our dt-perturbed runs
# separate little), pinned so that a change in either code shows.
CHECKED = [("p_Pa", "max_rel"), ("s_dev", "rms_rel"), ("F_dev", "rms_rel"), ("C", "rms_abs"), ("sliding_fraction", "rms_abs")]
MARGIN = {"D2": {"p_Pa": 1.5, "s_dev": 3.2, "F_dev": 1.5, "C": 1.5, "sliding_fraction": 1.5},
          "triax": {"p_Pa": 13, "s_dev": 8.5, "F_dev": 1.5, "C": 1.5, "sliding_fraction": 1.5, "eps_v": 9}}


def _distances(a, b):
    res, grid = compare(a, b)
    d = np.interp(grid, b["eps_d"], b["sliding_fraction"]) - np.interp(grid, a["eps_d"], a["sliding_fraction"])
    res["sliding_fraction"] = {"rms_abs": float(np.sqrt(np.mean(d * d)))}
    return res


def _floor(mode, folder=FRIC):
    ours = [read_curve(f) for f in [os.path.join(folder, f"ours_{mode}_dt0.04.csv")] +
            sorted(glob.glob(os.path.join(folder, f"perturbed_{mode}_dt*.csv")))]
    return ours, read_curve(os.path.join(folder, f"yade_{mode}_phi0.700.csv"))


# Hertz-Mindlin (data/yade_hm, docs/contact_models.md): the same packing and method; YADE's distance over
# the largest ours-ours one, about 1.2x that measured when stored (summary.md there). Under constant side
# stress the floor has not decorrelated at this strain (ours-ours 0.1 % in p): the offsets are systematic.
HM_MARGIN = {"D2": {"p_Pa": 2.0, "s_dev": 3.0, "F_dev": 1.5, "C": 1.5, "sliding_fraction": 1.5},
             "triax": {"p_Pa": 6.5, "s_dev": 13, "F_dev": 1.8, "C": 1.6, "sliding_fraction": 2.7, "eps_v": 8.5}}


def _yade_against_floor(mode, folder, margin):
    """The stored YADE curve of `folder` against the stored spread of our own dt-perturbed runs: the same
    packing as loaded; then YADE's distance to our run is within the largest ours-ours distance, times a
    margin for a floor of 6 runs. Returns (ours, yade, YADE's distances)."""
    ours, yade = _floor(mode, folder)
    assert len(ours) >= 5
    assert abs(ours[0]["E_pot_J"][0] / yade["E_pot_J"][0] - 1) < 1e-9
    assert abs(ours[0]["p_Pa"][0] / yade["p_Pa"][0] - 1) < 1e-5
    assert ours[0]["C"][0] == yade["C"][0]
    checked = CHECKED + ([("eps_v", "rms_abs")] if mode == "triax" else [])
    pairs = [_distances(a, b) for a, b in itertools.permutations(ours, 2)]
    floor = {q: max(r[q][k] for r in pairs) for q, k in checked}
    res = _distances(ours[0], yade)
    for q, k in checked:
        assert res[q][k] < margin[mode][q] * floor[q], (q, res[q][k], floor[q])
    return ours, yade, res


@pytest.mark.parametrize("mode", ["D2", "triax"])
def test_stored_hertz_mindlin_reference_against_our_floor(mode):
    _, _, res = _yade_against_floor(mode, os.path.join(ROOT, "data", "yade_hm"), HM_MARGIN)
    # the plateaus within 0.5 % in p and s_dev, and inside `dem compare`'s default tolerances by 5x
    assert res["p_Pa"]["max_rel"] < 0.006 and res["s_dev"]["rms_rel"] < 0.03 and res["F_dev"]["rms_rel"] < 0.05
    assert res["C"]["rms_abs"] < 0.03 and res["eps_v"]["rms_abs"] < 1e-4


@pytest.mark.parametrize("mode", ["D2", "triax"])
def test_stored_friction_reference_against_our_floor(mode):
    # data/yade_friction (docs/yade.md, "Friction")
    ours, yade, res = _yade_against_floor(mode, FRIC, MARGIN)
    # and within `dem compare`'s default tolerances (docs/yade.md)
    assert res["p_Pa"]["max_rel"] < 0.03 and res["s_dev"]["rms_rel"] < 0.15 and res["F_dev"]["rms_rel"] < 0.25
    assert res["C"]["rms_abs"] < 0.15 and res["eps_v"]["rms_abs"] < 5e-4
    if mode == "D2":
        assert abs(yade["eps_v"]).max() < 1e-6          # constant volume (YADE's linear cell update: 1.5e-7)
    else:                                                # the frictional packing compacts under side stress
        assert ours[0]["eps_v"][-1] < -0.01 and yade["eps_v"][-1] < -0.01


def test_current_runner_reproduces_stored_frictional_curve(tmp_path):
    # The floor above was measured on curves of ours stored with the friction engine of the time: the current
    # engine gives the same rows, bit for bit, on the first eps_d = 0.01 of D2 (1444 steps, about a second).
    ours = tmp_path / "ours.csv"
    run_dem("mode", "--scene", os.path.join(FRIC, "scene.toml"), "--packing", os.path.join(FRIC, "packing_phi0.700.txt"),
            "--mode", "D2", "--rate-tc", 1e-4, "--eps-max", 0.01, "--quiet", "--out", ours, check=True)
    a, b = read_curve(ours), read_curve(os.path.join(FRIC, "ours_D2_dt0.04.csv"))
    for q in ("p_Pa", "s_dev", "F_dev", "C", "sliding_fraction", "E_rot_J", "E_t_J", "W_friction_J"):
        assert np.array_equal(a[q][:5], b[q][:5]), q
