# YADE timing of frictional D2 on a packing, for bench/run_benchmarks.py (not a reference run:
# yade_ref/run_mode.py writes the curves). Run headless:
#
#   yade -n -x -j1 bench/yade_friction.py --packing P.txt --steps 1000 [--law viscel|frictphys]
#
# The scene as ours' `dem bench --set contact.friction=MU` (docs/benchmarks.md, "Friction"):
#  - viscel (default): ViscElMat kn = 2k, cn = 2 gamma, ks = 2 k_t, cs = 0, frictionAngle = atan(mu):
#    a pair gets half of each material value (two equal materials in series), checked below;
#    Law2_ScGeom_ViscElPhys_Basic. YADE 2023.02a's ViscEl law adds the periodic shift velocity with
#    the wrong sign, so pairs across the boundary of the deforming cell slip at about twice the
#    affine velocity across the cell (docs/yade.md, "Friction"): its timing is that of the law,
#    its springs across the boundary are not physics;
#  - frictphys: FrictMat per body, young = k / r (the series stiffness of every pair is k),
#    poisson = k_t / k, Law2_ScGeom_FrictPhys_CundallStrack: no dashpot (gamma = 0);
#  - rotations free (I = 2/5 m r^2), NewtonIntegrator(damping=0), no background damping (a Python
#    drag would dominate the timing), O.cell.velGrad = diag(rate, 0, -rate), dt = dt_over_tc t_c.
# Prints "N M particle-steps/s" (stepping only) and the state after the steps (p from
# utils.getStress, sum of kinetic and rotational energy) for the parity check.
import argparse
import math
import sys
import time

from yade import O, Matrix3, ViscElMat, FrictMat, ForceResetter, InsertionSortCollider, Bo1_Sphere_Aabb, \
    InteractionLoop, Ig2_Sphere_Sphere_ScGeom, Ip2_ViscElMat_ViscElMat_ViscElPhys, Law2_ScGeom_ViscElPhys_Basic, \
    Ip2_FrictMat_FrictMat_FrictPhys, Law2_ScGeom_FrictPhys_CundallStrack, NewtonIntegrator, utils

ap = argparse.ArgumentParser(prog="yade_friction.py")
ap.add_argument("--packing", required=True)
ap.add_argument("--steps", type=int, default=1000)
ap.add_argument("--rate-tc", type=float, default=5e-6)
ap.add_argument("--friction", type=float, default=0.5)
ap.add_argument("--kt-ratio", type=float, default=2.0 / 7.0)
ap.add_argument("--k", type=float, default=1e8)
ap.add_argument("--gamma", type=float, default=1.0)
ap.add_argument("--density", type=float, default=2000.0)
ap.add_argument("--dt-over-tc", type=float, default=0.02)
ap.add_argument("--law", default="viscel", choices=["viscel", "frictphys"])
a = ap.parse_args(sys.argv[1:])

cell, spheres = None, []
for line in open(a.packing):
    s = line.strip()
    if s.startswith("##PERIODIC::"):
        cell = [float(v) for v in s.split()[1:4]]
    elif s and not s.startswith("#"):
        spheres.append([float(v) for v in s.split()[:4]])
gamma = a.gamma if a.law == "viscel" else 0.0
mr = 4.0 / 3.0 * math.pi * min(s[3] for s in spheres) ** 3 * a.density / 2
tc = math.pi / math.sqrt(a.k / mr - (gamma / (2 * mr)) ** 2)
dt, rate, kt = a.dt_over_tc * tc, a.rate_tc / tc, a.kt_ratio * a.k

O.reset()
O.periodic = True
O.cell.setBox(*cell)
if a.law == "viscel":
    mat = O.materials.append(ViscElMat(kn=2 * a.k, cn=2 * gamma, ks=2 * kt, cs=0, frictionAngle=math.atan(a.friction),
                                       density=a.density))
for x, y, z, r in spheres:
    if a.law == "frictphys":
        mat = O.materials.append(FrictMat(young=a.k / r, poisson=a.kt_ratio, frictionAngle=math.atan(a.friction),
                                          density=a.density))
    O.bodies.append(utils.sphere((x, y, z), r, material=mat))
ip2, law2 = ((Ip2_ViscElMat_ViscElMat_ViscElPhys(), Law2_ScGeom_ViscElPhys_Basic()) if a.law == "viscel"
             else (Ip2_FrictMat_FrictMat_FrictPhys(), Law2_ScGeom_FrictPhys_CundallStrack()))
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [ip2], [law2]), NewtonIntegrator(damping=0)]
O.dt = dt
O.cell.velGrad = Matrix3(rate, 0, 0, 0, 0, 0, 0, 0, -rate)
O.run(1, True)
for i in O.interactions:
    if i.isReal:
        cn = getattr(i.phys, "cn", 0.0)
        if (abs(i.phys.kn - a.k) > 1e-6 * a.k or abs(i.phys.ks - kt) > 1e-6 * kt or abs(cn - gamma) > 1e-6 * max(gamma, 1e-30)
                or abs(i.phys.tangensOfFrictionAngle - a.friction) > 1e-9):
            sys.exit(f"yade_friction.py: pair kn={i.phys.kn}, ks={i.phys.ks}, cn={cn}, "
                     f"tan(phi)={i.phys.tangensOfFrictionAngle} differ from k={a.k}, k_t={kt}, gamma={gamma}, mu={a.friction}")
        break
t0 = time.time()
O.run(a.steps - 1, True)
wall = time.time() - t0
n = len(O.bodies)
S = utils.getStress()   # tension positive
ekin = sum(0.5 * b.state.mass * (b.state.vel - O.cell.velGrad * b.state.pos).squaredNorm() for b in O.bodies)
erot = sum(0.5 * b.state.inertia[0] * b.state.angVel.squaredNorm() for b in O.bodies)
contacts = sum(1 for i in O.interactions if i.isReal and i.geom.penetrationDepth > 0)
print(f"after {a.steps} steps: p_Pa={-(S[0, 0] + S[1, 1] + S[2, 2]) / 3:.8g} sxx_Pa={-S[0, 0]:.8g} syy_Pa={-S[1, 1]:.8g} "
      f"szz_Pa={-S[2, 2]:.8g} E_kin_J={ekin:.8g} E_rot_J={erot:.8g} contacts={contacts}")
print(f"yade_friction.py: {a.steps - 1} steps of {n} particles in {wall:.2f} s (stepping only): "
      f"{(a.steps - 1) * n / max(wall, 1e-9) / 1e6:.3f} M particle-steps/s")
