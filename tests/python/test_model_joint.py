"""One calibration for the constant-volume and the laboratory tests (issue 31, thirty-first round, demkit.model_joint):
the stored mu = 0.5 parameters predict, on an ensemble regenerated from the stored curves, every curve of the stored
summary to its digits; the stored tables (joint, the mu = 0.5 variants) rebuilt byte for byte; the grouping on hand-built rows (not integrable, lost); the calibration's
command line."""
import csv
import glob
import filecmp
import os
import shutil
import subprocess
import sys

import pytest

from conftest import DEM, ROOT

sys.path.insert(0, ROOT)
from demkit import model_joint  # noqa: E402

STORED = os.path.join(ROOT, model_joint.OUT)
# the joint folder as it stood before issue 31's thirty-sixth round (the fixed RK4 step): the two-sample jackknife, the
# variants at mu = 0.5 and their held-out choice were made there and are not rerun
FIXED = os.path.join(STORED, "fixed_step")


def ensemble_from_root(tmp_path):
    """model_joint.ensemble at mu = 0.5, run from the repository root (its paths are relative), into TMP_PATH/work."""
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        return model_joint.ensemble("0.5", str(tmp_path / "work"))
    finally:
        os.chdir(cwd)


def rows_of(path):
    with open(path, newline="") as fh:
        return [r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#")) if r["mode"] != "calibration"]


def test_the_stored_parameters_predict_every_stored_curve_again(tmp_path):
    """mu = 0.5: the ensemble rebuilt from data/geotech/curves and the friction study (both preparations, D2/D3, the
    isobaric paths), every curve predicted with the stored parameters: each error of the stored summary (fitted or
    predicted) to its printed digits."""
    ens = ensemble_from_root(tmp_path)
    out = tmp_path / "pred"
    r = subprocess.run([DEM, "model", ens, "--predict-with", os.path.join(STORED, "mu_0.5", "parameters.csv"),
                        "--family", "extended", "--no-plots", "--out", str(out)], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    stored = {(x["mode"], x["nu [-]"]): x for x in rows_of(os.path.join(STORED, "mu_0.5", "summary.csv"))}
    again = {(x["mode"], x["nu [-]"]): x for x in rows_of(out / "summary.csv")}
    assert set(stored) == set(again) and len(stored) == 6 + 14 + 14 + 3
    for key, x in stored.items():
        for q in ("p_star [band]", "eps_v [band]", "s_dev [band]", "F_dev [band]"):
            assert again[key][q] == x[q], (key, q)


@pytest.mark.parametrize("folder, tables", [(STORED, ["joint"]),
                                            (FIXED, ["joint", os.path.join("variants_mu_0.5", "variants")])],
                         ids=["today", "fixed_step"])
def test_the_stored_tables_rebuild_byte_for_byte(tmp_path, folder, tables):
    out = tmp_path / "out"
    shutil.copytree(folder, out, ignore=shutil.ignore_patterns("fixed_step"))
    for t in tables:
        for ext in ("md", "csv"):
            (out / f"{t}.{ext}").unlink()
    model_joint.write(str(out))
    for t in tables:
        for ext in ("md", "csv"):
            assert filecmp.cmp(out / f"{t}.{ext}", os.path.join(folder, f"{t}.{ext}"), shallow=False), (t, ext)


def test_one_parameter_set_holds_the_constant_volume_and_the_laboratory_curves_within_a_few_bands():
    """The stored mu = 0.5 calibration: D2/D3 and TC_s3 within 2.5 bands; every laboratory curve of both preparations
    predicted and finite, within 4 bands; where the D2 + D3 choice alone predicted 7 loose curves as not integrable
    and the dense ones up to 26 bands (data/geotech/model/choice_blind)."""
    chi, rows = model_joint.read(os.path.join(STORED, "mu_0.5", "summary.csv"))
    g = model_joint.groups(rows)
    assert g["D2 + D3"][2] < 2.5 and g["TC_s3 dense"][2] < 2.5
    assert g["dense laboratory"][0] == 12 and g["dense laboratory"][2] < 4.0
    assert g["loose laboratory"][0] == 14 and g["loose laboratory"][2] < 4.0
    assert 3.0 < chi < 20.0   # the target's chi2/dof <= 3 is not met


def test_groups_on_hand_built_rows():
    rows = [("D2", "0.69", "fitted", 0.5, "s_dev"), ("D3", "0.8", "fitted", 1.5, "F_dev"),
            ("TC_s3_dense", "0.658", "fitted", 0.9, "eps_v"), ("TE_p_dense", "0.682", "predicted", 3.0, "F_dev"),
            ("TC_p_loose", "0.593", "predicted", 1.0, "eps_v"), ("isobaric", "0.69", "predicted", 4.0, "eps_v"),
            ("TC_p_loose", "0.6", "predicted, not integrable (nu0 <= nu_c)", float("nan"), "nan")]
    g = model_joint.groups(rows)
    assert g["D2 + D3"] == (2, 1, 1.5, "D3 0.800 F_dev", 0)
    assert g["TC_s3 dense"] == (1, 1, 0.9, "TC_s3_dense 0.658 eps_v", 0)
    assert g["dense laboratory"] == (1, 0, 3.0, "TE_p_dense 0.682 F_dev", 0)
    assert g["loose laboratory"] == (2, 1, 1.0, "TC_p_loose 0.593 eps_v", 1)
    assert model_joint.cell(g["loose laboratory"]) == "1/2, 1 (TC_p_loose 0.593 eps_v), 1 not integrable"
    assert g["isobaric D2"][2] == 4.0
    lost = model_joint.groups([("TE_s3_dense", "0.658", "predicted", float("inf"), "p_star")])
    assert lost["dense laboratory"] == (1, 0, float("inf"), "TE_s3_dense 0.658 p_star", 0)


def test_the_calibration_line_names_its_start_and_holds():
    cmd = model_joint.command("0.3", "ENS", "OUT", "dem", jackknife=False)
    assert cmd[cmd.index("--start") + 1].endswith(os.path.join("state_volume", "mu_0.3", "dense", "parameters.csv"))
    assert cmd[cmd.index("--calibrate-on") + 1] == "D2,D3,TC_s3_dense"
    assert cmd[cmd.index("--state-limit") + 1] == "volume"
    assert "--no-jackknife" in cmd
    assert model_joint.start_of("0.5").endswith(os.path.join("state_volume", "dense", "parameters.csv"))
    with pytest.raises(SystemExit):
        model_joint.main(["--out", "/nonexistent/joint", "--table-only"])


def test_the_friction_means_come_back_from_the_members(tmp_path):
    """The two-sample jackknife's leave-one-out means are computed from the members as `dem ensemble` does: with every
    member they are the stored ensemble means to their printed digits; without one, K = 7 and the mean moves."""
    fmu = os.path.join(ROOT, "data", "friction_n1000", "mu_0.5")
    members = sorted(os.path.join(fmu, "members", m) for m in os.listdir(os.path.join(fmu, "members")))
    model_joint.friction_means(fmu, members, str(tmp_path / "all"), "all")
    model_joint.friction_means_without(fmu, "m003", str(tmp_path / "loo"))
    for name in ("D2_phi0.690.csv", "D3_phi0.800.csv"):
        _, stored = model_joint.read_columns(os.path.join(fmu, "ensemble", name))
        _, again = model_joint.read_columns(str(tmp_path / "all" / "ensemble" / name))
        _, loo = model_joint.read_columns(str(tmp_path / "loo" / "ensemble" / name))
        for q in ("p_star_mean", "s_dev_mean", "F_dev_sd", "s_dev_lo95"):
            assert again[q] == pytest.approx(stored[q], rel=1e-8, abs=1e-10), (name, q)
        assert set(loo["n_packings"]) == {7.0}
        assert not loo["s_dev_mean"] == pytest.approx(stored["s_dev_mean"], rel=1e-6)
    with pytest.raises(SystemExit):
        model_joint.friction_means_without(fmu, "m099", str(tmp_path / "bad"))


def test_the_two_sample_jackknife_on_hand_built_refits(tmp_path):
    """se^2 = (n_f - 1)/n_f sum (x_i - mean)^2 over the friction refits + the same over the laboratory's; a coefficient
    without a covariance error (held) is left out."""
    def write(path, a, held=1.0):
        path.write_text("parameter,law,value,se,se_method,lo95,hi95,se_covariance,se_jackknife,units\n"
                        f"s_max_a,x,{a!r},0.1,covariance,0,0,0.01,nan,-\n"
                        f"gamma_p,x,{held!r},nan,fixed,nan,nan,nan,nan,-\n")
        return str(path)
    full = write(tmp_path / "full.csv", 1.0)
    xf, xl = [1.0, 1.1, 0.9, 1.2], [1.0, 1.3, 0.8]
    refits = {("friction", f"m{i}"): write(tmp_path / f"f{i}.csv", v) for i, v in enumerate(xf)}
    refits.update({("laboratory", f"m{i}"): write(tmp_path / f"l{i}.csv", v) for i, v in enumerate(xl)})
    rows = model_joint.jackknife_rows(full, refits)
    assert [r[0] for r in rows] == ["s_max_a"]
    import numpy as np
    sf = np.sqrt(3 / 4 * np.sum((np.array(xf) - np.mean(xf)) ** 2))
    sl = np.sqrt(2 / 3 * np.sum((np.array(xl) - np.mean(xl)) ** 2))
    name, value, cov, f, lab, j = rows[0]
    assert (value, cov) == (1.0, 0.01)
    assert f == pytest.approx(sf) and lab == pytest.approx(sl) and j == pytest.approx(np.hypot(sf, sl))


JACKKNIFED = sorted(d[len("mu_"):] for d in os.listdir(FIXED)
                    if os.path.isdir(os.path.join(FIXED, d, "jackknife_refits")))


def test_the_jackknife_is_stored_at_mu_0_5():
    assert "0.5" in JACKKNIFED


@pytest.mark.parametrize("mu", JACKKNIFED)
def test_the_stored_jackknife_table_rebuilds_from_its_refits(tmp_path, mu):
    """jackknife_two_sample.{md,csv} from the 12 stored refits (8 friction, 4 laboratory), byte for byte; every refit
    within twice the full fit's chi2/dof (one basin), the errors above the covariance's in most coefficients."""
    stored = os.path.join(FIXED, f"mu_{mu}")
    refits = os.path.join(stored, "jackknife_refits")
    runs = {tuple(d.split("_", 1)): os.path.join(refits, d) for d in sorted(os.listdir(refits))}
    assert sorted(k[0] for k in runs).count("friction") == 8 and sorted(k[0] for k in runs).count("laboratory") == 4
    out = tmp_path / "out"
    shutil.copytree(stored, out / f"mu_{mu}")
    model_joint.write_jackknife(mu, str(out), os.path.join(stored, "parameters.csv"), runs)
    for ext in ("md", "csv"):
        assert filecmp.cmp(out / f"mu_{mu}" / f"jackknife_two_sample.{ext}",
                           os.path.join(stored, f"jackknife_two_sample.{ext}"), shallow=False), ext
    full = float(model_joint.free_values(os.path.join(stored, "parameters.csv"))["chi2_per_dof"]["value"])
    for run in runs.values():
        chi = float(model_joint.free_values(os.path.join(run, "parameters.csv"))["chi2_per_dof"]["value"])
        assert chi < 2 * full, run
    rows = model_joint.jackknife_rows(os.path.join(stored, "parameters.csv"),
                                      {k: os.path.join(r, "parameters.csv") for k, r in runs.items()})
    assert sum(j > c for *_, c, f, lab, j in rows) > len(rows) // 2


def test_the_friction_members_join_the_laboratory_members(tmp_path):
    """ensemble() puts the friction study's packings beside the laboratory's in one members/ (their D2/D3 curves and
    isobaric paths, no isotropic branch), so `dem model`'s jackknife leaves out either set's packings; a name both
    sets use is refused."""
    ens = ensemble_from_root(tmp_path)
    members = sorted(os.listdir(os.path.join(ens, "members")))
    friction = [m for m in members if os.path.isdir(os.path.join(ens, "members", m, "deviatoric"))]
    lab = [m for m in members if os.path.exists(os.path.join(ens, "members", m, "prep", "cycle_unloading.csv"))]
    assert len(friction) == 8 and len(lab) == 4 and not set(friction) & set(lab)
    for m in friction:
        dev = sorted(os.listdir(os.path.join(ens, "members", m, "deviatoric")))
        assert dev == [f"{mode}_phi{nu}.csv" for mode in ("D2", "D3") for nu in ("0.690", "0.740", "0.800")]
        assert not os.path.exists(os.path.join(ens, "members", m, "prep"))
        assert sorted(os.listdir(os.path.join(ens, "members", m, "paths"))) == [
            f"isobaric_phi{nu}.csv" for nu in ("0.690", "0.740", "0.800")]
    with pytest.raises(SystemExit, match="different names"):
        model_joint.add_friction_members(os.path.join(ROOT, "data", "friction_n1000", "mu_0.5"), str(tmp_path), ens)


def test_the_held_out_choice_on_hand_built_runs(tmp_path):
    """The joint calibration (overlap) against its variants, paired over the packings of both sets: a variant is
    chosen over the overlap rule only when it beats it; a variant with a failed refit is not scored."""
    def run(name, scores, coefficients, usable=None):
        d = tmp_path / name
        d.mkdir(parents=True)
        rows = "".join(f"{k},m{k},{int(k >= 8)},{s!r}\n" for k, s in enumerate(scores))
        (d / "heldout.csv").write_text("# held-out\npacking_left_out,packing,set,heldout_extended [-]\n" + rows)
        usable = usable or ["yes"] * len(scores)
        (d / "jackknife.csv").write_text("packing_left_out,set,usable\n" + "".join(
            f"m{k},{int(k >= 8)},{u}\n" for k, u in enumerate(usable)))
        (d / "parameters.csv").write_text("parameter,value,se_method,se_covariance\n" + "".join(
            f"c{i},1,jackknife over packings,0.1\n" for i in range(coefficients)) + "nu_ref,0.74,fixed,nan\n"
            "chi2_per_dof,2.0,nan,nan\n")
    base = [2.0, 2.1, 1.9, 2.2, 2.0, 1.8, 2.1, 2.0, 5.0, 5.2, 4.8, 5.1]
    run("mu_0.5", base, 33)
    run("variants_mu_0.5/weighted", [x - 0.5 for x in base], 35)            # better by 0.5 everywhere: beats overlap
    run("variants_mu_0.5/bounded", base, 33, ["yes"] * 11 + ["no"])
    assert model_joint.heldout_choice("0.5", str(tmp_path)) == "weighted"
    md = (tmp_path / "variants_mu_0.5" / "heldout_choice.md").read_text()
    assert "not scored: its refits without m11 failed" in md
    run("variants_mu_0.5/weighted2", [x + (0.3 if k % 2 else -0.3) for k, x in enumerate(base)], 35)
    shutil.rmtree(tmp_path / "variants_mu_0.5" / "weighted")
    (tmp_path / "variants_mu_0.5" / "weighted2").rename(tmp_path / "variants_mu_0.5" / "weighted")
    assert model_joint.heldout_choice("0.5", str(tmp_path)) == "overlap"   # no consistent gain: the fewer coefficients
    with open(tmp_path / "variants_mu_0.5" / "heldout_choice.csv", newline="") as fh:
        rows = {r["variant"]: r for r in csv.DictReader(fh)}
    assert rows["overlap"]["coefficients"] == "33" and rows["weighted"]["coefficients"] == "35"
    assert float(rows["overlap"]["heldout_laboratory_mean [-]"]) == pytest.approx(sum(base[8:]) / 4)
    # a variant that cannot predict some packings (their scores not numbers) is not compared, however good elsewhere
    shutil.rmtree(tmp_path / "variants_mu_0.5" / "bounded")
    run("variants_mu_0.5/bounded", [float("nan") if k in (0, 3) else x - 1.0 for k, x in enumerate(base)], 33)
    assert model_joint.heldout_choice("0.5", str(tmp_path)) == "overlap"
    md = (tmp_path / "variants_mu_0.5" / "heldout_choice.md").read_text()
    assert "not compared: the held-out predictions of m0, m3 are not numbers" in md
    with open(tmp_path / "variants_mu_0.5" / "heldout_choice.csv", newline="") as fh:
        rows = {r["variant"]: r for r in csv.DictReader(fh)}
    assert rows["bounded"]["chosen"] == "not predicting m0 m3" and rows["bounded"]["packings"] == "10"
    assert float(rows["bounded"]["heldout_friction_mean [-]"]) == pytest.approx(
        sum(x - 1.0 for k, x in enumerate(base[:8]) if k not in (0, 3)) / 6), "the mean over the predicted ones"


@pytest.mark.parametrize("mu", ["0", "0.1", "0.3", "0.5", "1"])
def test_the_stored_dem_model_jackknife_over_both_sets(mu):
    """mu = 0.3, 0.5 (thirty-second round), 0 and 0.1 (thirty-third), 1 (thirty-fourth) with `dem model`'s jackknife: 12 usable refits, the friction study's 8
    packings in one set and the laboratory's 4 in the other; every quoted error recomputed from jackknife_estimates.csv
    set by set; the intervals' t on Welch-Satterthwaite's degrees of freedom (between the smaller set's n - 1 = 3 and
    10)."""
    import math
    from scipy import stats
    d = os.path.join(STORED, f"mu_{mu}")
    with open(os.path.join(d, "jackknife.csv"), newline="") as fh:
        refits = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    assert len(refits) == 12 and all(r["usable"] == "yes" for r in refits)
    assert [r["set"] for r in refits] == ["0"] * 8 + ["1"] * 4
    assert all(r["packing_left_out"].startswith("m00") for r in refits[:8])
    with open(os.path.join(d, "jackknife_estimates.csv"), newline="") as fh:
        est = list(csv.DictReader(fh))
    params = model_joint.free_values(os.path.join(d, "parameters.csv"))
    quoted = 0
    for name, q in params.items():
        if q.get("se_method") != "jackknife over packings" or not math.isfinite(float(q["se"])):
            continue
        parts = []
        for s in ("0", "1"):
            x = [float(e[name]) for e in est if e["set"] == s]
            m = sum(x) / len(x)
            parts.append((len(x) - 1) / len(x) * sum((v - m) ** 2 for v in x))
        assert float(q["se"]) == pytest.approx(math.sqrt(sum(parts)), rel=1e-5), name
        dof = sum(parts) ** 2 / (parts[0] ** 2 / 7 + parts[1] ** 2 / 3)
        hi, se = float(q["hi95"]), float(q["se"])
        t = (hi - float(q["value"])) / se
        rounding = 0.5 * 10 ** (math.floor(math.log10(abs(hi))) - 5) / se   # hi95: six digits, half its last
        assert t == pytest.approx(stats.t.ppf(0.975, dof), rel=1e-4, abs=rounding), name
        assert stats.t.ppf(0.975, 10) * 0.999 <= t <= stats.t.ppf(0.975, 3) * 1.001, name
        quoted += 1
    # mu = 0: fewer act (n_dil: below), and since its thirty-seventh-round rerun ln_beta_F_b ends on its bound 40;
    # mu = 1: five on bounds
    assert quoted >= {"0": 17, "1": 19}.get(mu, 20)
    if mu == "0":
        assert float(params["ln_beta_F_b"]["value"]) == 40.0 and params["ln_beta_F_b"]["se"] == "nan"
    for name, q in params.items():   # refits all within round-off of one value quote no error (thirty-third round)
        x = [float(e[name]) for e in est] if name in est[0] else []
        if x and all(abs(v - x[0]) <= 1e-12 * abs(x[0]) for v in x):
            assert not math.isfinite(float(q["se"])), name
    if mu == "0":
        assert params["n_dil"]["se"] == "nan"
    with open(os.path.join(d, "heldout.csv"), newline="") as fh:
        held = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    assert [h["packing"] for h in held] == [r["packing_left_out"] for r in refits]
    assert all(math.isfinite(float(h["heldout_extended [-]"])) for h in held)


def test_keep_weights_copies_the_spread_of_the_same_mode_at_the_nearest_nu(tmp_path):
    """A leave-one-out ensemble's file named by its own mean start state (TC_s3_dense_phi0.657 against the full
    ensemble's 0.658) takes the full file's spread columns and n_packings; its means stay; a mode the full ensemble does
    not hold is left alone; files of different rows are refused."""
    def write(path, rows, mean, se, k):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("# x\neps_d_accumulated,n_packings,p_star_mean,p_star_se,p_star_lo95\n" + "".join(
            f"{i},{k},{mean + i},{se},{mean - se}\n" for i in range(rows)))
    full, loo = tmp_path / "full", tmp_path / "loo"
    write(full / "paths" / "TC_s3_dense_phi0.658.csv", 3, 1.0, 0.1, 4)
    write(full / "paths" / "TC_s3_dense_phi0.682.csv", 3, 5.0, 0.5, 4)
    write(loo / "paths" / "TC_s3_dense_phi0.657.csv", 3, 1.5, 0.3, 3)
    write(loo / "paths" / "TE_s3_dense_phi0.657.csv", 3, 2.0, 0.7, 3)
    model_joint.keep_weights(str(loo), str(full))
    _, c = model_joint.read_columns(str(loo / "paths" / "TC_s3_dense_phi0.657.csv"))
    assert list(c["p_star_mean"]) == [1.5, 2.5, 3.5] and set(c["p_star_se"]) == {0.1}
    assert set(c["p_star_lo95"]) == {0.9} and set(c["n_packings"]) == {4.0}
    _, e = model_joint.read_columns(str(loo / "paths" / "TE_s3_dense_phi0.657.csv"))
    assert set(e["p_star_se"]) == {0.7}
    write(loo / "paths" / "TC_s3_dense_phi0.681.csv", 2, 5.0, 0.5, 3)
    with pytest.raises(SystemExit, match="differ in rows"):
        model_joint.keep_weights(str(loo), str(full))


def test_the_stored_crosscheck_agrees_to_a_thousandth_of_an_error():
    """jackknife_crosscheck.csv: `dem model`'s refits without friction m003 and laboratory m2 against refits on
    ensembles this module rebuilt without them (the full weights kept): within 1e-3 jackknife errors, chi2/dof within
    1e-4 relative."""
    with open(os.path.join(FIXED, "mu_0.5", "jackknife_crosscheck.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted((r["set"], r["packing_left_out"]) for r in rows) == [("friction", "m003"), ("laboratory", "m2")]
    for r in rows:
        assert float(r["largest_difference [se]"]) < 1e-3, r
        assert float(r["chi2_per_dof_rebuilt"]) == pytest.approx(float(r["chi2_per_dof_dem"]), rel=1e-4), r


def test_the_stored_held_out_choice_rebuilds_and_keeps_the_overlap_rule(tmp_path):
    """variants_mu_0.5/heldout_choice.{md,csv} from the stored runs' heldout.csv and jackknife.csv, byte for byte: the
    weighted rule does not beat the overlap rule over the 12 packings (the overlap rule, with fewer coefficients, is
    kept). The bounded variant's refits all run since the thirty-third round (a start beyond the isotropic law's reach
    is moved within it), but it cannot predict five friction packings held out (their own start pressure at nu = 0.80
    lies above the refit's reach): it is not compared."""
    out = tmp_path / "out"
    shutil.copytree(FIXED, out)
    for ext in ("md", "csv"):
        (out / "variants_mu_0.5" / f"heldout_choice.{ext}").unlink()
    assert model_joint.heldout_choice("0.5", str(out)) == "overlap"
    for ext in ("md", "csv"):
        assert filecmp.cmp(out / "variants_mu_0.5" / f"heldout_choice.{ext}",
                           os.path.join(FIXED, "variants_mu_0.5", f"heldout_choice.{ext}"), shallow=False), ext
    assert model_joint.refits_failed(os.path.join(FIXED, "variants_mu_0.5", "bounded", "jackknife.csv")) == []
    with open(os.path.join(FIXED, "variants_mu_0.5", "bounded", "jackknife.csv"), newline="") as fh:
        moved = [r["packing_left_out"] for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))
                 if "p0 raised from" in r["start"]]
    assert moved == ["m001", "m002", "m004"], "the three refits whose start was moved within the reach say so"
    scores = model_joint.heldout_sets(os.path.join(FIXED, "variants_mu_0.5", "bounded", "heldout.csv"))
    assert sorted(p for p, (_, sc) in scores.items() if sc != sc) == ["m000", "m003", "m005", "m006", "m007"]


SV, SSJ = "state_volume", os.path.join("state_volume", "start_state_jackknife")
# thirty-fourth round: every stored restart of the relaxing and bounded excess's jackknife runs (README step 20)
RESTARTED = sorted((law, os.path.relpath(os.path.dirname(f), os.path.join(ROOT, "data", "geotech", "model", SSJ,
                                                                            f"{law}_excess")))
                   for law in ("relaxing", "bounded")
                   for f in glob.glob(os.path.join(ROOT, "data", "geotech", "model", SSJ, f"{law}_excess", "**",
                                                   "compare.md"), recursive=True))
assert len(RESTARTED) >= 4, RESTARTED


@pytest.mark.parametrize("stored,rerun", [(f"{SV}/dense", SSJ), (f"{SV}/loose", f"{SSJ}/loose")] +
                         [(f"{SV}/{t}", f"{SSJ}/{t}") for t in ("three_pressures/joint", "three_pressures/mu_0.3/joint",
                                                                "three_pressures/mu_1/joint",
                                                                "three_pressures/mu_0.1/joint")] +
                         [(f"lab_{p}", f"lab_{p}/start_state_jackknife") for p in ("dense", "loose")] +
                         [("lab_dense/start_state_jackknife", "lab_dense/basin_check")] +
                         [(f"{SV}/{law}_excess/jackknife/{n}", f"{SSJ}/{law}_excess/{n}") for law, n in RESTARTED])
def test_the_stored_start_state_comparison_rebuilds(tmp_path, stored, rerun):
    """RERUN/compare.{md,csv} (under data/geotech/model) from the two stored parameters.csv (the stored calibration
    STORED and its restart with the fixed jackknife: thirty-second round state_volume/dense, thirty-third the other
    state_volume ones, thirty-fourth lab_dense, lab_loose and the relaxing and bounded excess's jackknife runs;
    thirty-fifth lab_dense with the basin check against the thirty-fourth's), byte for byte (a se_method with a comma
    quoted as csv quotes it)."""
    m = os.path.join(ROOT, "data", "geotech", "model")
    d = os.path.join(m, rerun)
    with open(os.path.join(d, "compare.md")) as fh:
        comment = fh.readline()[len("<!-- demkit/model_joint.py: "):-len(" -->\n")]
    model_joint.compare_errors(os.path.join(m, stored, "parameters.csv"), os.path.join(d, "parameters.csv"),
                               str(tmp_path), "compare", comment)
    for ext in ("md", "csv"):
        assert filecmp.cmp(tmp_path / f"compare.{ext}", os.path.join(d, f"compare.{ext}"), shallow=False), ext
    with open(tmp_path / "compare.csv", newline="") as fh:
        assert all(len(r) == 8 for r in csv.reader(fh))


def _reach(law):
    """The highest p* of the isotropic law on [nu_c, 1] (demfit/model.hpp isotropic_reach: p_iso(1), or its maximum on
    a 256-step grid for a law that falls again)."""
    from demkit import model_jamming
    nu_c = law["nu_c"]
    return max([model_jamming.pressure(law, 1.0)] +
               [model_jamming.pressure(law, nu_c + (1 - nu_c) * i / 256) for i in range(1, 257)])


def _highest_start(mu):
    """The highest start pressure of the friction study's D2/D3 means at MU (the joint calibration's fitted curves)."""
    top = 0.0
    for f in sorted(os.listdir(os.path.join(ROOT, "data", "friction_n1000", f"mu_{mu}", "ensemble"))):
        if f.startswith(("D2_phi", "D3_phi")):
            with open(os.path.join(ROOT, "data", "friction_n1000", f"mu_{mu}", "ensemble", f), newline="") as fh:
                top = max(top, float(next(csv.DictReader(ln for ln in fh if not ln.startswith("#")))["p_star_mean"]))
    return top


def test_only_the_bounded_variant_sits_on_the_isotropic_laws_reach():
    """The stored bounded variant's isotropic law ends (at nu = 1) at the start pressure of D2 at nu = 0.80, to 1e-6: its
    optimum sits on the edge of the elastic split's domain (beyond it that start has no elastic volume fraction), the
    bound that made its jackknife refits without m001, m002 and m004 fail at their start before the thirty-third
    round. Every other stored joint calibration reaches at least 6 % above its highest start pressure."""
    from demkit import model_jamming
    top = _highest_start("0.5")
    bounded = model_jamming.read_law(os.path.join(FIXED, "variants_mu_0.5", "bounded", "parameters.csv"))
    assert _reach(bounded) == pytest.approx(top, rel=1e-6)
    assert _reach(bounded) == pytest.approx(model_jamming.pressure(bounded, 1.0), rel=1e-12), "reached at nu = 1"
    for mu in ("0", "0.1", "0.3", "0.5", "1"):
        law = model_jamming.read_law(os.path.join(STORED, f"mu_{mu}", "parameters.csv"))
        assert _reach(law) > 1.06 * _highest_start(mu), mu
    for name in ("weighted", "with_isobaric"):
        law = model_jamming.read_law(os.path.join(FIXED, "variants_mu_0.5", name, "parameters.csv"))
        assert _reach(law) > 1.06 * top, name


def test_the_bounded_variants_unpredicted_packings_start_beyond_their_refits_reach():
    """Why the bounded variant cannot predict five held-out friction packings: each refit without a packing ends on
    the reach again (its law reaches about the other packings' mean start pressure at nu = 0.80), and exactly the
    packings whose own start pressure lies above their refit's reach have a held-out score that is not a number."""
    from demkit import model_jamming
    d = os.path.join(FIXED, "variants_mu_0.5", "bounded")
    with open(os.path.join(d, "jackknife_estimates.csv"), newline="") as fh:
        refits = {r["packing_left_out"]: r for r in csv.DictReader(fh)}
    scores = model_joint.heldout_sets(os.path.join(d, "heldout.csv"))
    law_keys = ("p0", "nu_c", "gamma_p", "C0", "C1", "nu_cC", "alpha")
    for m in [f"m{i:03d}" for i in range(8)]:
        law = {k: float(refits[m][k]) for k in law_keys}
        assert model_jamming.pressure(law, 0.7) > 0
        f = os.path.join(ROOT, "data", "friction_n1000", "mu_0.5", "members", m, "deviatoric", "D2_phi0.800.csv")
        with open(f, newline="") as fh:
            own = float(next(csv.DictReader(ln for ln in fh if not ln.startswith("#")))["p_star"])
        beyond = own > _reach(law)
        assert beyond == (scores[m][1] != scores[m][1]), (m, own, _reach(law), scores[m])


def test_the_qs16_paths_start_every_packing_at_one_volume_fraction():
    """data/model_paths_qs16's path calibrations were not restarted with the fixed path jackknife (thirty-fourth round):
    each of its paths starts every packing at the same volume fraction, so a left-out mean starts where the full one
    does (rerun, their quoted errors moved by at most 6e-5 relative)."""
    base = os.path.join(ROOT, "data", "model_paths_qs16", "members")
    members = sorted(os.listdir(base))
    assert len(members) >= 8
    names = sorted(os.listdir(os.path.join(base, members[0], "paths")))
    assert any(n.startswith("isobaric") for n in names) and any(n.startswith("triaxial") for n in names)
    for name in names:
        starts = set()
        for m in members:
            with open(os.path.join(base, m, "paths", name), newline="") as fh:
                starts.add(next(csv.DictReader(ln for ln in fh if not ln.startswith("#")))["nu"])
        assert len(starts) == 1, (name, starts)


def test_the_stored_basin_check_ran_lab_dense_without_m2_again():
    """lab_dense/basin_check (thirty-fifth round): the refit without m2, which ended near twice the full fit's chi2/dof
    from the full fit's optimum in the thirty-fourth round's restart, was run again by the basin check from another
    refit's optimum and ends lower, within 1.1 times the full fit's chi2/dof; the other refits kept their first start, and none
    ends above the thirty-fourth round's refit of the same packing by more than round-off."""
    m = os.path.join(ROOT, "data", "geotech", "model", "lab_dense")

    def refits(d):
        with open(os.path.join(m, d, "jackknife.csv"), newline="") as fh:
            return {r["packing_left_out"]: r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}
    new, old = refits("basin_check"), refits("start_state_jackknife")
    assert sorted(new) == sorted(old) == ["m1", "m2", "m3", "m4"]
    again = [p for p, r in new.items() if "(basin check; from " in r["start"]]
    assert again == ["m2"] and new["m2"]["tries"] == "2"
    ended = float(new["m2"]["start"].split("it ended at chi2/dof ")[1].rstrip(")"))
    chi, full = float(new["m2"]["chi2_per_dof [-]"]), float(new["m2"]["full_fit_chi2_per_dof [-]"])
    assert chi < ended and chi < 1.1 * full and float(old["m2"]["chi2_per_dof [-]"]) > 1.9 * full
    for p in ("m1", "m3", "m4"):
        assert new[p]["start"] == "the full fit's optimum"
        assert float(new[p]["chi2_per_dof [-]"]) <= float(old[p]["chi2_per_dof [-]"]) * (1 + 1e-4)


def test_the_audit_counts_moved_curves_and_names_the_largest_move():
    """demkit.model_audit.compare on hand-built worst-per-curve tables: a curve not a number in both does not move, one
    that leaves inf is the largest move, the within-1 counts read each build's own numbers."""
    import math
    from demkit import model_audit
    old = {("D2", "0.69"): 0.8, ("D2", "0.8"): 0.9, ("TE", "0.66"): math.inf, ("TT", "0.66"): math.nan}
    new = {("D2", "0.69"): 0.8, ("D2", "0.8"): 1.9, ("TE", "0.66"): 2.7, ("TT", "0.66"): math.nan}
    c = model_audit.compare(old, new)
    assert c["curves"] == 4 and c["moved"] == 2
    assert c["inside"] == [2, 1]
    assert c["worst"] == [math.inf, 2.7]
    assert c["largest"] == ("TE", "0.66")
    assert model_audit.compare(old, dict(old))["moved"] == 0 and model_audit.compare(old, dict(old))["largest"] is None
    assert model_audit.short(math.inf) == "inf" and model_audit.short(1.2345) == "1.23"
