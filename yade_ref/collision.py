# Two-sphere head-on collision in YADE with the physics of our runner; prints JSON with the
# measured contact time and restitution next to the analytic values.
#   yade -n -x -j1 yade_ref/collision.py [--r1 5e-4] [--r2 5e-4] [--dt-over-tc 5e-4] [--out result.json]
import argparse
import json
import math
import sys

from yade import O, Vector3, ViscElMat, ForceResetter, InsertionSortCollider, Bo1_Sphere_Aabb, InteractionLoop, \
    Ig2_Sphere_Sphere_ScGeom, Ip2_ViscElMat_ViscElMat_ViscElPhys, Law2_ScGeom_ViscElPhys_Basic, NewtonIntegrator, utils

ap = argparse.ArgumentParser(prog="collision.py")
ap.add_argument("--r1", type=float, default=5e-4)
ap.add_argument("--r2", type=float, default=5e-4)
ap.add_argument("--k", type=float, default=1e8)
ap.add_argument("--gamma", type=float, default=1.0)
ap.add_argument("--density", type=float, default=2000.0)
ap.add_argument("--v0", type=float, default=0.1, help="approach speed [m/s]")
ap.add_argument("--dt-over-tc", type=float, default=5e-4)
ap.add_argument("--out", default="")
a = ap.parse_args(sys.argv[1:])

m1 = 4 / 3 * math.pi * a.r1 ** 3 * a.density
m2 = 4 / 3 * math.pi * a.r2 ** 3 * a.density
mr = m1 * m2 / (m1 + m2)
w0sq, eta = a.k / mr, a.gamma / (2 * mr)
tc = math.pi / math.sqrt(w0sq - eta * eta)
e_true = math.exp(-eta * tc)

O.reset()
mat = O.materials.append(ViscElMat(kn=2 * a.k, cn=2 * a.gamma, ks=0, cs=0, frictionAngle=0, density=a.density))
gap = 2e-7
b1 = O.bodies.append(utils.sphere((0, 0, 0), a.r1, material=mat))
b2 = O.bodies.append(utils.sphere((a.r1 + a.r2 + gap, 0, 0), a.r2, material=mat))
for b in (b1, b2):
    O.bodies[b].state.blockedDOFs = "XYZ"
O.bodies[b1].state.vel = Vector3(0.5 * a.v0, 0, 0)
O.bodies[b2].state.vel = Vector3(-0.5 * a.v0, 0, 0)
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_ViscElMat_ViscElMat_ViscElPhys()],
                             [Law2_ScGeom_ViscElPhys_Basic()]),
             NewtonIntegrator(damping=0)]
O.dt = a.dt_over_tc * tc


def overlap():
    return a.r1 + a.r2 - (O.bodies[b2].state.pos[0] - O.bodies[b1].state.pos[0])


t_in = t_out = None
prev, prev_t = overlap(), O.time
for _ in range(10_000_000):
    O.step()
    now = overlap()
    if prev <= 0 < now and t_in is None:
        t_in = prev_t + (O.time - prev_t) * (-prev) / (now - prev)
    if prev > 0 >= now and t_in is not None:
        t_out = prev_t + (O.time - prev_t) * prev / (prev - now)
        break
    prev, prev_t = now, O.time
O.run(10, True)
v_out = O.bodies[b2].state.vel[0] - O.bodies[b1].state.vel[0]
res = {"t_contact_s": t_out - t_in, "restitution": v_out / a.v0, "t_contact_analytic_s": tc,
       "restitution_analytic": e_true, "dt_s": O.dt, "r1_m": a.r1, "r2_m": a.r2}
print(json.dumps(res))
if a.out:
    with open(a.out, "w") as fh:
        json.dump(res, fh, indent=2)
