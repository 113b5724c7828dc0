// Head-on collision of two spheres, simulated with the engine: the closed-form check of the
// contact law and integrator (tests, `dem collide`, and the YADE cross-check).
#pragma once
#include "dem/core/model.hpp"

namespace dem {

struct CollisionResult {
  double contact_time;   ///< [s], from the interpolated zero crossings of the overlap
  double restitution;    ///< separation speed / approach speed
  long steps_in_contact = 0;   ///< time steps with a positive overlap
  double max_overlap = 0;      ///< largest overlap / smaller radius
};

/// Spheres of radii r1, r2 [m] (density from the model) approach along x at relative speed
/// v0 [m/s] from a gap of 2e-7 m, optionally across the periodic x boundary of a 20 mm box.
/// Uses the model's contact law, damping and integrator (set background damping to 0 for
/// the closed form). Throws std::invalid_argument unless r1, r2, v0 are positive and finite,
/// std::runtime_error if no contact ends within 1e7 steps.
CollisionResult simulate_collision(const Model& model, double r1, double r2, double v0,
                                   bool across_boundary = false);

}  // namespace dem
