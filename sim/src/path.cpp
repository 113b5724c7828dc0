// Loading paths: stages in order from one state, each with its control (prescribed strain
// rate, stress servo) and stop condition, written as one curve.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "dem/checks.hpp"
#include "dem/control.hpp"
#include "dem/curve_file.hpp"
#include "dem/io.hpp"
#include "dem/protocol.hpp"
#include "stage_common.hpp"

namespace dem {

const std::vector<std::string>& path_columns() {
  static const std::vector<std::string> cols = {"rate_xx_1_s",  "rate_yy_1_s",  "rate_zz_1_s", "target_xx_Pa",
                                                "target_yy_Pa", "target_zz_Pa", "target_p_Pa", "control_error_rel",
                                                "eps_d_accumulated"};
  return cols;
}

namespace {

// A stage with its relative targets resolved to pascals and its time stop in seconds.
PathStage resolve(const PathStage& s, double p0) {
  PathStage r = s;
  if (s.relative) { r.sigma = s.sigma * p0; r.pressure = s.pressure * p0; }
  if (s.until_relative) r.until = s.until * p0;
  return r;
}

// The stop value of a stage now: strain stops from the box, p and s_dev from the last response.
struct StopProbe {
  const PathStage& stage;
  Vec3 strain0;       // true strain (since the path start) at the stage start
  double time0;

  bool landable() const {   // linear in the step's rate scale, so the last step can land on it
    return !stage.has_servo() && (stage.stop == PathStop::EpsD || stage.stop == PathStop::Time ||
                                  stage.stop == PathStop::EpsV || stage.stop == PathStop::EpsXX ||
                                  stage.stop == PathStop::EpsYY || stage.stop == PathStop::EpsZZ);
  }
  double value(const State& s, const AxisResponse& r) const {
    const Vec3 e = s.box.true_strain();
    switch (stage.stop) {
      case PathStop::EpsD: return deviatoric_magnitude(e.x - strain0.x, e.y - strain0.y, e.z - strain0.z);
      case PathStop::Time: return s.time - time0;
      case PathStop::EpsV: return (e.x + e.y + e.z) / 3.0;
      case PathStop::EpsXX: return e.x;
      case PathStop::EpsYY: return e.y;
      case PathStop::EpsZZ: return e.z;
      case PathStop::Pressure: return r.p();
      case PathStop::SDev: {
        const double p = r.p();
        return p > 0 ? deviatoric_magnitude(r.stress.xx, r.stress.yy, r.stress.zz) / p : 0.0;
      }
      case PathStop::Phi: return s.volume_fraction();
    }
    return 0;
  }
  double target() const { return stage.until; }
  // Change of value() in one full step of prescribed rate `rate` [1/s] (landable stops only).
  double increment(const Vec3& rate, double dt) const {
    switch (stage.stop) {
      case PathStop::EpsD: return deviatoric_magnitude(rate.x, rate.y, rate.z) * dt;
      case PathStop::Time: return dt;
      case PathStop::EpsV: return std::fabs(rate.x + rate.y + rate.z) / 3.0 * dt;
      case PathStop::EpsXX: return std::fabs(rate.x) * dt;
      case PathStop::EpsYY: return std::fabs(rate.y) * dt;
      case PathStop::EpsZZ: return std::fabs(rate.z) * dt;
      default: return 0;
    }
  }
  // Reached: eps_d and time grow from 0 to the target; the others cross it from their start value.
  bool reached(double x, double x_start) const {
    if (stage.stop == PathStop::EpsD || stage.stop == PathStop::Time) return x >= stage.until;
    return (x - stage.until) * (x_start - stage.until) <= 0;
  }
};

std::string extra_row(const Vec3& rate, const Servo& servo, const Sym3& stress, double accumulated) {
  char b[400];
  const Vec3 t = servo.sigma_target();
  std::snprintf(b, sizeof b, ",%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g", rate.x, rate.y, rate.z, t.x, t.y,
                t.z, servo.pressure_target(), servo.relative_error(stress), accumulated);
  return b;
}

// Everything one stage of a path needs from the path.
struct PathRun {
  const Model& model;
  State& state;
  Engine& engine;
  CurveFile& csv;
  const std::string& label;
  bool quiet;
  double e_floor;
  double prev_ekin;
  double max_inertial = 0;
  State last_good;
  std::int64_t steps = 0;
  double accumulated = 0;   // eps_d travelled along the whole path (sum of |d eps_d| per step)
};

// Runs one stage to its stop condition, writing rows; returns nothing, throws on failure.
void run_path_stage(PathRun& run, const PathStage& stage) {
  const Model& model = run.model;
  State& state = run.state;
  const double dt = model.dt;
  // Rates re-based so opposite stages cancel exactly; strains keep counting from the path start.
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  const Vec3 prescribed = stage.rate_shape * model.protocol.deviatoric_rate;
  Servo servo(stage, prescribed, model.protocol.servo);
  const bool needs_response = servo.active() || stage.stop == PathStop::Pressure || stage.stop == PathStop::SDev;
  AxisResponse resp = axis_response(model, state, run.engine.neighbor_list(), prescribed);
  servo.start(resp, model, state);
  const std::int64_t every = servo.active() ? std::max<std::int64_t>(1, std::llround(servo.tau() / (20 * dt)))
                                            : (needs_response ? 50 : 0);
  Vec3 rate = servo.update(resp, 0);
  const StopProbe probe{stage, state.box.true_strain(), state.time};
  const double x_start = probe.value(state, resp);
  const double increment = probe.landable() ? probe.increment(prescribed, dt) : 0;
  // The sampling variable: the stop value itself for an eps_d stop without servo (as run_stage),
  // else the strain travelled (deviatoric or volumetric, whichever moved more), plus a row every
  // relax_sample_steps steps in a stage without prescribed rate.
  const bool sample_on_x = stage.stop == PathStop::EpsD && !servo.active();
  const bool time_rows = prescribed.x == 0 && prescribed.y == 0 && prescribed.z == 0;   // a servo-only stage
  double travel = 0, last_sample = sample_on_x ? x_start : 0.0;
  const double rate_floor = std::min(model.protocol.servo.rate_max, model.protocol.deviatoric_rate);
  const double time_limit = 4.0 / rate_floor;
  Vec3 e_prev = state.box.true_strain();
  std::int64_t stage_steps = 0;
  auto wall0 = std::chrono::steady_clock::now(), last_progress = wall0;
  Measurement last_m;
  bool done = false;
  while (!done) {
    double scale = 1.0;
    if (increment > 0) {
      const double remaining = std::fabs(probe.target() - probe.value(state, resp));
      if (remaining < increment) scale = remaining / increment;
    }
    run.engine.step(rate * scale);
    ++run.steps;
    ++stage_steps;
    const Vec3 e = state.box.true_strain();
    const Vec3 de = e - e_prev;
    e_prev = e;
    const double dd = deviatoric_magnitude(de.x, de.y, de.z);
    travel += std::max(dd, std::fabs(de.x + de.y + de.z) / 3.0);
    run.accumulated += dd;
    if (every > 0 && stage_steps % every == 0) {
      resp = axis_response(model, state, run.engine.neighbor_list(), rate);
      if (servo.active()) rate = servo.update(resp, every * dt);
    }
    const double x = probe.value(state, resp);
    if (increment > 0) done = scale < 1.0;
    else done = (every == 0 || stage_steps % every == 0 || !needs_response) && probe.reached(x, x_start);
    const double sx = sample_on_x ? x : travel;
    bool sample = std::fabs(sx - last_sample) >= model.output.sample_strain * (1 - 1e-9) ||
                  (time_rows && stage_steps % model.output.relax_sample_steps == 0);
    if (!done && (travel > 4 || state.time - probe.time0 > time_limit) && stage.stop != PathStop::Time)
      throw std::runtime_error("path " + run.label + ", stage '" + stage.name + "': its stop condition was not met after "
                               "a strain of " + std::to_string(travel) + " (or 4 / rate limit in time): the target "
                               "may be beyond what this packing reaches (e.g. an s_dev above its critical state); "
                               "change the stop condition");
    if (sample || done) {
      run.engine.check_sanity();
      last_m = measure(model, state, run.engine.neighbor_list(), servo.active() ? rate : prescribed);
      check_kinetic_energy(model, state, last_m, run.e_floor, run.prev_ekin);
      run.prev_ekin = last_m.E_kin;
      run.max_inertial = std::max(run.max_inertial, last_m.inertial_number);
      run.csv.row(curve_row(last_m) + extra_row(rate, servo, last_m.stress, run.accumulated), stage.name);
      run.csv.check(stage.name);
      last_sample = sample_on_x ? probe.value(state, resp) : travel;
      run.last_good = state;
    }
    const auto now = std::chrono::steady_clock::now();
    if (!run.quiet && (std::chrono::duration<double>(now - last_progress).count() >= model.output.progress_seconds || done)) {
      last_progress = now;
      char line[400];
      std::snprintf(line, sizeof line, "[%s/%s] step %lld  eps_d %.4f  eps_v %.4f  p %.3e Pa  s_dev %.4f  error %.2g%s\n",
                    run.label.c_str(), stage.name.c_str(), static_cast<long long>(stage_steps), last_m.eps_d,
                    last_m.eps_v, last_m.p, last_m.s_dev, servo.relative_error(last_m.stress), done ? "  (stage done)" : "");
      std::cerr << line << std::flush;
    }
  }
}

}  // namespace

std::int64_t run_path(const Model& model, State& state, const DeformationMode& mode, const std::string& label,
                      const std::string& csv_path, bool quiet, const std::string& failed_checkpoint) {
  // Strains from the path start.
  state.box.zero_strain();
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  Engine engine(model, state);
  CurveFile csv(csv_path, curve_preamble(model, label, shear_physics(model), mode_definition(model, mode)), path_columns());
  // p0: the pressure of the first row (the dashpots see the first stage's prescribed rate).
  const Vec3 rate0 = mode.path.front().rate_shape * model.protocol.deviatoric_rate;
  const double p0 = axis_response(model, state, engine.neighbor_list(), rate0).p();
  for (const PathStage& st : mode.path)
    if ((st.relative && st.has_servo()) || st.until_relative)
      if (!(p0 > 0))
        throw std::runtime_error("path " + label + ": targets are multiples of p0, the pressure at the path start, "
                                 "but it is " + std::to_string(p0) + " Pa (no contacts): give targets in Pa (*_Pa)");
  PathRun run{model, state, engine, csv, label, quiet, energy_floor(model, state), 0, 0, state, 0};
  // The first row: the start state, with the first stage's name.
  const Measurement m0 = measure(model, state, engine.neighbor_list(), rate0);
  run.prev_ekin = m0.E_kin;
  {
    const PathStage first = resolve(mode.path.front(), p0);
    Servo servo(first, rate0, model.protocol.servo);
    csv.row(curve_row(m0) + extra_row(rate0, servo, m0.stress, 0.0), first.name);
  }
  try {
    for (const PathStage& st : mode.path) run_path_stage(run, resolve(st, p0));
  } catch (const BlowUp& e) {
    csv.abandon();
    const std::string failed = failed_checkpoint.empty() ? csv_path + ".failed.ckpt" : failed_checkpoint;
    write_checkpoint(failed, Checkpoint{"", "last good state of path " + label, run.last_good});
    throw BlowUp(std::string(e.what()) + "\n     the last good state of path " + label + " was saved as " + failed);
  } catch (...) {
    csv.abandon();
    throw;
  }
  csv.commit(label);
  if (run.max_inertial > kQuasiStaticInertial)
    std::cerr << "dem: warning: path " << label << " reached an inertial number of " << run.max_inertial << " (> "
              << kQuasiStaticInertial << "): not quasi-static; lower protocol.deviatoric_rate_tc or servo.rate_max_tc\n";
  return run.steps;
}

}  // namespace dem
