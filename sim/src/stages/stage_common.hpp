// Pieces shared by the stage runners (stage.cpp: run_stage, path.cpp: run_path), and the one
// stage loop both run (run_stage_loop).
#pragma once
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "dem/engine/engine.hpp"
#include "dem/core/errors.hpp"
#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/curve_file.hpp"
#include "dem/stages/protocol.hpp"

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

/// Scene numbers no physics has (|v| >= 1e30: a stiffness, damping or stress target of 1e300
/// overflows the forces), as "key = value, ..."; "" when none.
inline std::string absurd_values(const Model& model) {
  std::string big;
  for (const auto& [key, value] : material_physics(model)) {
    const double v = std::strtod(value.c_str(), nullptr);
    if (std::isfinite(v) && std::fabs(v) >= 1e30) big += (big.empty() ? "" : ", ") + key + " = " + value;
  }
  for (const auto& mode : model.protocol.modes)
    for (const auto& st : mode.path)
      for (double t : {st.sigma.x, st.sigma.y, st.sigma.z, st.pressure})
        if (!st.relative && std::fabs(t) >= 1e30)
          big += (big.empty() ? "" : ", ") + std::string("paths.") + mode.name + " stage '" + st.name + "' target " +
                 physics_number(t) + " Pa";
  return big;
}

/// The likely cause of a non-finite result: an absurd scene value, else the integration itself.
inline std::string overflow_cause(const Model& model) {
  const std::string big = absurd_values(model);
  if (!big.empty())
    return "the likely cause is " + big + ": no physical value (forces and stresses of that order overflow the "
           "doubles); give values of the order of the scene's examples (data/scenes/)";
  return "the integration diverged: the time step (integration.dt_over_tc = " + physics_number(model.dt_over_tc) +
         ") or the strain rate is too large";
}

/// A blow-up's message with the absurd scene values named first when there are any (the engine's
/// own checks blame dt or the rate, which is then not the cause).
inline std::string blow_up_message(const Model& model, const std::string& what) {
  const std::string big = absurd_values(model);
  if (big.empty() || what.find("the likely cause is") != std::string::npos) return what;
  return what + "\n     but the likely cause is " + big + ": no physical value (forces and stresses of that order "
         "overflow the doubles)";
}

/// Throws BlowUp when a measured quantity of a curve row is not finite (inf or nan): such a row
/// would be written as a result and the run end with exit 0.
inline void check_finite_measurement(const Model& model, const State& state, const Measurement& m) {
  const std::vector<std::pair<const char*, double>> values = {
      {"p_Pa", m.p}, {"sigma_xx_Pa", m.stress.xx}, {"sigma_yy_Pa", m.stress.yy}, {"sigma_zz_Pa", m.stress.zz},
      {"sigma_xy_Pa", m.stress.xy}, {"sigma_xz_Pa", m.stress.xz}, {"sigma_yz_Pa", m.stress.yz},
      {"sigma_dev_Pa", m.sigma_dev}, {"s_dev", m.s_dev}, {"s_dev_eig", m.s_dev_eig}, {"F_dev", m.F_dev},
      {"E_kin_J", m.E_kin}, {"E_pot_J", m.E_pot}, {"overlap_max_rel", m.overlap_max_rel},
      {"inertial_number", m.inertial_number}, {"eps_d", m.eps_d}, {"eps_v", m.eps_v}, {"nu", m.nu}};
  for (const auto& [name, v] : values)
    if (!std::isfinite(v))
      throw BlowUp("the measured " + std::string(name) + " is " + physics_number(v) + " at step " +
                   std::to_string(state.step) + " (not a result): " + overflow_cause(model));
}

/// What a stage loop carries from step to step whatever the stage: the engine, the curve, the
/// energy reference of the blow-up check, the largest inertial number, the last good state (the
/// state of the last row) and the steps taken.
struct StageLoop {
  const Model& model;
  State& state;
  Engine& engine;
  CurveFile& csv;
  double e_floor;
  double prev_ekin;            ///< E_kin of the last row (the blow-up check compares with it)
  State last_good;
  double max_inertial = 0;
  std::int64_t steps = 0;
  Measurement last;            ///< the last row's measurement

  /// A row's measurement at `rate`, after the engine's sanity checks, checked finite and against
  /// an explosion of the kinetic energy.
  const Measurement& measure_checked(const VelGrad& rate) {
    engine.check_sanity();
    last = measure(model, state, engine.neighbor_list(), rate);
    check_finite_measurement(model, state, last);
    check_kinetic_energy(model, state, last, e_floor, prev_ekin);
    prev_ekin = last.E_kin;
    max_inertial = std::max(max_inertial, last.inertial_number);
    return last;
  }
  /// Writes a sampled row (checked) and keeps the state as the last good one.
  void write(const std::string& row, const std::string& stage) {
    csv.row(row, stage);
    csv.check(stage);
    last_good = state;
  }
  /// After a blow-up: the curve left as .part, the last good state saved (out.failed_checkpoint,
  /// or the curve's path + ".failed.ckpt"), and the error rethrown naming both (`what`: "stage
  /// NAME" or "path LABEL").
  [[noreturn]] void fail(const BlowUp& e, const StageOutput& out, const std::string& what) {
    csv.abandon();
    const std::string failed = out.failed_checkpoint.empty() ? out.csv + ".failed.ckpt" : out.failed_checkpoint;
    write_checkpoint(failed, Checkpoint{"", "last good state of " + what, last_good});
    throw BlowUp(blow_up_message(model, e.what()) + "\n     the last good state of " + what + " was saved as " + failed);
  }
};

/// What a step decided: a sampled row now, and whether the stage ends with it.
struct StepOutcome {
  bool sample = false, done = false;
};

/// The loop of every stage (a constant velocity gradient, run_stage; a stage of a path,
/// run_path): step, let the stage judge the step (events, sampling, its stop), write the sampled
/// rows, say the progress. What differs is the Stage:
///   VelGrad next_rate()                            the velocity gradient of the next step [1/s]
///   void step_failed(const std::runtime_error&)    the engine refused the step (may throw its own error)
///   StepOutcome after_step()                       after the step
///   VelGrad row_rate() const                       the rate the row's measurement sees
///   std::string row(const Measurement&, bool& done)  the row's text; a stop judged on rows sets done
///   void progress_line(bool done)                     the progress line
///   const std::string& name() const                the stage column
template <class Stage>
void run_stage_loop(StageLoop& loop, Stage& stage) {
  bool done = false;
  while (!done) {
    try {
      loop.engine.step(stage.next_rate());
    } catch (const BlowUp&) {
      throw;
    } catch (const std::runtime_error& e) {
      stage.step_failed(e);
      throw;
    }
    ++loop.steps;
    const StepOutcome o = stage.after_step();
    done = o.done;
    if (o.sample || done) {
      const Measurement& m = loop.measure_checked(stage.row_rate());
      const std::string row = stage.row(m, done);
      loop.write(row, stage.name());
    }
    stage.progress_line(done);
  }
}

}  // namespace dem
