// The stage of constant velocity gradient (run_stage): the preparation's compressions,
// expansions and relaxations and the deviatoric modes, on the stage loop of stage_common.hpp.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>

#include "dem/forces/contact_forces.hpp"
#include "dem/engine/engine.hpp"
#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/io/vtk.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/curve_file.hpp"
#include "dem/stages/protocol.hpp"
#include "stages/stage_common.hpp"

namespace dem {

namespace {

std::vector<int> contact_counts(const State& s, const NeighborList& list) {
  std::vector<int> c(s.count(), 0);
  for_each_contact(s, list, [&](int i, int j, const Vec3&, double, double) { ++c[i]; ++c[j]; });
  return c;
}

double potential_energy(const Model& m, const State& s, const NeighborList& list) {
  double e = 0;
  contact::for_each_contact_force(m, s, list, VelGrad{}, [&](const contact::ContactForce& c) { e += c.energy; });
  return e;
}

// How far a stage has come (its progress variable x) and where it must land exactly: ln(phi)
// for volume-fraction stages (events: the checkpoints, then the target), eps_d for deviatoric
// ones (the log strain's eigenvalues in a sheared cell), time for relaxations.
struct StageProgress {
  const StageSpec& spec;
  const VelGrad& gradient;
  bool sheared = false, isotropic_shape = false;
  double dev_shape = 0, vol_rate = 0;
  double step_increment = 0;         // x per full step (linear in the step's rate scale)
  std::vector<double> events;        // x values to land on exactly, in order
  std::size_t checkpoint_events = 0; // the first ones are checkpoints; the last ends the stage

  StageProgress(const StageSpec& s, double dt) : spec(s), gradient(s.gradient) {
    const Vec3& d = gradient.diag;
    sheared = gradient.sheared();
    vol_rate = d.x + d.y + d.z;
    dev_shape = sheared ? deviatoric_magnitude_eig(Sym3{d.x, d.y, d.z, 0.5 * gradient.shear.x,
                                                        0.5 * gradient.shear.y, 0.5 * gradient.shear.z})
                        : deviatoric_magnitude(d.x, d.y, d.z);
    isotropic_shape = dev_shape < 1e-12 * (std::fabs(vol_rate) + 1e-300);
    switch (s.stop) {
      case StopKind::VolumeFractionUp:
      case StopKind::VolumeFractionDown: {
        step_increment = -vol_rate * dt;
        for (double phi : s.checkpoint_phis) events.push_back(std::log(phi));
        events.push_back(std::log(s.target));
        const bool up = s.stop == StopKind::VolumeFractionUp;
        std::sort(events.begin(), events.end());
        if (!up) std::reverse(events.begin(), events.end());
        if ((up && !(vol_rate < 0)) || (!up && !(vol_rate > 0)))
          throw std::logic_error("stage " + s.name + ": rate does not move phi toward the target");
        checkpoint_events = events.size() - 1;
        break;
      }
      case StopKind::DeviatoricStrain:
        step_increment = (isotropic_shape ? std::fabs(vol_rate) / 3.0 : dev_shape) * dt;
        events.push_back(s.target);
        break;
      case StopKind::Relaxed: step_increment = dt; break;
    }
  }

  double value(const State& state) const {
    switch (spec.stop) {
      case StopKind::VolumeFractionUp:
      case StopKind::VolumeFractionDown: return std::log(state.volume_fraction());
      case StopKind::DeviatoricStrain: {
        if (sheared) return deviatoric_magnitude_eig(log_strain_tensor(state.box));
        const Vec3 e = state.box.true_strain();
        return isotropic_shape ? std::fabs(e.x + e.y + e.z) / 3.0 : deviatoric_magnitude(e.x, e.y, e.z);
      }
      case StopKind::Relaxed: return state.time;
    }
    return 0;
  }

  // The fraction of a full step that lands exactly on the next event (1: no event this step).
  double step_scale(const State& state, std::size_t next_event) const {
    if (spec.stop == StopKind::Relaxed || next_event >= events.size()) return 1.0;
    const double remaining = std::fabs(events[next_event] - value(state));
    return remaining < std::fabs(step_increment) ? remaining / std::fabs(step_increment) : 1.0;
  }
};

// VTK snapshots of a stage (dem/io/vtk.hpp): NAME_NNNN.vtu (particles), NAME_contacts_NNNN.vtu
// (the contact network), NAME_cell_NNNN.vtu (the periodic cell) and their .pvd series
// (nothing without a vtk folder).
struct VtkSeries {
  const Model& model;
  const std::string& dir;
  const std::string& name;
  std::vector<std::pair<double, std::string>> files, contact_files, cell_files;
  void snapshot(const State& state, const NeighborList& list) {
    if (!model.output.vtk || dir.empty()) return;
    char index[32];
    std::snprintf(index, sizeof index, "%04zu", files.size());
    const std::string particles = name + "_" + index + ".vtu", contacts = name + "_contacts_" + index + ".vtu",
                      cell = name + "_cell_" + index + ".vtu";
    write_vtk_particles(dir + "/" + particles, state, wrapped_positions(state), contact_counts(state, list));
    write_vtk_contacts(dir + "/" + contacts, contact_network(model, state, list));
    write_vtk_cell(dir + "/" + cell, state.box);
    files.emplace_back(state.time, particles);
    contact_files.emplace_back(state.time, contacts);
    cell_files.emplace_back(state.time, cell);
    write_pvd(dir + "/" + name + ".pvd", files);
    write_pvd(dir + "/" + name + "_contacts.pvd", contact_files);
    write_pvd(dir + "/" + name + "_cell.pvd", cell_files);
  }
};

// The progress line on stderr (every output.progress_seconds, and at the end): the stage's
// state, the speed and the time left.
struct ProgressLine {
  using Clock = std::chrono::steady_clock;
  const Model& model;
  const std::string& name;
  Clock::time_point start = Clock::now(), last = start;
  void maybe_print(const State& state, const Measurement& m, std::int64_t steps, std::int64_t stage_step,
                   double fraction, bool done) {
    const auto now = Clock::now();
    if (std::chrono::duration<double>(now - last).count() < model.output.progress_seconds && !done) return;
    last = now;
    const double wall = std::chrono::duration<double>(now - start).count();
    const double frac = std::clamp(fraction, 0.0, 1.0);
    const double rate = steps * static_cast<double>(state.count()) / std::max(wall, 1e-9);
    const double eta = frac > 0 ? wall * (1 - frac) / frac : 0;
    char line[400];
    std::snprintf(line, sizeof line,
                  "[%s] step %lld  eps_d %.4f  phi %.4f  p %.3e Pa  s_dev %.4f  C %.2f  "
                  "%.2f M particle-steps/s  %3.0f%%  ~%.0f s left\n",
                  name.c_str(), static_cast<long long>(stage_step), m.eps_d, state.volume_fraction(), m.p, m.s_dev,
                  m.C, rate / 1e6, 100 * frac, eta);
    std::cerr << line << std::flush;
  }
};

// A relaxation is over when E_kin < ke_ratio * max(E_pot, E_floor) (tested every 100 steps) or
// at its time limit.
bool relaxed(const Model& model, const StageSpec& spec, const State& state, const NeighborList& list,
             std::int64_t steps, double e_floor, double t_end) {
  if (steps % 100 == 0 &&
      state.kinetic_energy() < spec.ke_ratio * std::max(potential_energy(model, state, list), e_floor))
    return true;
  return state.time >= t_end;
}

// A stage of constant velocity gradient (run_stage): the step shortened to land on the next
// event, the checkpoint rows, sampling by the progress variable (or every relax_sample_steps
// steps in a relaxation), the VTK snapshots between start and end.
struct ConstantStage {
  StageLoop& loop;
  const StageSpec& spec;
  const StageOutput& out;
  const std::function<void(double, const State&)>& on_checkpoint;
  StageProgress& progress;
  VtkSeries& vtk;
  double x_start, x_end, sample_dx;
  double last_sample_x;
  int vtk_frames;
  double vtk_dx, next_vtk_x;
  int vtk_taken = 0;   // snapshots between start and end (the end one follows the loop)
  std::size_t next_event = 0;
  std::int64_t step0;
  ProgressLine line;
  double scale = 1, x_before = 0;

  ConstantStage(StageLoop& l, const StageSpec& s, const StageOutput& o,
                const std::function<void(double, const State&)>& on_ck, StageProgress& p, VtkSeries& v)
      : loop(l), spec(s), out(o), on_checkpoint(on_ck), progress(p), vtk(v), line{l.model, s.name} {
    const Model& model = loop.model;
    const State& state = loop.state;
    last_sample_x = progress.value(state);
    x_start = progress.value(state);
    x_end = spec.stop == StopKind::Relaxed ? state.time + spec.max_time : progress.events.back();
    vtk_frames = model.output.vtk_per_stage < 0 ? auto_vtk_per_stage(state.count()) : model.output.vtk_per_stage;
    vtk_dx = vtk_frames > 0 ? (x_end - x_start) / (vtk_frames + 1) : 0;
    next_vtk_x = x_start + vtk_dx;
    sample_dx = spec.stop == StopKind::VolumeFractionUp || spec.stop == StopKind::VolumeFractionDown
                    ? 3.0 * model.output.sample_strain   // ln(phi) changes 3x the axis strain
                    : model.output.sample_strain;
    step0 = state.step;
  }
  const std::string& name() const { return spec.name; }
  VelGrad next_rate() {
    scale = progress.step_scale(loop.state, next_event);   // shortened to land on an event
    x_before = progress.sheared ? progress.value(loop.state) : 0.0;
    return spec.gradient * scale;
  }
  void step_failed(const std::runtime_error&) {}
  StepOutcome after_step() {
    const Model& model = loop.model;
    State& state = loop.state;
    // The log strain of a shear is not linear in time: land with the last full step's increment.
    if (progress.sheared && scale == 1.0)
      progress.step_increment = std::max(progress.value(state) - x_before, 1e-3 * progress.dev_shape * model.dt);
    StepOutcome o;
    if (spec.stop == StopKind::Relaxed) {
      o.sample = loop.steps % model.output.relax_sample_steps == 0;
      o.done = relaxed(model, spec, state, loop.engine.neighbor_list(), loop.steps, loop.e_floor, x_end);
      return o;
    }
    const double x = progress.value(state);
    for (double s = scale; next_event < progress.events.size() && s < 1.0; s = 1.0) {   // one event per step
      // landed on events[next_event]
      if (next_event < progress.checkpoint_events && on_checkpoint) {
        const double phi = std::exp(progress.events[next_event]);
        loop.last = measure(model, state, loop.engine.neighbor_list(), spec.gradient);
        loop.csv.row(curve_row(loop.last), spec.name);
        last_sample_x = x;
        on_checkpoint(phi, state);
      }
      if (next_event == progress.events.size() - 1) o.done = true;
      ++next_event;
    }
    if (std::fabs(x - last_sample_x) >= sample_dx * (1 - 1e-9)) o.sample = true;
    if (vtk_dx != 0 && !o.done && vtk_taken < vtk_frames &&
        ((vtk_dx > 0 && x >= next_vtk_x) || (vtk_dx < 0 && x <= next_vtk_x))) {
      vtk.snapshot(state, loop.engine.neighbor_list());
      next_vtk_x += vtk_dx;
      ++vtk_taken;
    }
    return o;
  }
  VelGrad row_rate() const { return spec.gradient; }
  std::string row(const Measurement& m, bool&) {
    last_sample_x = progress.value(loop.state);
    return curve_row(m);
  }
  void progress_line(bool done) {
    if (!out.quiet)
      line.maybe_print(loop.state, loop.last, loop.steps, loop.state.step - step0,
                       (progress.value(loop.state) - x_start) / (x_end - x_start), done);
  }
};

}  // namespace

std::int64_t run_stage(const Model& model, State& state, const StageSpec& spec, const StageOutput& out,
                       const std::function<void(double, const State&)>& on_checkpoint) {
  // Strains from the stage start; lengths re-based so that opposite rates cancel exactly.
  state.box.zero_strain();
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  Engine engine(model, state);
  StageProgress progress(spec, model.dt);
  const bool shear = spec.stop == StopKind::DeviatoricStrain;
  CurveFile csv(out.csv, curve_preamble(model, spec.name, shear ? shear_physics(model) : preparation_physics(model),
                                        spec.definition),
                model.contact.frictional() ? friction_columns() : std::vector<std::string>{});
  const Measurement m0 = measure(model, state, engine.neighbor_list(), spec.gradient);
  check_finite_measurement(model, state, m0);
  csv.row(curve_row(m0), spec.name);
  StageLoop loop{model, state, engine, csv, energy_floor(model, state), m0.E_kin, state, 0, 0, m0};
  VtkSeries vtk{model, out.vtk_dir, spec.name, {}, {}, {}};
  vtk.snapshot(state, engine.neighbor_list());
  ConstantStage stage(loop, spec, out, on_checkpoint, progress, vtk);
  try {
    run_stage_loop(loop, stage);
  } catch (const BlowUp& e) {
    loop.fail(e, out, "stage " + spec.name);   // the partial curve stays visibly partial (.part)
  }
  vtk.snapshot(state, engine.neighbor_list());
  csv.commit(spec.name);
  if (spec.stop == StopKind::DeviatoricStrain && loop.max_inertial > kQuasiStaticInertial)
    std::cerr << "dem: warning: stage " << spec.name << " reached an inertial number of " << loop.max_inertial
              << " (> " << kQuasiStaticInertial << "): not quasi-static; the curves depend on the rate. "
              << "Lower protocol.deviatoric_rate_tc (see docs/stability.md)\n";
  if (out.stats) *out.stats = engine.rebuild_stats();
  return loop.steps;
}

}  // namespace dem
