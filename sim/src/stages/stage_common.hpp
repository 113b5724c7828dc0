// Pieces shared by the stage runners (protocol.cpp: run_stage, path.cpp: run_path).
#pragma once
#include <string>

#include "dem/engine/engine.hpp"
#include "dem/measure/measure.hpp"

namespace dem {

/// Energy of a 0.1%-of-r_min overlap per particle: the floor of energy ratios [J].
inline double energy_floor(const Model& m, const State& s) {
  const double d = 1e-3 * m.radius_min;
  return s.count() * 0.5 * m.contact.reference_stiffness() * d * d;
}

/// Above this inertial number the deviatoric response depends visibly on the strain rate.
constexpr double kQuasiStaticInertial = 1e-3;

/// Throws BlowUp when the kinetic energy of a sample exploded (1000x the elastic energy and 10x
/// the previous sample's).
inline void check_kinetic_energy(const Model& model, const State& state, const Measurement& m, double e_floor,
                                 double prev_ekin) {
  const double e_ref = std::max(m.E_pot, e_floor);
  if (m.E_kin > 1e3 * e_ref && m.E_kin > 10 * prev_ekin)
    throw BlowUp("kinetic energy exploded to " + std::to_string(m.E_kin) + " J (" + std::to_string(m.E_kin / e_ref) +
                 " x the elastic energy) at step " + std::to_string(state.step) + ": the time step (dt_over_tc = " +
                 std::to_string(model.dt_over_tc) + ") or the strain rate is too large");
}

}  // namespace dem
