// Mindlin's no-slip tangential spring with a Coulomb limit (the tangential half of
// Hertz-Mindlin), in two variants that differ only in what is kept when k_t changes with the
// overlap: the displacement ("mindlin", LAMMPS `mindlin`) or the force ("mindlin_force", the
// incremental force law of LAMMPS `mindlin/force`, YADE's Law2_ScGeom_MindlinPhys_Mindlin and
// Thornton et al. 2013, eq. 18). One body on lanes: every pair kernel runs it.
// docs/contact_models.md has the equations, tests and sources.
#pragma once
#include <cmath>
#include <string>
#include <vector>

#include "dem/contact/normal_hertz.hpp"
#include "dem/contact/slider.hpp"
#include "dem/contact/submodel.hpp"
#include "dem/contact/tangential.hpp"

namespace dem::contact {

/// Mindlin (1949) no-slip tangential stiffness k_t = 8 G* sqrt(R* delta), G* = G/(2(2 - nu)),
/// G = E/(2(1 + nu)) (E, nu: the Hertz normal law's keys; R* = a12), with the Coulomb limit
/// |f_t| <= mu f_n (the "no-slip" simplification of Mindlin & Deresiewicz). The history is the
/// tangential displacement xi [m], as Cundall-Strack stores it, rotated into the current
/// tangent plane keeping its length (objective), and the k_t of the last step. Each step:
///   kept displacement (ForceKept = false):  start = xi_old,               f = -k_t (start + v_t dt)
///   incremental force (ForceKept = true):   start = xi_old k_t,old / k_t, f = f_old - k_t v_t dt
/// (the second is the first with the stored spring rescaled so that -k_t start = f_old), then
/// one step of the slider (slider.hpp, no dashpot): sliding caps f at mu f_n and puts the spring
/// on the cone, xi = -f/k_t. At a fixed xi and a falling overlap the first gives
/// f_2/f_1 = sqrt(delta_2/delta_1), the second keeps f. History: xi (3 doubles, odd under
/// i <-> j), a slip flag, k_t of the last step [N/m] (the stored elastic energy k_t |xi|^2/2).
/// Scene keys: contact.tangential = "mindlin" or "mindlin_force", contact.friction (mu);
/// needs contact.normal = "hertz".
template <bool ForceKept>
struct MindlinLaw {
  double g8;   ///< 8 G* [Pa]
  double mu;
  static constexpr int history = 5;
  static constexpr bool rotations = true;
  static constexpr bool lane_body = true;    ///< update() runs on lanes: the vector kernels take it
  static constexpr bool per_pair = true;     ///< update() reads PairLanes (the overlap, a12)
  static constexpr unsigned odd_mask = 0x7;
  static constexpr const char* name = ForceKept ? "mindlin_force" : "mindlin";

  static double effective_shear_modulus(double E, double nu) { return E / (2.0 * (1.0 + nu)) / (2.0 * (2.0 - nu)); }
  static MindlinLaw from(const ContactLaw& law, double = 0) {
    return {8.0 * effective_shear_modulus(law.get_or("youngs_modulus_Pa", 0.0), law.get_or("poisson_ratio", 0.0)),
            law.get("friction")};
  }
  /// k_t = 8 G* sqrt(a12 delta) [N/m], the overlap clamped at zero.
  template <class T> __attribute__((always_inline)) T stiffness_of(T delta, T a12) const {
    const T zero = lanes::splat<T>(0.0);
    return lanes::splat<T>(g8) * lanes::sqrt(a12 * lanes::select(lanes::greater(delta, zero), delta, zero));
  }

  /// One step (unit normal n, contact-point velocity v_contact [m/s], normal force fn >= 0 [N],
  /// the pair p): updates h (xi, slip, k_t), adds the sliding loss to `dissipated` [J] and
  /// returns the tangential force on j [N].
  template <class T>
  __attribute__((always_inline)) V3<T> update(const V3<T>& n, const V3<T>& v_contact, T fn, T dt, T* h,
                                              T& dissipated, const PairLanes<T>& p) const {
    using lanes::splat;
    const T kt = stiffness_of(p.delta, p.a12), zero = splat<T>(0.0);
    V3<T> vt = CundallStrack::tangent_part(v_contact, n);   // not const: lanes.hpp
    V3<T> start = CundallStrack::rotate_spring(V3<T>{h[0], h[1], h[2]}, n);
    if constexpr (ForceKept) {   // the first step (k_t,old = 0) and a vanishing k_t keep xi
      const T k_old = h[4];
      start = start * lanes::select(lanes::greater(k_old * kt, zero), k_old / kt, splat<T>(1.0));
    }
    SliderStep<T, V3<T>> s = slider_step(start, vt, dt, kt, zero, splat<T>(mu) * fn);
    h[0] = s.spring.x; h[1] = s.spring.y; h[2] = s.spring.z;
    h[3] = lanes::select(s.sliding, splat<T>(1.0), zero);
    h[4] = kt;
    dissipated = dissipated + s.dissipated;
    return s.force;
  }
  /// The stiffness the stored spring acts with now: k_t at this overlap (kept displacement) or
  /// the last step's (incremental force: the stored force is -k_t,old xi).
  double acting_stiffness(const TangentialInput& c, const double* h) const {
    return ForceKept && h[4] > 0 ? h[4] : stiffness_of(c.delta, c.a12);
  }
  /// The force of the stored spring now, without changing it (capped at mu fn).
  Vec3 force(const TangentialInput& c, const double* h) const {
    Vec3 f = Vec3{h[0], h[1], h[2]} * (-acting_stiffness(c, h));
    const double limit = mu * c.fn, f2 = dot(f, f);
    if (f2 > limit * limit) f = f * (limit / std::sqrt(f2));
    return f;
  }
  double energy(const double* h) const { return 0.5 * h[4] * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]); }
  /// The servo's tangential stiffness of a sticking contact [N/m]: k_t at this overlap.
  double stiffness(const TangentialInput& c) const { return stiffness_of(c.delta, c.a12); }

  static const SubModelInfo& info();
};

using MindlinTangential = MindlinLaw<false>;
using MindlinForceTangential = MindlinLaw<true>;

template <bool ForceKept>
inline const SubModelInfo& MindlinLaw<ForceKept>::info() {
  static const SubModelInfo i = [] {
    SubModelInfo d;
    d.slot = Slot::Tangential;
    d.name = name;
    d.title = std::string("Mindlin no-slip tangential spring k_t = 8 G* sqrt(R* delta) (objective), Coulomb limit; ") +
              (ForceKept ? "incremental force (f kept when k_t changes)" : "the displacement kept when k_t changes");
    d.reference = std::string("Mindlin, J. Appl. Mech. 16 (1949) 259; no-slip simplification as in Di Renzo & Di Maio, "
                              "Chem. Eng. Sci. 59 (2004) 525") +
                  (ForceKept ? "; incremental force: Thornton, Cummins & Cleary, Powder Technol. 233 (2013) 30, eq. 18"
                             : "");
    d.keys = {{"friction", "1", 0.0, "", 0, 0, false, "mu, the Coulomb coefficient, e.g. 0.5"}};
    d.history = history;
    d.history_text = "the displacement xi (3 doubles [m], odd under i <-> j), a slip flag, the last k_t [N/m]";
    d.rotations = true;
    d.yade = ForceKept ? "FrictMat (young = E, poisson = nu, frictionAngle = atan(mu)) + Ip2_FrictMat_FrictMat_MindlinPhys "
                         "+ Law2_ScGeom_MindlinPhys_Mindlin (incremental shear force)"
                       : "none (YADE's Law2_ScGeom_MindlinPhys_Mindlin is incremental: use \"mindlin_force\")";
    d.liggghts = "not declared (LIGGGHTS' tangential history with model hertz; no benchmark uses it)";
    if (ForceKept) {
      d.yade_laws = [](const ContactLaw&) { return std::vector<std::string>{"mindlin"}; };
      d.yade_words = [](const ContactLaw& law) { return "--friction " + exact_num(law.get("friction")); };
    }
    d.lammps = ForceKept ? "tangential mindlin/force NULL 0 mu (k_t from E and nu, no tangential damping)"
                         : "tangential mindlin NULL 0 mu (k_t from E and nu, no tangential damping)";
    d.lammps_words = [](const ContactLaw& law) {
      return std::string(ForceKept ? "tangential mindlin/force" : "tangential mindlin") + " NULL 0 " +
             exact_num(law.get("friction"));
    };
    d.column_groups = {"rotations"};
    d.vtk_fields = {"sliding", "tangential_force_N"};
    d.describe = [](const ContactLaw& law, const PairScale&) {
      const double E = law.get_or("youngs_modulus_Pa", 0.0), nu = law.get_or("poisson_ratio", 0.0);
      const double gs = effective_shear_modulus(E, nu);
      return "Mindlin no-slip, mu = " + g_num(law.get("friction")) + ", G* = " + g_num(gs) +
             " Pa (k_t = 8 G* sqrt(R* delta), k_t/S_n = 4 G*/E* = " + g_num(4.0 * gs / HertzNormal::effective_modulus(E, nu)) +
             " of the Hertz tangent stiffness); " +
             (ForceKept ? "the force kept when k_t changes (incremental)" : "the displacement kept when k_t changes") +
             "; rotations on";
    };
    d.oscillators = [](const ContactLaw& law, const PairScale& s) {
      // At a given overlap k_t/S_n = 4 G*/E* <= 1 (nu in [0, 0.5]): the contact point (effective
      // mass 2/7 m_r) against k_t = (4 G*/E*) k, k the Hertz law's Rayleigh-equivalent spring.
      const double E = law.get_or("youngs_modulus_Pa", 0.0), nu = law.get_or("poisson_ratio", 0.0);
      const double ratio = 4.0 * effective_shear_modulus(E, nu) / HertzNormal::effective_modulus(E, nu);
      return std::vector<Oscillator>{{"the Mindlin tangential spring of the smallest pair's contact point (effective "
                                      "mass 2/7 m_r, k_t = 4 G*/E* of the normal's equivalent spring)",
                                      2.0 / 7.0 * s.m_r, ratio * law.time_step_stiffness(), 0.0, "", 1.0, ""}};
    };
    d.check = [](const ContactLaw& law) -> std::string {
      if (law.model(Slot::Normal) != HertzNormal::name)
        return std::string("contact.tangential = \"") + name + "\" needs contact.normal = \"hertz\" (k_t = 8 G* "
               "sqrt(R* delta) takes G* from contact.youngs_modulus_Pa and contact.poisson_ratio); use "
               "\"cundall_strack\" with \"" + law.model(Slot::Normal) + "\"";
      return "";
    };
    return d;
  }();
  return i;
}

}  // namespace dem::contact
