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

/// The rolling slot of the composed model holds one of NoRolling, RollingSpring or
/// RollingTwisting, the first whose `accepts` takes the law's rolling and twisting choice.
struct NoRolling {
  static constexpr int history = 0;
  static bool accepts(const ContactLaw& law) { return !law.rolling() && !law.twisting(); }
  static NoRolling from(const ContactLaw&, double) { return {}; }
};

namespace detail {
/// The description of a rolling or twisting spring-dashpot-slider (they differ in names only).
inline SubModelInfo sds_info(Slot slot, const std::string& what, const std::string& sym) {
  SubModelInfo d;
  d.slot = slot;
  d.name = "sds";
  d.switch_key = what + "_friction";
  d.title = what + " resistance: a spring-dashpot-slider on the relative " + what + " displacement, torque <= mu_" +
            sym + " a' f_n";
  d.reference = "Luding, Granular Matter 10 (2008) 235, sec. 2.3";
  d.keys = {{what + "_friction", "1", 0.0, "", 0, 0, false,
             "mu_" + sym + ": " + what + " torque <= mu_" + sym + " a' f_n; 0: off (needs a tangential model)"},
            {what + "_stiffness_ratio", "1", 2.0 / 7.0, "", 0, 10, true, "k_" + sym + "/k, in (0, 10]"},
            {what + "_damping_kg_s", "kg/s", 0.0, "", 0, 0, false, "gamma_" + sym + ", its dashpot, e.g. 0"}};
  d.rotations = true;
  d.lammps = what == "rolling" ? "rolling sds k_r gamma_r mu_r" : "twisting sds k_o gamma_o mu_o";
  d.lammps_words = [what](const ContactLaw& law) {
    return what + " sds " + exact_num(law.get(what + "_stiffness_ratio") * law.reference_stiffness()) + " " +
           exact_num(law.get(what + "_damping_kg_s")) + " " + exact_num(law.get(what + "_friction"));
  };
  d.liggghts = "none with this spring-dashpot-slider (LIGGGHTS' rolling_friction cdt/epsd2 are other laws)";
  d.yade = "none with this spring-dashpot-slider (CohFrictMat's moment law is elastic-plastic without a dashpot)";
  d.describe = [what, sym](const ContactLaw& law, const PairScale&) {
    return "mu_" + sym + " = " + g_num(law.get(what + "_friction")) + ", k_" + sym + "/k = " +
           g_num(law.get(what + "_stiffness_ratio")) + ", gamma_" + sym + " = " + g_num(law.get(what + "_damping_kg_s")) +
           " kg/s (torque " + (what == "rolling" ? "" : "about n ") + "<= mu_" + sym + " a' f_n)";
  };
  d.oscillators = [what](const ContactLaw& law, const PairScale& s) {
    // Two equal spheres turning against each other: xi'' = -2 a'^2 k xi / I, a' = r/2,
    // I = 2/5 m r^2, m = 2 m_r: an oscillator of effective mass 1.6 m_r.
    return std::vector<Oscillator>{{"the " + what + " spring-dashpot of the smallest pair (effective mass 1.6 m_r)",
                                    1.6 * s.m_r, law.get(what + "_stiffness_ratio") * s.k_ref,
                                    law.get(what + "_damping_kg_s"), what + "_stiffness_ratio", s.k_ref,
                                    what + "_damping_kg_s"}};
  };
  return d;
}
/// A rolling or twisting key's value, its default where the sub-model is off.
inline double key_or_default(const ContactLaw& law, const SubModelInfo& info, const std::string& key) {
  for (const KeySpec& k : info.keys)
    if (k.name == key) return law.get_or(key, k.fallback);
  return law.get(key);
}
}  // namespace detail


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
  static bool accepts(const ContactLaw& law) { return law.rolling() && !law.twisting(); }
  /// From the scene's keys (zero torque where rolling is off); k_ref: the normal reference stiffness.
  static RollingSpring from(const ContactLaw& law, double k_ref) {
    const SubModelInfo& i = info();
    return {detail::key_or_default(law, i, "rolling_stiffness_ratio") * k_ref,
            detail::key_or_default(law, i, "rolling_damping_kg_s"), detail::key_or_default(law, i, "rolling_friction")};
  }
  static const SubModelInfo& info() {
    static const SubModelInfo i = [] {
      SubModelInfo d = detail::sds_info(Slot::Rolling, "rolling", "r");
      d.history = 3;
      d.history_text = "the rolling spring xi_r (3 doubles [m], even under i <-> j)";
      return d;
    }();
    return i;
  }
  static constexpr bool lane_body = true;

  /// One step: updates h and returns the torque on i [N m] (on j: its negative); `dissipated`
  /// gains the energy lost at the rolling limit [J] (as CundallStrack::update).
  template <class T>
  __attribute__((always_inline)) V3<T> update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    V3<T> vr = cross(c.wi - c.wj, c.n) * (-c.a_red);
    V3<T> start = CundallStrack::rotate_spring(V3<T>{h[0], h[1], h[2]}, c.n);
    SliderStep<T, V3<T>> s =
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
  static TwistingSpring from(const ContactLaw& law, double k_ref) {
    const SubModelInfo& i = info();
    return {detail::key_or_default(law, i, "twisting_stiffness_ratio") * k_ref,
            detail::key_or_default(law, i, "twisting_damping_kg_s"), detail::key_or_default(law, i, "twisting_friction")};
  }
  static const SubModelInfo& info() {
    static const SubModelInfo i = [] {
      SubModelInfo d = detail::sds_info(Slot::Twisting, "twisting", "o");
      d.history = 1;
      d.history_text = "the twisting spring xi_o (1 double [m], even under i <-> j)";
      return d;
    }();
    return i;
  }
  static constexpr bool lane_body = true;

  /// One step: updates h[0] and returns the twisting force f_o [N] (torque on i: a' f_o n).
  template <class T>
  __attribute__((always_inline)) T update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    const T vo = c.a_red * dot(c.wi - c.wj, c.n);
    SliderStep<T, T> s =
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
  static bool accepts(const ContactLaw& law) { return law.twisting(); }
  static RollingTwisting from(const ContactLaw& law, double k_ref) {
    return {RollingSpring::from(law, k_ref), TwistingSpring::from(law, k_ref)};
  }
  static constexpr bool lane_body = true;

  /// One step: both springs; returns the torque on i [N m] (on j: its negative).
  template <class T>
  __attribute__((always_inline)) V3<T> update(const RollingInput<T>& c, T dt, T* h, T& dissipated) const {
    V3<T> tr = rolling.update(c, dt, h, dissipated);
    const T fo = twisting.update(c, dt, h + RollingSpring::history, dissipated);
    return tr + c.n * (c.a_red * fo);
  }
  double energy(const double* h) const { return rolling.energy(h) + twisting.energy(h + RollingSpring::history); }
};

}  // namespace dem::contact
