// Hertz's elastic normal law with Tsuji's viscoelastic damping: a normal sub-model without
// history that reads its pair beyond the geometry (`per_pair`: a12 and the reduced mass), with
// one body on lanes, so every pair kernel runs it. docs/contact_models.md has the equations,
// tests and sources.
#pragma once
#include <cmath>
#include <string>
#include <vector>

#include "dem/contact/geometry.hpp"
#include "dem/contact/submodel.hpp"
#include "dem/core/model.hpp"

namespace dem::contact {

/// No separate dashpot: the Hertz law's damping depends on the overlap and the pair's mass, so
/// it is part of HertzNormal::force.
struct NoDashpot {
  static NoDashpot from(const ContactLaw&, double = 0) { return {}; }
};

/// Hertz (1882) for two spheres of one material (Young's modulus E, Poisson ratio nu):
///   f_el = 4/3 E* sqrt(R*) delta^(3/2),  E* = E / (2 (1 - nu^2)),  R* = a12 = r_i r_j/(r_i + r_j),
/// tangent stiffness S_n = 2 E* sqrt(R* delta), elastic energy 8/15 E* sqrt(R*) delta^(5/2).
/// Damping in the form of LAMMPS' `damping tsuji` (Tsuji, Tanaka & Ishida, Powder Technol. 71
/// (1992) 239): f_d = alpha sqrt(m* k_n) d(delta)/dt with k_n = 4/3 E* sqrt(R* delta) (the
/// secant stiffness f_el/delta) and m* the pair's reduced mass. The impact then scales to one
/// dimensionless equation, so e depends on alpha alone: alpha(e) is solved from it
/// (tsuji_alpha), not taken from LAMMPS' polynomial fit, which misses e.
/// Repulsion positive, clamped at zero unless contact.allow_attractive. Scene keys:
/// contact.normal = "hertz", contact.youngs_modulus_Pa, contact.poisson_ratio, contact.restitution.
struct HertzNormal {
  double c_el;     ///< 4/3 E* [Pa]
  double e_star;   ///< E* [Pa]
  double alpha;    ///< Tsuji's damping factor alpha(e) [-]
  static constexpr int history = 0;
  static constexpr bool per_pair = true;   ///< force() reads PairLanes (a12, m_r)
  static constexpr const char* name = "hertz";
  using Damping = NoDashpot;

  static double effective_modulus(double E, double nu) { return E / (2.0 * (1.0 - nu * nu)); }
  /// LAMMPS' polynomial fit of Tsuji's alpha(e) (pair granular, `damping tsuji`), for the
  /// counterpart's input only: it does not give e (docs/contact_models.md).
  static double lammps_tsuji_alpha(double e) {
    const double c[7] = {1.2728, -4.2783, 11.087, -22.348, 27.467, -18.022, 4.8218};
    double a = 0, p = 1;
    for (double ci : c) { a += ci * p; p *= e; }
    return a;
  }
  /// The e' to give LAMMPS' `hertz/material E e' nu ... damping tsuji` so that its polynomial
  /// alpha(e') equals tsuji_alpha(e), this law's alpha (bisection; alpha(e') falls with e').
  static double lammps_restitution(double e) {
    if (e >= 1.0) return 1.0;
    const double alpha = tsuji_alpha(e);
    double lo = 0.0, hi = 1.0;
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      (lammps_tsuji_alpha(mid) > alpha ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
  }
  /// The restitution of the dimensionless impact x'' = -max(x^(3/2) + alpha x^(1/4) x', 0),
  /// x(0) = 0, x'(0) = 1 (m* = 1, 4/3 E* sqrt(R*) = 1, unit speed: every Hertz impact with
  /// Tsuji's dashpot scales to it, so e depends on alpha alone). Classical RK4, the exit
  /// speed interpolated at x = 0.
  static double restitution_of_alpha(double alpha) {
    const double h = 2e-3;
    auto acc = [alpha](double x, double u) {
      if (x <= 0) return 0.0;
      const double f = x * std::sqrt(x) + alpha * std::sqrt(std::sqrt(x)) * u;
      return f > 0 ? -f : 0.0;
    };
    double x = 0, u = 1;
    for (int step = 0; step < 1000000; ++step) {
      const double k1x = u, k1u = acc(x, u);
      const double k2x = u + 0.5 * h * k1u, k2u = acc(x + 0.5 * h * k1x, u + 0.5 * h * k1u);
      const double k3x = u + 0.5 * h * k2u, k3u = acc(x + 0.5 * h * k2x, u + 0.5 * h * k2u);
      const double k4x = u + h * k3u, k4u = acc(x + h * k3x, u + h * k3u);
      const double xn = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), un = u + h / 6 * (k1u + 2 * k2u + 2 * k3u + k4u);
      if (xn < 0 && un < 0) return -(u + (un - u) * x / (x - xn));
      x = xn; u = un;
    }
    return 0.0;
  }
  /// Tsuji's alpha that gives the restitution e, solved by bisection on the dimensionless impact
  /// (alpha(1) = 0); the last answer is kept per thread.
  static double tsuji_alpha(double e) {
    if (e >= 1.0) return 0.0;
    thread_local double last_e = -1, last_alpha = 0;
    if (e == last_e) return last_alpha;
    double lo = 0, hi = 1;
    while (restitution_of_alpha(hi) > e && hi < 64) hi *= 2;
    for (int it = 0; it < 48; ++it) {
      const double mid = 0.5 * (lo + hi);
      (restitution_of_alpha(mid) > e ? lo : hi) = mid;
    }
    last_e = e;
    last_alpha = 0.5 * (lo + hi);
    return last_alpha;
  }
  static HertzNormal from(const ContactLaw& law, double = 0) {
    const double es = effective_modulus(law.get("youngs_modulus_Pa"), law.get("poisson_ratio"));
    return {4.0 / 3.0 * es, es, tsuji_alpha(law.get("restitution"))};
  }

  /// Spring plus Tsuji's dashpot [N] (before the no-tension clamp), one body for one pair and
  /// for lanes of pairs: the overlap clamped at zero (a contact at the rounding edge), then
  /// k_n = 4/3 E* sqrt(a12 delta), f = k_n delta + alpha sqrt(m_r k_n) d(delta)/dt.
  template <class T>
  __attribute__((always_inline)) T force(const NormalGeometry<T>& g, const PairLanes<T>& p) const {
    using lanes::splat;
    const T zero = splat<T>(0.0);
    const T d = lanes::select(lanes::greater(g.delta, zero), g.delta, zero);
    const T kn = splat<T>(c_el) * lanes::sqrt(p.a12 * d);
    return kn * d + splat<T>(alpha) * lanes::sqrt(p.m_r * kn) * g.ddelta;
  }
  /// The elastic force alone [N].
  double elastic(double delta, double a12) const {
    return delta > 0 ? c_el * std::sqrt(a12 * delta) * delta : 0.0;
  }
  double energy(double delta, double a12, const double*) const {
    return delta > 0 ? 8.0 / 15.0 * e_star * std::sqrt(a12) * std::pow(delta, 2.5) : 0.0;
  }
  /// Tangent stiffness d f_el / d delta [N/m] (the servo's affine stiffness).
  double tangent_stiffness(double delta, double a12, const double*) const {
    return delta > 0 ? 2.0 * e_star * std::sqrt(a12 * delta) : 0.0;
  }

  /// Rayleigh-wave time of the smallest sphere [s] (YADE's RayleighWaveTimeStep, after Li, Xu &
  /// Thornton, Powder Technol. 160 (2005) 219): pi r sqrt(rho/G) / (0.1631 nu + 0.8766).
  static double rayleigh_time(const ContactLaw& law) {
    const double E = law.get("youngs_modulus_Pa"), nu = law.get("poisson_ratio");
    const double G = E / (2.0 * (1.0 + nu));
    return M_PI * law.scale_radius() * std::sqrt(law.scale_density() / G) / (0.1631 * nu + 0.8766);
  }
  /// The linear spring-dashpot of the smallest pair whose half-period is the Rayleigh time and
  /// whose restitution is e: what t_c, dt and the stability bound are computed from.
  struct Equivalent { double k, gamma, m_r; };
  static Equivalent equivalent(const ContactLaw& law) {
    const double r = law.scale_radius();
    const double m_r = 0.5 * 4.0 / 3.0 * M_PI * r * r * r * law.scale_density();
    const double tr = rayleigh_time(law), le = std::log(law.get("restitution"));
    return {m_r * (M_PI * M_PI + le * le) / (tr * tr), -2.0 * m_r * le / tr, m_r};
  }

  static const SubModelInfo& info();
};

inline const SubModelInfo& HertzNormal::info() {
  static const SubModelInfo i = [] {
    SubModelInfo d;
    d.slot = Slot::Normal;
    d.name = name;
    d.title = "Hertz, f_n = 4/3 E* sqrt(R*) delta^(3/2) + Tsuji's viscoelastic damping from the restitution e";
    d.reference = "Hertz 1882; Johnson, Contact Mechanics (1985) sec. 4.2; damping: Tsuji, Tanaka & Ishida, "
                  "Powder Technol. 71 (1992) 239, in the form of LAMMPS' `damping tsuji`, alpha solved for e";
    d.keys = {{"youngs_modulus_Pa", "Pa", 1e8, "", 0, 0, true,
               "E, Young's modulus of the particles' material, e.g. 7e10 (glass); E* = E/(2(1 - nu^2))"},
              {"poisson_ratio", "1", 0.3, "", -1, 0.5, true, "nu, Poisson's ratio, in (-1, 0.5], e.g. 0.3"},
              {"restitution", "1", 0.9, "", 0, 1, true,
               "e, the normal restitution coefficient the damping gives at every impact speed, in (0, 1]"}};
    d.yade = "FrictMat (young = E, poisson = nu) + Ip2_FrictMat_FrictMat_MindlinPhys (en = e) + "
             "Law2_ScGeom_MindlinPhys_Mindlin (its damping: alpha from en after Antypov 2011, not this alpha)";
    d.liggghts = "not declared: LIGGGHTS' model hertz damps with its own beta(e) (coefficientRestitution), not this "
                 "law's Tsuji alpha, so only e = 1 would match";
    d.yade_laws = [](const ContactLaw&) { return std::vector<std::string>{"mindlin"}; };
    d.yade_words = [](const ContactLaw& law) {
      return "--young " + exact_num(law.get("youngs_modulus_Pa")) + " --poisson " + exact_num(law.get("poisson_ratio")) +
             " --en " + exact_num(law.get("restitution"));
    };
    d.lammps = "pair granular: hertz/material E e' nu, damping tsuji, with e' the value whose polynomial alpha(e') "
               "equals this law's alpha (LAMMPS' fit does not give e' back)";
    d.lammps_words = [](const ContactLaw& law) {
      return "hertz/material " + exact_num(law.get("youngs_modulus_Pa")) + " " +
             exact_num(lammps_restitution(law.get("restitution"))) + " " + exact_num(law.get("poisson_ratio"));
    };
    d.lammps_tail = [](const ContactLaw& law) {
      return std::string("damping tsuji") + (law.allow_attractive() ? "" : " limit_damping");
    };
    d.vtk_fields = {"normal_force_N", "overlap_m", "normal"};
    d.describe = [](const ContactLaw& law, const PairScale& s) {
      const double es = effective_modulus(law.get("youngs_modulus_Pa"), law.get("poisson_ratio"));
      const double k = law.time_step_stiffness();
      // The overlap of the smallest pair (R* = r/2) at which the Hertz tangent stiffness equals k.
      const double delta_eq = k * k / (4.0 * es * es * 0.5 * s.r);
      return "Hertz: E* = " + g_num(es) + " Pa, e = " + g_num(law.get("restitution")) + " (Tsuji alpha = " +
             g_num(tsuji_alpha(law.get("restitution"))) + ", solved for e); t_c is the Rayleigh time " +
             g_num(rayleigh_time(law)) + " s (not the impact's duration, which depends on the speed), dt = "
             "dt_over_tc x it; its equivalent spring " + g_num(k) + " N/m is the Hertz tangent stiffness at "
             "overlap " + g_num(delta_eq / s.r) + " r_min";
    };
    d.time_step_stiffness = [](const ContactLaw& law) { return equivalent(law).k; };
    d.time_step_damping = [](const ContactLaw& law) { return equivalent(law).gamma; };
    // p* = 2<r>p/k_ref with k_ref = 2 E* r_min: p* = p/E* for equal spheres.
    d.reference_stiffness = [](const ContactLaw& law) {
      return 2.0 * effective_modulus(law.get("youngs_modulus_Pa"), law.get("poisson_ratio")) * law.scale_radius();
    };
    d.oscillators = [](const ContactLaw& law, const PairScale& s) {
      const Equivalent q = equivalent(law);
      return std::vector<Oscillator>{{"the Hertz contact of the smallest pair, linearised at its Rayleigh time "
                                      "(stiffer than the Hertz spring below an overlap of about 0.8 r_min)",
                                      s.m_r, q.k, q.gamma, "", 1.0, ""}};
    };
    d.check = [](const ContactLaw& law) -> std::string {
      if (!(law.scale_radius() > 0) || !(law.scale_density() > 0))
        return "contact.normal = \"hertz\" needs particles.radius_min_m and particles.density_kg_m3 (its Rayleigh "
               "time); the contact law was given none";
      return "";
    };
    return d;
  }();
  return i;
}

}  // namespace dem::contact
