# The periodic shift velocity in YADE's contact laws: two identical pairs, one inside the cell and one
# across the x and z boundaries, both moving with the affine field of D2 (rate 1e-4/t_c) and at rest in
# the fluctuation frame, overlap 1 %, branch vector at 45 deg in the x-z plane. After 20 steps the
# shear force of the two pairs must be the same. Prints |F_s| of both pairs for
#   viscel:    ViscElMat + Law2_ScGeom_ViscElPhys_Basic (adds shiftVel with the wrong sign),
#   frictphys: FrictMat (E = k/r) + Law2_ScGeom_FrictPhys_CundallStrack (ScGeom::getIncidentVel: right).
#   yade -n -x -j1 yade_ref/shift_velocity_check.py [--json out.json]
import json
import math
import sys

from yade import O, Matrix3, ViscElMat, FrictMat, ForceResetter, InsertionSortCollider, Bo1_Sphere_Aabb, \
    InteractionLoop, Ig2_Sphere_Sphere_ScGeom, Ip2_ViscElMat_ViscElMat_ViscElPhys, Law2_ScGeom_ViscElPhys_Basic, \
    Ip2_FrictMat_FrictMat_FrictPhys, Law2_ScGeom_FrictPhys_CundallStrack, NewtonIntegrator, utils

K, MU, R, TC = 1e8, 0.5, 5e-4, 2.2787e-7


def run(law):
    O.reset()
    O.periodic = True
    L = 20e-3
    O.cell.setBox(L, L, L)
    d = 2 * R * 0.99
    s = d / math.sqrt(2)
    pos = [(5e-3, 5e-3, 5e-3), (5e-3 + s, 5e-3, 5e-3 + s),
           (L - 1e-4, 15e-3, L - 1e-4), (L - 1e-4 + s - L, 15e-3, L - 1e-4 + s - L)]
    for p in pos:
        if law == "viscel":
            m = ViscElMat(kn=2 * K, cn=2.0, ks=2 * K * 2 / 7, cs=0, frictionAngle=math.atan(MU), density=2000)
        else:
            m = FrictMat(young=K / R, poisson=2 / 7, frictionAngle=math.atan(MU), density=2000)
        O.bodies.append(utils.sphere(p, R, material=O.materials.append(m)))
    rate = 1e-4 / TC
    O.cell.velGrad = Matrix3(rate, 0, 0, 0, 0, 0, 0, 0, -rate)
    for b in O.bodies:
        b.state.vel = O.cell.velGrad * b.state.pos
    ip, lw = ((Ip2_ViscElMat_ViscElMat_ViscElPhys(), Law2_ScGeom_ViscElPhys_Basic()) if law == "viscel"
              else (Ip2_FrictMat_FrictMat_FrictPhys(), Law2_ScGeom_FrictPhys_CundallStrack()))
    O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
                 InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [ip], [lw]), NewtonIntegrator(damping=0)]
    O.dt = 0.02 * TC
    O.run(20, True)
    out = {}
    for i in O.interactions:
        if i.isReal:
            out["across" if tuple(i.cellDist) != (0, 0, 0) else "inside"] = i.phys.shearForce.norm()
    return out


res = {law: run(law) for law in ("viscel", "frictphys")}
print(json.dumps(res))
if "--json" in sys.argv:
    with open(sys.argv[sys.argv.index("--json") + 1], "w") as fh:
        json.dump(res, fh, indent=2)
