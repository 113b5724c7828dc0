// Tangential sub-models: none (frictionless: no history, no rotations, 3 degrees of freedom per
// particle) and Cundall-Strack sliding friction (a linear tangential spring with an optional
// dashpot and a Coulomb limit; its spring is per-contact history). docs/contact_models.md has
// the equations and sources.
#pragma once
#include <cmath>

#include "dem/contact/submodel.hpp"
#include "dem/core/vec3.hpp"

namespace dem::contact {

/// What a tangential sub-model sees of a contact (scalar: frictional contacts run on the
/// reference loop): unit normal n (i to j), the relative velocity of the contact points
/// v_c = (v_j - v_i) + L d - (a_i w_i + a_j w_j) x n [m/s] (a = r - delta/2, the lever arms
/// to the middle of the overlap), and the normal force fn >= 0 [N] after the clamp.
struct TangentialInput {
  Vec3 n;
  Vec3 v_contact;
  double fn;
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
      d.lammps = "tangential linear_nohistory 0 0";
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
  static constexpr unsigned odd_mask = 0x7;  ///< history entries that change sign when i and j swap
  static constexpr const char* name = "cundall_strack";
  /// From the scene's keys; k_ref: the normal sub-model's reference stiffness [N/m].
  static CundallStrack from(const ContactLaw& law, double k_ref) {
    return {law.get("tangential_stiffness_ratio") * k_ref, law.get("tangential_damping_kg_s"), law.get("friction"),
            law.get_or("objective_spring", 1.0) != 0.0};
  }
  static const SubModelInfo& info();

  static Vec3 tangent_part(const Vec3& v, const Vec3& n) { return v - n * dot(v, n); }

  /// The spring rotated into the tangent plane of n, length kept.
  static Vec3 rotate_spring(const Vec3& xi, const Vec3& n) {
    const double len2 = dot(xi, xi);
    if (len2 == 0.0) return xi;
    const Vec3 p = tangent_part(xi, n);
    const double p2 = dot(p, p);
    return p2 > 0.0 ? p * std::sqrt(len2 / p2) : Vec3{0, 0, 0};
  }

  /// One step of the contact: updates h (xi, slip) and returns the tangential force on j [N].
  /// `dissipated` gains the energy lost to sliding [J]: the work the contact's motion did on the
  /// spring over the step (trapezoid of the spring force along the increment v_t dt, second
  /// order like the integrator) minus the change of the spring's energy; zero while sticking.
  Vec3 update(const TangentialInput& c, double dt, double* h, double* dissipated) const {
    const Vec3 vt = tangent_part(c.v_contact, c.n);
    const Vec3 old{h[0], h[1], h[2]};
    const Vec3 start = objective ? rotate_spring(old, c.n) : old;
    const Vec3 step = vt * dt;
    Vec3 xi = start + step;
    Vec3 f = xi * (-kt) - vt * gamma_t;
    const double limit = mu * c.fn, f2 = dot(f, f);
    h[3] = 0.0;
    if (f2 > limit * limit) {
      f = f * (limit / std::sqrt(f2));
      xi = (f + vt * gamma_t) * (-1.0 / kt);
      *dissipated += 0.5 * kt * (dot(start + xi, step) - dot(xi, xi) + dot(start, start));
      h[3] = 1.0;
    }
    h[0] = xi.x; h[1] = xi.y; h[2] = xi.z;
    return f;
  }

  /// The force the stored spring exerts now, without changing it (measurements: never mutate
  /// the history in a diagnostic).
  Vec3 force(const TangentialInput& c, const double* h) const {
    const Vec3 vt = tangent_part(c.v_contact, c.n);
    Vec3 f = Vec3{h[0], h[1], h[2]} * (-kt) - vt * gamma_t;
    const double limit = mu * c.fn, f2 = dot(f, f);
    if (f2 > limit * limit) f = f * (limit / std::sqrt(f2));
    return f;
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
    d.lammps = "tangential linear_history k_t x_gamma_t mu";
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
