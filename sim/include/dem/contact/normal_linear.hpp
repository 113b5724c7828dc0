// Normal sub-models: the linear spring (normal), the linear dashpot (damping) and the no-tension
// clamp of their sum. Luding-group defaults: k = 1e8 N/m, gamma = 1 kg/s (not mass-scaled).
#pragma once
#include <cmath>

#include "dem/contact/geometry.hpp"
#include "dem/contact/submodel.hpp"
#include "dem/core/model.hpp"

namespace dem::contact {

/// f = gamma d(delta)/dt [N] (constant viscosity). Scene key: contact.damping_kg_s.
/// With the spring: t_c = pi / sqrt(k/m_r - (gamma/2m_r)^2), e = exp(-gamma t_c / 2m_r)
/// (pair_collision in model.hpp).
struct LinearDashpot {
  double gamma;
  static LinearDashpot from(const ContactLaw& law, double = 0) { return {law.get("damping_kg_s")}; }
  template <class T> struct Bound {
    T gamma;
    __attribute__((always_inline)) T force(const NormalGeometry<T>& g) const { return gamma * g.ddelta; }
  };
  template <class T> Bound<T> bind() const { return {lanes::splat<T>(gamma)}; }
};

/// f = k delta [N]. Energy k delta^2 / 2 [J]; tangent stiffness k [N/m].
/// Scene keys: contact.stiffness_N_m, contact.damping_kg_s (its dashpot).
struct LinearSpring {
  double k;
  static constexpr int history = 0;
  static constexpr const char* name = "linear";
  using Damping = LinearDashpot;
  static LinearSpring from(const ContactLaw& law, double = 0) { return {law.get("stiffness_N_m")}; }
  /// The sub-model with its parameters in lanes (bound once, outside a kernel's loop).
  template <class T> struct Bound {
    T k;
    __attribute__((always_inline)) T force(const NormalGeometry<T>& g) const { return k * g.delta; }
  };
  template <class T> Bound<T> bind() const { return {lanes::splat<T>(k)}; }
  double energy(double delta) const { return 0.5 * k * delta * delta; }
  double stiffness() const { return k; }
  /// Tangent stiffness of a contact [N/m] (the servo's affine stiffness).
  double tangent_stiffness(double, double, const double*) const { return k; }

  static const SubModelInfo& info() {
    static const SubModelInfo i = [] {
      SubModelInfo d;
      d.slot = Slot::Normal;
      d.name = name;
      d.title = "linear spring-dashpot, f_n = k delta + gamma d(delta)/dt";
      d.reference = "Cundall & Strack 1979; Luding, Granular Matter 10 (2008) 235, eq. 2";
      d.keys = {{"stiffness_N_m", "N/m", 1e8, "", 0, 0, true, "k, the normal spring stiffness, e.g. 1e8"},
                {"damping_kg_s", "kg/s", 1.0, "", 0, 0, false,
                 "gamma, the normal dashpot's constant viscosity (not mass-scaled), e.g. 1"}};
      d.yade = "ViscElMat + Law2_ScGeom_ViscElPhys_Basic (kn, cn); in a deforming cell FrictMat with young = k/r "
               "+ Law2_ScGeom_FrictPhys_CundallStrack (no dashpot)";
      // run_mode.py: ViscElMat (kn, cn); without a dashpot also FrictMat (FrictPhys has none)
      d.yade_laws = [](const ContactLaw& law) {
        return law.get("damping_kg_s") > 0 ? std::vector<std::string>{"viscel"}
                                           : std::vector<std::string>{"viscel", "frictphys"};
      };
      d.yade_words = [](const ContactLaw& law) {
        return "--k " + exact_num(law.get("stiffness_N_m")) + " --gamma " + exact_num(law.get("damping_kg_s"));
      };
      d.lammps = "pair granular: hooke k gamma, damping velocity";
      d.liggghts = "pair gran: model hooke/stiffness, kn, gamman_abs (absolute_damping on)";
      d.liggghts_words = [](const ContactLaw&) { return std::string("model hooke/stiffness"); };
      d.liggghts_tail = [](const ContactLaw& law) {   // limitForce: ours' no-tension clamp
        return std::string("absolute_damping on") + (law.allow_attractive() ? "" : " limitForce on");
      };
      d.liggghts_properties = [](const ContactLaw& law) {
        return std::vector<std::string>{"kn " + exact_num(law.get("stiffness_N_m")),
                                        "gamman_abs " + exact_num(law.get("damping_kg_s"))};
      };
      d.lammps_words = [](const ContactLaw& law) {
        return "hooke " + exact_num(law.get("stiffness_N_m")) + " " + exact_num(law.get("damping_kg_s"));
      };
      // limit_damping: LAMMPS' no-tension clamp, ours' default (contact.allow_attractive = false)
      d.lammps_tail = [](const ContactLaw& law) {
        return std::string("damping velocity") + (law.allow_attractive() ? "" : " limit_damping");
      };
      d.vtk_fields = {"normal_force_N", "overlap_m", "normal"};
      d.describe = [](const ContactLaw& law, const PairScale&) {
        return "linear spring-dashpot: k = " + g_num(law.get("stiffness_N_m")) + " N/m, gamma = " +
               g_num(law.get("damping_kg_s")) + " kg/s";
      };
      d.time_step_stiffness = [](const ContactLaw& law) { return law.get("stiffness_N_m"); };
      d.time_step_damping = [](const ContactLaw& law) { return law.get("damping_kg_s"); };
      d.reference_stiffness = d.time_step_stiffness;
      d.oscillators = [](const ContactLaw& law, const PairScale& s) {
        return std::vector<Oscillator>{{"the normal spring-dashpot of the smallest pair", s.m_r,
                                        law.get("stiffness_N_m"), law.get("damping_kg_s"), "stiffness_N_m", 1.0,
                                        "damping_kg_s"}};
      };
      return d;
    }();
    return i;
  }
};

}  // namespace dem::contact
