// Luding's elasto-plastic adhesive normal law (S. Luding, Cohesive, frictional powders: contact
// models for tension, Granular Matter 10 (2008) 235-246, sec. 2.1; YADE's LudingPM and
// MercuryDPM's LinearPlasticViscoelastic normal species follow it). A normal sub-model with
// history: the largest overlap delta_max of the contact.
#pragma once
#include <algorithm>
#include <cmath>

#include "dem/contact/normal_linear.hpp"
#include "dem/contact/submodel.hpp"
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
  static constexpr const char* name = "luding";
  using Damping = LinearDashpot;
  static LudingNormal from(const ContactLaw& law, double = 0) {
    return {law.get("stiffness_N_m"), law.get("luding_kp_N_m"), law.get("luding_kc_N_m"),
            law.get("luding_plasticity_depth")};
  }
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
  /// The servo's affine stiffness of a contact [N/m]
  /// (k2 of the contact's delta_max, k1 <= k2 <= kp: its un-/reloading stiffness. An upper bound of
  /// the response on any branch but the adhesive one, so that a dead-beat servo never overshoots:
  /// with k1 the servo's gain was up to kp/k1 = 5x too high on reloaded contacts, docs/control.md.)
  double tangent_stiffness(double, double a12, const double* h) const { return h ? k2_of(h[0], a12) : k1; }

  static const SubModelInfo& info() {
    static const SubModelInfo i = [] {
      SubModelInfo d;
      d.slot = Slot::Normal;
      d.name = name;
      d.title = "Luding's elasto-plastic adhesive law (loading k1, un-/reloading k2 up to kp, adhesion -kc delta)";
      d.reference = "S. Luding, Granular Matter 10 (2008) 235, sec. 2.1";
      d.keys = {{"stiffness_N_m", "N/m", 1e8, "", 0, 0, true, "k1, the loading (virgin) branch's stiffness, e.g. 1e8"},
                {"damping_kg_s", "kg/s", 1.0, "", 0, 0, false, "gamma, the normal dashpot's viscosity, e.g. 1"},
                {"luding_kp_N_m", "N/m", 5.0, "stiffness_N_m", 0, 0, true,
                 "kp, the un-/reloading limit stiffness (> k1; default 5 k1)"},
                {"luding_kc_N_m", "N/m", 0.0, "", 0, 0, false, "kc, the adhesive stiffness (0: no adhesion)"},
                {"luding_plasticity_depth", "1", 0.05, "", 0, 1, true,
                 "phi_f, the plastic overlap depth as a fraction of 2 a12, in (0, 1], e.g. 0.05"}};
      d.history = 1;
      d.history_text = "delta_max [m], even under i <-> j";
      d.yade = "LudingMat + Law2_ScGeom_LudingPhys_Basic (its periodic shift velocity is wrong in a deforming cell: "
               "compare pair by pair)";
      d.lammps = "none (pair granular has no elasto-plastic adhesive normal law; the closest is jkr or dmt)";
      d.liggghts = "none (pair gran's cohesion models are not Luding's elasto-plastic law)";
      d.vtk_fields = {"delta_max_m"};
      d.describe = [](const ContactLaw& law, const PairScale&) {
        const double k1 = law.get("stiffness_N_m"), kp = law.get("luding_kp_N_m"), kc = law.get("luding_kc_N_m");
        return "Luding elasto-plastic adhesive: k1 = " + g_num(k1) + ", kp = " + g_num(kp) + ", kc = " + g_num(kc) +
               " N/m, phi_f = " + g_num(law.get("luding_plasticity_depth")) + ", gamma = " +
               g_num(law.get("damping_kg_s")) + " kg/s (t_c and dt from kp); restitution without adhesion "
               "sqrt(k1/k2): from 1 (small impacts) down to sqrt(k1/kp) = " + g_num(std::sqrt(k1 / kp)) +
               " at delta_max = delta*, then back towards 1 (elastic limit branch kp); " +
               (kc > 0 ? "tension limited by the adhesive branch -kc delta" : "no tension (kc = 0)");
      };
      d.time_step_stiffness = [](const ContactLaw& law) { return law.get("luding_kp_N_m"); };
      d.time_step_damping = [](const ContactLaw& law) { return law.get("damping_kg_s"); };
      d.reference_stiffness = [](const ContactLaw& law) { return law.get("stiffness_N_m"); };
      d.oscillators = [](const ContactLaw& law, const PairScale& s) {
        return std::vector<Oscillator>{{"the normal spring-dashpot of the smallest pair on its stiffest branch (kp)",
                                        s.m_r, law.get("luding_kp_N_m"), law.get("damping_kg_s"), "luding_kp_N_m",
                                        1.0, "damping_kg_s"}};
      };
      d.check = [](const ContactLaw& law) -> std::string {
        if (!(law.get("luding_kp_N_m") > law.get("stiffness_N_m")))
          return "contact.luding_kp_N_m must exceed contact.stiffness_N_m (k1, the loading stiffness), e.g. 5 k1";
        return "";
      };
      return d;
    }();
    return i;
  }
};

}  // namespace dem::contact
