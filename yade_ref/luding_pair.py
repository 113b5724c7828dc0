# Two spheres under YADE's LudingMat / Law2_ScGeom_LudingPhys_Basic: the same prescribed
# overlap loop and the same head-on impacts as bench/luding_pair.py runs through our engine.
#   yade -n -x yade_ref/luding_pair.py --dt-loop DT --dt-impacts DT [--out data/yade_luding]
# (pass our dt_s: bench/luding_pair.py prints them; data/yade_luding/COMMANDS.txt).
#
# Parameter map (YADE 2023.02a, pkg/dem/LudingPM.cpp): Ip2 combines two materials by
# 2 a1 a2/(a1 + a2) per parameter, so equal materials give the pair our values unchanged:
# LudingMat(k1 = k1, kp = kp, kc = kc, PhiF = phi_f, G0 = gamma (normal dashpot [kg/s]),
# ks = 0 and frictionAngle = 0 (no tangential force: the comparison is of the normal law)).
# YADE's DeltPMax = kp/(kp - k1) PhiF 2 a12 is our delta*, DeltPNull = PhiF 2 a12 its cap on
# delta0, as our delta_max cap at delta*.
# Writes OUT/yade_loop.csv (step, delta_m, fn_N) and OUT/yade_impacts.csv (kc_N_m, v_m_s,
# restitution; 0: the pair sticks: still in contact after 100 contact times).
import argparse
import math
import os
import sys

from yade import O, Vector3, LudingMat, ForceResetter, InsertionSortCollider, Bo1_Sphere_Aabb, InteractionLoop, \
    Ig2_Sphere_Sphere_ScGeom, Ip2_LudingMat_LudingMat_LudingPhys, Law2_ScGeom_LudingPhys_Basic, NewtonIntegrator, utils

R, RHO, K1, KP = 0.5e-3, 2000.0, 1e8, 5e8       # as bench/luding_pair.py
LOOP_PHI, LOOP_KC = 0.05, 0.5 * K1
LOOP_STOPS = [0.0, 0.35, 0.12, 0.7, 0.3, 1.3, 0.0]
LOOP_STEPS_PER_DSTAR = 2000
IMPACT_PHI = 0.001
IMPACT_KC = [0.0, 0.1 * K1, 1.0 * K1, 5.0 * K1]
IMPACT_V = [0.01, 0.03, 0.1, 0.3, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0, 60.0, 100.0]

ap = argparse.ArgumentParser(prog="luding_pair.py")
ap.add_argument("--dt-loop", type=float, required=True)
ap.add_argument("--dt-impacts", type=float, required=True)
ap.add_argument("--out", default="data/yade_luding")
ap.add_argument("--t-c", type=float, default=0.0, help="contact time for the sticking limit [s] (default from kp)")
ap.add_argument("--quick", action="store_true", help="a few impacts only (the test's list)")
a = ap.parse_args(sys.argv[1:])
QUICK = [(0.0, 1.0), (0.0, 10.0), (0.0, 30.0), (1e8, 4.0), (1e8, 6.0), (5e8, 2.0), (5e8, 4.0), (5e8, 30.0)]
MASS = 4 / 3 * math.pi * R ** 3 * RHO


def setup(kc, phi, dt, gap, masses_fixed):
    O.reset()
    mat = O.materials.append(LudingMat(k1=K1, kp=KP, kc=kc, PhiF=phi, G0=0.0, ks=0.0, frictionAngle=0.0, density=RHO))
    b0 = O.bodies.append(utils.sphere((5e-3, 10e-3, 10e-3), R, material=mat))
    b1 = O.bodies.append(utils.sphere((5e-3 + 2 * R + gap, 10e-3, 10e-3), R, material=mat))
    if masses_fixed:
        for b in (b0, b1):
            O.bodies[b].state.blockedDOFs = "xyzXYZ"
    O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]),
                 InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_LudingMat_LudingMat_LudingPhys()],
                                 [Law2_ScGeom_LudingPhys_Basic()]),
                 NewtonIntegrator(damping=0)]
    O.dt = dt
    return O.bodies[b0], O.bodies[b1]


def contact():
    for i in O.interactions:
        if i.isReal:
            return i
    return None


def loop():
    delta_star = KP / (KP - K1) * LOOP_PHI * 2 * (R * R / (2 * R))
    u = delta_star / (LOOP_STEPS_PER_DSTAR * a.dt_loop)
    b0, b1 = setup(LOOP_KC, LOOP_PHI, a.dt_loop, 0.0, True)
    rows, step = [], 0
    for lo, hi in zip(LOOP_STOPS[:-1], LOOP_STOPS[1:]):
        n = int(round(abs(hi - lo) * LOOP_STEPS_PER_DSTAR))
        sign = 1.0 if hi > lo else -1.0
        b0.state.vel = Vector3(0.5 * sign * u, 0, 0)
        b1.state.vel = Vector3(-0.5 * sign * u, 0, 0)
        for _ in range(n):
            O.step()
            step += 1
            i = contact()
            if i is not None and i.geom.penetrationDepth > 0:
                # the force of this step's InteractionLoop, at the overlap before Newton's move
                rows.append((step, i.geom.penetrationDepth, i.phys.normalForce.dot(i.geom.normal)))
    return rows


def impact(kc, v):
    gap = 20 * a.dt_impacts * v
    b0, b1 = setup(kc, IMPACT_PHI, a.dt_impacts, gap, False)
    b0.state.vel = Vector3(0.5 * v, 0, 0)
    b1.state.vel = Vector3(-0.5 * v, 0, 0)
    t_c = a.t_c if a.t_c > 0 else math.pi / math.sqrt(KP / (MASS / 2))
    touched = False
    for _ in range(int(100 * t_c / a.dt_impacts) + 100):
        O.step()
        d = 2 * R - (b1.state.pos - b0.state.pos).norm()
        if d > 0:
            touched = True
        elif touched:
            for _ in range(5):
                O.step()
            return abs(b1.state.vel[0] - b0.state.vel[0]) / v
    if not touched:
        raise RuntimeError(f"the spheres never touched at v = {v}")
    return 0.0


def write(path, header, rows):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(",".join(header) + "\n")
        for r in rows:
            fh.write(",".join(str(x) if isinstance(x, int) else repr(float(x)) for x in r) + "\n")
    os.replace(tmp, path)


os.makedirs(a.out, exist_ok=True)
write(os.path.join(a.out, "yade_loop.csv"), ["step", "delta_m", "fn_N"], loop())
write(os.path.join(a.out, "yade_impacts.csv"), ["kc_N_m", "v_m_s", "restitution"],
      [(kc, v, impact(kc, v)) for kc, v in (QUICK if a.quick else [(kc, v) for kc in IMPACT_KC for v in IMPACT_V])])
print("wrote", a.out)
