// Luding's elasto-plastic adhesive normal law (S. Luding, Cohesive, frictional powders: contact
// models for tension, Granular Matter 10 (2008) 235-246, sec. 2.1; YADE's LudingPM and
// MercuryDPM's LinearPlasticViscoelastic normal species follow it). A normal sub-model with
// history: the largest overlap delta_max of the contact.
#pragma once
#include <algorithm>
#include <cmath>

#include "dem/contact/lanes.hpp"

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
  static constexpr bool lane_body = true;   ///< update() runs on lanes: the vector kernels take it

  // Every function below is one body for one pair (T = double) and for lanes of pairs: branches
  // are picks, the operations those of the scalar law in its order.
  template <class T> __attribute__((always_inline)) T delta_star(T a12) const {
    using lanes::splat;
    return splat<T>(kp) / (splat<T>(kp) - splat<T>(k1)) * splat<T>(phi_f) * splat<T>(2.0) * a12;
  }
  template <class T> __attribute__((always_inline)) T k2_of(T delta_max, T a12) const {
    using lanes::splat;
    const T ds = delta_star(a12);
    return lanes::select(lanes::greater_equal(delta_max, ds), splat<T>(kp),
                         splat<T>(k1) + (splat<T>(kp) - splat<T>(k1)) * delta_max / ds);
  }
  /// The force at overlap delta with the stored delta_max, without changing it.
  template <class T> T force(T delta, T a12, const T* h) const {
    T copy = h[0];
    return update(delta, a12, &copy);
  }
  /// The force, and delta_max updated on the loading branch (up to delta*) and the adhesive limit.
  template <class T> __attribute__((always_inline)) T update(T delta, T a12, T* h) const {
    using lanes::select;
    using lanes::splat;
    const T h0 = h[0], K1 = splat<T>(k1), Kp = splat<T>(kp), one = splat<T>(1.0);
    const T k2 = k2_of(h0, a12);
    const T f = k2 * (delta - (one - K1 / k2) * h0);
    const T k1d = K1 * delta, kcd = -splat<T>(kc) * delta;
    const auto loading = lanes::greater_equal(f, k1d);
    const auto adhesive = lanes::less_equal(f, kcd);
    const T ds = delta_star(a12);
    const auto below = lanes::less(delta, ds);
    // on the limit branch beyond delta*: elastic along kp from there on
    const T h_load = select(below, select(lanes::less(h0, delta), delta, h0), ds);
    const T f_load = select(below, k1d, Kp * (delta - (one - K1 / Kp) * ds));
    h[0] = select(loading, h_load, select(adhesive, adhesive_delta_max(delta, a12), h0));
    return select(loading, f_load, select(adhesive, kcd, f));
  }
  /// The delta_max whose own k2-line passes through (delta, -kc delta): k2(h) delta -
  /// (k2(h) - k1) h = -kc delta. With k2(h) = k1 + c h (c = (kp - k1)/delta*) that is
  /// c h^2 - c delta h - (k1 + kc) delta = 0. (The peers' (k2 + kc)/(k2 - k1) delta keeps the old k2,
  /// so the next step's k2-line misses the point and the branch is not exactly -kc delta.)
  template <class T> __attribute__((always_inline)) T adhesive_delta_max(T delta, T a12) const {
    using lanes::splat;
    const T ds = delta_star(a12), c = (splat<T>(kp) - splat<T>(k1)) / ds;
    const T h = splat<T>(0.5) * delta +
                lanes::sqrt(splat<T>(0.25) * delta * delta + (splat<T>(k1) + splat<T>(kc)) * delta / c);
    // k2 = kp at and beyond delta*
    return lanes::select(lanes::less(h, ds), h,
                         (splat<T>(kp) + splat<T>(kc)) / (splat<T>(kp) - splat<T>(k1)) * delta);
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
