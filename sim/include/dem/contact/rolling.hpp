// Rolling sub-models: none, and rolling resistance as a spring-dashpot-slider on the relative
// rolling displacement (Luding 2008, Granular Matter 10:235, sec. 2.3; LAMMPS `rolling sds`,
// MercuryDPM's rolling friction). A couple: no net force, equal and opposite torques.
#pragma once
#include <cmath>

#include "dem/contact/tangential.hpp"
#include "dem/core/vec3.hpp"

namespace dem::contact {

/// What a rolling sub-model sees of a contact: the unit normal n (i to j), the angular
/// velocities, the reduced lever arm a' = a_i a_j / (a_i + a_j) [m] and the normal force fn [N].
struct RollingInput {
  Vec3 n;
  Vec3 wi, wj;
  double a_red;
  double fn;
};

struct NoRolling {
  static constexpr int history = 0;
};

/// Rolling velocity v_r = -a' (w_i - w_j) x n [m/s] (even under i <-> j); a spring xi_r [m]
/// rotated into the tangent plane keeping its length and advanced by v_r dt, as the tangential
/// spring; the rolling "force" f_r = -k_r xi_r - gamma_r v_r [N], capped at mu_r fn (the spring
/// reset to the cone). Torques: tau_i = -a' n x f_r, tau_j = +a' n x f_r (|tau| <= mu_r a' fn).
/// Energy k_r |xi_r|^2 / 2. History: xi_r (3 doubles, even under i <-> j).
/// Scene keys: contact.rolling_friction (mu_r), contact.rolling_stiffness_ratio (k_r/k),
/// contact.rolling_damping_kg_s (gamma_r).
struct RollingSpring {
  double kr;        ///< [N/m]
  double gamma_r;   ///< [kg/s]
  double mu_r;      ///< rolling friction coefficient (dimensionless: torque <= mu_r a' fn)
  static constexpr int history = 3;

  /// One step: updates h and returns the torque on i [N m] (on j: its negative); `dissipated`
  /// gains the energy lost at the rolling limit [J] (as CundallStrack::update).
  Vec3 update(const RollingInput& c, double dt, double* h, double* dissipated) const {
    const Vec3 vr = cross(c.wi - c.wj, c.n) * (-c.a_red);
    const Vec3 start = CundallStrack::rotate_spring(Vec3{h[0], h[1], h[2]}, c.n);
    const Vec3 step = vr * dt;
    Vec3 xi = start + step;
    Vec3 f = xi * (-kr) - vr * gamma_r;
    const double limit = mu_r * c.fn, f2 = dot(f, f);
    if (f2 > limit * limit) {
      f = f * (limit / std::sqrt(f2));
      xi = (f + vr * gamma_r) * (-1.0 / kr);
      *dissipated += 0.5 * kr * (dot(start + xi, step) - dot(xi, xi) + dot(start, start));
    }
    h[0] = xi.x; h[1] = xi.y; h[2] = xi.z;
    return cross(c.n, f) * (-c.a_red);
  }
  double energy(const double* h) const { return 0.5 * kr * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]); }
};

}  // namespace dem::contact
