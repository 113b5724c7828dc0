// The mutable state of a simulation: particles, box, time, and the neighbour-list reference.
// Together with the Model it is everything needed to continue a run bit for bit.
#pragma once
#include <cstdint>
#include <vector>

#include "dem/core/vec3.hpp"

namespace dem {

/// Periodic cell, deformed by a velocity gradient. The cell matrix H has the columns
/// a = (L_x, 0, 0), b = (xy, L_y, 0), c = (xz, yz, L_z) (upper triangular, LAMMPS' convention):
/// positions x = H s with fractional coordinates s in [0, 1)^3 at list builds. With no tilt it
/// is the orthorhombic box [0, L_x) x [0, L_y) x [0, L_z) of the diagonal modes, whose
/// arithmetic is unchanged. A tilt beyond half the edge it leans along is flipped to the most
/// orthogonal equivalent cell (the same lattice of images, docs/simple_shear.md).
struct Box {
  Vec3 length{1, 1, 1};      ///< current edge lengths [m] = reference (.) exp(log_strain)
  Vec3 length0{1, 1, 1};     ///< edge lengths when strains were last zeroed [m]
  Vec3 reference{0, 0, 0};   ///< lengths at log_strain = 0 [m] (0: not yet set)
  Vec3 log_strain{0, 0, 0};  ///< accumulated true strain since `reference`. Lengths are
                             ///< computed from it, so D2/D3 conserve volume to one rounding.
  Vec3 tilt{0, 0, 0};        ///< (xy, xz, yz) of the current (flipped) cell [m]
  Vec3 tilt0{0, 0, 0};       ///< the tilt when strains were last zeroed [m]
  /// The flips since strains were last zeroed, as the integer unitriangular M with
  /// H = H_unflipped M: flips = (M_xy, M_xz, M_yz). The deformation gradient is
  /// F = H M^-1 H0^-1, continuous across flips.
  std::int32_t flips[3] = {0, 0, 0};
  double volume() const { return length.x * length.y * length.z; }
  /// True (logarithmic) strain of each axis since length0; positive = extension.
  Vec3 true_strain() const;
  /// Any tilt now. False: the orthorhombic box (every diagonal run).
  bool tilted() const { return tilt.x != 0 || tilt.y != 0 || tilt.z != 0; }
  /// The deformation since strains were zeroed is not diagonal (tilt now or then, or flips).
  bool sheared() const {
    return tilted() || tilt0.x != 0 || tilt0.y != 0 || tilt0.z != 0 || flips[0] != 0 || flips[1] != 0 || flips[2] != 0;
  }
  /// H s [m] (the lattice vector of integer s; any s).
  Vec3 lattice(double sx, double sy, double sz) const {
    return {sx * length.x + sy * tilt.x + sz * tilt.y, sy * length.y + sz * tilt.z, sz * length.z};
  }
  /// H^-1 x: fractional coordinates.
  Vec3 fractional(const Vec3& x) const {
    const double sz = x.z / length.z;
    const double sy = (x.y - tilt.z * sz) / length.y;
    return {(x.x - tilt.x * sy - tilt.y * sz) / length.x, sy, sz};
  }
  /// Zeroes the strains here: length0, tilt0 = now, no flips (the log-strain reference is the
  /// caller's: run_stage and run_path re-base it too).
  void zero_strain() {
    length0 = length;
    tilt0 = tilt;
    flips[0] = flips[1] = flips[2] = 0;
  }
  /// The deformation gradient F (row-major) since strains were zeroed: H_unflipped H0^-1.
  void deformation_gradient(double F[3][3]) const;
};

struct State {
  // Per-particle arrays, all of size N, kept in the same (cell-sorted) order.
  std::vector<Vec3> position;     ///< [m], inside or near the box; wrapped at list rebuilds
  std::vector<Vec3> velocity;     ///< fluctuation velocity (relative to the affine flow) [m/s]
  std::vector<Vec3> force;        ///< total force of the last evaluation [N]
  std::vector<double> radius;     ///< [m]
  std::vector<double> mass;       ///< [kg]
  std::vector<std::int32_t> id;   ///< original particle index, stable across re-sorting

  // Rotations: sized N only when the contact model needs them (friction); empty otherwise, so
  // a frictionless state keeps 3 degrees of freedom per particle. Moment of inertia 2/5 m r^2.
  std::vector<Vec3> angular_velocity;   ///< [rad/s]
  std::vector<Vec3> torque;             ///< of the last evaluation [N m]

  /// Per-contact history (tangential springs...), one record of `width` doubles per listed
  /// pair in neighbour-list order, so the pair loop reads it contiguously. Carried across list
  /// rebuilds, re-sorts and cell flips by the pair's particle ids (rebuild_neighbor_list);
  /// written to checkpoints. Entries whose bit is set in `odd` change sign when i and j swap.
  struct ContactHistory {
    int width = 0;
    unsigned odd = 0;
    std::vector<double> values;        ///< width doubles per record
    std::vector<std::int32_t> ids;     ///< (id_i, id_j) of each record's pair, in its orientation
  } history;
  double friction_dissipated = 0;  ///< energy the Coulomb limit removed from the springs [J], cumulative

  Box box;
  double time = 0;                ///< simulated time [s]
  std::int64_t step = 0;

  // Neighbour-list reference (positions and box at the last rebuild). Part of the state so
  // that a restarted run rebuilds exactly the same list and continues bit for bit.
  std::vector<Vec3> position_at_build;
  Vec3 length_at_build{1, 1, 1};
  Vec3 tilt_at_build{0, 0, 0};    ///< the cell's tilt at the last rebuild [m]
  bool list_valid = false;        ///< false forces a rebuild before the next force evaluation

  int count() const { return static_cast<int>(position.size()); }
  double particle_volume() const;        ///< sum of sphere volumes [m^3]
  double volume_fraction() const { return particle_volume() / box.volume(); }
  double kinetic_energy() const;         ///< of fluctuation velocities [J]
  double rotational_energy() const;      ///< sum I w^2 / 2 [J] (0 without rotations)
  bool rotations() const { return !angular_velocity.empty(); }
  void resize(int n);
};

}  // namespace dem
