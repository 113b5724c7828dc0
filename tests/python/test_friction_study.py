"""A small frictional study end to end: two ensembles (mu = 0 and mu = 0.5) of the same tiny scene
through `dem ensemble` (prep, D2 and isobaric D2 per packing, the reduce), then
demkit.friction_study's per-packing quantities against what friction must do: jam lower, raise
the stress ratio, slide some contacts, and leave mu = 0 on the frictionless code path."""
import csv
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, run_dem
from demkit.curves import read_curve
from demkit import friction_study

TINY = """
[particles]
count = 200
seed = 11
[contact]
friction = 0.5
[protocol]
target_phi = 0.55
compress_rate_tc = 2e-4
cycle_rate_tc = 2e-4
cycle_phi_max = 0.80
checkpoints_unloading = [0.72]
modes = ["D2", "isobaric_D2"]
deviatoric_rate_tc = 6e-5
eps_d_max = 0.08
[paths]
isobaric_D2 = [ { rate = "D2", pressure_p0 = 1.0, until = { eps_d = 0.08 } } ]
[integration]
dt_over_tc = 0.2
[output]
sample_strain = 0.004
vtk = false
[ensemble]
packings = 2
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    d = tmp_path_factory.mktemp("fstudy")
    scene = d / "tiny.toml"
    scene.write_text(TINY)
    folders = {}
    for mu in ("0", "0.5"):
        out = d / f"mu{mu}"
        run_dem("ensemble", scene, "--out", out, "--cores", "2", "--set", f"contact.friction={mu}",
                check=True, timeout=900)
        folders[mu] = out
    p = subprocess.run(["/usr/bin/python3", "-m",
                        "demkit.friction_study", "--out", str(d / "study"), str(folders["0"]), str(folders["0.5"])],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    with open(d / "study" / "summary.csv") as fh:
        rows = list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    return {"dir": d, "folders": folders, "rows": rows}


def value(rows, mu, mode, quantity, nu="0.720"):
    for r in rows:
        if float(r["mu"]) == mu and r["mode"] == mode and r["quantity"] == quantity and r["nu"] == (
                "" if mode == "isotropic" else nu):
            return float(r["mean"]), float(r["se"]), int(r["packings"])
    raise AssertionError(f"no row mu={mu} {mode} {quantity}")


def test_mu_zero_runs_the_frictionless_code_path(study):
    """--set contact.friction=0 resolves to the frictionless scene: no friction columns or record."""
    smooth = study["folders"]["0"]
    path = smooth / "members" / "m000" / "deviatoric" / "D2_phi0.720.csv"
    physics = [ln for ln in path.read_text().splitlines() if ln.startswith("# physics:")]
    assert physics and "tangential" not in physics[0]
    c = read_curve(str(path))
    assert "sliding_fraction" not in c and "E_rot_J" not in c
    rough = read_curve(str(study["folders"]["0.5"] / "members" / "m000" / "deviatoric" / "D2_phi0.720.csv"))
    assert rough["sliding_fraction"].max() > 0   # some contacts reach the Coulomb limit under shear
    assert np.all(rough["sliding_fraction"] <= 1)


def test_friction_jams_lower_and_raises_the_stress_ratio(study):
    rows = study["rows"]
    nu0, se0, k0 = value(rows, 0.0, "isotropic", "nu_J")
    nu5, se5, k5 = value(rows, 0.5, "isotropic", "nu_J")
    assert k0 == k5 == 2
    assert 0.6 < nu0 < 0.70                      # frictionless polydisperse spheres jam near 0.65 (docs/friction.md)
    assert nu5 < nu0 - 0.02, (nu0, nu5)         # frictional ones markedly lower
    # the curves stop at eps_d = 0.08, before a peak: the largest stress ratio of the ensemble means
    s0, s5 = (read_curve(str(study["folders"][mu] / "ensemble" / "D2_phi0.720.csv"))["s_dev_mean"].max()
              for mu in ("0", "0.5"))
    assert s5 > 1.5 * s0, (s0, s5)               # friction at least 1.5x the frictionless stress ratio


def test_the_isobaric_path_holds_the_pressure_and_reports_dilatancy(study):
    for mu in ("0", "0.5"):
        c = read_curve(str(study["folders"][mu] / "members" / "m000" / "deviatoric" / "isobaric_D2_phi0.720.csv"))
        p = c["p_Pa"]
        assert np.max(np.abs(p[1:] / p[0] - 1)) < 0.05   # the servo holds p within 5 %
    d, se, k = value(study["rows"], 0.5, "isobaric_D2", "dilatancy_max")
    assert np.isfinite(d) and np.isfinite(se) and k == 2


def test_the_reduce_averages_the_frictional_columns(study):
    ens = read_curve(str(study["folders"]["0.5"] / "ensemble" / "D2_phi0.720.csv"))
    assert "sliding_fraction_mean" in ens and "W_friction_J_mean" in ens
    assert np.all(np.diff(ens["W_friction_J_mean"]) >= -1e-12 * max(1.0, ens["W_friction_J_mean"].max()))


def test_the_study_table_rounds_to_errors(study):
    md = (study["dir"] / "study" / "summary.md").read_text()
    assert "±" in md and "nu_J" in md
    assert os.path.isfile(study["dir"] / "study" / "jamming_vs_mu.png")


def test_a_curve_still_rising_at_its_end_has_no_peak():
    e = np.linspace(0, 0.08, 41)
    rising = 0.3 * (1 - np.exp(-e / 0.05))
    assert all(np.isnan(friction_study.peak(e, rising)))
    e = np.linspace(0, 0.3, 151)
    softening = 0.3 * (1 - np.exp(-e / 0.02)) + 0.1 * np.exp(-((e - 0.05) / 0.02) ** 2)
    s_peak, eps_peak = friction_study.peak(e, softening)
    assert abs(eps_peak - e[np.argmax(softening)]) < 1e-12 and s_peak == softening.max()
    assert 0.03 < eps_peak < 0.08


def test_t_quantiles_are_students():
    # published two-sided 95 % values (e.g. NIST/SEMATECH e-Handbook, table 1.3.6.7.2)
    for dof, t in ((1, 12.706), (3, 3.182), (7, 2.365), (13, 2.160), (30, 2.042)):
        assert abs(friction_study.t975(dof) - t) < 1e-3, dof
    assert np.isnan(friction_study.t975(0))


def test_round_to_error_rule():
    assert friction_study.round_to_error(0.196534, 0.00231554) == "0.197 ± 0.002"
    assert friction_study.round_to_error(0.196534, 0.00131554) == "0.1965 ± 0.0013"
    assert friction_study.round_to_error(12.34, 3.2) == "12 ± 3"


def test_folders_are_checked(tmp_path):
    p = subprocess.run(["/usr/bin/python3", "-m", "demkit.friction_study", "--out", str(tmp_path / "o"),
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode != 0 and "not an ensemble folder" in p.stderr


def test_two_summaries_compared_cell_by_cell(tmp_path):
    """demkit.summary_compare: z = (b - a)/sqrt(se_a^2 + se_b^2) per shared cell, by hand; a cell without an SE is
    'not determined' and not counted; the count beyond |z| = 2 against 5 % of the cells; --mu filters; no shared
    cell is refused by name."""
    from demkit import summary_compare
    head = "# summary\nmu,mode,nu,quantity,packings,mean,se,lo95,hi95\n"
    (tmp_path / "a.csv").write_text(head + "0.5,D2,0.690,s_cs,8,0.80,0.03,0,0\n0.5,D2,0.690,F_cs,8,0.30,0.01,0,0\n"
                                    "0.5,D2,0.800,s_peak,1,0.79,nan,0,0\n1,D2,0.690,s_cs,8,1.0,0.01,0,0\n")
    (tmp_path / "b.csv").write_text(head + "0.5,D2,0.690,s_cs,12,0.84,0.04,0,0\n0.5,D2,0.690,F_cs,12,0.35,0.01,0,0\n"
                                    "0.5,D2,0.800,s_peak,4,0.80,0.01,0,0\n1,D2,0.690,s_cs,12,0.0,0.01,0,0\n")
    out = str(tmp_path / "cmp")
    summary_compare.main([str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--out", out, "--mu", "0.5"])
    rows = {r["quantity"]: r for r in csv.DictReader(open(out + ".csv"))}
    assert set(rows) == {"s_cs", "F_cs", "s_peak"}
    assert abs(float(rows["s_cs"]["z"]) - 0.04 / 0.05) < 1e-9
    assert abs(float(rows["F_cs"]["z"]) - 0.05 / math.sqrt(2e-4)) < 1e-3   # 4 digits in the csv
    assert rows["s_peak"]["z"] == "nan"
    text = open(out + ".md").read()
    assert "1 of 2 cells beyond |z| = 2 (expected 0.1" in text and "not determined" in text, text
    with pytest.raises(SystemExit, match="share no cell"):
        summary_compare.main([str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--out", out, "--mu", "0.3"])


@pytest.mark.parametrize("study,mus", [("friction_n1000", ["0", "0.01", "0.1", "0.3", "0.5", "1"]),
                                       ("friction_n1000_k12", ["0", "0.1", "0.3", "0.5", "1"])])
def test_stored_summary_is_rebuilt_from_the_stored_folders(tmp_path, study, mus):
    """The stored summary and headline are what today's friction_study makes of the stored curves (the
    K = 8 study's first tables predated the still-rising-curve rule), and summary.json names its data by
    paths that resolve beside it wherever the repository is cloned."""
    import json
    src = os.path.join(ROOT, "data", study)
    folders = [os.path.join(src, f"mu_{m}") for m in mus]
    friction_study.main([*folders, "--out", str(tmp_path), "--no-plots"])
    for name in ("summary.csv", "summary.md", "headline.md"):
        with open(os.path.join(src, name)) as a, open(tmp_path / name) as b:
            assert a.read() == b.read(), f"data/{study}/{name} is not rebuilt by today's friction_study"
    with open(os.path.join(src, "summary.json")) as fh:
        named = json.load(fh)["folders"]
    assert sorted(named, key=float) == mus
    for m, rel in named.items():
        assert not os.path.isabs(rel) and os.path.isfile(os.path.join(src, rel, "scene.toml")), rel
    # a peak no packing has is "not determined", never a number or a bare n/a
    with open(tmp_path / "summary.md") as fh:
        rows = [l for l in fh if "| 0 | not determined |" in l]
    assert all("peak" in l or "softening" in l or "C_star_nr" in l for l in rows)
