"""demkit.geotech_cv (issue 31, thirteenth round; docs/geotech.md, "The constant-volume tests' Lode parameter"):
the plane-strain Lode parameter of a surface against an independent characterisation, the strain windows on a
hand-built curve, and the stored constant-volume curves and table."""
import csv
import glob
import math
import os

import numpy as np
import pytest

from conftest import ROOT
from demkit import geotech, geotech_cv

DATA = os.path.join(ROOT, "data", "geotech", "constant_volume")


def widest_shear_b(name, sin_phi_tc, n=20001):
    """The b where (sigma_1 - sigma_3)/I1 is largest along the surface's trace at fixed mean stress: there the
    trace's tangent is normal to the pure-shear direction (1, 0, -1), i.e. its normal in the deviatoric plane is
    pure shear, which has no intermediate component. A scan, independent of plane_strain_b's root finding."""
    const = geotech.constant_from_sin_phi(name, sin_phi_tc)
    best = (-1.0, math.nan)
    for b in np.linspace(0.0, 1.0, n):
        sp = geotech.predicted_sin_phi(name, const, b)
        s1, s2, s3 = geotech.principal_from_ratio((1 + sp) / (1 - sp), b)
        best = max(best, ((s1 - s3) / (s1 + s2 + s3), b))
    return best[1]


@pytest.mark.parametrize("name", ["MN", "LD"])
@pytest.mark.parametrize("phi", [5.0, 15.0, 21.0, 30.0])
def test_the_plane_strain_b_is_where_the_surface_is_widest_in_shear(name, phi):
    s = math.sin(math.radians(phi))
    assert geotech_cv.plane_strain_b(name, s) == pytest.approx(widest_shear_b(name, s), abs=2e-4)


def test_the_plane_strain_b_tends_to_a_half_as_the_surfaces_become_circles_and_falls_with_friction():
    for name in ("MN", "LD"):
        bs = [geotech_cv.plane_strain_b(name, math.sin(math.radians(p))) for p in (0.1, 10, 20, 30, 40)]
        assert bs[0] == pytest.approx(0.5, abs=2e-3)   # linear in phi near 0: 0.4985 (MN), 0.4990 (LD)
        assert all(a > b for a, b in zip(bs, bs[1:]))
    # Lade-Duncan is rounder than Matsuoka-Nakai at the same friction: its plane-strain b lies nearer 1/2
    s = math.sin(math.radians(25))
    assert geotech_cv.plane_strain_b("MN", s) < geotech_cv.plane_strain_b("LD", s) < 0.5


def test_the_windows_read_q_over_p_b_and_pressure_of_a_hand_built_curve():
    x = np.linspace(0, 1.0, 251)
    n = x.size
    b = np.where(x < 0.5, 0.5, 0.3)                       # the Lode parameter drops at eps_d = 0.5
    s1, s3 = 2.0e6 * np.ones(n), 1.0e6 * np.ones(n)
    s2 = s3 + b * (s1 - s3)
    p = (s1 + s2 + s3) / 3
    q = np.sqrt(((s1 - s2) ** 2 + (s2 - s3) ** 2 + (s3 - s1) ** 2) / 2)
    c = {"eps_d": x, "sigma_xx_Pa": s3, "sigma_yy_Pa": s2, "sigma_zz_Pa": s1, "sigma_xy_Pa": 0 * x,
         "sigma_xz_Pa": 0 * x, "sigma_yz_Pa": 0 * x, "sigma_dev_Pa": q, "p_Pa": p, "p_star": p / 5e7}
    w = geotech_cv.window_values(c)
    assert w[("b", 0.25)] == pytest.approx(0.5)
    assert w[("b", 0.9)] == pytest.approx(0.3)
    k = x >= 0.9
    assert w[("q_over_p", 0.9)] == pytest.approx(np.mean(q[k] / p[k]))
    assert w[("p_star", 0.55)] == pytest.approx(np.mean(p[(x >= 0.55) & (x <= 0.6)] / 5e7))
    assert geotech_cv.q_over_p(0.0, 0.3) == pytest.approx(0.0)


def test_the_drained_family_is_read_at_the_measured_b_between_neighbours():
    fam = [(0.0, 0.8, 0.02), (0.25, 0.7, 0.04), (0.5, 0.6, 0.06)]
    assert geotech_cv.drained_at(fam, 0.375) == pytest.approx((0.65, 0.05))
    assert all(math.isnan(v) for v in geotech_cv.drained_at(fam, 0.6))   # outside: not determined


def rows(path):
    with open(path) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    r = list(csv.reader(lines))
    return r[0], r[1:]


def test_the_stored_curves_hold_their_volume_and_run_to_eps_d_one():
    curves = glob.glob(os.path.join(DATA, "curves", "mu_*", "*", "iso_vhi", "CV_*", "m*.csv"))
    assert len(curves) == 5 * 2 * 8   # mu 0, 0.1, 0.3, 0.5, 1; D2, D3; K = 8
    for path in curves:
        header, rs = rows(path)
        col = lambda name: np.array([float(r[header.index(name)]) for r in rs])
        assert np.max(np.abs(col("eps_v"))) < 1e-12, path
        assert col("eps_d")[-1] == pytest.approx(1.0, abs=5e-3), path
        if "CV_D2" in path:
            assert np.max(np.abs(col("eps_yy"))) == 0.0, path


def test_the_stored_table_is_what_the_stored_curves_give(tmp_path):
    geotech_cv.analyse(os.path.join(DATA, "curves"), str(tmp_path), os.path.join(ROOT, "data", "geotech", "summary.csv"),
                       plots=False)
    with open(os.path.join(DATA, "constant_volume.csv")) as a, open(tmp_path / "constant_volume.csv") as b:
        assert a.read() == b.read()
