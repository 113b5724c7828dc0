# YADE reference run of one deformation mode from a packing, writing the same CSV columns as
# our runner (`dem mode`). Run headless:
#
#   yade -n -x -j1 yade_ref/run_mode.py --packing P.txt --mode D2 --rate-tc 4e-5 --eps-max 0.3 --out yade.csv
#
# With --scene SCENE.toml [--set KEY=VALUE ...] the YADE law, density, t_c radius, dt, rate, sampling and
# background damping come from ours' scene (`build/dem info SCENE --yade`: each contact sub-model's
# YADE counterpart in the registry; a law without one is refused by name); options given here win.
#
# Constant side stress (triaxial, docs/control.md): --mode uniaxial_z --side-stress-p0 1 holds
# sigma_xx = sigma_yy = 1 x p0 (the pressure of the packing as loaded) with YADE's own
# PeriTriaxController (quasi-static branch, dynCell=False, stressMask x|y) while z is compressed at
# the rate to eps_zz = -eps_max.
#
# Isobaric shear: --mode D2 --isobaric-p0 1 holds the mean contact stress at 1 x p0 by an
# isotropic strain rate added to the mode's, set every --servo-every steps by a Python servo
# (YADE has no mean-pressure controller): a PeriTriaxController-like dead-beat on the mean stress,
# u = (p - p_goal) / (G * servo_every * dt) x (1 - growDamping), G = sum_c kn l_c^2 / (3 V) the
# affine stiffness of p to an isotropic strain, |u| <= servo-rate-factor x rate. Not our PI law
# (docs/control.md): a second, independent control of the same test.
#
# Friction (--friction MU, as ours' contact.friction = MU, cundall_strack; docs/yade.md "Friction"):
# ViscElMat ks = 2 k_t, cs = 2 gamma_t (--kt-ratio, --gamma-t; pair values checked at run time like
# kn, cn), frictionAngle = atan(mu), rotations free (I = 2/5 m r^2, utils.sphere). The stress takes the
# tangential force (i.phys.shearForce: YADE stores the elastic shear force, not a displacement; its
# viscous part is not stored, so --gamma-t > 0 leaves it out of the stress), its symmetric part joins
# sigma and its antisymmetric part is reported; the extra columns are ours' friction_columns():
# sliding_fraction (|F_s| >= tan(phi) F_n (1 - 1e-9)), E_rot_J (sum 1/2 I w^2), omega_mean_rad_s (mean |w|),
# E_t_J (sum |F_s|^2 / (2 k_s)), W_friction_J (nan: Law2_ScGeom_ViscElPhys_Basic does not track it),
# sigma_antisym_rel; E_pot_J holds the normal plus the tangential spring energy, as ours.
#
# YADE 2023.02a's Law2_ScGeom_ViscElPhys_Basic adds the periodic shift velocity with the wrong sign
# (relative velocity (v1 + w1 x c1) - (v2 + w2 x c2) + shiftVel, where the image of 2 moves at
# v2 + shiftVel): a pair across the boundary of a deforming cell slips at 2 x velGrad.hSize.cellDist
# (17 m/s here, against ~0.4 m/s of real slip), so its tangential spring runs to the Coulomb limit
# at once (docs/yade.md "Friction": 56x the shear force of the same pair inside the cell). Frictional
# runs in a deforming periodic cell therefore use --law frictphys: FrictMat per body with
# young = k / r (Ip2_FrictMat_FrictMat_FrictPhys's series kn = 2 E1 r1 E2 r2 / (E1 r1 + E2 r2) = k for
# every pair) and poisson = k_t / k (ks = k_t), Law2_ScGeom_FrictPhys_CundallStrack() with O.trackEnergy (traceEnergy=False: it then adds to O.energy),
# whose shear increment (ScGeom::getIncidentVel) adds the shift velocity correctly. That law has no
# normal dashpot: --gamma 0, and ours contact.damping_kg_s = 0. W_friction_J = O.energy['plastDissip'].
#
# Hertz-Mindlin (--law mindlin, as ours' contact.normal = "hertz", contact.tangential = "mindlin_force"):
# FrictMat(young = E, poisson = nu, frictionAngle = atan(mu)) + Ip2_FrictMat_FrictMat_MindlinPhys +
# Law2_ScGeom_MindlinPhys_Mindlin: f_n = 4/3 E* sqrt(R*) delta^1.5, k_s = 8 G* sqrt(R* delta), the
# shear force incremental (ours' "mindlin_force"), its periodic shift velocity added correctly
# (ScGeom::getIncidentVel). --en e < 1 gives YADE's damping cn = alpha sqrt(m*) delta^(1/4) with its
# own alpha(e) (Antypov 2011: not ours' Tsuji alpha solved for e) and the same cs on the shear (ours
# has no tangential dashpot): compare at low rates, where the dashpots do little; --en 1: none.
# t_c is ours' Rayleigh time of --r-min, p* = 2 <r> p / (2 E* r_min) as ours'. E_pot_J: the Hertz
# energy 2/5 kno delta^2.5 plus the shear springs |F_s|^2 / (2 k_s).
#
# Physics set to match ours (see docs/yade.md for every choice):
#  - ViscElMat with kn = 2k, cn = 2*gamma per material: two equal materials combine in series
#    into a pair kn = k, cn = gamma (checked at start, the script stops if not);
#  - no friction, ks = cs = 0, rotations blocked (normal forces on spheres give no torque);
#  - NewtonIntegrator(damping=0): leapfrog = our symplectic_euler integrator;
#  - YADE 2023.02a's linear viscoelastic law clamps the force at zero on separation, as our
#    default contact.allow_attractive = false does (docs/yade.md: the collision check);
#  - background damping -gamma_b v' (v' = vel - velGrad.pos, the fluctuation velocity) by a
#    PyRunner every step when --gamma-b > 0 (slow in Python; default 0 in both codes);
#  - the cell is driven by O.cell.velGrad = diag(rate) (YADE integrates the cell linearly per
#    step: L <- L (1 + rate dt), so its true strain per step is ln(1 + rate dt); relative
#    difference ~rate*dt/2 ~ 1e-7 of the strain).
#
# Simple shear (docs/simple_shear.md): --mode SS_xy / SS_xz / SS_yz is v_i = 2 r x_j, i.e.
# O.cell.velGrad with the single off-diagonal entry L[i][j] = 2 r (as our SS_ij: the factor 2
# gives D = sym L the eigenvalues (1, 0, -1) r of D2). YADE integrates the deformation gradient
# as O.cell.trsf <- (I + L dt) trsf, exact for simple shear (L^2 = 0): trsf_ij = gamma. The cell is
# flipped by YADE itself (O.cell.flipFlippable = True; Cell::flipCell changes hSize and the
# interactions' cellDist, not trsf). In a sheared run the curve's strains are the log strain
# 0.5 ln(F F^T) of F = O.cell.trsf, and eps_d, sigma_dev_Pa, s_dev, F_dev hold the eigenvalue
# (objective) forms, as ours writes them; the run stops at eps_d = sqrt(3) asinh(gamma/2) = eps_max.
import argparse
import math
import sys
import time

import numpy as np

from yade import O, Vector3, Matrix3, ViscElMat, ForceResetter, InsertionSortCollider, Bo1_Sphere_Aabb, \
    InteractionLoop, Ig2_Sphere_Sphere_ScGeom, Ip2_ViscElMat_ViscElMat_ViscElPhys, \
    Law2_ScGeom_ViscElPhys_Basic, NewtonIntegrator, PyRunner, PeriTriaxController, utils, FrictMat, \
    Ip2_FrictMat_FrictMat_FrictPhys, Law2_ScGeom_FrictPhys_CundallStrack, Ip2_FrictMat_FrictMat_MindlinPhys, \
    Law2_ScGeom_MindlinPhys_Mindlin, MatchMaker

MODES = {"D2": (1.0, 0.0, -1.0), "D3": (0.5, 0.5, -1.0), "iso_compress": (-1.0, -1.0, -1.0),
         "iso_expand": (1.0, 1.0, 1.0), "uniaxial_x": (-1.0, 0.0, 0.0), "uniaxial_y": (0.0, -1.0, 0.0),
         "uniaxial_z": (0.0, 0.0, -1.0)}
# Simple shear SS_ij: v_i = 2 r x_j (upper triangular, as ours; docs/simple_shear.md).
SHEARS = {"SS_xy": (0, 1), "SS_xz": (0, 2), "SS_yz": (1, 2)}


def _dem_binary():
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(sys.argv[0])))
    return os.environ.get("DEM_BIN", os.path.join(root, "build", "dem"))


def _column_table():
    """The curve columns as ours defines them, once (sim/src/measure/measure.cpp, column_table):
    `dem info --columns --json` of the build beside this script (or $DEM_BIN)."""
    import json
    import subprocess
    dem = _dem_binary()
    try:
        out = subprocess.run([dem, "info", "--columns", "--json"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        sys.exit(f"run_mode.py: cannot read the curve columns from {dem} info --columns --json ({e}): build ours first "
                 "(bash scripts/setup.sh) or set DEM_BIN")
    return json.loads(out)


_TABLE = _column_table()
COLUMNS = [c["name"] for c in _TABLE if c["group"] == "every"] + ["stage"]
FRICTION_COLUMNS = [c["name"] for c in _TABLE if c["group"] == "rotations"]


def dev(a, b, c):
    return math.sqrt(((a - b) ** 2 + (b - c) ** 2 + (c - a) ** 2) / 2.0)


def dev_eig(m):
    """Deviatoric magnitude sqrt(3 J2) of the eigenvalues of a symmetric 3x3 matrix."""
    return dev(*np.linalg.eigvalsh(np.asarray(m, dtype=float)))


def extreme_direction(m, major):
    """Eigenvector of the largest (major) or smallest eigenvalue; None if it is degenerate
    (gap within 1e-9 of the scale), as ours (sim/src/measure/measure.cpp)."""
    w, v = np.linalg.eigh(np.asarray(m, dtype=float))
    scale = max(abs(w[0]), abs(w[2]))
    gap = w[2] - w[1] if major else w[1] - w[0]
    if not (scale > 0) or not (gap > 1e-9 * scale):
        return None
    return v[:, 2] if major else v[:, 0]


def axis_angle_deg(a, b):
    if a is None or b is None:
        return float("nan")
    c = min(1.0, abs(float(np.dot(a, b))) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(c))


def log_strain(F):
    """Hencky strain 0.5 ln(F F^T) (docs/simple_shear.md)."""
    F = np.asarray(F, dtype=float)
    w, v = np.linalg.eigh(F @ F.T)
    return v @ np.diag(0.5 * np.log(w)) @ v.T


def scene_options(argv):
    """--scene SCENE [--set KEY=VALUE ...]: the scene as this script's options, `dem info SCENE
    --yade` (the YADE law from each contact sub-model's counterpart in ours' registry, then density,
    t_c radius, dt, rate, sampling, background damping), put before the other options so that an
    option given on the command line wins. Returns (argv without --scene/--set, the scene's)."""
    import shlex
    import subprocess
    rest, scene, sets, i = [], None, [], 0
    while i < len(argv):
        if argv[i] in ("--scene", "--set") and i + 1 < len(argv):
            if argv[i] == "--scene":
                scene = argv[i + 1]
            else:
                sets += ["--set", argv[i + 1]]
            i += 2
            continue
        rest.append(argv[i])
        i += 1
    if scene is None:
        if sets:
            sys.exit("run_mode.py: --set needs --scene SCENE (it overrides a key of that scene)")
        return rest, []
    p = subprocess.run([_dem_binary(), "info", scene, "--yade"] + sets, capture_output=True, text=True)
    if p.returncode:
        sys.exit(f"run_mode.py: --scene {scene}: {p.stderr.strip() or p.stdout.strip()}")
    if p.stderr.strip():
        sys.stderr.write(p.stderr)
    return rest, shlex.split(p.stdout)


def parse():
    argv, from_scene = scene_options(sys.argv[1:])
    ap = argparse.ArgumentParser(prog="run_mode.py")
    ap.add_argument("--scene", help="ours' scene TOML: its contact law, density, t_c radius, dt, rate, sampling and "
                                    "background damping as the options below (`dem info SCENE --yade`); options "
                                    "given here win")
    ap.add_argument("--set", action="append", help="with --scene: override a scene key, KEY=VALUE (as ours)")
    ap.add_argument("--packing", required=True)
    ap.add_argument("--mode", default="D2", choices=sorted(MODES) + sorted(SHEARS))
    ap.add_argument("--rate-tc", type=float, default=5e-6, help="rate times t_c of the smallest pair")
    ap.add_argument("--eps-max", type=float, default=0.4)
    ap.add_argument("--sample-strain", type=float, default=0.002)
    ap.add_argument("--k", type=float, default=1e8, help="pair stiffness [N/m]")
    ap.add_argument("--gamma", type=float, default=1.0, help="pair damping [kg/s]")
    ap.add_argument("--gamma-b", type=float, default=0.0, help="background damping [kg/s] (Python loop, slow)")
    ap.add_argument("--density", type=float, default=2000.0)
    ap.add_argument("--dt-over-tc", type=float, default=0.02)
    ap.add_argument("--r-min", type=float, default=0.0,
                    help="radius [m] of the pair that defines t_c (default: the smallest in the packing). Ours takes "
                         "t_c from the scene's particles.radius_min_m (0.5 mm by default), not from the packing: "
                         "pass that value to run at our dt and rate exactly")
    ap.add_argument("--out", required=True)
    ap.add_argument("--max-steps", type=int, default=0, help="stop after this many steps (timing runs)")
    ap.add_argument("--side-stress-p0", type=float, default=0.0,
                    help="with --mode uniaxial_z: hold sigma_xx = sigma_yy at this multiple of p0 (PeriTriaxController)")
    ap.add_argument("--isobaric-p0", type=float, default=0.0,
                    help="with --mode D2/D3: hold the mean stress at this multiple of p0 (Python servo)")
    ap.add_argument("--servo-every", type=int, default=10, help="steps between updates of the isobaric servo")
    ap.add_argument("--servo-rate-factor", type=float, default=2.0,
                    help="PeriTriaxController maxStrainRate of the stress axes, in multiples of the rate")
    ap.add_argument("--friction", type=float, default=0.0,
                    help="Coulomb coefficient mu (ours: contact.friction); ViscElMat frictionAngle = atan(mu), rotations free")
    ap.add_argument("--kt-ratio", type=float, default=2.0 / 7.0, help="pair k_t / k (ours: contact.tangential_stiffness_ratio)")
    ap.add_argument("--gamma-t", type=float, default=0.0, help="pair tangential damping [kg/s] (ours: contact.tangential_damping_kg_s)")
    ap.add_argument("--young", type=float, default=1e8, help="--law mindlin: Young's modulus E [Pa] (ours: contact.youngs_modulus_Pa)")
    ap.add_argument("--poisson", type=float, default=0.3, help="--law mindlin: nu (ours: contact.poisson_ratio)")
    ap.add_argument("--en", type=float, default=1.0, help="--law mindlin: YADE's en (< 1: its nonlinear dashpot; 1: none)")
    ap.add_argument("--law", default="viscel", choices=["viscel", "frictphys", "mindlin"],
                    help="viscel: ViscElMat + Law2_ScGeom_ViscElPhys_Basic (normal dashpot; its shift velocity has the wrong "
                         "sign: wrong for friction across the boundary of a deforming cell); frictphys: FrictMat per body + "
                         "Law2_ScGeom_FrictPhys_CundallStrack (no dashpot: needs --gamma 0)")
    return ap.parse_args(from_scene + argv)


def read_packing(path):
    cell, spheres = None, []
    with open(path) as fh:
        for n, line in enumerate(fh, 1):
            s = line.strip()
            if not s:
                continue
            if s.startswith("##PERIODIC::"):
                cell = [float(v) for v in s.split()[1:4]]
                continue
            if s.startswith("#"):
                continue
            v = s.split()
            if len(v) < 4:
                sys.exit(f"run_mode.py: {path}:{n}: expected 'x y z r'")
            spheres.append(tuple(float(t) for t in v[:4]))
    if cell is None:
        sys.exit(f"run_mode.py: {path}: no '##PERIODIC:: Lx Ly Lz' line")
    return cell, spheres


def main():
    a = parse()
    globals()["ARGS"] = a
    cell, spheres = read_packing(a.packing)
    rmin = a.r_min if a.r_min > 0 else min(s[3] for s in spheres)
    m_small = 4.0 / 3.0 * math.pi * rmin ** 3 * a.density
    mr = m_small / 2
    if a.law == "mindlin":   # ours' Rayleigh time and reference stiffness (contact.normal = "hertz")
        G = a.young / (2 * (1 + a.poisson))
        tc = math.pi * rmin * math.sqrt(a.density / G) / (0.1631 * a.poisson + 0.8766)
        a.k = 2 * a.young / (2 * (1 - a.poisson ** 2)) * rmin
        a.gamma = 0.0
    else:
        w0sq, eta = a.k / mr, a.gamma / (2 * mr)
        tc = math.pi / math.sqrt(w0sq - eta * eta)
    dt = a.dt_over_tc * tc
    rate = a.rate_tc / tc
    sheared = a.mode in SHEARS
    grad = [[0.0] * 3 for _ in range(3)]          # velocity gradient in units of the rate
    if sheared:
        i_s, j_s = SHEARS[a.mode]
        grad[i_s][j_s] = 2.0
        shape = (0.0, 0.0, 0.0)
        # eps_d = sqrt(3) asinh(gamma/2), gamma = 2 r t: the initial eps_d rate is sqrt(3) r
        per_step = math.sqrt(3.0) * rate * dt
        gamma_end = 2.0 * math.sinh(a.eps_max / math.sqrt(3.0))
        n_steps = int(math.ceil(gamma_end / (2.0 * rate * dt) - 1e-9))
    else:
        shape = MODES[a.mode]
        for k in range(3):
            grad[k][k] = shape[k]
        dev_shape = dev(*shape)
        per_step = (dev_shape if dev_shape > 0 else abs(sum(shape)) / 3) * rate * dt
        n_steps = int(math.ceil(a.eps_max / per_step - 1e-9))
    D_rate = [[0.5 * (grad[p][q] + grad[q][p]) * rate for q in range(3)] for p in range(3)]
    d_dir = extreme_direction(D_rate, False)     # most compressive direction of D = sym L
    if a.max_steps:
        n_steps = min(n_steps, a.max_steps)

    O.reset()
    O.periodic = True
    O.cell.setBox(*cell)
    frict = a.friction > 0
    kt = a.kt_ratio * a.k if frict else 0.0
    gamma_t = a.gamma_t if frict else 0.0
    frictphys = a.law == "frictphys"
    mindlin = a.law == "mindlin"
    if frictphys and (a.gamma != 0 or gamma_t != 0 or a.kt_ratio <= 0):
        sys.exit("run_mode.py: --law frictphys has no dashpots: pass --gamma 0 (and ours contact.damping_kg_s=0), --gamma-t 0")
    if frict and a.law == "viscel" and a.mode in list(MODES) + list(SHEARS):
        sys.stderr.write("run_mode.py: warning: --law viscel with friction in a deforming periodic cell: YADE 2023.02a's "
                         "ViscEl law adds the periodic shift velocity with the wrong sign (docs/yade.md, Friction); "
                         "use --law frictphys --gamma 0\n")
    if mindlin:
        mat = O.materials.append(FrictMat(young=a.young, poisson=a.poisson, density=a.density,
                                          frictionAngle=math.atan(a.friction) if frict else 0))
    elif not frictphys:
        mat = O.materials.append(ViscElMat(kn=2 * a.k, cn=2 * a.gamma, ks=2 * kt, cs=2 * gamma_t,
                                           frictionAngle=math.atan(a.friction) if frict else 0, density=a.density))
    for x, y, z, r in spheres:
        if frictphys:                           # E r = k for every body: the pair kn = k, ks = poisson k
            mat = O.materials.append(FrictMat(young=a.k / r, poisson=kt / a.k if frict else 0.0,
                                              frictionAngle=math.atan(a.friction) if frict else 0, density=a.density))
        b = utils.sphere((x, y, z), r, material=mat)
        if not frict:
            b.state.blockedDOFs = "XYZ"         # frictionless: no torques, 3 degrees of freedom as ours
        O.bodies.append(b)
    if mindlin:
        ip2 = Ip2_FrictMat_FrictMat_MindlinPhys(en=MatchMaker(algo="val", val=a.en)) if a.en < 1 \
            else Ip2_FrictMat_FrictMat_MindlinPhys()
        loop = InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [ip2], [Law2_ScGeom_MindlinPhys_Mindlin()])
    elif frictphys:
        loop = InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_FrictPhys()],
                               [Law2_ScGeom_FrictPhys_CundallStrack()])
        O.trackEnergy = True
    else:
        loop = InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_ViscElMat_ViscElMat_ViscElPhys()],
                               [Law2_ScGeom_ViscElPhys_Basic()])
    engines = [ForceResetter(), InsertionSortCollider([Bo1_Sphere_Aabb()]), loop]
    if a.gamma_b > 0:
        engines.append(PyRunner(iterPeriod=1, command="background_damping()"))
    engines.append(NewtonIntegrator(damping=0))
    O.engines = engines
    O.dt = dt
    O.cell.velGrad = Matrix3(*[grad[p][q] * rate for p in range(3) for q in range(3)])
    if sheared:
        O.cell.flipFlippable = True
    size0 = Vector3(O.cell.size)
    vol_particles = sum(4.0 / 3.0 * math.pi * s[3] ** 3 for s in spheres)
    mean_r = sum(s[3] for s in spheres) / len(spheres)

    def fluct(b):
        return b.state.vel - O.cell.velGrad * b.state.pos

    def background_damping():
        for b in O.bodies:
            O.forces.addF(b.id, -a.gamma_b * fluct(b))

    def measure():
        L = O.cell.size
        if sheared:
            V = O.cell.volume                     # det hSize (|columns| are not the edges of a tilted cell)
            eps_t = log_strain([[O.cell.trsf[p, q] for q in range(3)] for p in range(3)])
            eps = [float(eps_t[k, k]) for k in range(3)]
        else:
            V = L[0] * L[1] * L[2]
            eps = [math.log(L[k] / size0[k]) for k in range(3)]
            eps_t = np.diag(eps)
        sig = [[0.0] * 3 for _ in range(3)]
        fab = [[0.0] * 3 for _ in range(3)]
        deg = [0] * len(O.bodies)
        pairs = []
        epot = 0.0
        e_t = 0.0
        n_slide = 0
        tsig = [[0.0] * 3 for _ in range(3)]       # branch (x) tangential force on id2
        omax = osum = 0.0
        H = O.cell.hSize
        for i in O.interactions:
            if not i.isReal:
                continue
            pen = i.geom.penetrationDepth
            if pen <= 0:
                continue
            b1, b2 = O.bodies[i.id1], O.bodies[i.id2]
            branch = b2.state.pos + H * Vector3(i.cellDist) - b1.state.pos
            f = i.phys.normalForce             # force on id2, along the normal for repulsion
            n = i.geom.normal
            v1 = 4.0 / 3.0 * math.pi * b1.shape.radius ** 3
            v2 = 4.0 / 3.0 * math.pi * b2.shape.radius ** 3
            for p in range(3):
                for q in range(3):
                    sig[p][q] += 0.5 * (branch[p] * f[q] + branch[q] * f[p])
                    fab[p][q] += (v1 + v2) * n[p] * n[q]
            epot += 0.4 * i.phys.kno * pen ** 2.5 if mindlin else 0.5 * a.k * pen * pen
            if frict:
                fs = i.phys.shearForce             # elastic shear force on id2 (after the Coulomb cap)
                for p in range(3):
                    for q in range(3):
                        tsig[p][q] += branch[p] * fs[q]
                fs2 = fs.dot(fs)
                e_t += 0.5 * fs2 / (i.phys.ks if mindlin else kt) if fs2 > 0 else 0.0
                if fs2 > 0 and math.sqrt(fs2) >= i.phys.tangensOfFrictionAngle * f.norm() * (1 - 1e-9):
                    n_slide += 1
            rel = pen / min(b1.shape.radius, b2.shape.radius)
            omax = max(omax, rel)
            osum += rel
            deg[i.id1] += 1
            deg[i.id2] += 1
            pairs.append((i.id1, i.id2))
        kin = [[0.0] * 3 for _ in range(3)]
        ekin = 0.0
        for b in O.bodies:
            v = fluct(b)
            for p in range(3):
                for q in range(3):
                    kin[p][q] += b.state.mass * v[p] * v[q]
            ekin += 0.5 * b.state.mass * v.dot(v)
        S = [[(sig[p][q] + 0.5 * (tsig[p][q] + tsig[q][p]) + kin[p][q]) / V for q in range(3)] for p in range(3)]
        F = [[fab[p][q] / V for q in range(3)] for p in range(3)]
        n = len(O.bodies)
        # rattlers: fewer than 4 contacts, removed recursively
        adj = [[] for _ in range(n)]
        for i1, i2 in pairs:
            adj[i1].append(i2)
            adj[i2].append(i1)
        d = list(deg)
        ratt = [x < 4 for x in d]
        stack = [k for k in range(n) if ratt[k]]
        while stack:
            k = stack.pop()
            for j in adj[k]:
                if not ratt[j]:
                    d[j] -= 1
                    if d[j] < 4:
                        ratt[j] = True
                        stack.append(j)
        nr = sum(ratt)
        cnr = sum(1 for i1, i2 in pairs if not ratt[i1] and not ratt[i2])
        p = (S[0][0] + S[1][1] + S[2][2]) / 3
        sdev = dev(S[0][0], S[1][1], S[2][2])
        fdev = dev(F[0][0], F[1][1], F[2][2])
        eps_d = dev(*eps)
        # objective forms (docs/definitions.md), and the non-coaxiality angles
        eps_d_eig = dev_eig(eps_t)
        sdev_eig = dev_eig(S)
        fdev_eig = dev_eig(F)
        s_dir = extreme_direction(S, True)
        f_dir = extreme_direction(F, True)
        if sheared:                               # a sheared cell's curve carries the objective forms
            eps_d, sdev, fdev = eps_d_eig, sdev_eig, fdev_eig
        rmax_rate = max(abs(grad[p_][q_]) for p_ in range(3) for q_ in range(3)) * rate
        row = [O.iter, O.time, eps[0], eps[1], eps[2], sum(eps) / 3, eps_d, vol_particles / V, p,
               2 * mean_r * p / a.k, S[0][0], S[1][1], S[2][2], S[0][1], S[0][2], S[1][2], sdev,
               sdev / p if p > 0 else 0.0, F[0][0], F[1][1], F[2][2], F[0][1], F[0][2], F[1][2],
               fdev, 2 * len(pairs) / n, 2 * cnr / (n - nr) if nr < n else 0.0,
               nr / n, ekin, omax, osum / len(pairs) if pairs else 0.0, epot + e_t,
               (kin[0][0] + kin[1][1] + kin[2][2]) / 3 / V,
               rmax_rate * 2 * mean_r * math.sqrt(a.density / p) if p > 0 else 0.0, len(pairs),
               float(eps_t[0, 1]), float(eps_t[0, 2]), float(eps_t[1, 2]), eps_d_eig, sdev_eig,
               sdev_eig / p if p > 0 else 0.0, fdev_eig, axis_angle_deg(s_dir, f_dir),
               axis_angle_deg(s_dir, d_dir), axis_angle_deg(f_dir, d_dir)]
        if frict:
            e_rot = 0.0
            w_sum = 0.0
            for b in O.bodies:
                w = b.state.angVel
                e_rot += 0.5 * b.state.inertia[0] * w.dot(w)
                w_sum += w.norm()
            anti = [0.5 * (tsig[0][1] - tsig[1][0]) / V, 0.5 * (tsig[0][2] - tsig[2][0]) / V,
                    0.5 * (tsig[1][2] - tsig[2][1]) / V]
            w_fric = float(dict(O.energy.items()).get("plastDissip", 0.0)) if frictphys else float("nan")
            row += [n_slide / len(pairs) if pairs else 0.0, e_rot, w_sum / n, e_t, w_fric,
                    math.sqrt(sum(x * x for x in anti)) / p if p > 0 else 0.0]
        return ["%.10g" % v if isinstance(v, float) else str(v) for v in row] + [a.mode]

    globals()["background_damping"] = background_damping
    out = open(a.out + ".part", "w")
    out.write(f"# yade curve: stage={a.mode} (YADE reference, yade_ref/run_mode.py)\n")
    if sheared:
        out.write(f"# simple shear: O.cell.velGrad[{SHEARS[a.mode][0]}][{SHEARS[a.mode][1]}] = 2 x rate; strains 0.5 ln(F F^T) "
                  "of F = O.cell.trsf; eps_d, sigma_dev_Pa, s_dev, F_dev are the eigenvalue forms\n")
        out.write("# units and definitions as in our runner (docs/definitions.md)\n")
    else:
        out.write("# units and definitions as in our runner (docs/definitions.md); strains ln(L/L0) of O.cell.size\n")
    out.write(f"# t_c={tc:.8g} s, dt={dt:.8g} s, k={a.k} N/m, gamma={a.gamma} kg/s, gamma_b={a.gamma_b} kg/s\n")
    steps_per_sample = max(1, int(round(a.sample_strain / per_step)))
    # One step with dt = 0 creates the interactions of the initial packing without moving it
    # (O.iter becomes 1), so the first row measures the packing as loaded.
    before = [(Vector3(b.state.pos), Vector3(b.state.vel), Vector3(b.state.angVel)) for b in O.bodies]
    O.dt = 0.0
    O.run(1, True)
    O.dt = dt
    if mindlin:   # its incident velocity divides by dt: the dt = 0 step's shear springs (and motion) are nan
        for i in O.interactions:
            if i.isReal:
                i.phys.shearElastic = i.phys.shearForce = i.phys.usElastic = i.phys.usTotal = Vector3(0, 0, 0)
        for b, (x, v, w) in zip(O.bodies, before):   # at rest in the flow, as the dt = 0 step leaves the others
            b.state.pos, b.state.angVel = x, w
            b.state.vel = v + O.cell.velGrad * x
    first = measure()
    check_pairs()
    if sheared and (a.side_stress_p0 > 0 or a.isobaric_p0 > 0):
        sys.exit("run_mode.py: simple shear runs at constant volume (no --side-stress-p0 / --isobaric-p0)")
    if a.side_stress_p0 > 0:
        if a.mode != "uniaxial_z":
            sys.exit("run_mode.py: --side-stress-p0 needs --mode uniaxial_z (x and y stress controlled, z compressed)")
        p0 = float(first[COLUMNS.index("p_Pa")])
        goal = -a.side_stress_p0 * p0          # YADE: tension positive
        # z: strain goal a little beyond the end, so it runs at the full rate until n_steps stop it
        ctrl = PeriTriaxController(goal=Vector3(goal, goal, -1.01 * a.eps_max), stressMask=3, dynCell=False,
                                   maxStrainRate=Vector3(a.servo_rate_factor * rate, a.servo_rate_factor * rate, rate),
                                   maxUnbalanced=-1.0, globUpdate=1, label="triax")
        O.engines = O.engines[:-1] + [ctrl] + O.engines[-1:]
        out.write(f"# PeriTriaxController: sigma_xx = sigma_yy = {a.side_stress_p0} x p0 = {-goal:.8g} Pa (contact stress), "
                  f"maxStrainRate x,y = {a.servo_rate_factor} x rate, growDamping {ctrl.growDamping}\n")
    if a.isobaric_p0 > 0:
        if abs(sum(shape)) > 1e-12:
            sys.exit("run_mode.py: --isobaric-p0 needs a volume-conserving --mode (D2, D3)")
        p_goal = a.isobaric_p0 * float(first[COLUMNS.index("p_Pa")])
        servo = {"u": 0.0}

        def isobaric_servo():
            L = O.cell.size
            V = L[0] * L[1] * L[2]
            H = O.cell.hSize
            g = 0.0
            s_tr = 0.0
            for i in O.interactions:
                if not i.isReal or i.geom.penetrationDepth <= 0:
                    continue
                b1, b2 = O.bodies[i.id1], O.bodies[i.id2]
                branch = b2.state.pos + H * Vector3(i.cellDist) - b1.state.pos
                g += i.phys.kn * branch.dot(branch)
                s_tr += branch.dot(i.phys.normalForce)
            p = s_tr / (3 * V)                   # compression positive (force on id2 along the branch)
            G = g / (3 * V)
            u = (p - p_goal) / (G * a.servo_every * dt) if G > 0 else 0.0
            u = (1 - 0.25) * u + 0.25 * servo["u"]   # low-pass, like growDamping
            lim = a.servo_rate_factor * rate
            u = max(-lim, min(lim, u))
            servo["u"] = u
            O.cell.velGrad = Matrix3(shape[0] * rate + u, 0, 0, 0, shape[1] * rate + u, 0, 0, 0, shape[2] * rate + u)

        globals()["isobaric_servo"] = isobaric_servo
        O.engines = O.engines[:-1] + [PyRunner(iterPeriod=a.servo_every, command="isobaric_servo()")] + O.engines[-1:]
        out.write(f"# isobaric servo (Python): p = {a.isobaric_p0} x p0 = {p_goal:.8g} Pa (contact stress), dead-beat over "
                  f"{a.servo_every} steps, low-pass 0.25, |u| <= {a.servo_rate_factor} x rate\n")
    if frict:
        if mindlin:
            out.write(f"# Hertz-Mindlin: E={a.young} Pa, nu={a.poisson}, mu={a.friction}, en={a.en}; FrictMat + "
                      "Ip2_FrictMat_FrictMat_MindlinPhys + Law2_ScGeom_MindlinPhys_Mindlin (incremental shear force); "
                      "W_friction_J not tracked (nan)\n")
        elif frictphys:
            out.write(f"# friction: mu={a.friction} (frictionAngle=atan(mu)), k_t={kt:.8g} N/m, no dashpots; FrictMat per body "
                      "(young = k/r, poisson = k_t/k) + Law2_ScGeom_FrictPhys_CundallStrack; W_friction_J = O.energy['plastDissip']\n")
        else:
            out.write(f"# friction: mu={a.friction} (frictionAngle=atan(mu)), k_t={kt:.8g} N/m, gamma_t={gamma_t} kg/s "
                      "(ViscElMat ks, cs = 2x the pair values); W_friction_J not tracked by YADE's ViscEl law (nan)\n")
    out.write(",".join(COLUMNS[:-1] + (FRICTION_COLUMNS if frict else []) + COLUMNS[-1:]) + "\n")
    out.write(",".join(first) + "\n")
    done = 0
    wall = 0.0
    while done < n_steps:
        chunk = min(steps_per_sample, n_steps - done)
        t0 = time.time()
        O.run(chunk, True)
        wall += time.time() - t0
        done += chunk
        out.write(",".join(measure()) + "\n")
        out.flush()
    out.close()
    import os
    os.replace(a.out + ".part", a.out)
    n = len(O.bodies)
    sys.stderr.write(f"run_mode.py: {done} steps of {n} particles in {wall:.2f} s (stepping only): "
                     f"{done * n / max(wall, 1e-9) / 1e6:.3f} M particle-steps/s -> {a.out}\n")
    if sheared:
        T = O.cell.trsf
        sys.stderr.write(f"run_mode.py: trsf = {[[T[p, q] for q in range(3)] for p in range(3)]}, "
                         f"hSize = {[[O.cell.hSize[p, q] for q in range(3)] for p in range(3)]}\n")
    check_pairs()


def check_pairs():
    """Sanity: pair parameters as intended (at the start and at the end of the run)."""
    a = ARGS
    frict = a.friction > 0
    kt = a.kt_ratio * a.k if frict else 0.0
    gamma_t = a.gamma_t if frict else 0.0
    if a.law == "mindlin":   # Mindlin: kn, ks depend on the overlap; the coefficients are checked
        E_star, G = a.young / (2 * (1 - a.poisson ** 2)), a.young / (2 * (1 + a.poisson))
        for i in O.interactions:
            if i.isReal:
                r1, r2 = O.bodies[i.id1].shape.radius, O.bodies[i.id2].shape.radius
                R = r1 * r2 / (r1 + r2)
                want_n, want_s = 4 / 3 * E_star * math.sqrt(R), 8 * G / (2 * (2 - a.poisson)) * math.sqrt(R)
                if abs(i.phys.kno - want_n) > 1e-9 * want_n or abs(i.phys.kso - want_s) > 1e-9 * want_s:
                    sys.exit(f"run_mode.py: pair kno={i.phys.kno}, kso={i.phys.kso} differ from {want_n}, {want_s}")
                break
        return
    for i in O.interactions:
        if i.isReal:
            cn = getattr(i.phys, "cn", 0.0)       # FrictPhys: no dashpots
            cs = getattr(i.phys, "cs", 0.0)
            if abs(i.phys.kn - a.k) > 1e-6 * a.k or abs(cn - a.gamma) > 1e-6 * max(a.gamma, 1e-30):
                sys.exit(f"run_mode.py: pair kn={i.phys.kn}, cn={cn} differ from k={a.k}, gamma={a.gamma}")
            if frict and (abs(i.phys.ks - kt) > 1e-6 * kt or abs(cs - gamma_t) > 1e-6 * max(gamma_t, 1e-30)
                          or abs(i.phys.tangensOfFrictionAngle - a.friction) > 1e-9 * a.friction):
                sys.exit(f"run_mode.py: pair ks={i.phys.ks}, cs={cs}, tan(phi)={i.phys.tangensOfFrictionAngle} "
                         f"differ from k_t={kt}, gamma_t={gamma_t}, mu={a.friction}")
            break


main()
