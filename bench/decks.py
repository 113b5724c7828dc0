"""Input decks for LAMMPS and LIGGGHTS generated from a packing and our scene's physics, so the
benchmark runs the same scene everywhere (see docs/benchmarks.md for what still differs)."""
import math


def read_packing(path):
    cell, spheres = None, []
    with open(path) as fh:
        for line in fh:
            s = line.strip()
            if s.startswith("##PERIODIC::"):
                cell = [float(v) for v in s.split()[1:4]]
            elif s and not s.startswith("#"):
                spheres.append([float(v) for v in s.split()[:4]])
    if cell is None:
        raise ValueError(f"{path}: no '##PERIODIC::' line")
    return cell, spheres


def tc_smallest(spheres, k=1e8, gamma=1.0, density=2000.0):
    rmin = min(s[3] for s in spheres)
    mr = 4 / 3 * math.pi * rmin ** 3 * density / 2
    return math.pi / math.sqrt(k / mr - (gamma / (2 * mr)) ** 2)


def write_lammps_data(path, cell, spheres, density, style):
    """style 'sphere' (LAMMPS: id type diameter density x y z) or 'granular' (LIGGGHTS, same columns)."""
    with open(path, "w") as fh:
        fh.write(f"packing for {style}\n\n{len(spheres)} atoms\n1 atom types\n\n")
        fh.write(f"0 {cell[0]!r} xlo xhi\n0 {cell[1]!r} ylo yhi\n0 {cell[2]!r} zlo zhi\n\nAtoms\n\n")
        for i, (x, y, z, r) in enumerate(spheres, 1):
            fh.write(f"{i} 1 {2 * r!r} {density!r} {x!r} {y!r} {z!r}\n")


def _motion(dt, rate, gamma_b, steps, warmup=0):
    """The part both codes share: velocity Verlet, drag on the peculiar velocity, D2 box. With
    warmup > 0: `warmup` untimed steps first (as `dem bench`'s warm-up), then the timed run with
    `pre no` (no second setup, so no list build between the two runs); the timed run's summary
    (loop time, list builds, timing breakdown) is then the last one in the log."""
    runs = f"run {warmup}\nrun {steps} pre no\n" if warmup else f"run {steps}\n"
    return f"""timestep {dt!r}
fix integ all nve/sphere
fix visc all viscous {gamma_b}
fix def all deform 1 x trate {rate!r} z trate {-rate!r} remap x
thermo 1000
""" + runs


def lammps_deck(data, steps, rate, dt, k=1e8, gamma=1.0, gamma_b=0.1, skin=2e-4, warmup=0):
    # pair granular: hooke normal force k*delta with absolute velocity damping (damping velocity:
    # eta_n = gamma), no tangential force; fix viscous: -gamma_b v on every atom; fix deform
    # trate: true strain rate (D2), remap x: positions follow the box, velocities stay peculiar.
    # neighbor skin bin + neigh_modify delay 0 every 1 check yes: the list (pairs within
    # r_i + r_j + skin) is rebuilt as soon as an atom has moved skin/2 since the last build, as
    # ours. warmup: untimed steps before the timed run (see _motion).
    return f"""units si
atom_style sphere
atom_modify map array
boundary p p p
newton off
comm_modify vel yes
read_data {data}
pair_style granular
pair_coeff * * hooke {k} {gamma} tangential linear_nohistory 0 0 damping velocity
neighbor {skin!r} bin
neigh_modify delay 0 every 1 check yes
""" + _motion(dt, rate, gamma_b, steps, warmup)


def lammps_friction_deck(data, steps, rate, dt, k=1e8, gamma=1.0, gamma_b=0.1, skin=2e-4, mu=0.5, kt_ratio=2 / 7):
    # As lammps_deck, with Cundall-Strack friction as ours' contact.friction = mu:
    # `tangential linear_history k_t x_gamma_t mu_s` takes k_t itself [N/m] (ours: k_t =
    # contact.tangential_stiffness_ratio x k), x_gamma_t the tangential damping as a multiple of
    # the normal eta_n (0: no tangential dashpot, ours' default tangential_damping_kg_s = 0) and
    # mu_s the Coulomb coefficient, the critical force mu_s |F_n| (F_n: spring + dashpot). The
    # spring xi is rotated into the tangent plane keeping its length and reset to the cone on
    # slip, as ours (Luding 2008, eqs. 17-20). atom_style sphere gives I = 2/5 m r^2; fix
    # nve/sphere integrates the rotations. The thermo line every 1000 steps (total kinetic and
    # rotational energy [J], the virial pressure and its diagonal [Pa]) is the parity check.
    return f"""units si
atom_style sphere
atom_modify map array
boundary p p p
newton off
comm_modify vel yes
read_data {data}
pair_style granular
pair_coeff * * hooke {k} {gamma} tangential linear_history {kt_ratio * k!r} 0 {mu} damping velocity
neighbor {skin} bin
neigh_modify delay 0 every 1 check yes
compute erot all erotate/sphere
compute prs all pressure NULL virial
thermo_style custom step ke c_erot c_prs c_prs[1] c_prs[2] c_prs[3]
thermo_modify format float %.10g
""" + _motion(dt, rate, gamma_b, steps)


def tsuji_restitution_of_alpha(alpha, h=2e-3):
    """The restitution of the dimensionless Hertz impact with Tsuji's dashpot,
    x'' = -max(x^1.5 + alpha x^0.25 x', 0), x(0) = 0, x'(0) = 1 (RK4): ours' HertzNormal::restitution_of_alpha."""
    def acc(x, u):
        if x <= 0:
            return 0.0
        f = x * math.sqrt(x) + alpha * math.sqrt(math.sqrt(x)) * u
        return -f if f > 0 else 0.0
    x, u = 0.0, 1.0
    for _ in range(1000000):
        k1x, k1u = u, acc(x, u)
        k2x, k2u = u + 0.5 * h * k1u, acc(x + 0.5 * h * k1x, u + 0.5 * h * k1u)
        k3x, k3u = u + 0.5 * h * k2u, acc(x + 0.5 * h * k2x, u + 0.5 * h * k2u)
        k4x, k4u = u + h * k3u, acc(x + h * k3x, u + h * k3u)
        xn = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        un = u + h / 6 * (k1u + 2 * k2u + 2 * k3u + k4u)
        if xn < 0 and un < 0:
            return -(u + (un - u) * x / (x - xn))
        x, u = xn, un
    return 0.0


def _bisect(f, target, lo, hi, decreasing=True, it=48):
    for _ in range(it):
        mid = 0.5 * (lo + hi)
        if (f(mid) > target) == decreasing:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def lammps_tsuji_alpha(e):
    """LAMMPS' `damping tsuji` polynomial alpha(e) (gran_sub_mod_damping.cpp)."""
    c = [1.2728, -4.2783, 11.087, -22.348, 27.467, -18.022, 4.8218]
    return sum(ci * e ** k for k, ci in enumerate(c))


def lammps_hertz_restitution(e):
    """The e' to give LAMMPS' `hertz/material E e' nu ... damping tsuji` so that its polynomial
    alpha(e') equals the alpha ours solves for the restitution e (contact.restitution): LAMMPS'
    fit does not give e back (docs/contact_models.md, Hertz)."""
    if e >= 1.0:
        return 1.0
    alpha = _bisect(tsuji_restitution_of_alpha, e, 0.0, 64.0)   # e(alpha) falls with alpha
    return _bisect(lammps_tsuji_alpha, alpha, 0.0, 1.0)          # alpha(e') falls with e'


def lammps_hertz_mindlin_deck(data, steps, rate, dt, E=1e8, nu=0.3, e=0.9, mu=0.5, rule="mindlin", gamma_b=0.1,
                              skin=2e-4, warmup=0):
    # Ours' contact.normal = "hertz" (E, nu, e) + contact.tangential = "mindlin" | "mindlin_force" (mu):
    # `hertz/material E e' nu` is 4/3 E* sqrt(R* delta) delta with E* = E/(2(1 - nu^2)) (mixing of
    # two equal materials), `damping tsuji` alpha(e') sqrt(m* F_el/delta) d(delta)/dt with e' from
    # lammps_hertz_restitution (so alpha equals ours), `limit_damping` the no-tension clamp (ours'
    # default contact.allow_attractive = false); `tangential mindlin NULL 0 mu` (k_t = 8 G*
    # sqrt(R* delta) from E and nu, no tangential damping) keeps the displacement when k_t changes,
    # `mindlin/force` the force (incremental), as ours' two rules. See lammps_friction_deck for the rest.
    lammps_rule = {"mindlin": "mindlin", "mindlin_force": "mindlin/force"}[rule]
    e_lammps = lammps_hertz_restitution(e)
    return f"""units si
atom_style sphere
atom_modify map array
boundary p p p
newton off
comm_modify vel yes
read_data {data}
pair_style granular
pair_coeff * * hertz/material {E!r} {e_lammps!r} {nu!r} tangential {lammps_rule} NULL 0 {mu!r} damping tsuji limit_damping
neighbor {skin!r} bin
neigh_modify delay 0 every 1 check yes
compute erot all erotate/sphere
compute prs all pressure NULL virial
thermo_style custom step ke c_erot c_prs c_prs[1] c_prs[2] c_prs[3]
thermo_modify format float %.10g
""" + _motion(dt, rate, gamma_b, steps, warmup)


def rayleigh_time(r_min, E, nu, density):
    """Ours' t_c of contact.normal = "hertz": the Rayleigh-wave time of the smallest sphere."""
    G = E / (2 * (1 + nu))
    return math.pi * r_min * math.sqrt(density / G) / (0.1631 * nu + 0.8766)


def liggghts_deck(data, steps, rate, dt, k=1e8, gamma=1.0, gamma_b=0.1, skin=2e-4):
    # gran model hooke/stiffness: kn, gamman given directly; absolute_damping on: gamman is
    # the damping coefficient itself (not times the effective mass); limitForce on: no
    # attraction (our default); tangential no_history with kt = gammat = 0.
    return f"""atom_style granular
atom_modify map array
boundary p p p
newton off
communicate single vel yes
units si
read_data {data}
neighbor {skin} bin
neigh_modify delay 0
hard_particles yes
fix m1 all property/global kn peratomtypepair 1 {k}
fix m2 all property/global kt peratomtypepair 1 0.0
fix m3 all property/global gamman_abs peratomtypepair 1 {gamma}
fix m4 all property/global gammat_abs peratomtypepair 1 0.0
fix m5 all property/global coefficientFriction peratomtypepair 1 0.0
pair_style gran model hooke/stiffness tangential no_history absolute_damping on limitForce on
pair_coeff * *
""" + _motion(dt, rate, gamma_b, steps)


def replicate_packing(src, k, dst):
    """Writes the packing `src` repeated k x k x k times (N -> k^3 N, box edges -> k L): the same
    state per particle (same contacts, same forces), so a timing against N isolates the cost of N."""
    cell, spheres = read_packing(src)
    with open(dst, "w") as fh:
        fh.write("##PERIODIC:: " + " ".join(repr(k * c) for c in cell) + "\n")
        for a in range(k):
            for b in range(k):
                for c in range(k):
                    for x, y, z, r in spheres:
                        fh.write(f"{x + a * cell[0]!r} {y + b * cell[1]!r} {z + c * cell[2]!r} {r!r}\n")
    return dst
