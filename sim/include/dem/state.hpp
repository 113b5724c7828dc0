// The mutable state of a simulation: particles, box, time, and the neighbour-list reference.
// Together with the Model it is everything needed to continue a run bit for bit.
#pragma once
#include <cstdint>
#include <vector>

#include "dem/vec3.hpp"

namespace dem {

/// Orthorhombic periodic box [0, L_x) x [0, L_y) x [0, L_z), deformed by a diagonal strain rate.
struct Box {
  Vec3 length{1, 1, 1};      ///< current edge lengths [m] = reference (.) exp(log_strain)
  Vec3 length0{1, 1, 1};     ///< edge lengths when strains were last zeroed [m]
  Vec3 reference{0, 0, 0};   ///< lengths at log_strain = 0 [m] (0: not yet set)
  Vec3 log_strain{0, 0, 0};  ///< accumulated true strain since `reference`. Lengths are
                             ///< computed from it, so D2/D3 conserve volume to one rounding.
  double volume() const { return length.x * length.y * length.z; }
  /// True (logarithmic) strain of each axis since length0; positive = extension.
  Vec3 true_strain() const;
};

struct State {
  // Per-particle arrays, all of size N, kept in the same (cell-sorted) order.
  std::vector<Vec3> position;     ///< [m], inside or near the box; wrapped at list rebuilds
  std::vector<Vec3> velocity;     ///< fluctuation velocity (relative to the affine flow) [m/s]
  std::vector<Vec3> force;        ///< total force of the last evaluation [N]
  std::vector<double> radius;     ///< [m]
  std::vector<double> mass;       ///< [kg]
  std::vector<std::int32_t> id;   ///< original particle index, stable across re-sorting

  Box box;
  double time = 0;                ///< simulated time [s]
  std::int64_t step = 0;

  // Neighbour-list reference (positions and box at the last rebuild). Part of the state so
  // that a restarted run rebuilds exactly the same list and continues bit for bit.
  std::vector<Vec3> position_at_build;
  Vec3 length_at_build{1, 1, 1};
  bool list_valid = false;        ///< false forces a rebuild before the next force evaluation

  int count() const { return static_cast<int>(position.size()); }
  double particle_volume() const;        ///< sum of sphere volumes [m^3]
  double volume_fraction() const { return particle_volume() / box.volume(); }
  double kinetic_energy() const;         ///< of fluctuation velocities [J]
  void resize(int n);
};

}  // namespace dem
