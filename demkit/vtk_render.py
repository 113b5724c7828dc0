"""Render one VTK snapshot of a run offscreen to a PNG: the packing (translucent spheres), its
force chains (the contact network as tubes, thickness and colour by the normal force) and the
periodic cell (its edges, following the tilt of a sheared cell).

    /usr/bin/python3 -m demkit.vtk_render RUN/vtk/D2_phi0.720 [--frame -1] --out frame.png

STAGE is the path without suffix: STAGE_NNNN.vtu, STAGE_contacts_NNNN.vtu and
STAGE_cell_NNNN.vtu are read (sim/include/dem/io/vtk.hpp). Needs python3-vtk9. Debian's VTK
renders through X even offscreen (it aborts without one), so without a display this starts a
virtual one itself: it runs again under `xvfb-run -a` (Debian's xvfb, scripts/install-deps.sh),
and says so when xvfb-run is missing instead of crashing.
"""
import argparse
import glob
import os
import re
import shutil
import sys

UNDER_XVFB = "DEMKIT_VTK_RENDER_UNDER_XVFB"


def frames(stage):
    pat = re.compile(re.escape(os.path.basename(stage)) + r"_(\d{4})\.vtu$")
    found = sorted(int(m.group(1)) for f in glob.glob(stage + "_*.vtu")
                   if (m := pat.search(os.path.basename(f))))
    return found


def read(path):
    import vtk
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    return r.GetOutput()


def render(stage, frame, out, size=900):
    import vtk
    idx = frames(stage)
    if not idx:
        raise SystemExit(f"vtk_render: no {stage}_NNNN.vtu files")
    n = idx[frame]
    particles = read(f"{stage}_{n:04d}.vtu")
    contacts = read(f"{stage}_contacts_{n:04d}.vtu")
    cell = read(f"{stage}_cell_{n:04d}.vtu")

    ren = vtk.vtkRenderer()
    ren.SetBackground(1, 1, 1)

    # spheres of the particles' radii
    particles.GetPointData().SetActiveScalars("radius_m")
    sphere = vtk.vtkSphereSource()
    sphere.SetThetaResolution(16)
    sphere.SetPhiResolution(12)
    sphere.SetRadius(1.0)
    glyph = vtk.vtkGlyph3D()
    glyph.SetInputData(particles)
    glyph.SetSourceConnection(sphere.GetOutputPort())
    glyph.SetScaleModeToScaleByScalar()
    glyph.SetScaleFactor(1.0)
    glyph.SetColorModeToColorByScale()
    m = vtk.vtkPolyDataMapper()
    m.SetInputConnection(glyph.GetOutputPort())
    m.ScalarVisibilityOff()
    a = vtk.vtkActor()
    a.SetMapper(m)
    a.GetProperty().SetColor(0.55, 0.6, 0.7)
    a.GetProperty().SetOpacity(0.12)
    ren.AddActor(a)

    # force chains: tubes, radius and colour by the normal force
    fn = contacts.GetCellData().GetArray("normal_force_N")
    if contacts.GetNumberOfCells() and fn is not None:
        fmax = fn.GetRange()[1]
        geo = vtk.vtkGeometryFilter()
        geo.SetInputData(contacts)
        c2p = vtk.vtkCellDataToPointData()
        c2p.SetInputConnection(geo.GetOutputPort())
        c2p.Update()
        pd = c2p.GetOutput()
        pd.GetPointData().SetActiveScalars("normal_force_N")
        rmean = particles.GetPointData().GetArray("radius_m").GetRange()
        rmean = 0.5 * (rmean[0] + rmean[1])
        tube = vtk.vtkTubeFilter()
        tube.SetInputData(pd)
        tube.SetVaryRadiusToVaryRadiusByAbsoluteScalar()
        tube.SetRadius(0.02 * rmean)
        tube.SetNumberOfSides(8)
        # absolute radius: scale the scalars into a copy
        scaled = vtk.vtkArrayCalculator()
        scaled.SetInputData(pd)
        scaled.SetAttributeTypeToPointData()
        scaled.AddScalarArrayName("normal_force_N")
        scaled.SetFunction(f"{0.35 * rmean / max(fmax, 1e-300)}*normal_force_N")
        scaled.SetResultArrayName("tube_radius")
        scaled.Update()
        sp = scaled.GetOutput()
        sp.GetPointData().SetActiveScalars("tube_radius")
        tube.SetInputData(sp)
        lut = vtk.vtkLookupTable()
        lut.SetHueRange(0.6, 0.0)   # blue (weak) to red (strong)
        lut.SetSaturationRange(0.9, 0.9)
        lut.Build()
        tm = vtk.vtkPolyDataMapper()
        tm.SetInputConnection(tube.GetOutputPort())
        tm.SetScalarModeToUsePointFieldData()
        tm.SelectColorArray("normal_force_N")
        tm.SetLookupTable(lut)
        tm.SetScalarRange(0, fmax)
        ta = vtk.vtkActor()
        ta.SetMapper(tm)
        ren.AddActor(ta)
        bar = vtk.vtkScalarBarActor()
        bar.SetLookupTable(lut)
        bar.SetTitle("normal force [N]")
        bar.SetNumberOfLabels(4)
        bar.GetTitleTextProperty().SetColor(0, 0, 0)
        bar.GetLabelTextProperty().SetColor(0, 0, 0)
        bar.SetWidth(0.08)
        bar.SetHeight(0.45)
        ren.AddActor2D(bar)

    # the periodic cell's edges
    edges = vtk.vtkExtractEdges()
    edges.SetInputData(cell)
    em = vtk.vtkPolyDataMapper()
    em.SetInputConnection(edges.GetOutputPort())
    em.ScalarVisibilityOff()
    ea = vtk.vtkActor()
    ea.SetMapper(em)
    ea.GetProperty().SetColor(0, 0, 0)
    ea.GetProperty().SetLineWidth(2)
    ren.AddActor(ea)

    ren.ResetCamera()
    cam = ren.GetActiveCamera()
    cam.Azimuth(30)
    cam.Elevation(20)
    ren.ResetCamera()
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.AddRenderer(ren)
    win.SetSize(size, size)
    win.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.Update()
    w = vtk.vtkPNGWriter()
    w.SetFileName(out)
    w.SetInputConnection(grab.GetOutputPort())
    w.Write()
    return {"frame": n, "particles": particles.GetNumberOfPoints(), "contacts": contacts.GetNumberOfCells()}


def ensure_display(argv):
    """Without an X display, run this command again under `xvfb-run -a` (does not return); with one,
    or already under it, return. Exits 2 naming the package when xvfb-run is missing."""
    if os.environ.get("DISPLAY") or os.environ.get(UNDER_XVFB):
        return
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        sys.exit("vtk_render: no display (DISPLAY is not set) and no xvfb-run to start a virtual one: install Debian's "
                 "xvfb and xauth (scripts/install-deps.sh does), or run where a display is")
    os.environ[UNDER_XVFB] = "1"
    sys.stdout.flush()
    sys.stderr.flush()
    os.execv(xvfb, [xvfb, "-a", sys.executable, "-m", "demkit.vtk_render", *argv])


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(prog="python3 -m demkit.vtk_render", description=__doc__.split("\n\n")[0])
    ap.add_argument("stage", help="RUN/vtk/STAGE (without _NNNN.vtu)")
    ap.add_argument("--frame", type=int, default=-1, help="snapshot index in the series (default: the last)")
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--size", type=int, default=900, help="image size in pixels")
    a = ap.parse_args(argv)
    try:
        import vtk  # noqa: F401
    except ImportError:
        raise SystemExit("vtk_render: needs Debian's python3-vtk9 (and xvfb without a display), which come with the "
                         "tests' packages: bash scripts/install-deps.sh --only test")
    ensure_display(argv)
    info = render(a.stage, a.frame, a.out, a.size)
    print(f"vtk_render: frame {info['frame']}: {info['particles']} particles, {info['contacts']} contacts -> {a.out}",
          file=sys.stderr)


if __name__ == "__main__":
    main()
