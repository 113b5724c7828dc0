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

/// What a rolling sub-model sees of a contact, in lanes of T: the unit normal n (i to j), the
/// angular velocities, the reduced lever arm a' = a_i a_j / (a_i + a_j) [m] and the normal
/// force fn >= 0 [N].
template <class T>
struct RollingInput {
  V3<T> n;
  V3<T> wi, wj;
  T a_red;
  T fn;
};

struct NoRolling {
  static constexpr int history = 0;
};

/// Rolling velocity v_r = -a' (w_i - w_j) x n [m/s] (even under i <-> j); a spring xi_r [m]
/// rotated into the tangent plane keeping its length and advanced by v_r dt, as the tangential
/// spring; the rolling "force" f_r = -k_r xi_r - gamma_r v_r [N], capped at mu_r fn (the spring
/// reset to the cone): the slider of slider.hpp. Torques: tau_i = -a' n x f_r, tau_j = +a' n x f_r
/// (|tau| <= mu_r a' fn). Energy k_r |xi_r|^2 / 2. History: xi_r (3 doubles, even under i <-> j).
/// Scene keys: contact.rolling_friction (mu_r), contact.rolling_stiffness_ratio (k_r/k),
/// contact.rolling_damping_kg_s (gamma_r).
struct RollingSpring {
  double kr;        ///< [N/m]
  double gamma_r;   ///< [kg/s]
  double mu_r;      ///< rolling friction coefficient (dimensionless: torque <= mu_r a' fn)
  static constexpr int history = 3;
  static constexpr bool lane_body = true;

  /// One step: updates h and returns the torque on i [N m] (on j: its negative); `dissipated`
  /// gains the energy lost at the rolling limit [J] (as CundallStrack::update).
  template <class T>
  __attribute__((always_inline)) V3<T> update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    const V3<T> vr = cross(c.wi - c.wj, c.n) * (-c.a_red);
    const V3<T> start = CundallStrack::rotate_spring(V3<T>{h[0], h[1], h[2]}, c.n);
    const SliderStep<T, V3<T>> s =
        slider_step(start, vr, dt, lanes::splat<T>(kr), lanes::splat<T>(gamma_r), lanes::splat<T>(mu_r) * c.fn);
    h[0] = s.spring.x; h[1] = s.spring.y; h[2] = s.spring.z;
    dissipated = dissipated + s.dissipated;
    return cross(c.n, s.force) * (-c.a_red);
  }
  double energy(const double* h) const { return 0.5 * kr * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]); }
};

/// Twisting (torsion) resistance: twist velocity v_o = a' (w_i - w_j) . n [m/s] (even under
/// i <-> j: n and the spins both swap), a scalar spring xi_o [m] advanced by v_o dt (it needs no
/// rotation: it lies along n), the twisting "force" f_o = -k_o xi_o - gamma_o v_o [N], capped at
/// mu_o fn (the spring reset to the cone): the slider of slider.hpp in one dimension; torques
/// tau_i = a' f_o n, tau_j = -a' f_o n (|tau| <= mu_o a' fn). Energy k_o xi_o^2 / 2. History:
/// xi_o (1 double, even under i <-> j). Scene keys: contact.twisting_friction (mu_o),
/// contact.twisting_stiffness_ratio (k_o/k), contact.twisting_damping_kg_s (gamma_o).
struct TwistingSpring {
  double ko;        ///< [N/m]
  double gamma_o;   ///< [kg/s]
  double mu_o;      ///< twisting friction coefficient (torque <= mu_o a' fn)
  static constexpr int history = 1;
  static constexpr bool lane_body = true;

  /// One step: updates h[0] and returns the twisting force f_o [N] (torque on i: a' f_o n).
  template <class T>
  __attribute__((always_inline)) T update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    const T vo = c.a_red * dot(c.wi - c.wj, c.n);
    const SliderStep<T, T> s =
        slider_step(h[0], vo, dt, lanes::splat<T>(ko), lanes::splat<T>(gamma_o), lanes::splat<T>(mu_o) * c.fn);
    h[0] = s.spring;
    dissipated = dissipated + s.dissipated;
    return s.force;
  }
  double energy(const double* h) const { return 0.5 * ko * h[0] * h[0]; }
};

/// Rolling and twisting resistance together (the rolling part may be off: mu_r = 0 caps its
/// torque at zero). History: xi_r (3 doubles), then xi_o (1), all even under i <-> j.
struct RollingTwisting {
  RollingSpring rolling;
  TwistingSpring twisting;
  static constexpr int history = RollingSpring::history + TwistingSpring::history;
  static constexpr bool lane_body = true;

  /// One step: both springs; returns the torque on i [N m] (on j: its negative).
  template <class T>
  __attribute__((always_inline)) V3<T> update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    const V3<T> tr = rolling.update(c, dt, h, dissipated);
    const T fo = twisting.update(c, dt, h + RollingSpring::history, dissipated);
    return tr + c.n * (c.a_red * fo);
  }
  double energy(const double* h) const { return rolling.energy(h) + twisting.energy(h + RollingSpring::history); }
};

}  // namespace dem::contact
