"""Where plastic flow starts (issue 31, twenty-eighth round): `dem model --dilatancy-gate mobilisation` (the plastic
dilatancy times the mobilisation r) and `--start-anisotropy unaligned` (s and F integrated as the aligned parts from 0,
observed as sqrt(x^2 + x0^2)), applied with --predict-with to the friction study's mu = 1 ensemble; their rows in
parameters.csv read back; refused where they do not apply; demkit.model_onset's table against model_variants' table
of the same stored runs (another implementation)."""
import csv
import os
import shutil
import subprocess
import sys

import pytest

from conftest import DEM, ROOT

sys.path.insert(0, ROOT)
from demkit import model_early, model_friction, model_onset  # noqa: E402

LWDIR = os.path.join(ROOT, "data", "friction_n1000", "model_friction", "lode_weight")
LW = os.path.join(LWDIR, "overlap_no_limit", "mu_1")


def predict(work, params, out, *extra):
    return subprocess.run([DEM, "model", work, "--predict-with", params, "--family", "extended", "--fabric-lode",
                           "overlap", "--calibrate-on", "D2,D3", "--no-plots", "--out", str(out), *extra],
                          capture_output=True, text=True)


def curve(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))


def parameter_rows(path):
    with open(path, newline="") as fh:
        return {r["parameter"]: r["value"] for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return model_friction.working_copy(os.path.join(ROOT, "data", "friction_n1000"),
                                       str(tmp_path_factory.mktemp("onset") / "work"), "1", "test_model_onset")


def test_both_options_are_written_read_back_and_undone(tmp_path, work):
    a = tmp_path / "both"
    r = predict(work, os.path.join(LW, "parameters.csv"), a, "--dilatancy-gate", "mobilisation",
                "--start-anisotropy", "unaligned")
    assert r.returncode == 0, r.stderr
    rows = parameter_rows(a / "parameters.csv")
    assert rows["dilatancy_gate"] == "1" and rows["start_anisotropy"] == "1"
    # the file's rows are read back: the same predictions without the options
    b = tmp_path / "again"
    assert predict(work, str(a / "parameters.csv"), b).returncode == 0
    assert model_early.curve_rows(a / "summary.csv") == model_early.curve_rows(b / "summary.csv")
    # ... and undone by the options: the stored run's predictions to their last digit (or within 0.002 band)
    c = tmp_path / "undone"
    assert predict(work, str(a / "parameters.csv"), c, "--dilatancy-gate", "none", "--start-anisotropy",
                   "aligned").returncode == 0
    assert "dilatancy_gate" not in parameter_rows(c / "parameters.csv")
    assert model_early.same_curves(model_early.curve_rows(c / "summary.csv"),
                                   model_early.curve_rows(os.path.join(LW, "summary.csv"))) is not None
    assert model_early.curve_rows(a / "summary.csv") != model_early.curve_rows(c / "summary.csv")
    # the unaligned start shows the measured start values on the first row
    for f in ("D2_phi0.690.csv", "D3_phi0.800.csv", os.path.join("paths", "isobaric_phi0.800.csv")):
        first = curve(a / "curves" / f)[0]
        for q in ("s_dev", "F_dev"):
            assert float(first[q + "_model"]) == pytest.approx(float(first[q + "_mean"]), rel=1e-6), (f, q)


def test_the_gate_starts_the_isobaric_volume_flat(tmp_path, work):
    """The stored mu = 1 calibration contracts the isobaric nu = 0.80 path from the first step at d_D chi_D per unit
    eps_d (chi_D = 3); gated by r (about 0.05 at eps_d = 0.009 there), the first rows' contraction falls tenfold."""
    plain, gated = tmp_path / "plain", tmp_path / "gated"
    assert predict(work, os.path.join(LW, "parameters.csv"), plain).returncode == 0
    assert predict(work, os.path.join(LW, "parameters.csv"), gated, "--dilatancy-gate", "mobilisation").returncode == 0
    p = curve(plain / "curves" / "paths" / "isobaric_phi0.800.csv")
    g = curve(gated / "curves" / "paths" / "isobaric_phi0.800.csv")
    assert float(p[3]["eps_d_accumulated"]) == pytest.approx(0.009, abs=1e-3)
    assert float(p[3]["eps_v_model"]) < -5e-5
    assert abs(float(g[3]["eps_v_model"])) < 0.1 * abs(float(p[3]["eps_v_model"]))


@pytest.mark.parametrize("extra, fix", [
    (["--family", "group", "--dilatancy-gate", "mobilisation"], "give --family extended"),
    (["--family", "extended", "--state-limit", "volume", "--dilatancy-gate", "mobilisation"], "driven by psi"),
    (["--family", "extended", "--dilatancy-gate", "yes"], "dilatancy-gate"),
    (["--family", "extended", "--start-anisotropy", "random"], "start-anisotropy"),
    # the thirtieth round's options (test_model_deviator.py)
    (["--family", "extended", "--fabric-limit", "state"], "--state-limit pressure"),
    (["--family", "group", "--deviator-volume", "reference"], "give --family extended"),
    (["--family", "extended", "--state-limit", "volume", "--deviator-volume", "reference"], "without --state-limit volume"),
    (["--family", "extended", "--deviator-volume", "yes"], "deviator-volume"),
])
def test_the_options_are_refused_where_they_do_not_apply(tmp_path, work, extra, fix):
    r = subprocess.run([DEM, "model", work, "--out", str(tmp_path / "x"), "--no-plots", *extra], capture_output=True,
                       text=True)
    assert r.returncode != 0 and fix in r.stderr, r.stderr
    assert not (tmp_path / "x" / "summary.csv").exists()


def test_the_onset_table_gives_the_variant_tables_numbers(tmp_path):
    """Two stored mu = 1 variants stand in for a run and its alternative (the chosen overlap, and weighted as OUT/gate):
    the onset table's chi2/dof, worst curves and held-out means are model_variants' for those variants."""
    shutil.copytree(os.path.join(LWDIR, "weighted_no_limit", "mu_1"), tmp_path / "gate" / "mu_1")
    model_onset.table(LWDIR, str(tmp_path), "gate", ["1"])
    with open(tmp_path / "gate.csv", newline="") as fh:
        got = {r["start"]: r for r in csv.DictReader(fh)}
    with open(os.path.join(LWDIR, "variants.csv"), newline="") as fh:
        want = {r["variant"]: r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#")) if r["mu"] == "1"}
    for start, variant in (("stored", "overlap"), ("alternative", "weighted")):
        for col in ("chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]",
                    "worst_predicted_isobaric [band]", "heldout_mean [-]"):
            assert float(got[start][col]) == pytest.approx(float(want[variant][col]), rel=2e-3), (start, col)
    assert sum(r["chosen"] == "yes" for r in got.values()) == 1
    assert "| 1 | overlap |" in (tmp_path / "gate.md").read_text()
    with pytest.raises(SystemExit, match="run without --table-only first"):
        model_onset.table(LWDIR, str(tmp_path), "both", ["1"])


def test_the_choice_needs_a_win_on_one_score_and_no_loss_on_the_other():
    """decide() on hand-built paired scores (K = 4; t_{3,0.975} = 3.18): the alternative lower by 1 everywhere with a
    spread of 0.1 wins; lower on the paths but higher on the fitted curves, it is not chosen; within the spread on both,
    the stored run stays."""
    base = {k: 2.0 + 0.1 * k for k in range(4)}
    lower = {k: v - 1.0 + (0.05 if k % 2 else -0.05) for k, v in base.items()}
    higher = {k: v + 1.0 + (0.05 if k % 2 else -0.05) for k, v in base.items()}
    close = {k: v + (0.05 if k % 2 else -0.05) for k, v in base.items()}
    chosen, tests = model_onset.decide({"stored": base, "alternative": lower}, {"stored": base, "alternative": lower})
    assert chosen == "alternative" and tests["paths"][3] == "alternative" and tests["fitted"][0] == pytest.approx(1.0)
    chosen, tests = model_onset.decide({"stored": base, "alternative": higher}, {"stored": base, "alternative": lower})
    assert chosen == "stored" and tests["fitted"][3] == "stored" and tests["paths"][3] == "alternative"
    chosen, tests = model_onset.decide({"stored": base, "alternative": close}, {"stored": base, "alternative": close})
    assert chosen == "stored" and tests["fitted"][3] is None and tests["paths"][3] is None
    chosen, tests = model_onset.decide({"stored": base, "alternative": lower}, {"stored": {}, "alternative": lower})
    assert chosen == "alternative" and tests["paths"] is None   # a run without path scores: the fitted test alone


def test_the_jackknife_scores_each_packings_predicted_paths(tmp_path):
    """The group model on the quasi-static path ensemble, calibrated on D2 and the reversal path: the jackknife writes
    each left-out packing's score on its own predicted (cyclic, isobaric, triaxial) paths beside the fitted curves'
    score (a run without predicted paths writes no such column: the stored runs before this round). One packing's own
    isobaric path is made to start below jamming (nu = 0.5, hand-edited): its score is nan, and (thirty-fifth round)
    heldout_followed_paths scores its other paths while paths_not_followed names that one and why; the other packings'
    two scores agree."""
    paths = tmp_path / "qs16"
    src = os.path.join(ROOT, "data", "model_paths_qs16")
    shutil.copytree(src, paths, ignore=lambda d, names: [n for n in names if n.startswith("model")] if d == src else [])
    bad = paths / "members" / "m003" / "paths" / "isobaric_phi0.740.csv"
    lines = bad.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("eps_d_accumulated"))
    assert lines[head].split(",")[1] == "nu"
    first = lines[head + 1].split(",")
    first[1] = "0.5"
    lines[head + 1] = ",".join(first)
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "pred"
    r = subprocess.run([DEM, "model", str(paths), "--out", str(out), "--no-plots", "--calibrate-on", "D2,reversal"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    scores = model_onset.path_scores(str(out))
    fitted = model_onset.model_state_limit.extended_scores(str(out))
    assert len(fitted) >= 4 and len(scores) == len(fitted) - 1
    assert all(0.05 < v < 50 for v in scores.values()), scores   # in units of the between-packing variance
    held = curve(out / "heldout.csv")
    lost = [h for h in held if h["paths_not_followed"]]
    assert len(lost) == 1 and lost[0]["heldout_predicted_paths [-]"] == "nan", lost
    why = lost[0]["paths_not_followed"]
    assert why.startswith("isobaric nu=0.74 (cannot start: ") and str(bad) in why and "nu = 0.500000" in why, why
    assert 0.05 < float(lost[0]["heldout_followed_paths [-]"]) < 50
    for h in held:
        if h is not lost[0]:
            assert h["heldout_followed_paths [-]"] == h["heldout_predicted_paths [-]"]


def test_the_stored_onset_table_is_rebuilt_from_the_stored_runs(tmp_path):
    """data/.../lode_weight/onset/gate.{md,csv} from its stored runs (the reruns in none/, the gated in gate/)."""
    src = os.path.join(LWDIR, "onset")
    for sub in ("none", "gate"):
        shutil.copytree(os.path.join(src, sub), tmp_path / sub)
    model_onset.main(["--variants", LWDIR, "--out", str(tmp_path), "--mu", "0", "0.01", "0.1", "0.3", "0.5", "1",
                      "--table-only"])
    for name in ("gate.md", "gate.csv"):
        assert (tmp_path / name).read_text() == open(os.path.join(src, name)).read(), name


def read_rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_versus_sets_the_variant_with_fewer_coefficients_left_with_the_current_choices_numbers(tmp_path):
    """--versus (twenty-ninth round): the stored weighted + Lode-limit runs of the eighth round stand in for a
    candidate's rerun and gated run (the same folder twice, so its own table keeps the rerun). Against the stored onset
    choice (weighted at mu = 0.5, overlap + gate at mu = 1): the current variant (9 and 7 coefficients) stands left with
    the numbers gate.csv gives its chosen run, the candidate (12) right with variants.csv's numbers; one is chosen."""
    for mu in ("0.5", "1"):
        for tag in ("none_weighted_lode_limit", "gate_weighted_lode_limit"):
            shutil.copytree(os.path.join(LWDIR, "weighted_lode_limit", f"mu_{mu}"), tmp_path / tag / f"mu_{mu}")
    model_onset.table(LWDIR, str(tmp_path), "gate", ["0.5", "1"], "weighted + Lode limit")
    model_onset.versus(LWDIR, str(tmp_path), "gate", ["0.5", "1"], "weighted + Lode limit", os.path.join(LWDIR, "onset"))
    got = read_rows(tmp_path / "versus_gate_weighted_lode_limit.csv")
    current = {r["mu"]: r for r in read_rows(os.path.join(LWDIR, "onset", "gate.csv")) if r["chosen"] == "yes"}
    with open(os.path.join(LWDIR, "variants.csv"), newline="") as fh:
        stored = {r["mu"]: r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))
                  if r["variant"] == "weighted + Lode limit"}
    cols = ("chi2_per_dof [-]", "worst_fitted_D2 [band]", "worst_fitted_D3 [band]", "worst_predicted_isobaric [band]",
            "heldout_mean [-]")
    for mu, left in (("0.5", "weighted"), ("1", "overlap + gate")):
        rows = {r["side"]: r for r in got if r["mu"] == mu}
        assert rows["left"]["variant"] == left and rows["right"]["variant"] == "weighted + Lode limit"
        for col in cols:
            assert float(rows["left"][col]) == pytest.approx(float(current[mu][col]), rel=1e-3), (mu, col)
            assert float(rows["right"][col]) == pytest.approx(float(stored[mu][col]), rel=2e-3), (mu, col)
        assert sum(r["chosen"] == "yes" for r in rows.values()) == 1
    md = (tmp_path / "versus_gate_weighted_lode_limit.md").read_text()
    assert "| 1 | overlap + gate → weighted + Lode limit |" in md and "not scored" in md   # the stored runs predate the path score
    with pytest.raises(SystemExit, match="give --variant"):
        model_onset.main(["--variants", LWDIR, "--out", str(tmp_path), "--table-only", "--versus", LWDIR])
    with pytest.raises(SystemExit, match="make that table first"):
        model_onset.versus(LWDIR, str(tmp_path), "both", ["1"], "weighted + Lode limit", os.path.join(LWDIR, "onset"))


def test_the_stored_lode_limit_tables_are_rebuilt_from_the_stored_runs(tmp_path):
    """data/.../onset/lode_limit: the gate tables and the versus tables of both Lode-limit variants from the stored
    runs, byte for byte (the mu of each table read from its csv)."""
    src = os.path.join(LWDIR, "onset", "lode_limit")
    for sub in os.listdir(src):
        if os.path.isdir(os.path.join(src, sub)):
            shutil.copytree(os.path.join(src, sub), tmp_path / sub)
    for variant, tag in (("weighted + Lode limit", "gate_weighted_lode_limit"),
                         ("overlap + Lode limit", "gate_overlap_lode_limit")):
        mus = list(dict.fromkeys(r["mu"] for r in read_rows(os.path.join(src, tag + ".csv"))))
        model_onset.main(["--variants", LWDIR, "--out", str(tmp_path), "--mu", *mus, "--table-only", "--variant",
                          variant, "--versus", os.path.join(LWDIR, "onset")])
        for name in (tag, "versus_" + tag):
            for ext in (".md", ".csv"):
                assert (tmp_path / (name + ext)).read_text() == open(os.path.join(src, name + ext)).read(), name + ext


def test_the_model_only_isobaric_path_is_the_predicted_isobaric_path(tmp_path, work):
    """The model-only paths a calibration writes (curves/isobaric_phiX.csv, from the D2 curve's start state, Segments of
    `integrate`) run the calibration's own family and options: at mu = 1 with the gate they are the predicted isobaric
    paths on the DEM's rows (curves/paths/, `integrate_rows`), which start from the same state, to 1e-3 of the curve's
    range (before, they ran the group model's right-hand side, and the D3 curve's start overwrote the D2 one's)."""
    import numpy as np
    out = tmp_path / "m"
    r = subprocess.run([DEM, "model", work, "--out", str(out), "--family", "extended", "--fabric-lode", "overlap",
                        "--calibrate-on", "D2,D3", "--start", os.path.join(LWDIR, "onset", "gate", "mu_1",
                                                                           "parameters.csv"),
                        "--max-iterations", "1", "--no-jackknife", "--no-plots", "--dilatancy-gate", "mobilisation"],
                       capture_output=True, text=True)
    assert r.returncode in (0, 1), r.stderr   # 1: stopped at its one iteration (said in its tables)
    for tag in ("0.690", "0.800"):
        a, b = curve(out / "curves" / f"isobaric_phi{tag}.csv"), curve(out / "curves" / "paths" / f"isobaric_phi{tag}.csv")
        ea = np.array([float(x["eps_d_accumulated"]) for x in a])
        eb = np.array([float(x["eps_d_accumulated"]) for x in b])
        for qa, qb, scale in (("eps_vol", "eps_v_model", 1 / 3), ("s_dev", "s_dev_model", 1), ("F_dev", "F_dev_model", 1)):
            ya = np.array([float(x[qa]) * scale for x in a])
            yb = np.array([float(x[qb]) for x in b])
            on = eb <= ea[-1]
            assert np.allclose(np.interp(eb[on], ea, ya), yb[on], atol=1e-3 * np.ptp(yb[on])), (tag, qa)
