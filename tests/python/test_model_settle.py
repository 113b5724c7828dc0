"""A calibration stopped at its iteration limit counts as converged where chi2 settled (demfit/settle.hpp; docs/model.md,
"A fit that settles"). The friction study's mu = 0.3 group fit creeps: F_max runs away along a valley where chi2 falls
by about 1e-4 per iteration. Stopped at 300 iterations it has settled (chi2 fell by far less than 1 % of s over the
last 50): exit 0, a `settled` row, the still-moving coefficient named. Stopped at 60 it has not (the last 50 include
the fit's descent): exit 1, a `converged` row saying no, and the fall in the warning."""
import csv
import os
import re
import subprocess

from conftest import DEM, ROOT

MU03 = os.path.join(ROOT, "data", "friction_n1000", "mu_0.3")


def fit(out, iterations):
    return subprocess.run([DEM, "model", MU03, "--out", str(out), "--family", "group", "--no-jackknife", "--no-plots",
                           "--max-iterations", str(iterations)], capture_output=True, text=True)


def rows(out):
    with open(os.path.join(out, "parameters.csv"), newline="") as fh:
        return {r["parameter"]: r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))}


def chi2_dof(out):
    return float(rows(out)["chi2_per_dof"]["value"])


def test_a_creep_below_one_percent_of_s_is_settled_a_descent_is_not(tmp_path):
    settled = tmp_path / "settled"
    r = fit(settled, 300)
    assert r.returncode == 0, r.stderr
    t = rows(settled)
    assert "converged" not in t and "settled" in t
    note = t["settled"]["law"]
    assert note.startswith("yes: Ceres stopped at its limit of 300 iterations"), note
    fall, frac = (float(x) for x in re.search(r"chi2 fell by ([0-9.e+-]+) over the last 50, ([0-9.e+-]+) of s", note).groups())
    s = max(1.0, chi2_dof(settled))
    assert 0 < fall < 0.01 * s and abs(frac - fall / s) < 1e-2 * frac   # three digits each
    assert "still moving over them: " in note and "F_max" in note   # the runaway coefficient named
    assert "settled, taken as converged" in r.stderr

    short = tmp_path / "short"
    r = fit(short, 60)
    assert r.returncode == 1, r.stderr
    t = rows(short)
    assert "converged" in t and "settled" not in t
    m = re.search(r"optimiser did not converge: .*\(chi2 fell by ([0-9.e+-]+) over the last 50 iterations, ([0-9.e+-]+) "
                  r"of s; settled below 0\.01\)", r.stderr)
    assert m, r.stderr
    assert float(m.group(1)) > 0.01 * max(1.0, chi2_dof(short))
    # the settled fit is the lower of the two, and by more than the settled one's last window fell
    assert chi2_dof(settled) < chi2_dof(short)
