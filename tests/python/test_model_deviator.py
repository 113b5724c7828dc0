"""The deviatoric stress under a volume change and the fabric's state limit (issue 31, thirtieth round):
`dem model --deviator-volume reference` (sigma_dev scales with the isotropic reference pressure p_ref(nu) under a volume
change) and `--fabric-limit state` (the fabric driven to F_lim times the stress ratio's state factor), applied with
--predict-with to the stored mu = 1 choice (weighted + Lode limit, gated); their rows in parameters.csv read back and
undone (their refusals: test_model_onset.py); `demkit.model_onset --compare` against the stored gate table; the stored
tables rebuilt from their runs."""
import csv
import math
import os
import subprocess
import sys

import pytest

from conftest import DEM, ROOT

sys.path.insert(0, ROOT)
from demkit import model_early, model_friction, model_onset  # noqa: E402

LWDIR = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "lode_weight")
LL = os.path.join(LWDIR, "onset", "lode_limit")
MU1 = os.path.join(LL, "gate_weighted_lode_limit", "mu_1", "parameters.csv")


def predict(work, params, out, *extra):
    return subprocess.run([DEM, "model", work, "--predict-with", params, "--family", "extended", "--fabric-lode",
                           "weighted", "--state-limit", "pressure-lode", "--calibrate-on", "D2,D3", "--no-plots",
                           "--out", str(out), *extra], capture_output=True, text=True)


def rows_of(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))


def parameter_rows(path):
    return {r["parameter"]: r["value"] for r in rows_of(path)}


def rms_band(out, name, q):
    """RMS of (model - mean) over the mean 95 % band half-width of column Q in curves/NAME."""
    rows = rows_of(os.path.join(out, "curves", name))
    half = sum((float(r[q + "_hi95"]) - float(r[q + "_lo95"])) / 2 for r in rows) / len(rows)
    return (sum((float(r[q + "_model"]) - float(r[q + "_mean"])) ** 2 for r in rows) / len(rows)) ** 0.5 / half


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return model_friction.working_copy(os.path.join(ROOT, "data", "friction_n1000"),
                                       str(tmp_path_factory.mktemp("deviator") / "work"), "1", "test_model_deviator")


def test_the_isobaric_softening_at_mu_1_is_predicted_with_the_reference_scaling(tmp_path, work):
    """The DEM's isobaric stress ratio at nu = 0.69 (mu = 1) falls from 1.02 at its peak to 0.94 as the packing dilates;
    the stored choice predicts a fall of 0.03 and misses by more than a band. With sigma_dev scaling with p_ref(nu) it
    is within one band; the constant-volume D2 and D3 curves are the same numbers (no volume change)."""
    fixed, ref = tmp_path / "fixed", tmp_path / "ref"
    assert predict(work, MU1, fixed).returncode == 0
    r = predict(work, MU1, ref, "--deviator-volume", "reference")
    assert r.returncode == 0, r.stderr
    iso = os.path.join("paths", "isobaric_phi0.690.csv")
    assert rms_band(fixed, iso, "s_dev") > 1.0
    assert rms_band(ref, iso, "s_dev") < 1.0
    last = rows_of(ref / "curves" / iso)[-1]
    assert float(last["s_dev_model"]) < 0.97   # the DEM's 0.94; the stored choice's 1.00
    for name in ("D2_phi0.690.csv", "D3_phi0.740.csv", "D3_phi0.800.csv"):
        a, b = rows_of(fixed / "curves" / name), rows_of(ref / "curves" / name)
        assert [x["s_dev_model"] for x in a] == [x["s_dev_model"] for x in b], name
    assert parameter_rows(ref / "parameters.csv")["deviator_volume"] == "1"
    assert "deviator_volume" not in parameter_rows(fixed / "parameters.csv")


def test_both_options_are_read_back_and_undone(tmp_path, work):
    a = tmp_path / "both"
    r = predict(work, MU1, a, "--deviator-volume", "reference", "--fabric-limit", "state")
    assert r.returncode == 0, r.stderr
    rows = parameter_rows(a / "parameters.csv")
    assert rows["deviator_volume"] == "1" and rows["fabric_limit"] == "1"
    b = tmp_path / "again"
    assert predict(work, str(a / "parameters.csv"), b).returncode == 0   # the file's rows
    assert model_early.curve_rows(a / "summary.csv") == model_early.curve_rows(b / "summary.csv")
    c, d = tmp_path / "undone", tmp_path / "stored"
    assert predict(work, str(a / "parameters.csv"), c, "--deviator-volume", "fixed", "--fabric-limit",
                   "fixed").returncode == 0
    assert predict(work, MU1, d).returncode == 0
    assert model_early.curve_rows(c / "summary.csv") == model_early.curve_rows(d / "summary.csv")
    assert model_early.curve_rows(a / "summary.csv") != model_early.curve_rows(c / "summary.csv")


def test_compare_gives_the_gate_tables_numbers_and_choice(tmp_path):
    """--compare on the stored rerun (left) and gated (right) weighted Lode-limit runs gives gate_weighted_lode_limit's
    numbers and choice, which `table` made from the same runs."""
    model_onset.compare(str(tmp_path), "t", ("rerun", os.path.join(LL, "none_weighted_lode_limit")),
                        ("gated", os.path.join(LL, "gate_weighted_lode_limit")), ["0.5", "1"])
    got = rows_of(tmp_path / "t.csv")
    with open(os.path.join(LL, "gate_weighted_lode_limit.csv"), newline="") as fh:
        want = [r for r in csv.DictReader(fh) if r["mu"] in ("0.5", "1")]
    assert len(got) == len(want) == 4
    for g, w in zip(got, want):
        assert g["side"] == {"stored": "left", "alternative": "right"}[w["start"]]
        for col in ("chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]",
                    "worst_predicted_isobaric [band]", "heldout_mean [-]", "heldout_paths_mean [-]", "chosen"):
            assert g[col] == w[col], col
    with pytest.raises(SystemExit, match="does not exist"):
        model_onset.compare(str(tmp_path), "t", ("a", os.path.join(LL, "none_overlap_lode_limit")),
                            ("b", os.path.join(LL, "gate_weighted_lode_limit")), ["0.5"])


def test_after_peak_on_hand_built_curves():
    """from the peak of s_dev (row 1) to the end: constant volume, d ln sigma_dev = d ln s + d ln p and p_iso fixed; on
    an isobaric path the volume fraction nu0 exp(-3 eps_v) in p_iso(nu) = nu^10 gives d ln p_iso = -30 d eps_v."""
    from demkit import model_deviator
    cv = [{"eps_d": "0", "s_dev_mean": "0.5", "p_star_mean": "0.01", "eps_v_mean": "0"},
          {"eps_d": "0.1", "s_dev_mean": "1.0", "p_star_mean": "0.02", "eps_v_mean": "0"},
          {"eps_d": "0.2", "s_dev_mean": "0.8", "p_star_mean": "0.025", "eps_v_mean": "0"}]
    v = model_deviator.after_peak(cv, 0.7, lambda nu: nu ** 10, False)
    assert v[0] == 0.1
    assert v[1:] == pytest.approx((math.log(0.8), math.log(0.8 * 0.025 / 0.02), math.log(1.25), 0.0))
    iso = [{"eps_d_accumulated": r["eps_d"], "s_dev_mean": r["s_dev_mean"], "p_star_mean": "0.02",
            "eps_v_mean": e} for r, e in zip(cv, ("0", "0.001", "0.004"))]
    v = model_deviator.after_peak(iso, 0.7, lambda nu: nu ** 10, True)
    assert v[1:] == pytest.approx((math.log(0.8), math.log(0.8), 0.0, -30 * 0.003))
    for mu, name in (("1", "weighted + Lode limit + gate"), ("0.1", "weighted"), ("0.5", "weighted"),
                     ("0", "overlap")):
        got = model_deviator.chosen(LWDIR, mu)
        assert got[0] == name and os.path.exists(got[1]), mu


DEV = os.path.join("data", "friction_n1000", "model_friction", "lode_weight", "onset", "deviator")
LWREL = os.path.join("data", "friction_n1000", "model_friction", "lode_weight")
K12 = os.path.join("data", "friction_n1000_k12", "model", "lode_limit_gate")   # the K = 12 versus table's runs
STORED = [  # (tag, left, right, names, mus): the stored tables of onset/deviator/ (its README's commands)
    ("deviator_mu_1", os.path.join(LWREL, "onset", "lode_limit", "gate_weighted_lode_limit"),
     os.path.join(DEV, "gate_deviator_weighted_lode_limit"), ("weighted + Lode limit + gate", "... + deviator reference"),
     ["1"]),
    ("deviator_weighted", os.path.join(LWREL, "onset", "none"), os.path.join(DEV, "deviator"),
     ("weighted", "weighted + deviator reference"), ["0.3", "0.5"]),
    ("deviator_overlap", os.path.join(LWREL, "onset", "none"), os.path.join(DEV, "deviator"),
     ("overlap", "overlap + deviator reference"), ["0"]),
    ("deviator_mu_0.1", os.path.join(DEV, "none_weighted_start"), os.path.join(DEV, "deviator_weighted_start"),
     ("weighted", "weighted + deviator reference"), ["0.1"]),
    ("fabric_on_gate", os.path.join(LWREL, "onset", "lode_limit", "gate_weighted_lode_limit"),
     os.path.join(DEV, "gate_fabric_weighted_lode_limit"), ("weighted + Lode limit + gate", "... + fabric state"),
     ["0.5"]),
    ("fabric_versus", os.path.join(LWREL, "onset", "none"), os.path.join(DEV, "gate_fabric_weighted_lode_limit"),
     ("weighted", "weighted + Lode limit + gate + fabric state"), ["0.5"]),
    ("versus_mu_0.5", os.path.join(K12, "weighted"), K12, ("weighted", "weighted + Lode limit + gate"), ["0.5"]),
]


@pytest.mark.parametrize("tag, left, right, names, mus", STORED)
def test_the_stored_tables_are_rebuilt_from_their_runs(tmp_path, monkeypatch, tag, left, right, names, mus):
    """Each stored table of onset/deviator/ from its stored runs, byte for byte (the docs quote them); the fits with
    and without --deviator-volume are the same (held-out scores of the fitted curves equal)."""
    monkeypatch.chdir(ROOT)
    model_onset.compare(str(tmp_path), tag, (names[0], left), (names[1], right), mus)
    for ext in ("md", "csv"):
        where = K12 if tag == "versus_mu_0.5" else DEV
        assert (tmp_path / f"{tag}.{ext}").read_text() == open(os.path.join(where, f"{tag}.{ext}")).read(), ext
    if tag.startswith("deviator"):
        got = rows_of(tmp_path / f"{tag}.csv")
        for a, b in zip(got[::2], got[1::2]):
            assert a["heldout_mean [-]"] == b["heldout_mean [-]"] and a["chi2_per_dof [-]"] == b["chi2_per_dof [-]"]


def test_the_choice_table_names_the_runs_its_deciding_tables_chose(tmp_path, monkeypatch):
    """demkit.model_choice: every mu's run is the one its deciding table chose, with that table's numbers (chi2/dof and
    the worst curves to the table's 4 digits); the stored choice.{md,csv} rebuilt byte for byte."""
    from demkit import model_choice
    monkeypatch.chdir(ROOT)
    for mu, name, params, opts, chi, worst, table in model_choice.rows(LWREL):
        assert os.path.exists(os.path.join(LWREL, params)), mu
        side = model_choice.CHOICES[mu][6]
        with open(os.path.join(LWREL, table + ".csv"), newline="") as fh:
            chosen = [r for r in csv.DictReader(fh) if r["mu"] == mu and r["chosen"] == "yes"]
        assert len(chosen) == 1 and chosen[0]["variant"] == side, (mu, chosen)
        assert float(chosen[0]["chi2_per_dof [-]"]) == pytest.approx(chi, rel=1e-3), mu
        for col, kind in zip(("worst_fitted_D2 [band]", "worst_fitted_D3 [band]", "worst_predicted_isobaric [band]"),
                             model_choice.KINDS):
            assert float(chosen[0][col]) == pytest.approx(worst[kind][0], rel=1e-3, abs=1e-4), (mu, col)
        assert opts[:2] == ["--family", "extended"]
    model_choice.write(LWREL, str(tmp_path))
    for ext in ("md", "csv"):
        assert (tmp_path / f"choice.{ext}").read_text() == open(os.path.join(LWREL, f"choice.{ext}")).read()
