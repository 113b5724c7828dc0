"""Figures: every PNG and SVG carries the toolkit version and the scene hash; no panel is drawn
empty (one volume fraction: no parameters-against-nu figure; a constant quantity: no panel)."""
import csv
import hashlib
import re
import shutil
import struct

import numpy as np

from demkit import figures, plots


def png_text(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = {}, 8
    while i < len(data):
        n, = struct.unpack(">I", data[i:i + 4])
        kind, chunk = data[i + 4:i + 8], data[i + 8:i + 8 + n]
        if kind == b"tEXt":
            k, v = chunk.split(b"\0", 1)
            out[k.decode()] = v.decode("latin-1")
        i += 12 + n
    return out


def test_figures_carry_version_and_scene_hash_and_no_panel_is_empty(small_run, tmp_path, capsys):
    run = small_run["dir"]
    figures.SAVED.clear()
    assert plots.main([str(run), "--fits"]) == 0        # what `dem plot RUN --fits` runs
    assert figures.SAVED and all(f["empty"] == 0 for f in figures.SAVED), figures.SAVED
    params = [f for f in figures.SAVED if f["stem"].endswith("fit_parameters")]
    assert params and params[0]["axes"] >= 2
    scene = hashlib.sha256((run / "scene.toml").read_bytes()).hexdigest()[:16]
    pngs = sorted((run / "plots").glob("*.png"))
    assert len(pngs) >= 8
    for png in pngs:
        meta = png_text(png)
        assert re.fullmatch(r"dem-toolkit [0-9.]+( \(git [0-9a-f]+\))?", meta["Software"]), meta
        assert f"scene sha256:{scene}" in meta["Source"], (png.name, meta)
        assert re.search(r"physics [0-9a-f]{8,}", meta["Source"]), meta
        svg = png.with_suffix(".svg").read_text()
        assert f"<dc:source>scene sha256:{scene}" in svg, png.name
        assert "dem-toolkit" in svg
    # one volume fraction: the parameters cannot be drawn against nu, and are not drawn at all
    one = tmp_path / "one"
    (one / "deviatoric").mkdir(parents=True)
    (one / "fit").mkdir()
    shutil.copy(run / "scene.toml", one / "scene.toml")
    for m in ("D2", "D3"):
        shutil.copy(run / "deviatoric" / f"{m}_phi0.720.csv", one / "deviatoric")
    with open(run / "fit" / "parameters.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["nu"] == "0.72"]
    assert rows
    with open(one / "fit" / "parameters.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    figures.SAVED.clear()
    capsys.readouterr()
    assert plots.main([str(one), "--fits"]) == 0
    assert not (one / "plots" / "fit_parameters.png").exists()
    assert "fewer than two volume fractions" in capsys.readouterr().err
    assert figures.SAVED and all(f["empty"] == 0 for f in figures.SAVED), figures.SAVED


def synthetic_path(constant_volume, servo):
    x = np.linspace(0, 0.3, 60)
    rng = np.random.default_rng(1)
    c = {"eps_d_accumulated": x, "s_dev": 0.1 + 0.1 * np.tanh(20 * x), "F_dev": 0.05 + 0.05 * np.tanh(15 * x),
         "sigma_xx_Pa": 1e3 * (1 + x), "sigma_zz_Pa": 1e3 * (1 - x), "p_Pa": np.full_like(x, 1e3),
         "eps_v": rng.normal(0, 1e-17, x.size) if constant_volume else 0.01 * x,
         "control_error_rel": rng.uniform(1e-4, 1e-2, x.size) if servo else np.zeros_like(x),
         "stage": np.array(["load"] * 30 + ["back"] * 30)}
    return c


def test_path_figure_is_2x2_and_leaves_out_constant_quantities(tmp_path):
    figures.SAVED.clear()
    plots.plot_path("mixed", 0.7, synthetic_path(constant_volume=False, servo=True), str(tmp_path))
    plots.plot_path("reversal", 0.7, synthetic_path(constant_volume=True, servo=False), str(tmp_path))
    mixed, rev = figures.SAVED
    assert mixed["axes"] == 4 and mixed["empty"] == 0
    # eps_v of 1e-17 is round-off: no curve of it, and no servo panel; the title says why
    assert rev["axes"] == 2 and rev["empty"] == 0
    assert "constant volume" in rev["title"] and "no servo" in rev["title"]
    assert "constant volume" not in mixed["title"]


def test_compare_overlay_leaves_out_round_off_and_labels_by_file(tmp_path):
    from demkit import compare
    e = np.linspace(0, 0.2, 41)
    rng = np.random.default_rng(3)
    files = []
    for k in range(2):
        d = tmp_path / f"m00{k}" / "deviatoric"
        d.mkdir(parents=True)
        f = d / "D2_phi0.700.csv"
        cols = {"eps_d": e, "p_Pa": 1e6 * (1 + 0.01 * k + 0.1 * e), "s_dev": 0.2 * np.tanh(30 * e) + 0.01 * k,
                "F_dev": 0.1 * np.tanh(20 * e), "C": 6 + e, "eps_v": rng.normal(0, 1e-17, e.size)}
        with open(f, "w") as fh:
            fh.write("# synthetic\n" + ",".join(cols) + "\n")
            for i in range(e.size):
                fh.write(",".join(repr(float(v[i])) for v in cols.values()) + "\n")
        files.append(f)
    figures.SAVED.clear()
    out = tmp_path / "overlay.png"
    compare.main([str(files[0]), str(files[1]), "--plot", str(out)])
    fig = figures.SAVED[-1]
    assert fig["axes"] == 4 and fig["empty"] == 0, fig          # p, s_dev, F_dev, C; eps_v is round-off
    assert "constant volume" in fig["title"]
    assert out.exists() and out.with_suffix(".svg").exists()
    assert png_text(out)["Software"].startswith("dem-toolkit")
    assert compare.short_labels(str(files[0]), str(files[1])) == ["m000/deviatoric/D2_phi0.700.csv",
                                                                   "m001/deviatoric/D2_phi0.700.csv"]
