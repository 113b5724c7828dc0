"""The preparation as scene data (protocol.preparation, issue 11): spelling out the built-in
compress / relax / cycle gives the default run byte for byte; a load-unload-reload list runs
its own stages, writes its checkpoint series where it says and starts the modes from the
series named by modes_from; an interrupted custom preparation resumes after its last finished
stage; bad lists are refused before anything runs."""
import json
import re

import numpy as np
import pytest

from conftest import run_dem
from demkit.curves import read_curve
from test_faults import files_of

MATERIAL = """
[particles]
count = 200
seed = 5
[integration]
threads = 1
[output]
sample_strain = 0.002
vtk = false
"""
BUILTIN = """
[protocol]
target_phi = 0.64
compress_rate_tc = 1e-3
cycle_rate_tc = 2e-5
cycle_phi_max = 0.74
checkpoints_unloading = [0.74, 0.72, 0.69, 0.64]
checkpoints_loading = [0.70]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.03
relax_max_time_tc = 2e3
"""
# The same preparation, spelled out (the checkpoints at 0.74 and 0.64 are the unloading's start
# and end: saved before and after the stage).
SPELLED = """
[protocol]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.03
preparation = [
  { name = "compress", kind = "compress", rate_tc = 1e-3, until = { phi = 0.64 } },
  { name = "relax", kind = "relax", until = { ke_ratio = 1e-8 }, max_time_tc = 2e3 },
  { name = "cycle_loading", kind = "compress", rate_tc = 2e-5, until = { phi = 0.74 }, checkpoint_name = "loading", checkpoints = [0.70] },
  { name = "cycle_unloading", kind = "expand", rate_tc = 2e-5, until = { phi = 0.64 }, checkpoint_name = "unloading", checkpoints = [0.74, 0.72, 0.69, 0.64] },
]
"""
# Load to 0.72, unload to 0.66, reload to 0.74 with checkpoints; the modes start from the reload.
RELOAD = """
[protocol]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.03
modes_from = "reload"
preparation = [
  { name = "fill", kind = "compress", rate_tc = 1e-3, until = { phi = 0.64 } },
  { name = "settle", kind = "relax", max_time_tc = 2e3 },
  { name = "load", kind = "compress", rate_tc = 4e-5, until = { phi = 0.72 }, checkpoints = [0.70] },
  { name = "unload", kind = "expand", rate_tc = 4e-5, until = { phi = 0.66 } },
  { name = "reload", kind = "compress", rate_tc = 4e-5, until = { phi = 0.74 }, checkpoints = [0.66, 0.70, 0.74] },
]
"""


def run_scene(tmp_path, name, protocol, *extra, check=True):
    scene = tmp_path / f"{name}.toml"
    scene.write_text(MATERIAL + protocol)
    out = tmp_path / name
    r = run_dem("run", scene, "--out", out, "--quiet", *extra)
    if check:
        assert r.returncode == 0, r.stderr
    return out, r


@pytest.fixture(scope="module")
def builtin_and_spelled(tmp_path_factory):
    d = tmp_path_factory.mktemp("prep")
    return run_scene(d, "builtin", BUILTIN)[0], run_scene(d, "spelled", SPELLED)[0]


def test_spelling_out_the_builtin_preparation_gives_the_default_run_byte_for_byte(builtin_and_spelled):
    a, b = builtin_and_spelled
    files = [f for f in files_of(a) if f.endswith((".csv", ".txt"))]
    assert files == [f for f in files_of(b) if f.endswith((".csv", ".txt"))]
    assert "checkpoints/loading_phi0.700.txt" in files and "checkpoints/unloading_phi0.640.txt" in files
    assert "deviatoric/D2_phi0.740.csv" in files and "deviatoric/D2_phi0.640.csv" in files
    for f in files:   # curves (physics record included) and the exported packings
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    ma, mb = (json.loads((d / "manifest.json").read_text()) for d in (a, b))
    assert [(o["file"], o["physics"]) for o in ma["outputs"]] == [(o["file"], o["physics"]) for o in mb["outputs"]]


def test_the_checkpoints_at_the_ends_of_a_stage_are_its_end_states(builtin_and_spelled):
    a, _ = builtin_and_spelled
    unload = read_curve(a / "prep" / "cycle_unloading.csv")
    for phi, row in (("0.740", 0), ("0.640", -1)):
        deviatoric = read_curve(a / "deviatoric" / f"D2_phi{phi}.csv")
        # The mode's first row is the checkpoint's state: the stage's first (last) row (judged on
        # what positions alone fix; stresses carry the dashpots of the rate the row is measured at).
        for q in ("nu", "E_pot_J", "contacts", "F_dev"):
            assert deviatoric[q][0] == pytest.approx(unload[q][row], rel=1e-9), q


@pytest.fixture(scope="module")
def reload_run(tmp_path_factory):
    return run_scene(tmp_path_factory.mktemp("reload"), "reload", RELOAD)[0]


def test_a_load_unload_reload_list_runs_its_stages_and_starts_the_modes_from_its_series(reload_run):
    d = reload_run
    files = files_of(d)
    for st in ("fill", "settle", "load", "unload", "reload"):
        assert f"prep/{st}.csv" in files and f"prep/after_{st}.ckpt" in files
    assert sorted(f for f in files if f.startswith("checkpoints/") and f.endswith(".ckpt")) == [
        "checkpoints/load_phi0.700.ckpt", "checkpoints/reload_phi0.660.ckpt", "checkpoints/reload_phi0.700.ckpt",
        "checkpoints/reload_phi0.740.ckpt"]
    assert sorted(f for f in files if f.startswith("deviatoric/")) == [
        "deviatoric/D2_phi0.660.csv", "deviatoric/D2_phi0.700.csv", "deviatoric/D2_phi0.740.csv"]
    load, unload, reload = (read_curve(d / "prep" / f"{s}.csv") for s in ("load", "unload", "reload"))
    assert load["nu"][-1] == pytest.approx(0.72, rel=1e-12)
    assert unload["nu"][0] == pytest.approx(0.72, rel=1e-12) and unload["nu"][-1] == pytest.approx(0.66, rel=1e-12)
    assert reload["nu"][-1] == pytest.approx(0.74, rel=1e-12)
    # Volume fractions go where the stages say, monotonically.
    assert np.all(np.diff(load["nu"]) > 0) and np.all(np.diff(unload["nu"]) < 0) and np.all(np.diff(reload["nu"]) > 0)
    # Each mode starts at its checkpoint's volume fraction.
    for phi in (0.66, 0.70, 0.74):
        assert read_curve(d / "deviatoric" / f"D2_phi{phi:.3f}.csv")["nu"][0] == pytest.approx(phi, rel=1e-9)
    # The preparation is recorded stage by stage in the physics of its curves.
    line = next(ln for ln in (d / "prep" / "reload.csv").read_text().splitlines() if ln.startswith("# physics:"))
    assert re.search(r"protocol\.preparation=fill:compress:.*/reload:compress:.*reload=\[0\.66", line)


def test_dem_info_and_the_plan_follow_the_list(tmp_path):
    scene = tmp_path / "reload.toml"
    scene.write_text(MATERIAL + RELOAD)
    info = run_dem("info", scene, check=True).stdout
    assert re.search(r"prep reload\s+compress to phi 0.74 at 4e-05/t_c, checkpoints reload at 0.66 0.7 0.74", info)
    plan = json.loads(run_dem("info", scene, "--json", check=True).stdout)
    assert plan["series"] == "reload"
    assert [c["stem"] for c in plan["checkpoints"]] == ["reload_phi0.740", "reload_phi0.700", "reload_phi0.660"]


def test_an_interrupted_custom_preparation_resumes_after_its_last_finished_stage(reload_run, tmp_path):
    import shutil
    d = tmp_path / "interrupted"
    shutil.copytree(reload_run, d)
    # As if killed during "reload": its curve, resume point, checkpoints and the modes are missing.
    for f in ["prep/reload.csv", "prep/after_reload.ckpt"] + [f for f in files_of(d) if "reload_phi" in f or
                                                               f.startswith("deviatoric/")]:
        (d / f).unlink()
    m = d / "manifest.json"
    m.write_text(m.read_text().replace('"complete": true', '"complete": false'))
    r = run_dem("run", d / "scene.toml", "--out", d, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "after the finished stage unload" in r.stderr
    for f in files_of(reload_run):
        if f.endswith((".csv", ".txt", ".ckpt")):
            assert (d / f).read_bytes() == (reload_run / f).read_bytes(), f


BAD = [
    ('target_phi = 0.64\npreparation = [{ name = "a", kind = "relax" }]', "protocol.target_phi belongs to the built-in"),
    ('preparation = [{ name = "a", kind = "squeeze" }]', 'kind must be "compress", "expand", "relax", "pressure" or "uniaxial"'),
    ('preparation = [{ name = "a", kind = "compress", rate_tc = 1e-3, until = { phi = 0.64 }, checkpoints = [0.7] }]',
     "lies beyond the stage's target"),
    ('preparation = [{ name = "a", kind = "relax" }, { name = "a", kind = "relax" }]', "two stages are named 'a'"),
    ('preparation = [{ name = "a", kind = "compress", rate_tc = 1e-3, until = { phi = 0.64 } }]',
     'modes_from = "unloading" names no checkpoints'),
    ('preparation = [{ name = "a", kind = "relax", rate_tc = 1e-3 }]', "rate_tc has no meaning for a relaxation"),
    ('preparation = [{ name = "a", kind = "expand", until = { phi = 0.6 } }]', "rate_tc (true strain rate"),
    ('preparation = [{ name = "a/b", kind = "relax" }]', "name must be letters, digits"),
    ('preparation = [{ name = "a", kind = "compress", rate_tc = 0.5, until = { phi = 0.64 } }]', "far from quasi-static"),
    ("preparation = []", "lists no stage"),
]


@pytest.mark.parametrize("protocol,message", BAD)
def test_bad_preparation_lists_are_refused_before_anything_runs(tmp_path, protocol, message):
    scene = tmp_path / "bad.toml"
    scene.write_text(MATERIAL + "[protocol]\nmodes = [\"D2\"]\n" + protocol + "\n")
    r = run_dem("run", scene, "--out", tmp_path / "out", "--quiet")
    assert r.returncode == 2, r.stderr
    assert message in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()
