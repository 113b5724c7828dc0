// Head-on collision of two spheres, simulated with the engine: the closed-form check of the
// contact law and integrator (tests, `dem collide`, and the YADE cross-check).
#pragma once
#include "dem/core/model.hpp"
#include "dem/core/vec3.hpp"

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

/// An oblique impact of two spheres (friction: Chung & Ooi 2011, Test 4, for two spheres in
/// relative velocities). Outcomes in the pair's frame: n from 0 to 1 along the initial line of
/// centres, t the initial tangential direction of the relative velocity (1 relative to 0).
struct ObliqueResult {
  double normal_restitution;       ///< -(v_rel . n) after / before
  double tangential_restitution;   ///< (v_rel . t) after / before (centre velocities)
  Vec3 omega[2];                   ///< angular velocities after [rad/s]
  double normal_impulse;           ///< on sphere 1 [N s]
  double tangential_impulse;       ///< on sphere 1 along -t [N s] (> 0 opposes the slip)
};

/// Spheres of radii r1, r2 [m] meet at relative speed v0 [m/s], angle theta [rad] from the
/// normal (0: head-on), no initial spin, zero total momentum. `across`: sphere 1 is the image
/// across the periodic z boundary of a cell under simple shear at rate `shear_rate` [1/s]
/// (L_xz), the fluctuation velocities chosen so that the full relative velocity (with the
/// image's affine velocity L d) is the same as in the plain case. Uses the model's contact law.
ObliqueResult simulate_oblique_collision(const Model& model, double r1, double r2, double v0, double theta,
                                         bool across = false, double shear_rate = 0.0);

}  // namespace dem
