# Two-sphere head-on collision in YADE with the physics of our runner; prints JSON with the
# measured contact time and restitution next to the analytic values.
#   yade -n -x -j1 yade_ref/collision.py [--r1 5e-4] [--r2 5e-4] [--dt-over-tc 5e-4] [--out result.json]
#
# Oblique impact with friction (as `dem collide --angle-deg A --set contact.friction=MU`, i.e.
# dem::simulate_oblique_collision): --angle-deg A [--friction MU --kt-ratio 0.2857 --gamma-t 0].
# Line of centres z (sphere 0 -> 1, gap 2e-7 m), initial tangential direction of the relative
# velocity (1 relative to 0) x, relative speed v0 at A degrees from the normal, zero total
# momentum, no initial spin; rotations free. ViscElMat(kn = 2k, cn = 2 gamma, ks = 2 k_t,
# cs = 2 gamma_t, frictionAngle = atan(mu)): equal materials combine in series (checked at run
# time). Prints normal_restitution, tangential_restitution (centre velocities), the spins about y
# and the impulses on sphere 1, with ours' JSON keys.
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
ap.add_argument("--angle-deg", type=float, default=-1.0, help="oblique impact: angle from the normal [deg]")
ap.add_argument("--friction", type=float, default=0.0, help="Coulomb coefficient mu (frictionAngle = atan(mu))")
ap.add_argument("--kt-ratio", type=float, default=2.0 / 7.0, help="pair k_t / k")
ap.add_argument("--gamma-t", type=float, default=0.0, help="pair tangential damping [kg/s]")
ap.add_argument("--dt", type=float, default=0.0, help="time step [s] (default: dt-over-tc x t_c of this pair; ours takes "
                "t_c of the scene's smallest pair: pass ours' dt_s to match)")
a = ap.parse_args(sys.argv[1:])

m1 = 4 / 3 * math.pi * a.r1 ** 3 * a.density
m2 = 4 / 3 * math.pi * a.r2 ** 3 * a.density
mr = m1 * m2 / (m1 + m2)
w0sq, eta = a.k / mr, a.gamma / (2 * mr)
tc = math.pi / math.sqrt(w0sq - eta * eta)
e_true = math.exp(-eta * tc)



def oblique():
    """dem::simulate_oblique_collision in YADE (sim/src/stages/collision.cpp)."""
    O.reset()
    kt = a.kt_ratio * a.k
    mat = O.materials.append(ViscElMat(kn=2 * a.k, cn=2 * a.gamma, ks=2 * kt, cs=2 * a.gamma_t,
                                       frictionAngle=math.atan(a.friction), density=a.density))
    gap = 2e-7
    z0 = 5e-3
    i0 = O.bodies.append(utils.sphere((10e-3, 10e-3, z0), a.r1, material=mat))
    i1 = O.bodies.append(utils.sphere((10e-3, 10e-3, z0 + a.r1 + a.r2 + gap), a.r2, material=mat))
    th = math.radians(a.angle_deg)
    v_rel = Vector3(a.v0 * math.sin(th), 0, -a.v0 * math.cos(th))     # 1 relative to 0: t = x, n = z
    M = m1 + m2
    O.bodies[i0].state.vel = v_rel * (-m2 / M)
    O.bodies[i1].state.vel = v_rel * (m1 / M)
    O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
                 InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_ViscElMat_ViscElMat_ViscElPhys()],
                                 [Law2_ScGeom_ViscElPhys_Basic()]),
                 NewtonIntegrator(damping=0)]
    O.dt = a.dt if a.dt > 0 else a.dt_over_tc * tc
    b0, b1 = O.bodies[i0], O.bodies[i1]
    checked = False

    def dist():
        return (b1.state.pos - b0.state.pos).norm()

    touched = False
    for _ in range(10_000_000):
        O.step()
        if dist() <= a.r1 + a.r2:
            touched = True
            if not checked:
                for i in O.interactions:
                    if i.isReal:
                        ph = i.phys
                        want = (a.k, a.gamma, kt, a.gamma_t, a.friction)
                        got = (ph.kn, ph.cn, ph.ks, ph.cs, ph.tangensOfFrictionAngle)
                        if any(abs(g - w) > 1e-6 * max(abs(w), 1e-30) for g, w in zip(got, want)):
                            sys.exit(f"collision.py: pair (kn, cn, ks, cs, tan phi) = {got} differ from {want}")
                        checked = True
        elif touched:
            break
    if not touched:
        sys.exit("collision.py: the spheres never touched")
    O.run(10, True)
    after = b1.state.vel - b0.state.vel
    mr_ = m1 * m2 / M
    J = (after - v_rel) * mr_
    res = {"angle_deg": a.angle_deg, "normal_restitution": -after[2] / v_rel[2],
           "tangential_restitution": after[0] / v_rel[0] if v_rel[0] != 0 else float("nan"),
           "omega0_y_rad_s": b0.state.angVel[1], "omega1_y_rad_s": b1.state.angVel[1],
           "normal_impulse_Ns": J[2], "tangential_impulse_Ns": -J[0], "friction": a.friction, "dt_s": O.dt,
           "pair_checked": checked}
    print(json.dumps(res))
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(res, fh, indent=2)


if a.angle_deg >= 0:
    oblique()
    sys.exit(0)

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
