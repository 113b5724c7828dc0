// Tangential sub-models: none (frictionless: no history, no rotations, 3 degrees of freedom per
// particle) and Cundall-Strack sliding friction (a linear tangential spring with an optional
// dashpot and a Coulomb limit; its spring is per-contact history). docs/contact_models.md has
// the equations and sources.
#pragma once
#include <cmath>
#include <stdexcept>

#include "dem/contact/submodel.hpp"
#include "dem/contact/slider.hpp"
#include "dem/core/vec3.hpp"

namespace dem::contact {

/// What a tangential sub-model's `force` sees of a contact (the measurements): unit normal
/// n (i to j), the relative velocity of the contact points v_c = (v_j - v_i) + L d - (a_i w_i + a_j w_j) x n [m/s] (a = r - delta/2, the lever arms
/// to the middle of the overlap), the normal force fn >= 0 [N] after the clamp, and for a
/// per-pair law (Mindlin) the overlap delta [m] and a12 = r_i r_j/(r_i + r_j) [m].
struct TangentialInput {
  Vec3 n;
  Vec3 v_contact;
  double fn;
  double delta = 0;
  double a12 = 0;
};

/// Frictionless: no tangential force.
struct NoTangential {
  static constexpr int history = 0;          ///< doubles of per-contact history
  static constexpr bool rotations = false;   ///< needs angular velocities and torques
  static constexpr const char* name = "none";
  static NoTangential from(const ContactLaw&, double) { return {}; }
  static const SubModelInfo& info() {
    static const SubModelInfo i = [] {
      SubModelInfo d;
      d.slot = Slot::Tangential;
      d.name = name;
      d.title = "frictionless: no tangential force, no rotations (3 degrees of freedom per particle)";
      d.yade = "FrictMat with frictionAngle = 0 and blockedDOFs = \"XYZ\", or ViscElMat with ks = cs = 0";
      d.yade_words = [](const ContactLaw&) { return std::string(); };   // run_mode.py's default: --friction 0
      d.lammps = "tangential linear_nohistory 0 0";
      d.lammps_words = [](const ContactLaw&) { return std::string("tangential linear_nohistory 0 0"); };
      d.liggghts = "pair gran: tangential no_history with kt = gammat_abs = coefficientFriction = 0";
      d.liggghts_words = [](const ContactLaw&) { return std::string("tangential no_history"); };
      d.liggghts_properties = [](const ContactLaw&) {
        return std::vector<std::string>{"kt 0", "gammat_abs 0", "coefficientFriction 0"};
      };
      d.describe = [](const ContactLaw&, const PairScale&) { return std::string("frictionless, no rotations"); };
      return d;
    }();
    return i;
  }
};

/// Cundall-Strack (1979) sliding friction as in Luding (2008), eqs. 17-21, and LAMMPS'
/// `tangential linear_history`: the spring is stored as a displacement xi [m]; each step it is
/// first rotated into the current tangent plane keeping its length (xi - (xi.n)n, rescaled to
/// |xi|: objective, the spring's energy is unchanged by a rigid rotation of the pair), then
/// advanced by v_t dt. The trial force f* = -k_t xi - gamma_t v_t [N on j]; if
/// |f*| > mu fn the force is f* scaled to mu fn (sliding) and the spring is reset to the cone,
/// xi = -(f + gamma_t v_t)/k_t. History: xi (3 doubles, odd under i <-> j) and a slip flag.
/// The energy lost to sliding is accumulated (W_friction); the tangential dashpot's is not.
/// Scene keys: contact.tangential = "cundall_strack", contact.friction (mu),
/// contact.tangential_stiffness_ratio (k_t/k), contact.tangential_damping_kg_s (gamma_t).
struct CundallStrack {
  double kt;        ///< [N/m]
  double gamma_t;   ///< [kg/s]
  double mu;        ///< Coulomb coefficient
  bool objective = true;   ///< false: no rotation of the spring (the tests' mutation check)
  static constexpr int history = 4;          ///< xi_x, xi_y, xi_z [m], slipping (0/1)
  static constexpr bool rotations = true;
  static constexpr bool lane_body = true;    ///< update() runs on lanes: the vector kernels take it
  static constexpr unsigned odd_mask = 0x7;  ///< history entries that change sign when i and j swap
  static constexpr const char* name = "cundall_strack";
  /// From the scene's keys; k_ref: the normal sub-model's reference stiffness [N/m].
  static CundallStrack from(const ContactLaw& law, double k_ref) {
    return {law.get("tangential_stiffness_ratio") * k_ref, law.get("tangential_damping_kg_s"), law.get("friction"),
            law.get_or("objective_spring", 1.0) != 0.0};
  }
  static const SubModelInfo& info();

  template <class T>
  __attribute__((always_inline)) static V3<T> tangent_part(const V3<T>& v, const V3<T>& n) {
    return v - n * dot(v, n);
  }

  /// The spring rotated into the tangent plane of n, length kept (a zero spring stays as it is;
  /// one along n, which has no tangent direction, becomes zero).
  template <class T>
  __attribute__((always_inline)) static V3<T> rotate_spring(const V3<T>& xi, const V3<T>& n) {
    const T zero = lanes::splat<T>(0.0);
    const T len2 = dot(xi, xi);
    V3<T> p = tangent_part(xi, n);
    const T p2 = dot(p, p);
    V3<T> rotated = pick(lanes::greater(p2, zero), p * lanes::sqrt(len2 / p2), V3<T>{zero, zero, zero});
    return pick(lanes::equal(len2, zero), xi, rotated);
  }

  /// One step of the contact (unit normal n from i to j, relative velocity of the contact points
  /// v_contact [m/s], normal force fn >= 0 [N]): updates h (xi, slip), adds the energy lost to
  /// sliding to `dissipated` [J] and returns the tangential force on j [N]. The spring is
  /// rotated (objective), then one step of the slider (slider.hpp) with the tangential velocity.
  template <class T>
  __attribute__((always_inline)) V3<T> update(const V3<T>& n, const V3<T>& v_contact, T fn, T dt, T* h,
                                              T& dissipated) const {
    V3<T> vt = tangent_part(v_contact, n);
    V3<T> old{h[0], h[1], h[2]};
    V3<T> start = objective ? rotate_spring(old, n) : old;
    SliderStep<T, V3<T>> s =
        slider_step(start, vt, dt, lanes::splat<T>(kt), lanes::splat<T>(gamma_t), lanes::splat<T>(mu) * fn);
    h[0] = s.spring.x; h[1] = s.spring.y; h[2] = s.spring.z;
    h[3] = lanes::select(s.sliding, lanes::splat<T>(1.0), lanes::splat<T>(0.0));
    dissipated = dissipated + s.dissipated;
    return s.force;
  }

  /// The force the stored spring exerts now, without changing it (measurements: never mutate
  /// the history in a diagnostic): the slider over a step of zero length.
  Vec3 force(const TangentialInput& c, const double* h) const {
    const V3<double> vt = tangent_part(v3(c.v_contact), v3(c.n));
    return vec3(slider_step(V3<double>{h[0], h[1], h[2]}, vt, 0.0, kt, gamma_t, mu * c.fn).force);
  }

  double energy(const double* h) const { return 0.5 * kt * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]); }
  double stiffness() const { return kt; }
};

inline const SubModelInfo& CundallStrack::info() {
  static const SubModelInfo i = [] {
    SubModelInfo d;
    d.slot = Slot::Tangential;
    d.name = name;
    d.title = "Cundall-Strack sliding friction: linear tangential spring (objective), optional dashpot, Coulomb limit";
    d.reference = "Cundall & Strack, Geotechnique 29 (1979) 47; Luding, Granular Matter 10 (2008) 235, eqs. 17-21";
    d.keys = {{"friction", "1", 0.0, "", 0, 0, false, "mu, the Coulomb coefficient, e.g. 0.5 (a value > 0 alone selects "
                                                      "cundall_strack)"},
              {"tangential_stiffness_ratio", "1", 2.0 / 7.0, "", 0, 10, true,
               "k_t/k, in (0, 10]; 2/7 gives the tangential oscillation the normal one's period"},
              {"tangential_damping_kg_s", "kg/s", 0.0, "", 0, 0, false, "gamma_t, the tangential dashpot, e.g. 0"}};
    d.implied_by = "friction";
    d.history = history;
    d.history_text = "the spring xi (3 doubles [m], odd under i <-> j) and a slip flag";
    d.rotations = true;
    d.yade = "FrictMat (young = k/r, poisson = k_t/k, frictionAngle = atan(mu)) + Law2_ScGeom_FrictPhys_CundallStrack";
    // run_mode.py: FrictMat + CundallStrack only (ViscEl's periodic shift velocity is wrong in a
    // deforming cell, docs/yade.md); FrictPhys has no tangential dashpot
    d.yade_laws = [](const ContactLaw&) { return std::vector<std::string>{"frictphys"}; };
    d.yade_words = [](const ContactLaw& law) {
      if (law.get("tangential_damping_kg_s") > 0)
        throw std::invalid_argument("contact.tangential_damping_kg_s > 0 has no counterpart in yade_ref/run_mode.py: "
                                    "FrictPhys has no tangential dashpot (set it to 0 for the YADE comparison)");
      return "--friction " + exact_num(law.get("friction")) + " --kt-ratio " +
             exact_num(law.get("tangential_stiffness_ratio")) + " --gamma-t 0";
    };
    d.lammps = "tangential linear_history k_t x_gamma_t mu";
    d.liggghts = "pair gran: tangential history (with model hooke/stiffness: kt, gammat_abs, coefficientFriction)";
    d.liggghts_words = [](const ContactLaw&) { return std::string("tangential history"); };
    d.liggghts_properties = [](const ContactLaw& law) {
      return std::vector<std::string>{
          "kt " + exact_num(law.get("tangential_stiffness_ratio") * law.reference_stiffness()),
          "gammat_abs " + exact_num(law.get("tangential_damping_kg_s")), "coefficientFriction " + exact_num(law.get("friction"))};
    };
    // x_gamma_t is LAMMPS' tangential dashpot as a multiple of the normal one's (damping velocity)
    d.lammps_words = [](const ContactLaw& law) {
      const double gt = law.get("tangential_damping_kg_s"), gn = law.get_or("damping_kg_s", 0.0);
      if (gt > 0 && !(gn > 0))
        throw std::invalid_argument("contact.tangential_damping_kg_s > 0 with no normal dashpot has no LAMMPS "
                                    "counterpart (x_gamma_t multiplies the normal dashpot)");
      return "tangential linear_history " + exact_num(law.get("tangential_stiffness_ratio") * law.reference_stiffness()) +
             " " + exact_num(gt > 0 ? gt / gn : 0.0) + " " + exact_num(law.get("friction"));
    };
    d.column_groups = {"rotations"};
    d.vtk_fields = {"sliding", "tangential_force_N"};
    d.describe = [](const ContactLaw& law, const PairScale& s) {
      const double kt = law.get("tangential_stiffness_ratio") * s.k_ref;
      return "Cundall-Strack, mu = " + g_num(law.get("friction")) + ", k_t = " + g_num(kt) + " N/m (k_t/k = " +
             g_num(law.get("tangential_stiffness_ratio")) + "), gamma_t = " + g_num(law.get("tangential_damping_kg_s")) +
             " kg/s; tangential half-period pi sqrt(2 m_r/(7 k_t)) = " + g_num(M_PI * std::sqrt(2.0 * s.m_r / (7.0 * kt))) +
             " s; rotations on (6 degrees of freedom)";
    };
    d.oscillators = [](const ContactLaw& law, const PairScale& s) {
      // The contact point of two equal spheres: 1/m_eff = 1/m_r + a^2/I_i + a^2/I_j = 7/(2 m_r).
      return std::vector<Oscillator>{{"the tangential spring-dashpot of the smallest pair's contact point "
                                      "(effective mass 2/7 m_r)", 2.0 / 7.0 * s.m_r,
                                      law.get("tangential_stiffness_ratio") * s.k_ref, law.get("tangential_damping_kg_s"),
                                      "tangential_stiffness_ratio", s.k_ref, "tangential_damping_kg_s"}};
    };
    return d;
  }();
  return i;
}

}  // namespace dem::contact
