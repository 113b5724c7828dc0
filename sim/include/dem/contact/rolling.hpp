// Rolling sub-models: none; rolling resistance as a spring-dashpot-slider on the relative
// rolling displacement (Luding 2008, Granular Matter 10:235, sec. 2.3; LAMMPS `rolling sds`,
// MercuryDPM's rolling friction); and rolling plus twisting (torsion) resistance, the same
// spring-dashpot-slider on the relative spin about the normal (Luding 2008, sec. 2.3; LAMMPS
// `twisting sds`, MercuryDPM's torsion friction). Couples: no net force, equal and opposite torques.
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

/// Twisting (torsion) resistance: twist velocity v_o = a' (w_i - w_j) . n [m/s] (even under
/// i <-> j: n and the spins both swap), a scalar spring xi_o [m] advanced by v_o dt (it needs no
/// rotation: it lies along n), the twisting "force" f_o = -k_o xi_o - gamma_o v_o [N], capped at
/// mu_o fn (the spring reset to the cone); torques tau_i = a' f_o n, tau_j = -a' f_o n
/// (|tau| <= mu_o a' fn). Energy k_o xi_o^2 / 2. History: xi_o (1 double, even under i <-> j).
/// Scene keys: contact.twisting_friction (mu_o), contact.twisting_stiffness_ratio (k_o/k),
/// contact.twisting_damping_kg_s (gamma_o).
struct TwistingSpring {
  double ko;        ///< [N/m]
  double gamma_o;   ///< [kg/s]
  double mu_o;      ///< twisting friction coefficient (torque <= mu_o a' fn)
  static constexpr int history = 1;

  /// One step: updates h[0] and returns the twisting force f_o [N] (torque on i: a' f_o n).
  double update(const RollingInput& c, double dt, double* h, double* dissipated) const {
    const double vo = c.a_red * dot(c.wi - c.wj, c.n);
    const double start = h[0], step = vo * dt;
    double xi = start + step;
    double f = -ko * xi - gamma_o * vo;
    const double limit = mu_o * c.fn;
    if (std::fabs(f) > limit) {
      f = std::copysign(limit, f);
      xi = -(f + gamma_o * vo) / ko;
      *dissipated += 0.5 * ko * ((start + xi) * step - xi * xi + start * start);
    }
    h[0] = xi;
    return f;
  }
  double energy(const double* h) const { return 0.5 * ko * h[0] * h[0]; }
};

/// Rolling and twisting resistance together (the rolling part may be off: mu_r = 0 caps its
/// torque at zero). History: xi_r (3 doubles), then xi_o (1), all even under i <-> j.
struct RollingTwisting {
  RollingSpring rolling;
  TwistingSpring twisting;
  static constexpr int history = RollingSpring::history + TwistingSpring::history;

  /// One step: both springs; returns the torque on i [N m] (on j: its negative).
  Vec3 update(const RollingInput& c, double dt, double* h, double* dissipated) const {
    const Vec3 tr = rolling.update(c, dt, h, dissipated);
    const double fo = twisting.update(c, dt, h + RollingSpring::history, dissipated);
    return tr + c.n * (c.a_red * fo);
  }
  double energy(const double* h) const { return rolling.energy(h) + twisting.energy(h + RollingSpring::history); }
};

}  // namespace dem::contact
