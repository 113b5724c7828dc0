"""One rounding-to-error rule: demkit.rounding (the figures, sweeps, the friction study) gives the
text of demfit::format_paren / format_pm (the fit tables) on the same numbers."""
import math
import os
import sys

import numpy as np
import pytest

from conftest import ROOT
from demkit import rounding

sys.path.insert(0, os.path.join(ROOT, "build", "python"))


def cases():
    rng = np.random.default_rng(5)
    out = [(0.196534, 0.00231554), (12.7865, 1.282), (1234.5, 23), (3.7e-4, 1.1e-4), (1.234e-5, 2.1e-7),
           (2.5e7, 1.5e5), (-0.0004, 0.003), (1.2345, 0.0096), (0.5, 0.05), (4500, 1100), (2.1e-4, 2e-5),
           (0.3, float("nan")), (float("nan"), 0.1), (7.0, 0.0)]
    for _ in range(400):
        v = rng.choice([-1, 1]) * 10 ** rng.uniform(-7, 7)
        out.append((float(v), float(abs(v) * 10 ** rng.uniform(-5, 1))))
    return out


def test_the_python_rule_is_the_tables_rule():
    demtk = pytest.importorskip("demtk")
    for v, e in cases():
        assert rounding.paren(v, e) == demtk.format_paren(v, e), (v, e)
        if math.isfinite(v):
            assert rounding.pm(v, e) == demtk.format_pm(v, e), (v, e)


def test_known_values():
    assert rounding.paren(0.196534, 0.00231554) == "0.197(2)"
    assert rounding.paren(3.7e-4, 1.1e-4) == "3.7(11)e-4"    # not 0.00037(11): one notation everywhere
    assert rounding.pm(0.196534, 0.00131554) == "0.1965 ± 0.0013"
    assert rounding.pm(1.234e-5, 2.1e-7) == "(1.23 ± 0.02)e-5"
