"""VTK for ParaView: the files read back with VTK's own reader (python3-vtk9), their cells,
counts and fields checked against the run's curves and the geometry, and one frame rendered
offscreen to a PNG that must not be blank."""
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from conftest import ROOT, run_dem
from demkit.curves import read_curve

vtk = pytest.importorskip("vtk", reason="python3-vtk9 is not installed (scripts/install-deps.sh installs it)")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402

SCENE = """
[particles]
count = 300
seed = 3
[protocol]
target_phi = 0.64
compress_rate_tc = 1e-3
cycle_rate_tc = 5e-4
cycle_phi_max = 0.75
checkpoints_unloading = [0.72]
modes = ["D2"]
deviatoric_rate_tc = 2e-4
eps_d_max = 0.05
[output]
sample_strain = 0.005
"""
VTK_VERTEX, VTK_LINE, VTK_HEXAHEDRON = 1, 3, 12


@pytest.fixture(scope="module")
def vtk_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("vtk")
    (d / "s.toml").write_text(SCENE)
    run_dem("run", d / "s.toml", "--out", d / "run", "--quiet", check=True)
    # simple shear from the same checkpoint: a tilted cell
    shutil.copytree(d / "run" / "checkpoints", d / "ss" / "checkpoints")
    run_dem("run", d / "s.toml", "--out", d / "ss", "--stages", "deviatoric", "--quiet",
            "--set", "protocol.eps_d_max=0.1", "--set", 'protocol.modes=["SS_xz"]', check=True)
    return d


def read(path):
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    r.Update()
    g = r.GetOutput()
    assert g is not None and r.GetErrorCode() == 0, path
    return g


def cell_types(g):
    return {g.GetCellType(i) for i in range(g.GetNumberOfCells())}


def field(g, name, cells=False):
    data = g.GetCellData() if cells else g.GetPointData()
    a = data.GetArray(name)
    assert a is not None, f"no {'cell' if cells else 'point'} field {name}"
    return vtk_to_numpy(a)


def points(g):
    return vtk_to_numpy(g.GetPoints().GetData())


def series(pvd):
    root = ET.parse(pvd).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def check_snapshot(vtkdir, stem, index, radius_bounds=None):
    """Particles, contacts and cell of one snapshot, consistent with each other."""
    p = read(vtkdir / f"{stem}_{index:04d}.vtu")
    c = read(vtkdir / f"{stem}_contacts_{index:04d}.vtu")
    box = read(vtkdir / f"{stem}_cell_{index:04d}.vtu")
    n = p.GetNumberOfPoints()
    # one vertex cell per particle: ParaView shows them on opening
    assert p.GetNumberOfCells() == n and cell_types(p) == {VTK_VERTEX}
    r = field(p, "radius_m")
    assert np.all(r > 0)
    assert sorted(field(p, "id")) == list(range(n))
    assert field(p, "velocity_m_s").shape == (n, 3)
    # the contact network: one line per contact, 2 points each
    m = c.GetNumberOfCells()
    assert m > n, (m, n)                      # a jammed packing has C = 2m/n > 2
    assert cell_types(c) == {VTK_LINE} and c.GetNumberOfPoints() == 2 * m
    # each particle's contact count is the number of lines it ends
    i, j = field(c, "i", True), field(c, "j", True)
    counts = np.bincount(np.concatenate([i, j]), minlength=n)
    assert np.array_equal(counts, field(p, "contacts"))
    # lines join i to the touching image of j: length = r_i + r_j - overlap, never across the box
    xy = points(c).reshape(m, 2, 3)
    length = np.linalg.norm(xy[:, 1] - xy[:, 0], axis=1)
    overlap = field(c, "overlap_m", True)
    assert np.all(overlap > 0)
    np.testing.assert_allclose(length, r[i] + r[j] - overlap, rtol=1e-9)
    np.testing.assert_allclose(xy[:, 0], points(p)[i], rtol=0, atol=1e-12 * r.max())
    # the normal force of a linear spring: one stiffness for every contact, along the branch
    fn = field(c, "normal_force_N", True)
    k = fn / overlap
    np.testing.assert_allclose(k, k[0], rtol=1e-9)
    normal = field(c, "normal", True)
    np.testing.assert_allclose(normal, (xy[:, 1] - xy[:, 0]) / length[:, None], atol=1e-9)
    # the periodic cell: one hexahedron whose volume is the field's, every particle inside it
    assert box.GetNumberOfCells() == 1 and cell_types(box) == {VTK_HEXAHEDRON} and box.GetNumberOfPoints() == 8
    q = points(box)
    H = np.column_stack([q[1] - q[0], q[3] - q[0], q[4] - q[0]])   # lattice vectors a, b, c
    volume = float(np.linalg.det(H))
    np.testing.assert_allclose(volume, field(box, "volume_m3", True)[0], rtol=1e-12)
    frac = np.linalg.solve(H, (points(p) - q[0]).T).T
    assert frac.min() >= -1e-12 and frac.max() < 1 + 1e-12
    return {"n": n, "contacts": m, "H": H, "volume": volume, "radius": r}


def test_vtk_files_read_back_with_cells_counts_and_fields(vtk_run):
    vtkdir = vtk_run / "run" / "vtk"
    for stem in ("compress", "relax", "cycle_loading", "cycle_unloading", "D2_phi0.720"):
        for kind in ("", "_contacts", "_cell"):
            s = series(vtkdir / f"{stem}{kind}.pvd")
            assert all((vtkdir / f).exists() for _, f in s), stem + kind
            assert [t for t, _ in s] == sorted(t for t, _ in s)
        # binary appended data, not ASCII
        head = (vtkdir / f"{stem}_0000.vtu").read_bytes()
        assert b'format="appended"' in head and b'format="ascii"' not in head
        assert b'<AppendedData encoding="raw">' in head
    # a small scene makes an animation by default: 20 snapshots between start and end
    frames = series(vtkdir / "D2_phi0.720.pvd")
    assert len(frames) == 22, len(frames)
    assert len(series(vtkdir / "cycle_unloading.pvd")) == 22   # a stage that decreases phi too
    curve = read_curve(vtk_run / "run" / "deviatoric" / "D2_phi0.720.csv")
    last = check_snapshot(vtkdir, "D2_phi0.720", len(frames) - 1)
    first = check_snapshot(vtkdir, "D2_phi0.720", 0)
    assert last["n"] == 300
    # the contacts of the first and last snapshots are the curve's first and last `contacts`
    assert first["contacts"] == curve["contacts"][0]
    assert last["contacts"] == curve["contacts"][-1]
    # the cell's volume holds the particles at the curve's volume fraction
    solid = np.sum(4 / 3 * np.pi * last["radius"] ** 3)
    np.testing.assert_allclose(solid / last["volume"], curve["nu"][-1], rtol=1e-6)
    # an orthorhombic cell stays orthorhombic; D2 stretched it (x and z edges differ)
    H = last["H"]
    assert np.allclose(H - np.diag(np.diag(H)), 0, atol=1e-15 * H.max())
    assert abs(H[0, 0] - H[2, 2]) > 0.01 * H[0, 0]


def test_sheared_cell_is_a_tilted_hexahedron_and_contacts_cross_it(vtk_run):
    vtkdir = vtk_run / "ss" / "vtk"
    frames = series(vtkdir / "SS_xz_phi0.720.pvd")
    snap = check_snapshot(vtkdir, "SS_xz_phi0.720", len(frames) - 1)
    H = snap["H"]
    # SS_xz tilts the z lattice vector along x (never beyond half an edge: remapped)
    assert H[0, 2] > 0.02 * H[2, 2], H
    assert abs(H[0, 2]) <= 0.5 * H[0, 0] * (1 + 1e-9)
    curve = read_curve(vtk_run / "ss" / "deviatoric" / "SS_xz_phi0.720.csv")
    assert snap["contacts"] == curve["contacts"][-1]
    np.testing.assert_allclose(np.sum(4 / 3 * np.pi * snap["radius"] ** 3) / snap["volume"], curve["nu"][-1], rtol=1e-6)


def test_one_frame_renders_offscreen_to_a_picture_of_the_force_chains(vtk_run, tmp_path):
    png = tmp_path / "frame.png"
    # As a user without a display runs it: no DISPLAY, no xvfb-run in front (it starts one itself).
    cmd = ["/usr/bin/python3", "-m", "demkit.vtk_render", str(vtk_run / "run" / "vtk" / "D2_phi0.720"),
           "--out", str(png), "--size", "400"]
    if not shutil.which("xvfb-run"):
        pytest.skip("no xvfb-run (scripts/install-deps.sh installs xvfb)")
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=ROOT, env={**env, "PYTHONPATH": ROOT})
    assert p.returncode == 0, p.stderr[-2000:]
    import matplotlib.image
    img = matplotlib.image.imread(str(png))[..., :3]
    assert img.shape[:2] == (400, 400)
    white = np.all(img > 0.97, axis=2)
    assert white.mean() < 0.9, "the picture is (almost) blank"
    # force chains are coloured (blue to red); the spheres and the cell are grey and black
    rgb_spread = img.max(axis=2) - img.min(axis=2)
    assert (rgb_spread > 0.3).mean() > 0.02, "no coloured force chains in the picture"
    # the cell's edges: dark pixels
    assert (img.max(axis=2) < 0.15).mean() > 0.001
