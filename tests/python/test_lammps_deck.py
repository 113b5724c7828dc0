"""The LAMMPS `pair granular` line of a contact law comes from the sub-models' own counterparts in
the registry (`dem info SCENE --lammps`, bench/decks.py; issue 30 item 1). Checked against what
LAMMPS' pair granular documentation says each keyword's coefficients mean, computed here from the
scene's physics: hooke k gamma + damping velocity (+ limit_damping, ours' no-tension clamp);
linear_history k_t (absolute, N/m) x_gamma_t (a multiple of the normal dashpot) mu; rolling and
twisting sds k gamma mu; hertz/material E e' nu + damping tsuji with e' the value whose LAMMPS
polynomial alpha(e') equals the alpha that gives ours' restitution e (an RK4 impact here)."""
import math
import sys
from pathlib import Path

import pytest

from conftest import ROOT, run_dem

sys.path.insert(0, str(Path(ROOT) / "bench"))
import decks  # noqa: E402

SCENE = Path(ROOT) / "data" / "scenes" / "quickstart.toml"
K, GAMMA = 1e8, 1.0          # the quickstart's (paper_n9261's) contact.stiffness_N_m, damping_kg_s


def line(*sets):
    args = ["info", SCENE, "--lammps"]
    for kv in sets:
        args += ["--set", kv]
    r = run_dem(*args)
    assert r.returncode == 0, r.stderr
    words = r.stdout.split()
    assert words[:3] == ["pair_coeff", "*", "*"], r.stdout
    return words[3:]


def same(words, expected):
    """Words equal, numbers to 1e-15 relative (the line prints every digit)."""
    assert len(words) == len(expected), (words, expected)
    for w, e in zip(words, expected):
        if isinstance(e, float):
            assert float(w) == pytest.approx(e, rel=1e-15, abs=0), (w, e, words)
        else:
            assert w == e, (words, expected)


def test_linear_frictionless_law():
    same(line(), ["hooke", K, GAMMA, "tangential", "linear_nohistory", "0", "0", "damping", "velocity",
                  "limit_damping"])
    # the textbook spring-dashpot that may pull: no clamp
    assert "limit_damping" not in line("contact.allow_attractive=true")


def test_cundall_strack_friction_with_rolling_and_twisting():
    same(line("contact.friction=0.5"), ["hooke", K, GAMMA, "tangential", "linear_history", 2 / 7 * K, 0.0, 0.5,
                                        "damping", "velocity", "limit_damping"])
    words = line("contact.friction=0.5", "contact.rolling_friction=0.1", "contact.twisting_friction=0.2",
                 "contact.rolling_stiffness_ratio=0.5", "contact.twisting_damping_kg_s=0.25")
    same(words, ["hooke", K, GAMMA, "tangential", "linear_history", 2 / 7 * K, 0.0, 0.5,
                 "rolling", "sds", 0.5 * K, 0.0, 0.1, "twisting", "sds", 2 / 7 * K, 0.25, 0.2,
                 "damping", "velocity", "limit_damping"])
    # a tangential dashpot is LAMMPS' x_gamma_t times the normal one
    same(line("contact.friction=0.3", "contact.tangential_damping_kg_s=0.5", "contact.damping_kg_s=2"),
         ["hooke", K, 2.0, "tangential", "linear_history", 2 / 7 * K, 0.25, 0.3, "damping", "velocity",
          "limit_damping"])


def tsuji_restitution(alpha, h=2e-3):
    """e of the dimensionless Hertz impact x'' = -max(x^1.5 + alpha x^0.25 x', 0), x(0) = 0, x'(0) = 1."""
    def acc(x, u):
        f = x * math.sqrt(x) + alpha * x ** 0.25 * u if x > 0 else 0.0
        return -f if f > 0 else 0.0
    x, u = 0.0, 1.0
    while True:
        k1 = (u, acc(x, u))
        k2 = (u + 0.5 * h * k1[1], acc(x + 0.5 * h * k1[0], u + 0.5 * h * k1[1]))
        k3 = (u + 0.5 * h * k2[1], acc(x + 0.5 * h * k2[0], u + 0.5 * h * k2[1]))
        k4 = (u + h * k3[1], acc(x + h * k3[0], u + h * k3[1]))
        xn = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        un = u + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        if xn < 0 and un < 0:
            return -(u + (un - u) * x / (x - xn))
        x, u = xn, un


def lammps_alpha(e):
    """LAMMPS' `damping tsuji` polynomial alpha(e) (pair granular documentation)."""
    c = [1.2728, -4.2783, 11.087, -22.348, 27.467, -18.022, 4.8218]
    return sum(ci * e ** k for k, ci in enumerate(c))


@pytest.mark.parametrize("rule", ["mindlin", "mindlin_force"])
def test_hertz_mindlin(rule):
    words = line("contact.normal=hertz", f"contact.tangential={rule}", "contact.friction=0.5",
                 "contact.youngs_modulus_Pa=7e10", "contact.poisson_ratio=0.25", "contact.restitution=0.8")
    assert words[0] == "hertz/material" and float(words[1]) == 7e10 and float(words[3]) == 0.25, words
    e_lammps = float(words[2])
    # LAMMPS' alpha(e') gives back, through the impact, ours' e = 0.8 (LAMMPS' fit itself would not)
    assert tsuji_restitution(lammps_alpha(e_lammps)) == pytest.approx(0.8, abs=2e-4)
    assert abs(tsuji_restitution(lammps_alpha(0.8)) - 0.8) > 5e-3
    same(words[4:], ["tangential", "mindlin/force" if rule == "mindlin_force" else "mindlin", "NULL", "0", 0.5,
                     "damping", "tsuji", "limit_damping"])


@pytest.mark.parametrize("sets,needle", [
    (["contact.normal=luding"], 'contact.normal = "luding" has no LAMMPS pair granular counterpart'),
    (["contact.friction=0.5", "contact.damping_kg_s=0", "contact.tangential_damping_kg_s=1"],
     "no LAMMPS counterpart (x_gamma_t multiplies the normal dashpot)"),
])
def test_a_law_without_a_lammps_counterpart_is_refused(sets, needle):
    args = ["info", SCENE, "--lammps"]
    for kv in sets:
        args += ["--set", kv]
    r = run_dem(*args)
    assert r.returncode == 2 and needle in r.stderr, r.stderr


def test_bench_decks_use_the_registry_line(tmp_path):
    deck = decks.lammps_deck("packing.data", 100, 1.0, 1e-9, sets=("contact.friction=0.5",), k=2e8, thermo=True)
    coeff = next(ln for ln in deck.splitlines() if ln.startswith("pair_coeff"))
    same(coeff.split()[3:], ["hooke", 2e8, GAMMA, "tangential", "linear_history", 2 / 7 * 2e8, 0.0, 0.5,
                             "damping", "velocity", "limit_damping"])
    assert "compute erot all erotate/sphere" in deck and "run 100" in deck


# LIGGGHTS (`dem info SCENE --liggghts`): the gran model hooke/stiffness documentation's meaning of
# each global property: kn, kt absolute [N/m]; gamman_abs, gammat_abs the dashpots themselves
# [kg/s] (absolute_damping on); coefficientFriction mu; limitForce on = no attraction (ours' clamp).
def liggghts(*sets):
    args = ["info", SCENE, "--liggghts"]
    for kv in sets:
        args += ["--set", kv]
    return run_dem(*args)


def liggghts_properties(out):
    props, style = {}, None
    for ln in out.splitlines():
        w = ln.split()
        if w[:1] == ["fix"]:
            assert w[2:4] == ["all", "property/global"] and w[5:7] == ["peratomtypepair", "1"], ln
            props[w[4]] = float(w[7])
        elif w[:1] == ["pair_style"]:
            style = w[1:]
    return props, style


def test_liggghts_frictionless_is_the_hand_written_deck():
    r = liggghts()
    assert r.returncode == 0, r.stderr
    props, style = liggghts_properties(r.stdout)
    assert props == {"kn": K, "gamman_abs": GAMMA, "kt": 0.0, "gammat_abs": 0.0, "coefficientFriction": 0.0}
    assert style == ["gran", "model", "hooke/stiffness", "tangential", "no_history", "absolute_damping", "on",
                     "limitForce", "on"]
    assert r.stdout.rstrip().endswith("pair_coeff * *")


def test_liggghts_cundall_strack():
    r = liggghts("contact.friction=0.4", "contact.tangential_stiffness_ratio=0.5", "contact.tangential_damping_kg_s=0.3",
                 "contact.allow_attractive=true")
    assert r.returncode == 0, r.stderr
    props, style = liggghts_properties(r.stdout)
    assert props["kt"] == pytest.approx(0.5 * K, rel=1e-15) and props["gammat_abs"] == 0.3
    assert props["coefficientFriction"] == 0.4 and props["kn"] == K
    assert style[2:5] == ["hooke/stiffness", "tangential", "history"] and "limitForce" not in style


@pytest.mark.parametrize("sets,named", [(("contact.normal=hertz",), 'contact.normal = "hertz"'),
                                        (("contact.normal=luding",), 'contact.normal = "luding"'),
                                        (("contact.friction=0.5", "contact.rolling_friction=0.1"), 'contact.rolling = "sds"')])
def test_liggghts_refuses_laws_without_counterpart(sets, named):
    r = liggghts(*sets)
    assert r.returncode != 0 and named in r.stderr and "LIGGGHTS" in r.stderr, r.stderr


def test_liggghts_deck_uses_the_registry_lines():
    deck = decks.liggghts_deck("packing.data", 100, 1.0, 1e-9, sets=("contact.friction=0.5",))
    assert "pair_style gran model hooke/stiffness tangential history" in deck
    assert "coefficientFriction peratomtypepair 1 0.5" in deck
