"""demkit.path_ensemble on synthetic member curves (fast): a constant-side-stress (triaxial) path
is flagged, gridded on eps_d since the start (not the servo-inflated eps_d_accumulated), and carries
the axial strain and the side stress over the start pressure (docs/model.md, "Constant side stress")."""
import csv
import os

import numpy as np

from demkit import path_ensemble

COLS = ["eps_xx", "eps_yy", "eps_zz", "eps_v", "eps_d", "nu", "p_Pa", "p_star", "sigma_xx_Pa", "sigma_yy_Pa",
        "sigma_zz_Pa", "s_dev", "F_xx", "F_zz", "F_dev", "target_xx_Pa", "target_yy_Pa", "target_zz_Pa",
        "target_p_Pa", "eps_d_accumulated"]


def write_member(path, k):
    n = 41
    ea = -np.linspace(0, 0.1, n)
    ev = -0.002 * np.sin(np.linspace(0, 2, n)) * (1 + 0.1 * k)
    er = (3 * ev - ea) / 2
    noise = 1e-4 * (-1) ** np.arange(n) * (np.arange(n) > 0)
    exx, eyy = er + noise, er - noise          # two servos: side strains differ by noise
    ed = np.sqrt(((exx - eyy) ** 2 + (eyy - ea) ** 2 + (ea - exx) ** 2) / 2)
    acc = np.concatenate([[0], np.cumsum(np.abs(np.diff(ed)) + 2e-4)])   # inflated by the servo
    p0 = 1e6
    s = 0.2 * (1 - np.exp(-40 * ed))
    p = p0 / (1 - s / 3)
    sr = np.full(n, p0)
    sz = p + 2 * s * p / 3
    rows = np.column_stack([exx, eyy, ea, ev, ed, 0.7 * np.exp(-3 * ev), p, p * 2e-8, sr, sr, sz, s,
                            1 - s / 4, 1 + s / 2, s * 0.7, np.full(n, p0), np.full(n, p0), np.full(n, np.nan),
                            np.full(n, np.nan), acc])
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", newline="") as fh:
        fh.write("# synthetic triaxial member\n")
        w = csv.writer(fh)
        w.writerow(COLS)
        for r in rows:
            w.writerow([repr(float(v)) for v in r])
    return ed


def test_triaxial_paths_are_flagged_and_gridded_on_eps_d(tmp_path):
    raw = tmp_path / "raw"
    eds = [write_member(str(raw / f"m00{k}" / "triaxial_phi0.700.csv"), k) for k in range(3)]
    assert path_ensemble.main(["--members", str(raw), "--out", str(tmp_path / "out")]) == 0
    with open(tmp_path / "out" / "paths" / "triaxial_phi0.700.csv") as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    head = lines[0].strip().split(",")
    d = {h: np.array([float(ln.split(",")[i]) for ln in lines[1:]]) for i, h in enumerate(head)}
    assert np.all(d["triaxial"] == 1) and np.all(d["isobaric"] == 0) and np.all(d["direction"] == 1)
    assert d["eps_d_accumulated"][-1] <= min(e[-1] for e in eds) + 1e-9   # eps_d, not the inflated sum
    assert d["eps_d_accumulated"][-1] > min(e[-1] for e in eds) - 0.004   # cut at a row of member 0
    assert np.allclose(d["sigma_r_p0_mean"], 1.0)
    assert abs(d["eps_zz_mean"][-1] + 0.1) < 0.004   # the last rows of the shortest member
    assert np.all(np.diff(d["eps_d_accumulated"]) >= 0)
