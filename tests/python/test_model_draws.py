"""demkit.model_draws (issue 31, thirty-fourth round): one calibration on two draws of packings, in band half-widths
and in between-packing SDs."""
import csv
import math
import os

import pytest

from demkit import model_draws

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_one_band_in_sds_is_t_over_root_k():
    """t_{7,0.975} = 2.3646, t_{11,0.975} = 2.2010 (tables): 1 band = 0.8360 SD at K = 8 and 0.6354 at K = 12."""
    assert model_draws.sd_per_band(8) == pytest.approx(2.364624 / math.sqrt(8), rel=1e-6)
    assert model_draws.sd_per_band(12) == pytest.approx(2.200985 / math.sqrt(12), rel=1e-6)


def test_the_sd_scale_agrees_with_the_absolute_columns(monkeypatch):
    """rms/SD from rms_over_band x t/sqrt(K) equals rms [quantity] / (band_halfwidth [quantity] sqrt(K)/t), read from
    the other columns of prediction.csv, for every curve of both draws at mu = 1."""
    monkeypatch.chdir(ROOT)
    _, a, b = model_draws.PAIRS["1"]
    for run, k in zip((a, b), model_draws.KS):
        with open(os.path.join(run, "prediction.csv"), newline="") as fh:
            rows = list(csv.DictReader(l for l in fh if not l.startswith("#")))
        t = model_draws.sd_per_band(k) * math.sqrt(k)
        got = model_draws.misses(run)
        for r in rows:
            direct = float(r["rms [quantity]"]) / (float(r["band_halfwidth [quantity]"]) * math.sqrt(k) / t)
            key = (r["mode"], f"{float(r['nu']):.2f}", r["quantity"])
            assert got[key] * model_draws.sd_per_band(k) == pytest.approx(direct, rel=6e-3), key   # 3 printed digits


def test_the_stored_table_is_rebuilt(tmp_path, monkeypatch):
    """draws.{md,csv} from the stored runs byte for byte; at mu = 1 the K = 12 fit misses the band target and is not
    worse in SDs than the K = 8 choice (the finding docs/model.md quotes)."""
    monkeypatch.chdir(ROOT)
    model_draws.main(["--out", str(tmp_path)])
    stored = os.path.join(model_draws.K12, "draws")
    for ext in ("md", "csv"):
        assert (tmp_path / f"draws.{ext}").read_text() == open(os.path.join(stored, f"draws.{ext}")).read(), ext
    with open(os.path.join(stored, "draws.csv"), newline="") as fh:
        rows = {r["mu"]: r for r in csv.DictReader(fh)}
    one = rows["1"]
    assert float(one["worst_band_k12 [band]"]) > 1 >= float(one["worst_band_k8 [band]"])
    assert float(one["worst_sd_k12 [SD]"]) <= float(one["worst_sd_k8 [SD]"])


def test_a_missing_run_is_named(tmp_path):
    with pytest.raises(SystemExit, match="prediction.csv does not exist"):
        model_draws.misses(str(tmp_path))


def test_the_k12_mu_1_fit_settles_at_one_optimum_from_two_starts():
    """mu_1_settled/ (from the quick look's optimum) and its from_k8_choice/ (from mu = 1's K = 8 choice): the same
    chi2/dof to 5 digits and every coefficient within 0.1 of its covariance error of the other's (the docs say 0.04);
    both settle, and the worst curve misses the band target (1.23) in both."""
    d = os.path.join(ROOT, model_draws.K12, "lode_limit_gate", "mu_1_settled")

    def params(f):
        with open(f, newline="") as fh:
            return {r["parameter"]: r for r in csv.DictReader(l for l in fh if not l.startswith("#"))}

    a, b = params(os.path.join(d, "parameters.csv")), params(os.path.join(d, "from_k8_choice", "parameters.csv"))
    assert float(a["chi2_per_dof"]["value"]) == pytest.approx(float(b["chi2_per_dof"]["value"]), rel=1e-5)
    assert a["settled"]["law"].startswith("yes") and b["settled"]["law"].startswith("yes")
    compared = 0
    for k, r in a.items():
        try:
            se = float(r["se"])
        except ValueError:
            continue
        if se == se and se > 0:
            assert abs(float(r["value"]) - float(b[k]["value"])) <= 0.1 * se, k
            compared += 1
    assert compared >= 25
    for run in (d, os.path.join(d, "from_k8_choice")):
        with open(os.path.join(run, "summary.csv"), newline="") as fh:
            worst = [r for r in csv.DictReader(l for l in fh if not l.startswith("#")) if r["mode"] == "calibration"]
        assert float(worst[0]["worst [band]"]) == pytest.approx(1.23, abs=0.005), run
