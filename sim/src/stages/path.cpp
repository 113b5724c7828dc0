// Loading paths: stages in order from one state, each with its control (prescribed strain
// rate, stress servo) and stop condition, written as one curve.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include <Eigen/Dense>

#include "dem/io/checks.hpp"
#include "dem/measure/control.hpp"
#include "dem/stages/curve_file.hpp"
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/protocol.hpp"
#include "stages/stage_common.hpp"

namespace dem {

const std::vector<std::string>& path_columns() {   // the column table's (measure.cpp), written by extra_row
  static const std::vector<std::string> cols = columns_of(ColumnGroup::Path);
  return cols;
}

namespace {

// A Relaxed stop also wants every servo target held within this relative error.
constexpr double kRelaxedTolerance = 1e-2;

// A path with a shear stage also writes the shear rates (L_xy, L_xz, L_yz) after the usual
// columns; a diagonal path's columns are unchanged.
bool path_sheared(const DeformationMode& mode) {
  for (const PathStage& s : mode.path)
    if (s.sheared()) return true;
  return false;
}

std::vector<std::string> columns_of(bool sheared) {
  std::vector<std::string> c = path_columns();
  if (sheared) {
    const std::vector<std::string> shear = columns_of(ColumnGroup::PathSheared);
    c.insert(c.end(), shear.begin(), shear.end());
  }
  return c;
}

// F (row-major) of the box since strains were zeroed, as an Eigen matrix.
Eigen::Matrix3d deformation(const Box& box) {
  double F[3][3];
  box.deformation_gradient(F);
  Eigen::Matrix3d f;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) f(i, j) = F[i][j];
  return f;
}

// eps_d (eigenvalues) of the log strain 0.5 ln(G G^T) of the deformation G = F F0^-1 since F0.
// From the path start (F0 = I) the curve's own eps_d, so that a constant-volume shear path gives
// the shear mode's curve bit for bit.
double stage_eps_d(const Box& box, const Eigen::Matrix3d& F0_inverse) {
  if (F0_inverse == Eigen::Matrix3d::Identity()) return deviatoric_magnitude_eig(log_strain_tensor(box));
  const Eigen::Matrix3d g = deformation(box) * F0_inverse;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(g * g.transpose());
  const Eigen::Vector3d e = es.eigenvalues().array().log() * 0.5;
  return deviatoric_magnitude(e(0), e(1), e(2));
}

// eps_d rate (eigenvalues of the stretching D = sym L) of a velocity gradient [1/s].
double stretching_eps_d(const VelGrad& L) {
  return deviatoric_magnitude_eig(
      Sym3{L.diag.x, L.diag.y, L.diag.z, 0.5 * L.shear.x, 0.5 * L.shear.y, 0.5 * L.shear.z});
}

// A stage with its relative targets resolved to pascals and its time stop in seconds.
PathStage resolve(const Model& model, const PathStage& s, double p0) {
  PathStage r = s;
  if (s.relative) { r.sigma = s.sigma * p0; r.pressure = s.pressure * p0; }
  if (s.until_relative) r.until = s.until * p0;
  // Presence is the key's (finite at parse); after scaling by p0 every present target must still be finite.
  const double given[4] = {s.sigma.x, s.sigma.y, s.sigma.z, s.pressure}, scaled[4] = {r.sigma.x, r.sigma.y, r.sigma.z, r.pressure};
  for (int k = 0; k < 4; ++k)
    if (std::isfinite(given[k]) && !std::isfinite(scaled[k]))
      throw SceneError("path stage '" + s.name + "': a stress target of " + std::to_string(given[k]) + " p0 is not a "
                       "finite pressure (p0 = " + std::to_string(p0) + " Pa): give a target of the order of 1");
  for (int k = 0; k < 4; ++k)
    if (std::isfinite(scaled[k]) && scaled[k] > stress_target_limit(model))
      throw SceneError("path stage '" + s.name + "': a stress target of " + std::to_string(given[k]) + " p0 = " +
                       std::to_string(scaled[k]) + " Pa is beyond what these spheres carry (" +
                       std::to_string(stress_target_limit(model)) + " Pa = integration.max_overlap_fraction x "
                       "contact.stiffness_N_m / (2 particles.radius_min_m), where the overlaps reach the blow-up limit): "
                       "give a target of the order of 1");
  if (!std::isfinite(r.until))
    throw SceneError("path stage '" + s.name + "': its stop value times p0 is not finite: give a value of the order of 1");
  return r;
}

// The stop value of a stage now: strain stops from the box, p and s_dev from the last response.
struct StopProbe {
  const PathStage& stage;
  Vec3 strain0;       // true strain (since the path start) at the stage start
  double time0;
  // Under shear (this stage's rate or the cell since the path start) strains are tensors: eps_d is
  // that of the log strain of the deformation this stage adds (F F0^-1), components those of the
  // log strain since the path start (the curve's columns). Diagonal paths: the old arithmetic.
  bool tensor = false;
  Eigen::Matrix3d F0_inverse = Eigen::Matrix3d::Identity();

  bool landable() const {   // linear in the step's rate scale, so the last step can land on it
    return !stage.has_servo() && (stage.stop == PathStop::EpsD || stage.stop == PathStop::Time ||
                                  stage.stop == PathStop::EpsV || stage.stop == PathStop::EpsXX ||
                                  stage.stop == PathStop::EpsYY || stage.stop == PathStop::EpsZZ);
  }
  double value(const State& s, const AxisResponse& r) const {
    const Vec3 e = s.box.true_strain();
    if (tensor && (stage.stop == PathStop::EpsD || stage.stop == PathStop::EpsXX || stage.stop == PathStop::EpsYY ||
                   stage.stop == PathStop::EpsZZ || stage.stop == PathStop::SDev)) {
      if (stage.stop == PathStop::EpsD) return stage_eps_d(s.box, F0_inverse);
      if (stage.stop == PathStop::SDev) {
        const double p = r.p();
        return p > 0 ? deviatoric_magnitude_eig(r.stress) / p : 0.0;
      }
      const Sym3 t = log_strain_tensor(s.box);
      return stage.stop == PathStop::EpsXX ? t.xx : stage.stop == PathStop::EpsYY ? t.yy : t.zz;
    }
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
      case PathStop::TauXY: return -r.stress.xy;
      case PathStop::TauXZ: return -r.stress.xz;
      case PathStop::TauYZ: return -r.stress.yz;
      case PathStop::Relaxed: return 0;   // judged on the sampled rows (run_path_stage)
    }
    return 0;
  }
  double target() const { return stage.until; }
  // Change of value() in one full step of prescribed rate `rate` [1/s] (landable stops only).
  double increment(const VelGrad& L, double dt) const {
    const Vec3& rate = L.diag;
    switch (stage.stop) {
      case PathStop::EpsD: return (tensor ? stretching_eps_d(L) : deviatoric_magnitude(rate.x, rate.y, rate.z)) * dt;
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
    if (stage.stop == PathStop::Relaxed) return false;
    if (stage.stop == PathStop::EpsD || stage.stop == PathStop::Time) return x >= stage.until;
    return (x - stage.until) * (x_start - stage.until) <= 0;
  }
};

std::string extra_row(const VelGrad& L, const Servo& servo, const Sym3& stress, double accumulated, bool sheared) {
  char b[500];
  const Vec3 t = servo.sigma_target();
  const Vec3& rate = L.diag;
  int n = std::snprintf(b, sizeof b, ",%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g", rate.x, rate.y, rate.z,
                        t.x, t.y, t.z, servo.pressure_target(), servo.relative_error(stress), accumulated);
  if (sheared) std::snprintf(b + n, sizeof b - n, ",%.10g,%.10g,%.10g", L.shear.x, L.shear.y, L.shear.z);
  return b;
}

// The servo's hold on its targets, per controlled component, over a path's rows: the start-up
// rows (less than kStartupEpsD of eps_d_accumulated past their stage's start) apart from the rest.
constexpr double kStartupEpsD = 0.02;
struct ServoSummary {
  struct Component { long rows = 0, startup_rows = 0; double max = 0, sum_sq = 0, startup_max = 0; };
  std::vector<std::pair<std::string, Component>> components;   // in order of first appearance
  void add(const Servo& servo, const Sym3& stress, double stage_eps_d) {
    for (const auto& [name, e] : servo.component_errors(stress)) {
      // (a structured binding cannot be captured before C++20: clang refuses it)
      auto it = std::find_if(components.begin(), components.end(), [&n = name](const auto& c) { return c.first == n; });
      if (it == components.end()) it = components.insert(components.end(), {name, Component{}});
      Component& c = it->second;
      if (stage_eps_d < kStartupEpsD) { ++c.startup_rows; c.startup_max = std::max(c.startup_max, e); }
      else { ++c.rows; c.max = std::max(c.max, e); c.sum_sq += e * e; }
    }
  }
  // Two comment lines after the rows (docs/control.md, "The servo's summary"); none without a servo.
  void write(CurveFile& csv) const {
    if (components.empty()) return;
    char head[300];
    std::snprintf(head, sizeof head, "servo: |measured - target| / scale per controlled component (scale: the target; "
                  "b: the p target), rows with eps_d_accumulated >= %g past their stage's start (the start-up: "
                  "startup_*), as servo_summary below", kStartupEpsD);
    csv.comment(head);
    std::string s = "servo_summary: {\"startup_eps_d\": " + number(kStartupEpsD) + ", \"components\": {";
    for (std::size_t k = 0; k < components.size(); ++k) {
      const Component& c = components[k].second;
      const double rms = c.rows > 0 ? std::sqrt(c.sum_sq / c.rows) : NAN;
      s += (k ? ", \"" : "\"") + components[k].first + "\": {\"max_rel\": " + number(c.rows ? c.max : NAN) +
           ", \"rms_rel\": " + number(rms) + ", \"rows\": " + std::to_string(c.rows) +
           ", \"startup_max_rel\": " + number(c.startup_rows ? c.startup_max : NAN) +
           ", \"startup_rows\": " + std::to_string(c.startup_rows) + "}";
    }
    csv.comment(s + "}}");
  }
  static std::string number(double x) {   // JSON: a missing value (no rows) is null
    if (!std::isfinite(x)) return "null";
    char b[40];
    std::snprintf(b, sizeof b, "%.6g", x);
    return b;
  }
};

// Everything one stage of a path needs from the path.
struct PathRun {
  StageLoop& loop;
  const std::string& label;
  bool quiet;
  double accumulated = 0;   // eps_d travelled along the whole path (sum of |d eps_d| per step)
  bool sheared = false;     // the path has a shear stage (extra columns)
  ServoSummary summary;
  // The largest inertial number of the rows, the servo's start-up rows (kStartupEpsD) apart: the
  // servo at its rate limit while it finds its targets is not the flow the warning is about.
  double inertial_flow = 0, inertial_startup = 0;
};

// The quasi-static warning, on the rows past the servo's start-up; a start-up above the bound
// alone is a note (the servo at its rate limit, servo.rate_max_tc), not a warning.
void warn_inertial(const PathRun& run) {
  if (run.inertial_flow > kQuasiStaticInertial)
    std::cerr << "dem: warning: path " << run.label << " reached an inertial number of " << run.inertial_flow << " (> "
              << kQuasiStaticInertial << "): not quasi-static; lower protocol.deviatoric_rate_tc or servo.rate_max_tc\n";
  else if (run.inertial_startup > kQuasiStaticInertial && !run.quiet)
    std::cerr << "dem: note: path " << run.label << ": inertial number " << run.inertial_startup << " (> "
              << kQuasiStaticInertial << ") only in the servo's start-up (the first " << kStartupEpsD
              << " of eps_d of a stage), " << run.inertial_flow << " after it; servo.rate_max_tc bounds it\n";
}

// One stage of a path on the stage loop (stage_common.hpp): the servo, the stop probe, the
// landing on a linear stop, sampling by the strain travelled (or the stop value).
struct PathStageRun {
  PathRun& run;
  const PathStage& stage;
  const Model& model;
  State& state;
  const double dt;
  const VelGrad gradient;   // the prescribed velocity gradient [1/s]
  Servo servo;
  bool needs_response;
  AxisResponse resp;
  std::int64_t every;
  VelGrad rate;             // the box's velocity gradient: prescribed + the servo's [1/s]
  StopProbe probe;
  double x_start, increment;
  bool nonlinear_stop, sample_on_x, time_rows;
  double travel = 0, last_sample;
  double time_limit;
  Vec3 e_prev;
  std::int64_t stage_steps = 0;
  std::chrono::steady_clock::time_point last_progress = std::chrono::steady_clock::now();
  double scale = 1, x_before = 0;
  double accumulated0;      // run.accumulated at the stage start

  PathStageRun(PathRun& r, const PathStage& st)
      : run(r), stage(st), model(r.loop.model), state(r.loop.state), dt(model.dt),
        gradient(st.shape * model.protocol.deviatoric_rate), servo(st, gradient, model.protocol.servo),
        probe{st, Vec3{}, 0}, accumulated0(r.accumulated) {
    // Rates re-based so opposite stages cancel exactly; strains keep counting from the path start.
    state.box.reference = state.box.length;
    state.box.log_strain = Vec3{0, 0, 0};
    needs_response = servo.active() || stage.stop == PathStop::Pressure || stage.stop == PathStop::SDev ||
                     stage.stop == PathStop::TauXY || stage.stop == PathStop::TauXZ || stage.stop == PathStop::TauYZ;
    resp = axis_response(model, state, run.loop.engine.neighbor_list(), gradient);
    servo.start(resp, model, state);
    every = servo.active() ? servo.update_steps()
                           : (needs_response ? 50 : 0);
    rate = servo.update(resp, 0);
    probe.strain0 = state.box.true_strain();
    probe.time0 = state.time;
    if (stage.sheared() || state.box.sheared()) {
      probe.tensor = true;
      probe.F0_inverse = deformation(state.box).inverse();
    }
    x_start = probe.value(state, resp);
    increment = probe.landable() ? probe.increment(gradient, dt) : 0;
    // Strains under shear are not linear in time: land with the last full step's increment (as a
    // sheared mode does), except eps_v (ln det F, linear) and time.
    nonlinear_stop = probe.tensor && stage.stop != PathStop::EpsV && stage.stop != PathStop::Time;
    // The sampling variable: the stop value itself for an eps_d stop without servo (as run_stage),
    // else the strain travelled (deviatoric or volumetric, whichever moved more), plus a row every
    // relax_sample_steps steps in a stage without prescribed rate.
    sample_on_x = stage.stop == PathStop::EpsD && !servo.active();
    time_rows = gradient.zero();   // a servo-only stage
    last_sample = sample_on_x ? x_start : 0.0;
    const double rate_floor = std::min(model.protocol.servo.rate_max, model.protocol.deviatoric_rate);
    time_limit = 4.0 / rate_floor;
    e_prev = state.box.true_strain();
  }
  const std::string& name() const { return stage.name; }
  VelGrad next_rate() {
    scale = 1.0;
    if (increment > 0) {
      const double remaining = std::fabs(probe.target() - probe.value(state, resp));
      if (remaining < increment) scale = remaining / increment;
    }
    x_before = increment > 0 && nonlinear_stop ? probe.value(state, resp) : 0.0;
    return rate * scale;
  }
  // The box got too thin for the neighbour grid before the stop came: that is the stop
  // condition not met (the documented error), the geometry only its symptom.
  [[noreturn]] void step_failed(const std::runtime_error& e) const {
    throw std::runtime_error("path " + run.label + ", stage '" + stage.name + "': its stop condition was not met after "
                             "a strain of " + std::to_string(travel) + ", when the box could deform no further (" +
                             e.what() + "): the target may be beyond what this packing reaches (e.g. an s_dev above "
                             "its critical state); change the stop condition");
  }
  StepOutcome after_step() {
    ++stage_steps;
    if (increment > 0 && nonlinear_stop && scale == 1.0)
      increment = std::max(std::fabs(probe.value(state, resp) - x_before), 1e-3 * probe.increment(gradient, dt));
    const Vec3 e = state.box.true_strain();
    const Vec3 de = e - e_prev;
    e_prev = e;
    // Under a shear rate the box lengths do not show the shear: the eps_d travelled in the step is
    // that of the stretching D = sym L applied (equal to the diagonal form for a diagonal rate).
    const double dd = rate.sheared() ? stretching_eps_d(rate * scale) * dt : deviatoric_magnitude(de.x, de.y, de.z);
    travel += std::max(dd, std::fabs(de.x + de.y + de.z) / 3.0);
    run.accumulated += dd;
    if (every > 0 && stage_steps % every == 0) {
      resp = axis_response(model, state, run.loop.engine.neighbor_list(), rate);
      if (servo.active()) rate = servo.update(resp, every * dt);
    }
    const double x = probe.value(state, resp);
    StepOutcome o;
    if (increment > 0) o.done = scale < 1.0;
    else o.done = (every == 0 || stage_steps % every == 0 || !needs_response) && probe.reached(x, x_start);
    const double sx = sample_on_x ? x : travel;
    o.sample = std::fabs(sx - last_sample) >= model.output.sample_strain * (1 - 1e-9) ||
               (time_rows && stage_steps % model.output.relax_sample_steps == 0);
    const bool relaxed_stop = stage.stop == PathStop::Relaxed;
    if (relaxed_stop && stage.max_time > 0 && state.time - probe.time0 >= stage.max_time) {
      o.done = true;
      std::cerr << "dem: warning: path " << run.label << ", stage '" << stage.name << "': not relaxed (E_kin < "
                << stage.until << " E_pot, targets within 1 %) after max_time; it ends there\n";
    }
    if (!o.done && !(relaxed_stop && stage.max_time > 0) && (travel > 4 || state.time - probe.time0 > time_limit) &&
        stage.stop != PathStop::Time)
      throw std::runtime_error("path " + run.label + ", stage '" + stage.name + "': its stop condition was not met after "
                               "a strain of " + std::to_string(travel) + " (or 4 / rate limit in time): the target "
                               "may be beyond what this packing reaches (e.g. an s_dev above its critical state); "
                               "change the stop condition");
    return o;
  }
  VelGrad row_rate() const { return servo.active() ? rate : gradient; }
  std::string row(const Measurement& m, bool& done) {
    // A Relaxed stop: the row that finds the packing at rest with its targets held is the last.
    if (stage.stop == PathStop::Relaxed && !done)
      done = m.E_kin < stage.until * std::max(m.E_pot, run.loop.e_floor) &&
             servo.relative_error(m.stress) < kRelaxedTolerance;
    last_sample = sample_on_x ? probe.value(state, resp) : travel;
    run.summary.add(servo, m.stress, run.accumulated - accumulated0);
    const bool startup = servo.active() && run.accumulated - accumulated0 < kStartupEpsD;
    double& inertial = startup ? run.inertial_startup : run.inertial_flow;
    inertial = std::max(inertial, m.inertial_number);
    return curve_row(m) + extra_row(rate, servo, m.stress, run.accumulated, run.sheared);
  }
  void progress_line(bool done) {
    const auto now = std::chrono::steady_clock::now();
    if (run.quiet || (std::chrono::duration<double>(now - last_progress).count() < model.output.progress_seconds && !done))
      return;
    last_progress = now;
    const Measurement& m = run.loop.last;
    char line[400];
    std::snprintf(line, sizeof line, "[%s/%s] step %lld  eps_d %.4f  eps_v %.4f  p %.3e Pa  s_dev %.4f  error %.2g%s\n",
                  run.label.c_str(), stage.name.c_str(), static_cast<long long>(stage_steps), m.eps_d, m.eps_v, m.p,
                  m.s_dev, servo.relative_error(m.stress), done ? "  (stage done)" : "");
    std::cerr << line << std::flush;
  }
};

// Runs one stage to its stop condition, writing rows; returns nothing, throws on failure.
void run_path_stage(PathRun& run, const PathStage& stage) {
  PathStageRun st(run, stage);
  run_stage_loop(run.loop, st);
}

}  // namespace

std::int64_t run_path(const Model& model, State& state, const DeformationMode& mode, const std::string& label,
                      const StageOutput& out) {
  // Strains from the path start.
  state.box.zero_strain();
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  Engine engine(model, state);
  const bool sheared = path_sheared(mode);
  std::vector<std::string> extra = columns_of(sheared);
  if (model.contact.frictional()) extra.insert(extra.begin(), friction_columns().begin(), friction_columns().end());
  CurveFile csv(out.csv, curve_preamble(model, label, shear_physics(model), mode_definition(model, mode)), extra);
  // p0: the pressure of the first row (the dashpots see the first stage's prescribed rate).
  const VelGrad rate0 = mode.path.front().shape * model.protocol.deviatoric_rate;
  const double p0 = axis_response(model, state, engine.neighbor_list(), rate0).p();
  for (const PathStage& st : mode.path)
    if ((st.relative && st.has_servo()) || st.until_relative)
      if (!(p0 > 0))
        throw std::runtime_error("path " + label + ": targets are multiples of p0, the pressure at the path start, "
                                 "but it is " + std::to_string(p0) + " Pa (no contacts): give targets in Pa (*_Pa)");
  StageLoop loop{model, state, engine, csv, energy_floor(model, state), 0, state, 0, 0, Measurement{}};
  PathRun run{loop, label, out.quiet, 0.0, false, ServoSummary{}};
  run.sheared = sheared;
  // The first row: the start state, with the first stage's name.
  const Measurement m0 = measure(model, state, engine.neighbor_list(), rate0);
  check_finite_measurement(model, state, m0);
  loop.prev_ekin = m0.E_kin;
  {
    const PathStage first = resolve(model, mode.path.front(), p0);
    Servo servo(first, rate0, model.protocol.servo);
    csv.row(curve_row(m0) + extra_row(rate0, servo, m0.stress, 0.0, sheared), first.name);
    run.summary.add(servo, m0.stress, 0.0);
  }
  try {
    for (const PathStage& st : mode.path) run_path_stage(run, resolve(model, st, p0));
  } catch (const BlowUp& e) {
    loop.fail(e, out, "path " + label);
  } catch (...) {
    csv.abandon();
    throw;
  }
  run.summary.write(csv);
  csv.commit(label);
  warn_inertial(run);
  if (out.stats) *out.stats = engine.rebuild_stats();
  return loop.steps;
}

}  // namespace dem
