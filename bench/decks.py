"""Input decks for LAMMPS and LIGGGHTS generated from a packing and our scene's physics, so the
benchmark runs the same scene everywhere (see docs/benchmarks.md for what still differs)."""
import functools
import math
import os
import subprocess


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


DEM = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "build", "dem")
SCENE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "scenes", "quickstart.toml")


def dem_info(dem, scene, flag, sets):
    """`dem info SCENE FLAG --set ...` (FLAG --lammps, --liggghts): its output; RuntimeError with
    dem's message when it refuses (a sub-model without a counterpart)."""
    cmd = [dem, "info", scene, flag]
    for kv in sets:
        cmd += ["--set", kv]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError(f"{' '.join(cmd)}: {r.stderr.strip()}")
    return r.stdout.strip()


@functools.lru_cache(maxsize=None)
def pair_coeff(sets=(), dem=DEM, scene=SCENE):
    """The LAMMPS `pair_coeff * * ...` line of our contact law for the scene with `sets` (a tuple of
    "key=value" overrides, as `dem --set`), from the sub-models' own counterparts in the registry
    (`dem info SCENE --lammps`): e.g. `hooke k gamma tangential linear_history k_t 0 mu damping
    velocity limit_damping` for the linear law with Cundall-Strack friction (LAMMPS' limit_damping is
    ours' no-tension clamp, contact.allow_attractive = false; Hertz's e' is the value whose LAMMPS
    polynomial alpha(e') equals ours' alpha, docs/contact_models.md). Raises RuntimeError with
    dem's message when a chosen sub-model has no LAMMPS counterpart (Luding's law)."""
    return dem_info(dem, scene, "--lammps", sets)


def lammps_deck(data, steps, rate, dt, sets=(), k=None, gamma=None, gamma_b=0.1, skin=2e-4, warmup=0, thermo=False):
    # pair granular with the pair_coeff line of ours' contact law (pair_coeff above; k, gamma, if
    # given, override the scene's contact.stiffness_N_m and contact.damping_kg_s); fix viscous:
    # -gamma_b v on every atom; fix deform trate: true strain rate (D2), remap x: positions follow
    # the box, velocities stay peculiar. atom_style sphere gives I = 2/5 m r^2 and fix nve/sphere
    # integrates the rotations of a frictional law. neighbor skin bin + neigh_modify delay 0 every
    # 1 check yes: the list (pairs within r_i + r_j + skin) is rebuilt as soon as an atom has moved
    # skin/2 since the last build, as ours. warmup: untimed steps before the timed run (see
    # _motion). thermo: a line every 1000 steps with the total kinetic and rotational energy [J],
    # the virial pressure and its diagonal [Pa] (the parity check of the frictional decks).
    sets = tuple(sets) + ((f"contact.stiffness_N_m={k!r}",) if k is not None else ()) + \
        ((f"contact.damping_kg_s={gamma!r}",) if gamma is not None else ())
    head = f"""units si
atom_style sphere
atom_modify map array
boundary p p p
newton off
comm_modify vel yes
read_data {data}
pair_style granular
{pair_coeff(sets)}
neighbor {skin!r} bin
neigh_modify delay 0 every 1 check yes
"""
    if thermo:
        head += """compute erot all erotate/sphere
compute prs all pressure NULL virial
thermo_style custom step ke c_erot c_prs c_prs[1] c_prs[2] c_prs[3]
thermo_modify format float %.10g
"""
    return head + _motion(dt, rate, gamma_b, steps, warmup)


def rayleigh_time(r_min, E, nu, density):
    """Ours' t_c of contact.normal = "hertz": the Rayleigh-wave time of the smallest sphere."""
    G = E / (2 * (1 + nu))
    return math.pi * r_min * math.sqrt(density / G) / (0.1631 * nu + 0.8766)


@functools.lru_cache(maxsize=None)
def liggghts_lines(sets=(), dem=DEM, scene=SCENE):
    """The LIGGGHTS lines of our contact law for the scene with `sets`, from each sub-model's
    counterpart in the registry (`dem info SCENE --liggghts`): a `fix property/global` per
    coefficient, `pair_style gran model hooke/stiffness tangential ... absolute_damping on limitForce
    on` (absolute_damping: gamma is the dashpot itself, not times the effective mass; limitForce:
    ours' no-tension clamp) and `pair_coeff * *`. Raises RuntimeError with dem's message when a
    chosen sub-model has no LIGGGHTS counterpart declared (Hertz, Mindlin, rolling, Luding)."""
    return dem_info(dem, scene, "--liggghts", sets)


def liggghts_deck(data, steps, rate, dt, sets=(), k=None, gamma=None, gamma_b=0.1, skin=2e-4):
    # gran model hooke/stiffness etc. from the registry (liggghts_lines); k, gamma, if given,
    # override the scene's contact.stiffness_N_m and contact.damping_kg_s, as lammps_deck.
    sets = tuple(sets) + ((f"contact.stiffness_N_m={k!r}",) if k is not None else ()) + \
        ((f"contact.damping_kg_s={gamma!r}",) if gamma is not None else ())
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
{liggghts_lines(sets)}
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
