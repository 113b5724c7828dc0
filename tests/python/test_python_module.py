"""demtk, the Python module over the engine (python/, docs/python.md): the same bits as the CLI,
numpy views that alias the engine's memory, errors as exceptions with the CLI's messages,
callbacks that stop a run, the GIL released while stepping, the examples."""
import json
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from conftest import DEM, ROOT, run_dem

sys.path.insert(0, os.path.join(ROOT, "build", "python"))
import demtk  # noqa: E402

# 200 spheres prepared in a few seconds; one thread (the bits do not depend on it, but the CLI
# comparison below pins it anyway).
TINY = """
[particles]
count = 200
seed = 5
[integration]
threads = 1
[protocol]
target_phi = 0.64
compress_rate_tc = 1e-3
cycle_rate_tc = 1e-4
cycle_phi_max = 0.70
checkpoints_unloading = [0.68]
modes = ["D2", "D3"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.03
relax_max_time_tc = 2e3
[output]
sample_strain = 0.002
vtk = false
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("demtk")
    scene = d / "tiny.toml"
    scene.write_text(TINY)
    run_dem("run", scene, "--out", d / "run", "--stages", "prep", "--quiet", check=True)
    ckpt = d / "run" / "checkpoints" / "unloading_phi0.680.ckpt"
    assert ckpt.exists()
    return {"dir": d, "scene": scene, "ckpt": ckpt, "txt": ckpt.with_suffix(".txt")}


def data_rows(path):
    """The CSV's data rows keyed by step, without the stage column."""
    rows = [ln for ln in open(path).read().splitlines() if ln and not ln.startswith("#")][1:]
    return {int(r.split(",")[0]): r.rsplit(",", 1)[0] for r in rows}


# ---- the same bits as the CLI ------------------------------------------------------------------

def test_stepped_engine_equals_dem_mode(tiny):
    out = tiny["dir"] / "cli_D2.csv"
    run_dem("mode", "--scene", tiny["scene"], "--packing", tiny["ckpt"], "--mode", "D2", "--threads", 1,
            "--out", out, "--quiet", check=True)
    cli = data_rows(out)
    steps = sorted(cli)
    assert len(steps) >= 10
    scene = demtk.load_scene(tiny["scene"], set={"integration.threads": 1})
    state = demtk.read_checkpoint(tiny["ckpt"]).state
    state.zero_strain()                      # as every stage runner does at its start
    eng = demtk.Engine(scene, state)
    L = scene.velocity_gradient("D2")
    np.testing.assert_array_equal(L, np.diag([1.0, 0.0, -1.0]) * scene.deviatoric_rate)
    assert eng.measure(L).row() == cli[steps[0]]
    # every row but the last (whose step is shortened to land on eps_d_max) from plain steps
    for s in steps[1:-1]:
        eng.step(s - state.step, velocity_gradient=L)
        assert eng.measure().row() == cli[s], f"step {s}"
    assert eng.list_builds > 1


def test_run_mode_and_checkpoints_equal_the_cli_byte_for_byte(tiny, tmp_path):
    scene = demtk.load_scene(tiny["scene"], set={"integration.threads": 1, "protocol.modes": ["D3"]})
    cli = tmp_path / "cli.csv"
    run_dem("mode", "--scene", tiny["scene"], "--packing", tiny["ckpt"], "--mode", "D3", "--threads", 1,
            "--out", cli, "--quiet", check=True)
    state = demtk.read_checkpoint(tiny["ckpt"]).state
    ours = tmp_path / "py.csv"
    steps = demtk.run_mode(scene, state, "D3", str(ours))
    assert steps > 100 and ours.read_bytes() == cli.read_bytes()
    assert not os.path.exists(str(ours) + ".part")
    with pytest.raises(RuntimeError, match="force=True"):
        demtk.run_mode(scene, demtk.read_checkpoint(tiny["ckpt"]).state, "D3", str(ours))

    # A state stepped in Python, saved as a checkpoint: the CLI continues from it exactly as
    # Python does; and the reverse (CLI checkpoint -> Python) is the test above.
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    eng = demtk.Engine(scene, st)
    eng.step(500, velocity_gradient=scene.velocity_gradient("D2", rate=0.5 * scene.deviatoric_rate))
    saved = tmp_path / "py.ckpt"
    st.save_checkpoint(str(saved), scene, "after 500 steps in Python")
    back = demtk.read_checkpoint(saved)
    assert back.label == "after 500 steps in Python" and back.scene_toml == scene.toml
    np.testing.assert_array_equal(back.state.positions, st.positions)
    cli2 = tmp_path / "cli2.csv"
    run_dem("mode", "--scene", tiny["scene"], "--packing", saved, "--mode", "D3", "--threads", 1,
            "--out", cli2, "--quiet", check=True)
    py2 = tmp_path / "py2.csv"
    demtk.run_mode(scene, st, "D3", str(py2))
    assert py2.read_bytes() == cli2.read_bytes()


def test_run_protocol_equals_dem_run(tiny, tmp_path):
    run_dem("run", tiny["scene"], "--out", tmp_path / "cli", "--quiet", check=True)
    demtk.run_protocol(demtk.load_scene(tiny["scene"]), str(tmp_path / "py"))
    files = sorted(p.relative_to(tmp_path / "cli") for p in (tmp_path / "cli").rglob("*")
                   if p.is_file() and p.name not in ("manifest.json",))
    assert any(f.suffix == ".ckpt" for f in files) and any(f.parts[0] == "deviatoric" for f in files)
    for f in files:
        assert (tmp_path / "py" / f).read_bytes() == (tmp_path / "cli" / f).read_bytes(), f


# A preparation list with a stress-controlled stage (a one-stage path) between two strain stages.
PRESS = """
[particles]
count = 200
seed = 4
[integration]
threads = 1
[protocol]
initial_phi = 0.3
preparation = [
  { name = "gas", kind = "compress", rate_tc = 1e-3, until = { phi = 0.5 }, checkpoint_name = "gas", checkpoints = [0.4, 0.5] },
  { name = "press", kind = "pressure", target_Pa = 1e5, rate_tc = 1e-3, until = { ke_ratio = 1e-3 }, max_time_tc = 200, checkpoint_name = "pressed" },
  { name = "relax", kind = "relax", until = { ke_ratio = 1e-4 }, max_time_tc = 100 },
]
modes_from = "pressed"
modes = ["D2"]
[output]
vtk = false
"""


def test_every_preparation_stage_from_python_is_dem_runs_byte_for_byte(tmp_path):
    # One runner for both doors (run_prep_stage): compress with checkpoints at its end and on the
    # way, a stress-controlled stage (refused from Python before the runner was shared), a relax.
    path = tmp_path / "press.toml"
    path.write_text(PRESS)
    run_dem("run", path, "--out", tmp_path / "cli", "--stages", "prep", "--quiet", check=True)
    scene = demtk.load_scene(path)
    state = demtk.random_packing(scene, 0.3)
    saved = []
    for name in scene.preparation:
        out = tmp_path / f"{name}.csv"
        demtk.run_prep_stage(scene, state, name, str(out), on_checkpoint=lambda phi, st: saved.append((phi, st)))
        assert out.read_bytes() == (tmp_path / "cli" / "prep" / f"{name}.csv").read_bytes(), name
    cli = sorted((tmp_path / "cli" / "checkpoints").glob("*.ckpt"))
    assert [p.stem for p in cli] == sorted(f"{s}_phi{phi:.3f}" for s, (phi, _) in
                                           zip(["gas", "gas", "pressed"], saved))
    for p in cli:
        phi = float(p.stem.split("_phi")[1])
        st = next(st for q, st in saved if f"{q:.3f}" == f"{phi:.3f}")
        np.testing.assert_array_equal(st.positions, demtk.read_checkpoint(p).state.positions)
    np.testing.assert_array_equal(state.positions,
                                  demtk.read_checkpoint(tmp_path / "cli" / "prep" / "after_relax.ckpt").state.positions)


# ---- scenes ------------------------------------------------------------------------------------

def test_scene_from_dict_equals_the_file_and_derived_quantities(tiny):
    import tomllib
    d = tomllib.loads(TINY)
    a = demtk.load_scene(tiny["scene"], set={"contact.damping_kg_s": 0.5})
    b = demtk.load_scene(d, set={"contact.damping_kg_s": 0.5})
    c = demtk.load_scene(tiny["scene"], set=["contact.damping_kg_s=0.5"])   # the CLI's spelling
    assert a.toml == b.toml == c.toml
    assert a["contact.damping_kg_s"] == 0.5 and a.damping == 0.5
    assert a.to_dict()["particles"]["count"] == 200 and a.count == 200
    assert a.dt == pytest.approx(a.t_c * a["integration.dt_over_tc"], rel=1e-15)
    assert a.deviatoric_rate == pytest.approx(a["protocol.deviatoric_rate_tc"] / a.t_c, rel=1e-15)
    assert a.compress_rate == pytest.approx(a["protocol.compress_rate_tc"] / a.t_c, rel=1e-15)
    assert 0 < a.e < 1 and a.modes == ["D2", "D3"]
    info = run_dem("info", tiny["scene"], "--set", "contact.damping_kg_s=0.5", check=True).stdout
    assert f"t_c = {a.t_c:g} s, e = {a.e:g}" in info and f"dt = {a.dt:g} s" in info
    assert f"deviatoric rate {a.deviatoric_rate:.4g} /s" in info
    plan = json.loads(run_dem("info", tiny["scene"], "--json", check=True).stdout)
    assert plan["mode_particle_steps"]["D2"] == pytest.approx(200 * a.mode_steps("D2"), rel=1e-15)


@pytest.mark.parametrize("body,override", [
    ("[contact]\nstifness_N_m = 1e8\n", None),                      # unknown key
    ("[particles]\ncount = 300\n", "integration.dt_over_tc=0.8"),   # beyond the stability limit
    ("[particles]\ncount = 300\n", "particles.radius_min_m=-1"),    # impossible value
    ("[particles\ncount = 300\n", None),                            # TOML syntax
])
def test_scene_errors_carry_the_cli_message(tmp_path, body, override):
    scene = tmp_path / "s.toml"
    scene.write_text(body)
    args = ["info", scene] + (["--set", override] if override else [])
    p = run_dem(*args)
    assert p.returncode == 2 and p.stderr.startswith("dem: scene error: ")
    cli_message = p.stderr[len("dem: scene error: "):].rstrip("\n")
    with pytest.raises(demtk.SceneError) as e:
        demtk.load_scene(scene, set=[override] if override else None)
    assert str(e.value) == cli_message
    assert isinstance(e.value, ValueError)


def test_scene_dict_errors_name_the_key():
    with pytest.raises(demtk.SceneError, match="contact.dampin.*damping_kg_s"):
        demtk.load_scene({"contact": {"dampin": 1.0}})
    with pytest.raises(demtk.SceneError, match="must be a section"):
        demtk.load_scene({"count": 3})
    with pytest.raises(demtk.SceneError, match="protocol.modes"):
        demtk.run_mode(demtk.load_scene(), demtk.State.from_arrays([[0, 0, 0], [1, 1, 1]], [0.5e-3, 0.5e-3],
                                                                   [3, 3, 3], density=2000), "D9", "x.csv")


def test_unreadable_and_malformed_files_carry_the_cli_message(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.02 0.001\n0.005 0.005 0.005 0.001\n")
    p = run_dem("mode", "--packing", bad, "--out", tmp_path / "o.csv")
    assert p.returncode == 1 and "outside the periodic cell" in p.stderr
    cli_message = p.stderr.strip().splitlines()[-1][len("dem: error: "):]
    with pytest.raises(RuntimeError) as e:
        demtk.read_packing(str(bad), 2000.0)
    assert str(e.value) == cli_message
    junk = tmp_path / "junk.ckpt"
    junk.write_bytes(b"not a checkpoint")
    p = run_dem("mode", "--packing", junk, "--out", tmp_path / "o.csv")
    assert p.returncode == 1
    with pytest.raises(RuntimeError) as e:
        demtk.read_checkpoint(junk)
    assert str(e.value) in p.stderr
    with pytest.raises(RuntimeError, match="cannot|No such|missing"):
        demtk.read_checkpoint(tmp_path / "absent.ckpt")
    assert not (tmp_path / "o.csv").exists()


def test_blow_up_raises_with_the_cli_message_and_the_last_good_state(tiny, tmp_path):
    bad = ["integration.dt_over_tc=0.6", "integration.check_every_steps=20", "contact.damping_kg_s=0",
           "contact.background_damping_kg_s=0", "protocol.eps_d_max=0.3"]
    cli = tmp_path / "cli.csv"
    p = run_dem("mode", "--scene", tiny["scene"], "--packing", tiny["ckpt"], "--mode", "D2", "--out", cli,
                "--quiet", *[a for s in bad for a in ("--set", s)])
    assert p.returncode == 3, p.stderr[-2000:]
    scene = demtk.load_scene(tiny["scene"], set=bad)
    ours = tmp_path / "py.csv"
    with pytest.raises(demtk.BlowUp) as e:
        demtk.run_mode(scene, demtk.read_checkpoint(tiny["ckpt"]).state, "D2", str(ours))
    assert str(e.value).replace(str(ours), "OUT") in p.stderr.replace(str(cli), "OUT")
    assert "dt_over_tc" in str(e.value)
    assert e.value.checkpoint == str(ours) + ".failed.ckpt" and os.path.exists(e.value.checkpoint)
    assert not ours.exists() and isinstance(e.value, RuntimeError)

    # Stepping: the exception carries the state at the last callback (or at the call).
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    st.zero_strain()
    eng = demtk.Engine(scene, st)
    start = st.step
    with pytest.raises(demtk.BlowUp) as e:
        eng.step(100000, velocity_gradient=scene.velocity_gradient("D2"), callback=lambda en: None, every=50)
    good = e.value.last_good_state
    assert isinstance(good, demtk.State) and (good.step - start) % 50 == 0 and start < good.step < st.step
    assert np.isfinite(good.positions).all()


# ---- state as numpy ----------------------------------------------------------------------------

def test_views_alias_memory_and_keep_ids_across_resorts(tiny):
    scene = demtk.load_scene(tiny["scene"])
    st = demtk.read_packing(str(tiny["txt"]), scene.density)   # no list yet: the engine sorts the rows
    x_file, r_file, m_file = st.positions.copy(), st.radii.copy(), st.masses.copy()
    L_file = st.box.lengths
    np.testing.assert_array_equal(st.ids, np.arange(200))
    pos, vel, rad, ids, mass, frc = st.positions, st.velocities, st.radii, st.ids, st.masses, st.forces
    for a in (pos, rad, ids, mass, frc):
        assert not a.flags.writeable
        with pytest.raises(ValueError):
            a[0] = 1
    assert pos.shape == (200, 3) and pos.dtype == np.float64 and ids.dtype == np.int32
    eng = demtk.Engine(scene, st)
    assert not np.array_equal(ids, np.arange(200)), "the engine's cell sort permuted the rows"
    L = scene.velocity_gradient("D2", rate=5 * scene.deviatoric_rate)
    builds, orders = eng.list_builds, {ids.tobytes()}
    for _ in range(20):
        eng.step(100, velocity_gradient=L)
        orders.add(ids.tobytes())
        # the views taken before any step are still the engine's memory
        assert np.shares_memory(pos, st.positions) and np.shares_memory(ids, st.ids)
        assert pos.shape == (200, 3) and ids.shape == (200,)
        np.testing.assert_array_equal(st.by_id(rad), r_file)
        np.testing.assert_array_equal(st.by_id(mass), m_file)
    assert eng.list_builds > builds + 3 and len(orders) > 1, "re-sorts happened"
    assert sorted(ids) == list(range(200))
    # each particle's fractional coordinates moved by its small fluctuation only (box affine, wrapped)
    ds = st.by_id(pos) / st.box.lengths - x_file / L_file
    assert np.abs(ds - np.round(ds)).max() < 0.1
    np.testing.assert_array_equal(frc, st.forces)
    # a write through the velocity view is the engine's state
    vel[:] = 0.0
    vel[3] = (1e-3, -2e-3, 0.5e-3)
    np.testing.assert_array_equal(st.velocities[3], [1e-3, -2e-3, 0.5e-3])
    assert st.kinetic_energy == pytest.approx(0.5 * mass[3] * (1 + 4 + 0.25) * 1e-6, rel=1e-12)
    # contacts: rows and ids agree
    c = eng.contacts()
    assert len(c["id_i"]) > 200
    np.testing.assert_array_equal(ids[c["row_i"]], c["id_i"])
    np.testing.assert_array_equal(ids[c["row_j"]], c["id_j"])
    np.testing.assert_allclose(np.linalg.norm(c["normal"], axis=1), 1, rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(c["branch"], axis=1),
                               rad[c["row_i"]] + rad[c["row_j"]] - c["overlap"], rtol=1e-12)
    assert (c["overlap"] > 0).all() and (c["force_normal"] >= 0).all()
    assert eng.measure()["contacts"] == len(c["id_i"])


def test_set_positions_rebuilds_the_list_and_the_forces(tiny):
    scene = demtk.load_scene(tiny["scene"])
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    eng = demtk.Engine(scene, st)
    p0 = eng.measure()["p_Pa"]
    builds = eng.list_builds
    st.set_positions(st.positions + 0.01 * st.box.lengths)   # a rigid translation
    assert not st.list_valid
    eng.step(0)
    assert st.list_valid and eng.list_builds == builds + 1
    assert eng.measure()["p_Pa"] == pytest.approx(p0, rel=1e-9)
    with pytest.raises(ValueError, match=r"\(200, 3\)"):
        st.set_positions(np.zeros((3, 3)))


def test_state_from_arrays_and_packing_round_trip(tiny, tmp_path):
    scene = demtk.load_scene(tiny["scene"])
    st = demtk.read_packing(str(tiny["txt"]), scene.density)
    st2 = demtk.State.from_arrays(st.positions, st.radii, st.box.lengths, density=scene.density)
    np.testing.assert_array_equal(st2.masses, st.masses)
    st2.save_packing(str(tmp_path / "p.txt"))
    assert (tmp_path / "p.txt").read_text() == tiny["txt"].read_text()
    st2.check_against(scene)
    with pytest.raises(RuntimeError, match="id 0 appears twice"):
        demtk.State.from_arrays(st.positions, st.radii, st.box.lengths, density=2000, ids=np.zeros(200))
    F = st.box.deformation_gradient
    np.testing.assert_array_equal(F, np.eye(3))


# ---- callbacks, threads ------------------------------------------------------------------------

def test_a_callback_stops_the_run(tiny):
    scene = demtk.load_scene(tiny["scene"])
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    st.zero_strain()
    eng = demtk.Engine(scene, st)
    seen = []

    def cb(e):
        m = e.measure()
        seen.append((e.step_count, m["eps_d"]))
        return m["eps_d"] >= 0.01

    L = scene.velocity_gradient("D2")
    taken = eng.step(10 ** 7, velocity_gradient=L, callback=cb, every=100)
    assert taken == len(seen) * 100 and taken < 10 ** 7
    assert seen[-1][1] >= 0.01 > seen[-2][1]
    # every_strain: called at eps_d increments; engine.stop() ends the run too
    calls = []

    def cb2(e):
        calls.append(e.measure()["eps_d"])
        if len(calls) == 3:
            e.stop()

    eng.step(10 ** 7, velocity_gradient=L, callback=cb2, every_strain=0.002)
    assert len(calls) == 3 and np.all(np.diff(calls) == pytest.approx(0.002, rel=0.05))


def test_the_gil_is_released_while_stepping(tiny):
    scene = demtk.load_scene(tiny["scene"])
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    eng = demtk.Engine(scene, st)
    ticks, stop = [], threading.Event()

    def other():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=other)
    t.start()
    time.sleep(0.05)
    t0 = time.perf_counter()
    eng.step(20000)
    t1 = time.perf_counter()
    stop.set()
    t.join()
    during = [x for x in ticks if t0 < x < t1]
    assert t1 - t0 > 0.1
    assert len(during) > 20, f"the other thread ran {len(during)} times in {t1 - t0:.2f} s of stepping"


# ---- fits, curves ------------------------------------------------------------------------------

def test_fit_is_a_structured_result(tiny):
    e = np.linspace(0, 0.3, 60)
    y = 0.3 - 0.3 * np.exp(-20 * e)
    assert demtk.saturating(0.0, 0.3, 20.0, e[20]) == pytest.approx(y[20], rel=1e-12)
    r = demtk.fit_saturating(e, y)
    assert r.ok and r.x_max == pytest.approx(0.3, rel=1e-6) and r.beta == pytest.approx(20, rel=1e-6)
    assert r.corr.shape == (3, 3) and isinstance(r.warnings, list)
    d = r.as_dict()
    assert d["n"] == 60 and d["ok"]
    with pytest.raises(ValueError):
        demtk.fit_saturating([0, 1], [0, 1])


def test_read_curve_as_pandas(tiny, tmp_path):
    out = tmp_path / "d2.csv"
    scene = demtk.load_scene(tiny["scene"])
    demtk.run_mode(scene, demtk.read_checkpoint(tiny["ckpt"]).state, "D2", str(out))
    df = demtk.read_curve(out)
    assert list(df.columns) == demtk.curve_columns() + ["stage"]
    assert df["step"].dtype == np.int64 and df["stage"].iloc[0] == "D2"
    assert any(c.startswith("# physics:") for c in df.attrs["comments"])
    rec = demtk.read_curve(out, frame=False)
    np.testing.assert_array_equal(rec["s_dev"], df["s_dev"].to_numpy())
    st = demtk.read_checkpoint(tiny["ckpt"]).state
    st.zero_strain()
    m = demtk.Engine(scene, st).measure(scene.velocity_gradient("D2"))
    assert list(m.keys()) == demtk.curve_columns()
    assert m.stress.shape == (3, 3) and m["p_Pa"] == pytest.approx(np.trace(m.stress) / 3, rel=1e-12)
    assert m["F_xy"] == m.fabric[0, 1]


# ---- examples ----------------------------------------------------------------------------------

def test_example_script_runs(tmp_path):
    p = subprocess.run(["/usr/bin/python3", os.path.join(ROOT, "examples", "custom_protocol.py"),
                        "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    assert "stopped at C =" in p.stdout and (tmp_path / "networks.npz").exists()
    # a showcase ends in a result the toolkit stands behind: a fit's numbers only when it is usable (else
    # the reason), and the model-free mean rounded to its error
    assert ("s_dev fit: x0 =" in p.stdout) != ("s_dev fit not usable: " in p.stdout), p.stdout
    assert re.search(r"s_dev over eps_d = 0.05-0.25: 0\.\d+\(\d+\) ", p.stdout), p.stdout


def test_notebook_executes(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(os.path.join(ROOT, "examples", "parameter_loop.ipynb"), as_version=4)
    env_path = os.environ.get("PYTHONPATH", "")
    os.environ["PYTHONPATH"] = os.path.join(ROOT, "build", "python") + (os.pathsep + env_path if env_path else "")
    try:
        nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                resources={"metadata": {"path": str(tmp_path)}}).execute()
    finally:
        os.environ["PYTHONPATH"] = env_path
    outputs = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "chosen rate" in outputs
    assert ("fit: x_max =" in outputs) != ("fit not usable: " in outputs), outputs[-1500:]   # as in the script
    assert re.search(r"s_dev over eps_d = 0.05-0.25: 0\.\d+\(\d+\)", outputs), outputs[-1500:]


# ---- inside YADE -------------------------------------------------------------------------------

@pytest.mark.skipif(not __import__("shutil").which("yade"), reason="yade is not installed")
def test_inside_yade_a_state_from_o_bodies_runs_dem_mode_bit_for_bit(tiny, tmp_path):
    cli = tmp_path / "cli.csv"
    run_dem("mode", "--scene", tiny["scene"], "--packing", tiny["txt"], "--mode", "D2", "--threads", 1,
            "--out", cli, "--quiet", check=True)
    ours = tmp_path / "yade.csv"
    env = dict(os.environ, PYTHONPATH=os.path.join(ROOT, "build", "python"))
    p = subprocess.run(["yade", "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", "demtk_in_yade.py"),
                        "--packing", str(tiny["txt"]), "--scene", str(tiny["scene"]), "--mode", "D2",
                        "--out", str(ours), "--back"], capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0 and "handed back to O.bodies" in p.stdout, p.stdout[-2000:] + p.stderr[-2000:]
    assert ours.read_bytes() == cli.read_bytes()


def test_contacts_carry_the_friction_state():
    """contacts() of a frictional packing under shear: the tangential force obeys the Coulomb limit
    |f_t| <= mu f_n, is at it on the contacts flagged sliding, lies in the tangent plane, adds to the
    normal force to the total, and the springs are there (the rolling ones zero without rolling resistance)."""
    mu = 0.5
    scene = demtk.load_scene({"particles": {"count": 150, "seed": 2}, "contact": {"friction": mu},
                              "integration": {"threads": 1}, "protocol": {"compress_rate_tc": 1e-3}})
    state = demtk.random_packing(scene, 0.5)
    eng = demtk.Engine(scene, state)
    eng.step(10 ** 6, velocity_gradient=-scene.compress_rate * np.ones(3), every=200,
             callback=lambda e: e.state.volume_fraction >= 0.68)
    eng.step(20000, velocity_gradient=scene.velocity_gradient("D2", rate=1e-3 / scene.t_c))
    c = eng.contacts()
    fn, ft, n = c["force_normal"], c["force_tangential"], c["normal"]
    assert len(fn) > 100 and c["sliding"].dtype == bool
    mag = np.linalg.norm(ft, axis=1)
    assert np.all(mag <= mu * np.maximum(fn, 0) * (1 + 1e-9) + 1e-300)
    assert c["sliding"].any() and not c["sliding"].all()
    # flagged at the last step's limit; fn here is recomputed at the current velocities, so the limit
    # has moved by at most a step's change of fn
    np.testing.assert_allclose(mag[c["sliding"]], mu * fn[c["sliding"]], rtol=1e-2)
    assert np.max(np.abs(np.einsum("ij,ij->i", ft, n))) <= 1e-9 * np.max(mag)
    np.testing.assert_allclose(c["force"], n * fn[:, None] + ft, rtol=1e-12, atol=1e-12 * np.max(np.abs(c["force"])))
    assert np.linalg.norm(c["spring_tangential"], axis=1).max() > 0
    assert not np.any(c["spring_rolling"]) and not np.any(c["spring_twisting"])   # no rolling resistance here
