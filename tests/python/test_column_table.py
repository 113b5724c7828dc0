"""The curve columns and the contact sub-models are defined once (issue 30 items 1 and 4): the CSV
header, `dem info --columns`, docs/curve_columns.md, demtk.measure() and the registry agree."""
import json
import os
import subprocess

import pytest

from conftest import run_dem

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
demtk = pytest.importorskip("demtk")


def table():
    return json.loads(run_dem("info", "--columns", "--json", check=True).stdout)


def test_the_docs_column_list_is_the_tables():
    made = run_dem("info", "--columns", check=True).stdout
    with open(os.path.join(REPO, "docs", "curve_columns.md")) as fh:
        doc = fh.read()
    assert made.strip() in doc, "docs/curve_columns.md is stale: regenerate it with scripts/make_docs_tables.sh"


def test_demtk_measure_has_every_column_the_cli_writes_friction_included():
    names = {c["name"]: c["group"] for c in table()}
    for mu, groups in ((0.0, {"every"}), (0.5, {"every", "rotations"})):
        scene = demtk.load_scene(os.path.join(REPO, "data", "scenes", "quickstart.toml"),
                                 set={"contact.friction": mu, "particles.count": 60})
        state = demtk.random_packing(scene, 0.3)
        m = demtk.Engine(scene, state).measure()
        want = [n for n, g in names.items() if g in groups]
        assert list(m.keys()) == want, (mu, set(want) ^ set(m.keys()))
        assert demtk.curve_columns(rotations=mu > 0) == want


def test_every_contact_key_is_documented_with_unit_and_default():
    models = json.loads(run_dem("info", "--contact-models", "--json", check=True).stdout)
    assert models == demtk.contact_models()
    with open(os.path.join(REPO, "docs", "contact_models.md")) as fh:
        doc = fh.read()
    for m in models:
        for k in m["keys"]:
            assert k["unit"] and k["meaning"], k
            assert k["key"] in doc, f"{k['key']} of {m['slot']} \"{m['name']}\" is not in docs/contact_models.md"
    text = run_dem("info", "--contact-models", check=True).stdout
    assert "contact.luding_kp_N_m [N/m] default 5 x contact.stiffness_N_m" in text
    assert text in doc, "docs/contact_models.md's key list is stale: run scripts/make_docs_tables.sh"


def test_dem_info_shows_each_chosen_sub_model_and_its_stability_limit():
    out = run_dem("info", os.path.join(REPO, "data", "scenes", "quickstart.toml"), "--no-probe",
                  "--set", "contact.friction=0.5", check=True).stdout
    assert "  tangential       cundall_strack: Cundall-Strack, mu = 0.5" in out
    assert "contact.tangential_damping_kg_s <= " in out
    bad = run_dem("info", os.path.join(REPO, "data", "scenes", "quickstart.toml"), "--no-probe",
                  "--set", "contact.friction=0.5", "--set", "contact.tangential_stiffness_ratio=5")
    assert bad.returncode == 2 and "contact.tangential_stiffness_ratio = 5 -> at most 2.88" in bad.stderr
