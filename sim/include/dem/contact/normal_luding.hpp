// Luding's elasto-plastic adhesive normal law (S. Luding, Cohesive, frictional powders: contact
// models for tension, Granular Matter 10 (2008) 235-246, sec. 2.1; YADE's LudingPM and
// MercuryDPM's LinearPlasticViscoelastic normal species follow it). A normal sub-model with
// history: the largest overlap delta_max of the contact.
#pragma once
#include <algorithm>
#include <cmath>

namespace dem::contact {

/// Hysteretic force f_hys [N] (repulsion positive) of overlap delta, pair radius
/// a12 = r_i r_j / (r_i + r_j):
///   loading (virgin) branch      f = k1 delta                     (if k2 (delta - delta0) >= k1 delta)
///   un-/reloading branch         f = k2 (delta - delta0)          (between the other two)
///   adhesive (tensile) limit     f = -kc delta                    (if k2 (delta - delta0) <= -kc delta)
/// with the plastic overlap delta0 = (1 - k1/k2) delta_max and k2 growing with delta_max from
/// k1 to kp: k2 = k1 + (kp - k1) delta_max / delta*, delta* = kp/(kp - k1) phi_f 2 a12 (phi_f:
/// the plasticity depth). delta_max never exceeds delta*: beyond it the contact is elastic on
/// the limit branch kp (delta - phi_f 2 a12) (the "fluid branch": MercuryDPM caps delta_max at
/// delta*, YADE caps delta0 at phi_f 2 a12; the same law). On the loading branch
/// delta_max = delta; on the adhesive branch delta_max moves down so that its own k2-line
/// passes through the current point (adhesive_delta_max): unloading stays exactly on -kc delta,
/// and reloading from there follows that k2-line. The contact (and its
/// history) ends when the spheres separate geometrically (delta <= 0), where the adhesive force
/// is zero: the list's skin needs no extra range. The dashpot adds gamma d(delta)/dt; there is
/// no clamp (the law bounds the tension). Scene keys: contact.normal = "luding",
/// contact.stiffness_N_m (k1), contact.luding_kp_N_m, contact.luding_kc_N_m,
/// contact.luding_plasticity_depth (phi_f).
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
    double copy = h[0];
    return update(delta, a12, &copy);
  }
  /// The force, and delta_max updated on the loading branch (up to delta*) and the adhesive limit.
  double update(double delta, double a12, double* h) const {
    const double k2 = k2_of(h[0], a12);
    const double f = k2 * (delta - (1.0 - k1 / k2) * h[0]);
    if (f >= k1 * delta) {
      const double ds = delta_star(a12);
      if (delta < ds) {
        h[0] = std::max(h[0], delta);
        return k1 * delta;
      }
      h[0] = ds;   // on the limit branch: elastic along kp from here on
      return kp * (delta - (1.0 - k1 / kp) * ds);
    }
    if (f <= -kc * delta) {
      h[0] = adhesive_delta_max(delta, a12);
      return -kc * delta;
    }
    return f;
  }
  /// The delta_max whose own k2-line passes through (delta, -kc delta): k2(h) delta -
  /// (k2(h) - k1) h = -kc delta. With k2(h) = k1 + c h (c = (kp - k1)/delta*) that is
  /// c h^2 - c delta h - (k1 + kc) delta = 0. (The peers' (k2 + kc)/(k2 - k1) delta keeps the old k2,
  /// so the next step's k2-line misses the point and the branch is not exactly -kc delta.)
  double adhesive_delta_max(double delta, double a12) const {
    const double ds = delta_star(a12), c = (kp - k1) / ds;
    const double h = 0.5 * delta + std::sqrt(0.25 * delta * delta + (k1 + kc) * delta / c);
    return h < ds ? h : (kp + kc) / (kp - k1) * delta;   // k2 = kp at and beyond delta*
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
