"""yade_ref/run_mode.py takes its YADE law from the scene (`dem info SCENE --yade`, the registry's
counterparts; issue 30 item 1): the options it makes are the ones the stored YADE comparisons were
run with, written by hand (data/yade_friction/COMMANDS.txt, data/yade_hm/run.sh); a law YADE has no
counterpart for is refused by name; and a YADE run with --scene is the run with those options."""
import os
import re
import shlex
import shutil
import subprocess

import pytest

from conftest import run_dem, ROOT

YADE = shutil.which("yade")
needs_yade = pytest.mark.skipif(YADE is None, reason="yade is not installed (scripts/install-deps.sh installs it)")


def options(words):
    """{'--opt': value} of an option list (every option here takes one value)."""
    out, i = {}, 0
    while i < len(words):
        assert words[i].startswith("--"), words
        out[words[i]] = words[i + 1]
        i += 2
    return out


def yade_options(scene, *sets):
    args = ["info", os.path.join(ROOT, scene), "--yade"]
    for s in sets:
        args += ["--set", s]
    return options(shlex.split(run_dem(*args, check=True).stdout))


def stored_command(path, var):
    """The options of the shell variable `var="..."` of a stored command file."""
    text = open(os.path.join(ROOT, path)).read()
    m = re.search(var + r'="([^"]*)"', text, re.S)
    assert m, f"{path}: no {var}=\"...\""
    return options(shlex.split(m.group(1).replace("\\\n", " ")))


def same_values(ours, stored):
    for key, value in stored.items():
        if key in ("--packing", "--mode", "--eps-max", "--out", "--side-stress-p0"):
            continue
        assert key in ours, f"{key} missing from dem info --yade: {ours}"
        try:
            assert float(ours[key]) == pytest.approx(float(value), rel=1e-15), key
        except ValueError:
            assert ours[key] == value, key


@pytest.mark.parametrize("scene,commands", [("data/yade_friction/scene.toml", "data/yade_friction/COMMANDS.txt"),
                                            ("data/yade_hm/scene.toml", "data/yade_hm/run.sh")])
def test_scene_gives_the_hand_written_yade_options(scene, commands):
    ours = yade_options(scene)
    stored = stored_command(commands, "C")
    same_values(ours, stored)
    # and the scene's own zero background damping (YADE's default in run_mode.py too)
    assert float(ours["--gamma-b"]) == 0


def test_frictionless_linear_scene_is_viscel_with_its_dashpot():
    ours = yade_options("data/scenes/quickstart.toml", "contact.damping_kg_s=0.25")
    assert ours["--law"] == "viscel"
    assert float(ours["--gamma"]) == 0.25 and float(ours["--k"]) == 1e8
    assert "--friction" not in ours


@pytest.mark.parametrize("sets,named", [
    (["contact.normal=luding"], 'contact.normal = "luding" has no counterpart'),
    (["contact.friction=0.5", "contact.damping_kg_s=0", "contact.rolling_friction=0.1"], 'contact.rolling = "sds"'),
    (["contact.normal=hertz", "contact.tangential=mindlin", "contact.friction=0.5"], 'contact.tangential = "mindlin"'),
    (["contact.friction=0.5"], "no YADE law of yade_ref/run_mode.py takes this contact law"),
    (["contact.friction=0.5", "contact.damping_kg_s=0", "contact.tangential_damping_kg_s=1"],
     "contact.tangential_damping_kg_s > 0"),
    (["contact.normal=hertz", "contact.tangential=cundall_strack", "contact.friction=0.5"],
     "no YADE law of yade_ref/run_mode.py takes this contact law"),
])
def test_law_without_yade_counterpart_is_refused_by_name(sets, named):
    args = ["info", os.path.join(ROOT, "data/scenes/quickstart.toml"), "--yade"]
    for s in sets:
        args += ["--set", s]
    p = run_dem(*args)
    assert p.returncode != 0
    assert named in p.stderr, p.stderr


def test_run_mode_refuses_set_without_scene():
    # run_mode.py imports yade at the top: its argument check is reached only inside YADE
    if YADE is None:
        pytest.skip("yade is not installed")
    p = subprocess.run([YADE, "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", "run_mode.py"), "--packing", "x",
                        "--set", "contact.friction=0.5", "--out", "/dev/null"], capture_output=True, text=True,
                       cwd=ROOT, timeout=300)
    assert p.returncode != 0 and "--set needs --scene" in p.stdout + p.stderr


@needs_yade
def test_yade_run_with_scene_is_the_run_with_its_options(tmp_path):
    """The same short frictional YADE run twice: with --scene, and with the options written out by
    hand (data/yade_friction/COMMANDS.txt): the same curve, row for row."""
    packing = os.path.join(ROOT, "data/yade_friction/packing_phi0.700.txt")
    common = ["--packing", packing, "--mode", "D2", "--eps-max", "0.004", "--max-steps", "300"]
    runs = {"scene": ["--scene", "data/yade_friction/scene.toml"],
            "hand": shlex.split("--rate-tc 1e-4 --dt-over-tc 0.04 --r-min 0.0005 --friction 0.5 "
                                "--kt-ratio 0.2857142857142857 --law frictphys --gamma 0 --sample-strain 0.002")}
    rows = {}
    for name, extra in runs.items():
        out = tmp_path / f"{name}.csv"
        p = subprocess.run([YADE, "-n", "-x", "-j1", os.path.join(ROOT, "yade_ref", "run_mode.py"), *common, *extra,
                            "--out", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=600)
        assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
        rows[name] = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    assert len(rows["scene"]) >= 3
    assert rows["scene"] == rows["hand"]
