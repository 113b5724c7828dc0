// Luding's elasto-plastic adhesive normal law (S. Luding, Cohesive, frictional powders: contact
// models for tension, Granular Matter 10 (2008) 235-246, sec. 2.1; YADE's LudingPM and
// MercuryDPM's LinearPlasticViscoelastic normal species follow it). A normal sub-model with
// history: the largest overlap delta_max of the contact.
#pragma once
#include <algorithm>

namespace dem::contact {

/// Hysteretic force f_hys [N] (repulsion positive) of overlap delta, pair radius
/// a12 = r_i r_j / (r_i + r_j):
///   loading (virgin) branch      f = k1 delta                     (if k2 (delta - delta0) >= k1 delta)
///   un-/reloading branch         f = k2 (delta - delta0)          (between the other two)
///   adhesive (tensile) limit     f = -kc delta                    (if k2 (delta - delta0) <= -kc delta)
/// with the plastic overlap delta0 = (1 - k1/k2) delta_max and k2 growing with delta_max from
/// k1 to kp: k2 = k1 + (kp - k1) delta_max / delta*_max below delta*_max = kp/(kp - k1) phi_f 2 a12,
/// kp above (phi_f: the plasticity depth). On the loading branch delta_max = delta; on the
/// adhesive branch delta_max = (k2 + kc)/(k2 - k1) delta, so unloading and reloading from there
/// follow a k2-line through the current point. The contact (and its history) ends when the
/// spheres separate geometrically (delta <= 0), where the adhesive force is zero: the list's
/// skin needs no extra range. The dashpot adds gamma d(delta)/dt; there is no clamp (the law
/// bounds the tension). Scene keys: contact.normal = "luding", contact.stiffness_N_m (k1),
/// contact.luding_kp_N_m, contact.luding_kc_N_m, contact.luding_plasticity_depth (phi_f).
struct LudingNormal {
  double k1, kp, kc, phi_f;
  static constexpr int history = 1;   ///< delta_max [m] (even under i <-> j)

  double delta_star(double a12) const { return kp / (kp - k1) * phi_f * 2.0 * a12; }
  double k2_of(double delta_max, double a12) const {
    const double ds = delta_star(a12);
    return delta_max >= ds ? kp : k1 + (kp - k1) * delta_max / ds;
  }
  /// The force at overlap delta with the stored delta_max, without changing it.
  double force(double delta, double a12, const double* h) const {
    const double k2 = k2_of(h[0], a12);
    const double delta0 = (1.0 - k1 / k2) * h[0];
    return std::clamp(k2 * (delta - delta0), -kc * delta, k1 * delta);
  }
  /// The force, and delta_max updated on the loading branch and the adhesive limit.
  double update(double delta, double a12, double* h) const {
    const double k2 = k2_of(h[0], a12);
    const double f = k2 * (delta - (1.0 - k1 / k2) * h[0]);
    if (f >= k1 * delta) {
      h[0] = std::max(h[0], delta);
      return k1 * delta;
    }
    if (f <= -kc * delta) {
      h[0] = (k2 + kc) / (k2 - k1) * delta;
      return -kc * delta;
    }
    return f;
  }
  /// The energy the contact would give back unloading along its k2-line [J].
  double energy(double delta, double a12, const double* h) const {
    const double k2 = k2_of(h[0], a12);
    const double d = delta - (1.0 - k1 / k2) * h[0];
    return 0.5 * k2 * d * d;
  }
  double stiffness() const { return kp; }
};

}  // namespace dem::contact
