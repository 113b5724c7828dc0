"""demkit.model_early (issue 31, twenty-seventh round): the RMS of model - DEM over the mean band half-width of each
model curve, split at an eps_d. Checked against a hand-built curve whose errors are known in closed form, and against
`dem model`'s own prediction table (another implementation) on a stored calibration applied with --predict-with to
the friction study's mu = 1 ensemble, its isobaric paths included."""
import csv
import math
import os
import subprocess
import sys

import pytest

from conftest import DEM, ROOT

sys.path.insert(0, ROOT)
from demkit import model_early, model_friction  # noqa: E402

LW = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "lode_weight", "overlap_no_limit", "mu_1")


def test_a_hand_built_curve_splits_as_its_closed_form(tmp_path):
    """Band half-width 2 everywhere; model - DEM = 1 before eps_d = 0.1 (3 points with eps_d > 0) and 3 from it on (6
    points): RMS over band early 0.5, late 1.5, whole sqrt((3 * 0.25 + 6 * 2.25) / 9), early share 0.75 / 14.25."""
    d = tmp_path / "run" / "curves"
    d.mkdir(parents=True)
    cols = ["eps_d"] + [f"{q}_{s}" for q in ("p_star", "s_dev", "F_dev") for s in ("model", "mean", "lo95", "hi95")]
    lines = ["# a hand-built curve", ",".join(cols)]
    for i in range(10):
        e = round(0.025 * i, 3)
        diff = 0 if i == 0 else 1 if e < 0.1 else 3
        lines.append(",".join(str(v) for v in [e] + [5 + diff, 5, 3, 7] * 3))
    (d / "D2_phi0.700.csv").write_text("\n".join(lines) + "\n")
    # a model-only path (`dem model` writes cyclic and isobaric ones where no DEM path exists): nothing to judge
    (d / "cyclic_phi0.700.csv").write_text("# model only\neps_d_accumulated,eps_d,p_star,s_dev,F_dev\n0,0,1,0,0\n")
    rows = model_early.table(str(tmp_path / "run"), 0.1)
    assert [r[1] for r in rows] == ["p_star", "s_dev", "F_dev"]
    for r in rows:
        assert r[2] == pytest.approx(math.sqrt((3 * 0.25 + 6 * 2.25) / 9))
        assert r[3:] == pytest.approx([0.5, 1.5, 0.75 / 14.25, 3, 6])
    with pytest.raises(SystemExit, match="give a strain above 0"):
        model_early.main([str(tmp_path / "run"), "--split", "0"])
    with pytest.raises(SystemExit, match="run `dem model` there first"):
        model_early.main([str(tmp_path)])


def test_the_whole_curve_gives_dem_models_prediction_table(tmp_path):
    work = model_friction.working_copy(os.path.join(ROOT, "data", "friction_n1000"), str(tmp_path / "work"), "1",
                                       "test_model_early")
    out = tmp_path / "pred"
    r = subprocess.run([DEM, "model", work, "--predict-with", os.path.join(LW, "parameters.csv"), "--family",
                        "extended", "--fabric-lode", "overlap", "--calibrate-on", "D2,D3", "--no-plots", "--out",
                        str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with open(out / "prediction.csv", newline="") as fh:
        want = {(f"{x['mode']}_phi{float(x['nu']):.3f}", x["quantity"].replace("_signed", "")): float(x["rms_over_band [-]"])
                for x in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}
    got = {(c.replace("paths/", ""), q): rms for c, q, rms, *_ in model_early.table(str(out), 0.1)}
    assert len(got) == 27 and set(got) == set(want)   # 6 curves + 3 isobaric paths, 3 quantities each
    for k, v in got.items():
        assert v == pytest.approx(want[k], rel=5e-3, abs=1e-3), k   # the table's three digits
    table = tmp_path / "early"
    model_early.main([str(out), "--table", str(table)])
    assert (tmp_path / "early.md").read_text().count("\n") == 27 + 3


def summary_rows(path):
    """summary.csv's curve rows without the role column (fitted there, predicted here) and the calibration row."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))
    return [r[:2] + r[3:] for r in rows[1:] if r[0] != "calibration"]


def test_predict_with_a_weighted_calibration_gives_its_stored_curves(tmp_path):
    """`--predict-with` a stored calibration under the weighted fabric rule was refused (the check that the calibration
    has a second Lode angle ran on the empty set of fitted curves); now it applies it, and its errors on every curve are
    the stored run's to the table's three digits (mu = 0.1, D2 + D3 calibration without the state limit)."""
    stored = os.path.join(os.path.dirname(LW), "..", "weighted_no_limit", "mu_0.1")
    work = model_friction.working_copy(os.path.join(ROOT, "data", "friction_n1000"), str(tmp_path / "work"), "0.1",
                                       "test_model_early")
    out = tmp_path / "pred"
    r = subprocess.run([DEM, "model", work, "--predict-with", os.path.join(stored, "parameters.csv"), "--family",
                        "extended", "--fabric-lode", "weighted", "--state-limit", "none", "--calibrate-on", "D2,D3",
                        "--no-plots", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    got, want = summary_rows(out / "summary.csv"), summary_rows(os.path.join(stored, "summary.csv"))
    assert len(got) == 9 and got == want
    # the closing line counts summary.csv's curves within 1 band and names the worst predicted one
    line = next(ln for ln in r.stderr.splitlines() if "curves within 1 band" in ln)
    worst = max(got, key=lambda row: float(row[-1]))
    assert line.startswith(f"dem model: {sum(float(row[-1]) <= 1 for row in got)} of 9 curves within 1 band"), line
    assert f"worst fitted none, worst predicted {worst[-1]} ({worst[0]} nu={worst[1]} " in line, line
    assert line.endswith("chi2/dof nan (nothing fitted) (summary.md)"), line


def test_the_chosen_variants_are_applied_and_checked_against_their_stored_runs(tmp_path):
    """--variants: each mu's chosen D2 + D3 variant (variants.csv) applied to a working copy, its summary held against
    the stored run's (equal, or within the table's last digit: said; else refused), the split table written."""
    lw = os.path.dirname(os.path.dirname(LW))
    out = tmp_path / "early"
    model_early.main(["--variants", lw, "--work", str(tmp_path / "work"), "--out", str(out), "--dem", DEM])
    chosen = model_early.chosen_runs(lw)
    assert [c[0] for c in chosen] == ["0", "0.01", "0.1", "0.3", "0.5", "1"]
    for mu, *_ in chosen:
        with open(out / f"early_mu_{mu}.csv") as fh:
            assert len([ln for ln in fh if not ln.startswith("#")]) == 1 + 27
    row = ["D2", "0.69", "0.5", "nan", "0.4"]
    assert model_early.same_curves([row], [row]) is True
    assert model_early.same_curves([row], [row[:4] + ["0.402"]]) is False
    assert model_early.same_curves([row], [row[:4] + ["0.41"]]) is None
    assert model_early.same_curves([row], [row[:3] + ["0.1", "0.4"]]) is None   # nan against a number
    with pytest.raises(SystemExit, match="needs --work and --out"):
        model_early.main(["--variants", lw])
