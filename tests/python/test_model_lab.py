"""Each mu's D2 + D3 choice predicting the laboratory tests (issue 31, thirty-first round, demkit.model_lab): a stored
prediction reproduced by `dem model --predict-with` from the stored curves, the stored tables rebuilt byte for byte,
the counting rules on a hand-built summary, and the choice's options."""
import filecmp
import os
import shutil
import sys

import pytest

from conftest import DEM, ROOT

sys.path.insert(0, ROOT)
from demkit import model_choice, model_lab  # noqa: E402

STORED = os.path.join(ROOT, model_lab.OUT)


def test_the_choice_is_predicted_with_its_own_options_and_no_calibration_set():
    opts = model_lab.choice_options("1")
    assert "--calibrate-on" not in opts and "D2,D3" not in opts
    full = model_choice.options("1")
    assert [o for o in full if o not in ("--calibrate-on", "D2,D3")] == opts
    assert opts[opts.index("--state-limit") + 1] == "pressure-lode"
    assert "--deviator-volume" in opts


def test_a_stored_prediction_is_reproduced_from_the_stored_curves(tmp_path):
    """mu = 0.5: the laboratory curves converted again and predicted with the stored choice give the stored summary
    to the last digit (dense and loose)."""
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        preps = model_lab.predict("0.5", str(tmp_path / "work"), str(tmp_path / "out"), DEM)
    finally:
        os.chdir(cwd)
    assert preps == ["dense", "loose"]
    for prep in preps:
        assert filecmp.cmp(tmp_path / "out" / "mu_0.5" / prep / "summary.csv",
                           os.path.join(STORED, "mu_0.5", prep, "summary.csv"), shallow=False), prep


def test_the_stored_tables_rebuild_byte_for_byte(tmp_path):
    out = tmp_path / "out"
    shutil.copytree(STORED, out)
    for stem in ("blind", "curves"):
        for ext in ("md", "csv"):
            (out / f"{stem}.{ext}").unlink()
    model_lab.write(str(out))
    for stem in ("blind", "curves"):
        for ext in ("md", "csv"):
            assert filecmp.cmp(out / f"{stem}.{ext}", os.path.join(STORED, f"{stem}.{ext}"), shallow=False), stem


def test_every_laboratory_curve_is_counted_once_and_none_is_within_a_band():
    """The stored finding: at every mu and preparation no laboratory curve is within 1 band of the D2 + D3 choice's
    prediction; each preparation has 7 tests at 2 pressures."""
    for mu, prep, path in model_lab.runs(STORED):
        rows = model_lab.laboratory_rows(path)
        n, ok, ni, dv, med, top = model_lab.counts(rows)
        assert n == 14 and ok == 0, (mu, prep)
        assert ni + dv <= n
        assert len({(t, nu) for t, nu, *_ in rows}) == n


def test_counting_rules_on_a_hand_built_summary(tmp_path):
    path = tmp_path / "summary.csv"
    path.write_text(
        "mode,nu [-],role,p_star [band],eps_v [band],s_dev [band],F_dev [band],worst [band]\n"
        "D2,0.69,predicted,0.1,nan,0.2,0.3,0.3\n"
        "TC_s3_dense,0.66,predicted,0.5,2.5,0.7,0.1,2.5\n"
        "TE_p_dense,0.66,predicted,nan,0.4,0.9,0.2,0.9\n"
        "TC_p_dense,0.6,\"predicted, not integrable (nu0 <= nu_c)\",nan,nan,nan,nan\n"
        "TT_b050_dense,0.6,predicted,nan,inf,inf,inf,inf\n"
        "calibration,nan,chi2/dof nan,nan,nan,nan,nan,inf\n")
    rows = model_lab.laboratory_rows(str(path))
    assert [(t, what) for t, _, _, _, what in rows] == [
        ("TC_s3_dense", "eps_v"), ("TE_p_dense", "s_dev"), ("TC_p_dense", model_lab.NOT_INTEGRABLE),
        ("TT_b050_dense", "diverged")]
    assert model_lab.counts(rows) == (4, 1, 1, 1, pytest.approx(1.7), 2.5)
