"""Luding's law on a pair of spheres: our engine against YADE's LudingMat /
Law2_ScGeom_LudingPhys_Basic (the prescribed overlap loop and head-on impacts of
bench/luding_pair.py and yade_ref/luding_pair.py), and both against the closed form of
demkit/luding.py.

The stored YADE output (data/yade_luding/yade_*.csv, COMMANDS.txt) is compared on every run; with
`yade` installed the YADE script is run again (a shorter impact list) and compared too.

Tolerances:
- loop, 5e-3 k1 delta*: YADE computes k2 from delta_max before the step's update but delta0 after
  it, so on the step that ends a loading its delta0 lags by one step of overlap
  (d delta = delta*/2000 here): the unloading line is shifted by up to
  (kp - k1)/k2 * d delta/delta* * k1 delta_max <= 2e-3 k1 delta* (worst at the kp branch);
  elsewhere the two agree to rounding.
- impacts, 2e-3 in e: the same time step and the same (leapfrog = velocity Verlet) positions;
  what differs is YADE's one-step lag above and where within a step each code switches branch.
  Against the closed form (no time discretisation) 2e-3 + the O(dt^2) error of t_c/50 steps.
"""
import csv
import math
import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, "bench"))
demtk = pytest.importorskip("demtk")
import luding_pair as lp  # noqa: E402
from demkit.luding import Luding  # noqa: E402

DATA = os.path.join(REPO, "data", "yade_luding")


def read(path):
    with open(path) as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def ours_loop():
    return lp.run_loop(lp.scene(lp.LOOP_KC, lp.LOOP_PHI), lp.LOOP_STOPS, lp.LOOP_STEPS_PER_DSTAR)


def compare_loops(ours, yade):
    """max |f_ours - f_yade| / (k1 delta*) over the steps where both overlaps agree. YADE reports
    the overlap before its step's move, ours after: its step k is our step k - 1."""
    L = lp.law(lp.LOOP_KC, lp.LOOP_PHI)
    scale = lp.K1 * L.delta_star
    ours_by_step = {int(s): (d, f) for s, d, f in ours}
    worst, matched = 0.0, 0
    for r in yade:
        o = ours_by_step.get(int(r["step"]) - 1)
        if o is None:
            continue
        assert abs(o[0] - r["delta_m"]) < 1e-9 * L.delta_star, (r, o)
        worst = max(worst, abs(o[1] - r["fn_N"]) / scale)
        matched += 1
    return worst, matched


def test_our_loop_follows_the_piecewise_closed_form(ours_loop):
    L = lp.law(lp.LOOP_KC, lp.LOOP_PHI)
    d = [r[1] for r in ours_loop]
    closed = [x[0] for x in L.path(d)]
    worst = max(abs(r[2] - c) for r, c in zip(ours_loop, closed)) / (lp.K1 * L.delta_star)
    assert worst < 1e-9
    # the loop reaches every branch: tension at the adhesive limit, the kp branch beyond delta*
    assert min(r[2] for r in ours_loop) < -0.2 * lp.LOOP_KC * L.delta_star
    assert max(r[1] for r in ours_loop) > 1.2 * L.delta_star


def test_our_loop_matches_stored_yade(ours_loop):
    worst, matched = compare_loops(ours_loop, read(os.path.join(DATA, "yade_loop.csv")))
    assert matched > 7000
    assert worst < 5e-3


IMPACTS = [(0.0, 1.0), (0.0, 10.0), (0.0, 30.0), (1e8, 4.0), (1e8, 6.0), (5e8, 2.0), (5e8, 4.0), (5e8, 30.0)]


def test_our_impacts_match_stored_yade_and_the_closed_form():
    yade = {(r["kc_N_m"], r["v_m_s"]): r["restitution"] for r in read(os.path.join(DATA, "yade_impacts.csv"))}
    mr = lp.reduced_mass()
    for kc, v in IMPACTS:
        e = lp.run_impact(lp.scene(kc, lp.IMPACT_PHI), v)
        closed = lp.law(kc, lp.IMPACT_PHI).restitution(mr, v)
        assert abs(e - yade[(kc, v)]) < 2e-3, (kc, v, e, yade[(kc, v)])
        assert abs(e - closed) < 3e-3, (kc, v, e, closed)
        assert (e == 0.0) == (closed == 0.0), (kc, v, e, closed)   # sticking exactly where the closed form says


def test_closed_form_sticks_in_a_window_and_rebounds_on_both_sides():
    mr = lp.reduced_mass()
    L = Luding(lp.K1, lp.KP, 5e8, lp.IMPACT_PHI, lp.R / 2)
    lo, hi = L.sticking_window(mr)
    assert 2.0 < lo < 3.0 and 12.0 < hi < 15.0
    assert L.restitution(mr, 0.01) > 0.99 and L.restitution(mr, 100.0) > 0.98
    # without adhesion: e = sqrt(k1/k2) below delta*
    L0 = Luding(lp.K1, lp.KP, 0.0, lp.IMPACT_PHI, lp.R / 2)
    dm = 1.0 * math.sqrt(mr / lp.K1)
    assert abs(L0.restitution(mr, 1.0) - math.sqrt(lp.K1 / L0.k2(dm))) < 1e-12


@pytest.mark.skipif(shutil.which("yade") is None, reason="yade is not installed")
def test_yade_run_now_matches_ours(tmp_path, ours_loop):
    sc = lp.scene(lp.LOOP_KC, lp.LOOP_PHI)
    dt = repr(sc.dt)
    assert lp.scene(0.0, lp.IMPACT_PHI).dt == sc.dt
    r = subprocess.run(["yade", "-n", "-x", "-j1", os.path.join(REPO, "yade_ref", "luding_pair.py"), "--dt-loop", dt,
                        "--dt-impacts", dt, "--out", str(tmp_path), "--quick"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    worst, matched = compare_loops(ours_loop, read(str(tmp_path / "yade_loop.csv")))
    assert matched > 7000 and worst < 5e-3
    for row in read(str(tmp_path / "yade_impacts.csv")):
        e = lp.run_impact(lp.scene(row["kc_N_m"], lp.IMPACT_PHI), row["v_m_s"])
        assert abs(e - row["restitution"]) < 2e-3, row


def test_dem_info_prints_ludings_tension_limit_and_twisting():
    from conftest import run_dem
    keys = ["--set", "contact.normal=luding", "--set", "contact.luding_kc_N_m=2e7", "--set", "contact.friction=0.5",
            "--set", "contact.twisting_friction=0.1"]
    out = run_dem("info", os.path.join(REPO, "data", "scenes", "quickstart.toml"), *keys, check=True).stdout
    contact_line = next(line for line in out.splitlines() if line.startswith("contact "))
    normal_line = next(line for line in out.splitlines() if line.startswith("  normal "))
    assert "clamped at zero" not in contact_line and "-kc delta" in normal_line and "2e+07" in normal_line
    assert "  twisting         sds: mu_o = 0.1" in out
    plain = run_dem("info", os.path.join(REPO, "data", "scenes", "quickstart.toml"), check=True).stdout
    assert "clamped at zero" in next(line for line in plain.splitlines() if line.startswith("contact "))
