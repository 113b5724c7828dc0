# demtk inside a YADE session: our engine runs the deformation stage of a YADE script.
#
#   PYTHONPATH=build/python yade -n -x -j1 yade_ref/demtk_in_yade.py --packing P.txt --scene S.toml \
#       --mode D2 --out OUT.csv [--back]
#
# The spheres are made in YADE as yade_ref/run_mode.py makes them (O.bodies, O.cell); then our
# State is built from O.bodies/O.cell (state_from_yade), the mode runs in our engine
# (demtk.run_mode: what `dem mode` does) and, with --back, the final positions, velocities and
# cell go back to O.bodies/O.cell (state_to_yade) so the YADE script could go on from there.
# The curve equals `dem mode --packing P.txt` byte for byte (tests/python/test_python_module.py):
# positions and radii are YADE's doubles; masses are taken from the scene's density with our
# formula (YADE's agree to round-off: printed), so that the bits agree.
# Frictionless spheres in an orthorhombic cell only (friction and tilted cells: not yet).
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "build", "python"))

import numpy as np  # noqa: E402

import demtk  # noqa: E402
from yade import O, Matrix3, Sphere, Vector3, ViscElMat, utils  # noqa: E402


def spheres_of_yade():
    return [b for b in O.bodies if b is not None and isinstance(b.shape, Sphere)]


def state_from_yade(scene, yade_masses=False):
    """Our State from the spheres of O.bodies and the cell O.cell (row k = k-th sphere body).
    Velocities are the fluctuation part (b.state.vel minus O.cell.velGrad x)."""
    bodies = spheres_of_yade()
    H = O.cell.hSize
    if any(H[i, j] != 0 for i in range(3) for j in range(3) if i != j):
        raise ValueError("state_from_yade: a tilted cell is not supported yet (orthorhombic O.cell only)")
    box = np.array([H[0, 0], H[1, 1], H[2, 2]])
    L = O.cell.velGrad
    pos = np.array([[b.state.pos[k] for k in range(3)] for b in bodies])
    pos = pos - box * np.floor(pos / box)   # YADE keeps unwrapped positions
    vel = np.array([[(b.state.vel - L * b.state.pos)[k] for k in range(3)] for b in bodies])
    radii = np.array([b.shape.radius for b in bodies])
    masses = np.array([b.state.mass for b in bodies]) if yade_masses else None
    st = demtk.State.from_arrays(pos, radii, box, density=None if yade_masses else scene.density,
                                 masses=masses, velocities=vel)
    return st, bodies


def state_to_yade(state, bodies, velocity_gradient):
    """Positions, velocities (fluctuation + L x) and the cell back to YADE (ids map rows to bodies)."""
    L = np.asarray(velocity_gradient)
    box = state.box.lengths
    O.cell.hSize = Matrix3(box[0], 0, 0, 0, box[1], 0, 0, 0, box[2])
    for k, i in enumerate(state.ids):
        x = state.positions[k]
        v = state.velocities[k] + L @ x
        bodies[i].state.pos = Vector3(*x)
        bodies[i].state.vel = Vector3(*v)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--packing", required=True)
    ap.add_argument("--scene", default=None)
    ap.add_argument("--mode", default="D2")
    ap.add_argument("--out", required=True)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--back", action="store_true", help="hand the final state back to O.bodies/O.cell")
    a = ap.parse_args(sys.argv[1:])
    scene = demtk.load_scene(a.scene, set={"protocol.modes": [a.mode], "integration.threads": a.threads})

    # the YADE side, as a YADE script would have it
    cell, spheres = None, []
    for line in open(a.packing):
        s = line.split()
        if line.startswith("##PERIODIC::"):
            cell = [float(v) for v in s[1:4]]
        elif s and not line.startswith("#"):
            spheres.append([float(v) for v in s[:4]])
    O.reset()
    O.periodic = True
    O.cell.setBox(*cell)
    mat = O.materials.append(ViscElMat(kn=2 * scene.stiffness, cn=2 * scene.damping, density=scene.density))
    for x, y, z, r in spheres:
        O.bodies.append(utils.sphere((x, y, z), r, material=mat))

    # ours from YADE's bodies
    st, bodies = state_from_yade(scene)
    ym = np.array([b.state.mass for b in bodies])
    print(f"demtk in YADE: {st.count} spheres from O.bodies, cell {st.box.lengths}; "
          f"YADE's masses / ours - 1: max {np.abs(ym / st.by_id(st.masses) - 1).max():.2g}")
    st.check_against(scene, a.packing)
    steps = demtk.run_mode(scene, st, a.mode, a.out, force=True)
    print(f"demtk in YADE: {a.mode} ran {steps} steps in our engine -> {a.out}")
    if a.back:
        state_to_yade(st, bodies, scene.velocity_gradient(a.mode))
        moved = max(abs(bodies[i].state.pos[k] - st.positions[row][k])
                    for row, i in enumerate(st.ids) for k in range(3))
        print(f"demtk in YADE: state handed back to O.bodies (max |x_yade - x_ours| = {moved:.2g} m), "
              f"O.cell.hSize diagonal {[O.cell.hSize[k, k] for k in range(3)]}")


main()
