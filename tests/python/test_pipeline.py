"""The whole protocol on a small scene: the physics the papers report, and the outputs."""
import csv
import glob
import json
import os

import numpy as np

from demkit.curves import read_curve, REQUIRED_COLUMNS


def curves(run, pattern):
    return {os.path.basename(f)[:-4]: read_curve(f) for f in sorted(glob.glob(os.path.join(run, pattern)))}


def test_run_folder_layout_and_columns(small_run):
    run = small_run["dir"]
    man = json.loads((run / "manifest.json").read_text())
    assert man["complete"] is True
    for stage in ("compress", "relax", "cycle_loading", "cycle_unloading"):
        c = read_curve(run / "prep" / f"{stage}.csv")
        for col in REQUIRED_COLUMNS:
            assert col in c, f"{stage}.csv lacks {col}"
    dev = curves(run, "deviatoric/*.csv")
    assert sorted(dev) == sorted(f"{m}_phi{nu}" for m in ("D2", "D3") for nu in ("0.690", "0.720", "0.780"))
    # checkpoints: binary + YADE text packing with the periodic cell line
    txt = sorted(glob.glob(str(run / "checkpoints" / "unloading_phi*.txt")))
    assert len(txt) == 3
    with open(txt[0]) as fh:
        assert fh.readline().startswith("##PERIODIC::")
    assert not glob.glob(str(run / "**" / "*.part"), recursive=True), "half-written files left behind"
    # ParaView index points at existing snapshots
    pvd = (run / "vtk" / "D2_phi0.720.pvd").read_text()
    for name in [p.split('"')[0] for p in pvd.split('file="')[1:]]:
        assert (run / "vtk" / name).exists()


def test_jamming_fraction_in_the_range_of_the_papers(small_run):
    # Unloading branch: the lowest nu with a mechanically stable skeleton (non-rattler
    # coordination > 0, p* > 1e-5). Goncu et al. 2010 / Imole et al. 2013 report nu_c of about
    # 0.66 for w = 3 frictionless spheres; a small fast-prepared sample may lie a bit off.
    c = read_curve(small_run["dir"] / "prep" / "cycle_unloading.csv")
    jammed = (c["C_nonrattler"] > 0) & (c["p_star"] > 1e-5)
    nu_j = c["nu"][jammed].min()
    assert 0.64 <= nu_j <= 0.69, nu_j
    # above jamming the pressure is positive and grows with nu
    above = c["nu"] > nu_j + 0.02
    assert np.all(c["p_Pa"][above] > 0)
    order = np.argsort(c["nu"][above])
    assert np.corrcoef(c["nu"][above][order], c["p_star"][above][order])[0, 1] > 0.95


def test_deviatoric_modes_conserve_volume_and_saturate(small_run):
    grid = np.linspace(0, 0.3, 301)
    mean = np.zeros_like(grid)
    all_curves = curves(small_run["dir"], "deviatoric/*.csv")
    for name, c in all_curves.items():
        e, s = c["eps_d"], c["s_dev"]
        assert np.max(np.abs(c["eps_v"])) < 1e-12, name          # volume conserved
        assert abs(c["nu"][-1] - c["nu"][0]) < 1e-10, name
        assert abs(e[-1] - 0.3) < 1e-9, name                      # stops exactly at eps_d_max
        early, late = s[e < 0.01].mean(), s[e > 0.15].mean()
        assert late > early + 0.05, (name, early, late)           # s_dev grows ...
        assert 0.05 < late < 0.4, (name, late)                    # macroscopic friction of order 0.1-0.2
        mean += np.interp(grid, e, s) / len(all_curves)
    # ... and saturates, judged on the mean of the six curves: a single 400-sphere curve
    # fluctuates by +-0.05 around its plateau (avalanches), and one of six realisations may
    # still rise at eps_d = 0.3 (seen once with another summation order). Above eps_d = 0.15 the
    # mean lies less than half its early gain (by eps_d = 0.05-0.1) above the early level; a
    # linear rise would lie 2x above it.
    early, mid, late = mean[grid < 0.01].mean(), mean[(grid > 0.05) & (grid < 0.1)].mean(), mean[grid > 0.15].mean()
    assert mid > early + 0.03, (early, mid)
    assert late < mid + 0.5 * (mid - early), (early, mid, late)
    for name, c in all_curves.items():
        e = c["eps_d"]
        # fabric anisotropy builds up along the loading: contacts align with the compressed z
        # axis. (Judged signed: a 400-sphere packing can start with an anisotropy of the
        # opposite orientation as large as the plateau, so F_dev's magnitude may dip first.)
        a = c["F_zz"] - 0.5 * (c["F_xx"] + c["F_yy"])
        assert a[e > 0.15].mean() > max(a[0], 0) + 0.02, (name, a[0], a[e > 0.15].mean())
        assert np.all(c["p_Pa"] > 0), name


def test_fit_tables_in_all_formats_and_parameters_in_range(small_run):
    fit = small_run["dir"] / "fit"
    for stem in ("parameters", "shared_path"):
        for ext in ("csv", "json", "md", "tex"):
            assert (fit / f"{stem}.{ext}").exists(), f"{stem}.{ext}"
    with open(fit / "parameters.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12
    # Judged on the median over the six curves: one chaotic 400-sphere curve may still rise at
    # eps_d = 0.3 and fit a slow law (x_max 0.45, beta 1.6 seen once), which is what its data say.
    fitted = [r for r in rows if r["quantity"] == "s_dev" and r["x_max"] != "nan"]
    assert len(fitted) >= 4, rows
    assert 0.05 < np.median([float(r["x_max"]) for r in fitted]) < 0.4, fitted
    assert np.median([float(r["beta"]) for r in fitted]) > 3.0, fitted
    assert all(float(r["beta"]) > 1.0 for r in fitted), fitted
    data = json.loads((fit / "parameters.json").read_text())
    assert len(data["rows"]) == 12
    assert glob.glob(str(small_run["dir"] / "plots" / "fit_D2_phi0.720.png"))
    assert glob.glob(str(small_run["dir"] / "plots" / "deviatoric_s_dev.svg"))


def test_deviatoric_stage_alone_reuses_the_checkpoints(small_run, tmp_path):
    # `--stages deviatoric` on a folder holding only checkpoints runs the modes from them.
    import shutil
    from conftest import run_dem
    out = tmp_path / "again"
    shutil.copytree(small_run["dir"] / "checkpoints", out / "checkpoints")
    run_dem("run", small_run["scene"], "--out", out, "--stages", "deviatoric", "--quiet",
            "--set", "protocol.eps_d_max=0.02", "--set", 'protocol.modes=["D3"]', check=True)
    made = sorted(p.name for p in (out / "deviatoric").iterdir())
    assert made == ["D3_phi0.690.csv", "D3_phi0.720.csv", "D3_phi0.780.csv"]
    c = read_curve(out / "deviatoric" / "D3_phi0.720.csv")
    first = read_curve(small_run["dir"] / "deviatoric" / "D3_phi0.720.csv")
    assert abs(c["eps_d"][-1] - 0.02) < 1e-12
    assert c["p_Pa"][0] == first["p_Pa"][0]          # same checkpoint, same first row
    # A second invocation with one more mode keeps the finished curves and adds the new ones,
    # and the manifest lists the outputs of both invocations.
    before = (out / "deviatoric" / "D3_phi0.720.csv").read_bytes()
    p = run_dem("run", small_run["scene"], "--out", out, "--stages", "deviatoric",
                "--set", "protocol.eps_d_max=0.02", "--set", 'protocol.modes=["D2","D3"]', check=True)
    assert "D3_phi0.720: finished earlier, kept" in p.stderr
    assert (out / "deviatoric" / "D3_phi0.720.csv").read_bytes() == before
    files = sorted(o["file"] for o in json.loads((out / "manifest.json").read_text())["outputs"])
    assert files == sorted(f"deviatoric/{m}_phi{phi}.csv" for m in ("D2", "D3")
                           for phi in ("0.690", "0.720", "0.780"))
