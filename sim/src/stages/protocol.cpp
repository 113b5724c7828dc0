#include "dem/stages/protocol.hpp"
#include "dem/stages/preparation.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>

#include "dem/io/checks.hpp"
#include "dem/contact/contact_forces.hpp"
#include "dem/stages/curve_file.hpp"
#include "dem/engine/engine.hpp"
#include "dem/io/io.hpp"
#include "dem/io/vtk.hpp"
#include "dem/measure/measure.hpp"
#include "dem/io/scene.hpp"
#include "stages/stage_common.hpp"

namespace fs = std::filesystem;

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

// The resolved scene less its integration.threads line (no part of the physics or the bits).
std::string scene_without_threads(const std::string& toml) {
  std::istringstream in(toml);
  std::string out, line, section;
  while (std::getline(in, line)) {
    const std::size_t a = line.find_first_not_of(" \t");
    const std::string t = a == std::string::npos ? "" : line.substr(a);
    if (!t.empty() && t[0] == '[') section = t;
    if (section.rfind("[integration]", 0) == 0 && t.rfind("threads", 0) == 0) {
      const std::size_t e = t.find_first_not_of(" \t", 7);
      if (e != std::string::npos && t[e] == '=') continue;
    }
    out += line + "\n";
  }
  return out;
}

}  // namespace


namespace {

// How far a stage has come (its progress variable x) and where it must land exactly: ln(phi)
// for volume-fraction stages (events: the checkpoints, then the target), eps_d for deviatoric
// ones (the log strain's eigenvalues in a sheared cell), time for relaxations.
struct StageProgress {
  const StageSpec& spec;
  VelGrad grad;
  bool sheared = false, isotropic_shape = false;
  double dev_shape = 0, vol_rate = 0;
  double step_increment = 0;         // x per full step (linear in the step's rate scale)
  std::vector<double> events;        // x values to land on exactly, in order
  std::size_t checkpoint_events = 0; // the first ones are checkpoints; the last ends the stage

  StageProgress(const StageSpec& s, double dt) : spec(s), grad(s.gradient()) {
    sheared = grad.sheared();
    vol_rate = s.rate.x + s.rate.y + s.rate.z;
    dev_shape = sheared ? deviatoric_magnitude_eig(Sym3{grad.diag.x, grad.diag.y, grad.diag.z, 0.5 * grad.shear.x,
                                                        0.5 * grad.shear.y, 0.5 * grad.shear.z})
                        : deviatoric_magnitude(s.rate.x, s.rate.y, s.rate.z);
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

}  // namespace

std::int64_t run_stage(const Model& model, State& state, const StageSpec& spec,
                       const std::string& csv_path, const std::string& vtk_dir,
                       const std::function<void(double, const State&)>& on_checkpoint,
                       bool quiet, const std::string& failed_checkpoint, RebuildStats* stats) {
  // Strains from the stage start; lengths re-based so that opposite rates cancel exactly.
  state.box.zero_strain();
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  Engine engine(model, state);
  const double dt = model.dt;
  StageProgress progress(spec, dt);
  const VelGrad& grad = progress.grad;
  const bool shear = spec.stop == StopKind::DeviatoricStrain;
  CurveFile csv(csv_path, curve_preamble(model, spec.name, shear ? shear_physics(model) : preparation_physics(model),
                                         spec.definition),
                model.contact.frictional() ? friction_columns() : std::vector<std::string>{});

  Measurement last_m = measure(model, state, engine.neighbor_list(), grad);
  check_finite_measurement(model, state, last_m);
  auto write_row = [&](const Measurement& m) { csv.row(curve_row(m), spec.name); };
  write_row(last_m);
  State last_good = state;
  double last_sample_x = progress.value(state);
  VtkSeries vtk{model, vtk_dir, spec.name, {}, {}, {}};
  vtk.snapshot(state, engine.neighbor_list());

  const double x_start = progress.value(state);
  const double x_end = spec.stop == StopKind::Relaxed ? state.time + spec.max_time : progress.events.back();
  const int vtk_frames =
      model.output.vtk_per_stage < 0 ? auto_vtk_per_stage(state.count()) : model.output.vtk_per_stage;
  const double vtk_dx = vtk_frames > 0 ? (x_end - x_start) / (vtk_frames + 1) : 0;
  double next_vtk_x = x_start + vtk_dx;
  int vtk_taken = 0;   // snapshots between start and end (the end one follows the loop)
  const double sample_dx = spec.stop == StopKind::VolumeFractionUp || spec.stop == StopKind::VolumeFractionDown
                               ? 3.0 * model.output.sample_strain   // ln(phi) changes 3x the axis strain
                               : model.output.sample_strain;
  const double e_floor = energy_floor(model, state);
  std::size_t next_event = 0;
  std::int64_t steps = 0;
  const std::int64_t step0 = state.step;
  ProgressLine line{model, spec.name};
  double prev_sample_ekin = last_m.E_kin;
  double max_inertial = 0;
  bool done = false;

  try {
    while (!done) {
      double scale = progress.step_scale(state, next_event);   // shortened to land on an event
      const double x_before = progress.sheared ? progress.value(state) : 0.0;
      engine.step(grad * scale);
      ++steps;
      // The log strain of a shear is not linear in time: land with the last full step's increment.
      if (progress.sheared && scale == 1.0)
        progress.step_increment = std::max(progress.value(state) - x_before, 1e-3 * progress.dev_shape * dt);
      bool sample = false;
      if (spec.stop == StopKind::Relaxed) {
        sample = steps % model.output.relax_sample_steps == 0;
        done = relaxed(model, spec, state, engine.neighbor_list(), steps, e_floor, x_end);
      } else {
        const double x = progress.value(state);
        while (next_event < progress.events.size() && scale < 1.0) {
          // landed on events[next_event]
          if (next_event < progress.checkpoint_events && on_checkpoint) {
            const double phi = std::exp(progress.events[next_event]);
            last_m = measure(model, state, engine.neighbor_list(), grad);
            write_row(last_m);
            last_sample_x = x;
            on_checkpoint(phi, state);
          }
          if (next_event == progress.events.size() - 1) done = true;
          ++next_event;
          scale = 1.0;   // only one event per step
        }
        if (std::fabs(x - last_sample_x) >= sample_dx * (1 - 1e-9)) sample = true;
        if (vtk_dx != 0 && !done && vtk_taken < vtk_frames &&
            ((vtk_dx > 0 && x >= next_vtk_x) || (vtk_dx < 0 && x <= next_vtk_x))) {
          vtk.snapshot(state, engine.neighbor_list());
          next_vtk_x += vtk_dx;
          ++vtk_taken;
        }
      }
      if (sample || done) {
        engine.check_sanity();
        last_m = measure(model, state, engine.neighbor_list(), grad);
        check_finite_measurement(model, state, last_m);
        check_kinetic_energy(model, state, last_m, e_floor, prev_sample_ekin);
        prev_sample_ekin = last_m.E_kin;
        max_inertial = std::max(max_inertial, last_m.inertial_number);
        write_row(last_m);
        csv.check(spec.name);
        last_sample_x = progress.value(state);
        last_good = state;
      }
      if (!quiet)
        line.maybe_print(state, last_m, steps, state.step - step0, (progress.value(state) - x_start) / (x_end - x_start),
                         done);
    }
  } catch (const BlowUp& e) {
    csv.abandon();
    // Keep the partial curve visibly partial (.part) and save the last good state.
    const std::string failed = failed_checkpoint.empty() ? csv_path + ".failed.ckpt" : failed_checkpoint;
    write_checkpoint(failed, Checkpoint{"", "last good state of stage " + spec.name, last_good});
    throw BlowUp(blow_up_message(model, e.what()) + "\n     the last good state of stage " + spec.name + " was saved as " + failed);
  }
  vtk.snapshot(state, engine.neighbor_list());
  csv.commit(spec.name);
  if (spec.stop == StopKind::DeviatoricStrain && max_inertial > kQuasiStaticInertial)
    std::cerr << "dem: warning: stage " << spec.name << " reached an inertial number of " << max_inertial
              << " (> " << kQuasiStaticInertial << "): not quasi-static; the curves depend on the rate. "
              << "Lower protocol.deviatoric_rate_tc (see docs/stability.md)\n";
  if (stats) *stats = engine.rebuild_stats();
  return steps;
}

// ---------------------------------------------------------------------------------------

namespace {

struct Manifest {
  struct Output {
    std::string stage, file, physics;
    std::int64_t steps = -1;   // -1: produced by an earlier invocation
    double wall_s = 0, particle_steps_per_s = 0;
  };
  std::string path, scene, command;
  std::vector<Output> stages;
  bool complete = false;
  // JSON through nlohmann-json (strings escaped, a non-finite number written as null).
  void save() const {
    nlohmann::ordered_json j{{"tool", "dem"}, {"version", DEM_VERSION}, {"command", command}, {"complete", complete}};
    j["outputs"] = nlohmann::ordered_json::array();
    for (const Output& st : stages) {
      nlohmann::ordered_json o{{"stage", st.stage}, {"file", st.file}, {"physics", st.physics}};
      if (st.steps >= 0) {
        o["steps"] = st.steps;
        o["wall_s"] = st.wall_s;
        o["particle_steps_per_s"] = st.particle_steps_per_s;
      }
      j["outputs"].push_back(std::move(o));
    }
    write_file_atomic(path, j.dump(2) + "\n");
  }
};

// The preparation stages' names in order; each ends with DIR/prep/after_<stage>.ckpt (resume point).
std::vector<std::string> prep_stage_names(const Model& model) {
  std::vector<std::string> names;
  for (const auto& s : model.protocol.preparation) names.push_back(s.name);
  return names;
}

// Runs a stage spec on the state (with the run's bookkeeping), calling on_checkpoint at its checkpoints.
using RunSpec = std::function<void(State&, const StageSpec&, const std::function<void(double, const State&)>&)>;
// Saves the state as checkpoint <series>_<phi>.
using SaveCheckpoint = std::function<void(const std::string& series, double phi, const State&)>;

// Runs a stress-controlled preparation stage (pressure / uniaxial) on the state.
using RunStress = std::function<void(State&, const PrepStage&)>;

// A stress-controlled stage as a one-stage loading path (path.cpp): the servo drives p, or sigma_zz
// with the x and y lengths fixed, to the target (at most at the stage's rate) and holds it until
// the packing is at rest there (PathStop::Relaxed) or max_time.
DeformationMode stress_stage_path(const PrepStage& s) {
  PathStage st;
  st.name = s.name;
  st.relative = false;
  if (s.kind == PrepStage::Kind::Pressure) st.pressure = s.target;
  else st.sigma.z = s.target;
  st.stop = PathStop::Relaxed;
  st.until = s.ke_ratio;
  st.max_time = s.max_time;
  DeformationMode m;
  m.name = s.name;
  m.path = {st};
  return m;
}

// Runs one preparation stage (PrepStage in model.hpp says what it does). Returns false if skipped.
bool run_prep_stage(const PrepStage& s, State& st, const RunSpec& run, const RunStress& run_stress,
                    const SaveCheckpoint& save) {
  if (s.kind == PrepStage::Kind::Pressure || s.kind == PrepStage::Kind::Uniaxial) {
    run_stress(st, s);
    if (!s.checkpoint_name.empty()) save(s.checkpoint_name, st.volume_fraction(), st);
    return true;
  }
  if (s.kind == PrepStage::Kind::Relax) {
    run(st, StageSpec{s.name, Vec3{0, 0, 0}, StopKind::Relaxed, 0, {}, s.ke_ratio, s.max_time, ""}, nullptr);
    return true;
  }
  const bool up = s.kind == PrepStage::Kind::Compress;
  const double phi0 = st.volume_fraction();
  if (up ? phi0 >= s.phi : phi0 <= s.phi) {
    std::cerr << "dem: stage " << s.name << " skipped: the packing is already at phi " << phi0 << ", "
              << (up ? "at or above" : "at or below") << " its target " << s.phi << "\n";
    if (!s.checkpoints.empty())
      std::cerr << "dem: warning: the checkpoints of stage " << s.name << " (" << s.checkpoint_name
                << ") are not written\n";
    return false;
  }
  StageSpec spec{s.name, Vec3{1, 1, 1} * (up ? -s.rate : s.rate),
                 up ? StopKind::VolumeFractionUp : StopKind::VolumeFractionDown, s.phi, {}, 0, 0, ""};
  auto same = [](double a, double b) { return std::fabs(a - b) <= 1e-9 * b; };
  std::vector<double> at_start, at_end;
  for (double cp : s.checkpoints) {
    if (same(cp, phi0)) at_start.push_back(cp);
    else if (same(cp, s.phi)) at_end.push_back(cp);
    else if (up ? (cp > phi0 && cp < s.phi) : (cp < phi0 && cp > s.phi)) spec.checkpoint_phis.push_back(cp);
    else
      std::cerr << "dem: warning: checkpoint " << checkpoint_stem(s.checkpoint_name, cp) << " not written: stage "
                << s.name << " started at phi " << phi0 << ", already past it\n";
  }
  for (double cp : at_start) save(s.checkpoint_name, cp, st);
  run(st, spec, [&](double phi, const State& now) { save(s.checkpoint_name, phi, now); });
  for (double cp : at_end) save(s.checkpoint_name, cp, st);
  return true;
}

std::string read_text(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A manifest that does not parse, or has no "complete": true, is of an unfinished run.
bool manifest_complete(const fs::path& file) {
  const nlohmann::json j = nlohmann::json::parse(read_text(file), nullptr, false);
  if (j.is_discarded() || !j.is_object()) return false;
  const auto it = j.find("complete");
  return it != j.end() && it->is_boolean() && it->get<bool>();
}

// The text after `tag` (e.g. "# physics: ") in the comment lines of a curve CSV ("" if none:
// written by an older dem).
std::string curve_comment(const fs::path& csv, const std::string& tag) {
  std::ifstream in(csv);
  std::string line;
  while (std::getline(in, line) && !line.empty() && line[0] == '#')
    if (line.rfind(tag, 0) == 0) return line.substr(tag.size());
  return "";
}
std::string curve_physics_line(const fs::path& csv) { return curve_comment(csv, "# physics: "); }

std::string first_word(const std::string& s) { return s.substr(0, s.find(' ')); }

std::vector<std::string> csv_stems(const fs::path& folder) {
  std::vector<std::string> names;
  if (fs::is_directory(folder))
    for (auto& f : fs::directory_iterator(folder))
      if (f.path().extension() == ".csv") names.push_back(f.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

// The physics of the scene stored in a checkpoint.
Model checkpoint_model(const Checkpoint& c, const std::string& origin) {
  try {
    return load_scene(c.scene_toml, {}, nullptr, origin + " (its scene)");
  } catch (const SceneError& e) {
    throw std::runtime_error(origin + ": the scene stored in the checkpoint cannot be read (" + e.what() +
                             "): rerun the preparation");
  }
}

// --stages deviatoric: every checkpoint exists and was prepared by this scene (material physics
// and preparation), so that the scene.toml written beside the curves describes their start.
void check_checkpoints(const Model& model, const fs::path& dir) {
  for (double phi : mode_checkpoints(model.protocol)) {
    const fs::path ck = dir / "checkpoints" / (checkpoint_stem(model.protocol.modes_from, phi) + ".ckpt");
    if (!fs::exists(ck))
      throw std::runtime_error("checkpoint " + ck.string() + " is missing: run --stages prep first");
    const Checkpoint c = read_checkpoint(ck.string());
    const std::string d = physics_diff(preparation_physics(checkpoint_model(c, ck.string())),
                                       preparation_physics(model), "checkpoint", "this scene");
    if (!d.empty())
      throw SceneError(ck.string() + " was prepared with other physics: " + d + ". Curves from it would not be what "
                       "this scene describes: run with the scene it was prepared with (" + (dir / "scene.toml").string() +
                       "; change only the modes and the deviatoric rate), or rerun the preparation (--stages all --force)");
  }
}

// Curves that a rerun keeps must be of this scene's shear physics.
void check_kept_curves(const Model& model, const fs::path& dir) {
  const Physics want = shear_physics(model);
  for (const auto& name : csv_stems(dir / "deviatoric")) {
    const fs::path f = dir / "deviatoric" / (name + ".csv");
    const std::string line = curve_physics_line(f);
    if (line.empty()) continue;   // older dem: no record to check
    const std::string d = physics_diff(parse_physics_line(line), want, "kept curve", "this scene");
    if (!d.empty())
      throw SceneError(f.string() + " was computed with other physics: " + d + ". Keeping it would mix two physics "
                       "in one folder (and in dem fit): pass --force to recompute the deviatoric curves, or choose "
                       "another --out");
    // The same mode, defined as this scene defines it (rate shape, eps_d_max, path stages).
    const std::string had = curve_comment(f, "# definition: ");
    const std::string mode_name = name.substr(0, name.rfind("_phi"));
    for (const auto& mode : model.protocol.modes)
      if (mode.name == mode_name && !had.empty() && had != mode_definition(model, mode))
        throw SceneError(f.string() + " is mode " + mode_name + " as an earlier scene defined it (" + had +
                         "); this scene defines it as " + mode_definition(model, mode) + ". A rerun would keep the "
                         "old curve: pass --force to recompute the deviatoric curves, or choose another --out");
  }
}

// A folder `dem ensemble` made ("" for any other): a run into it would write a single run's
// folders beside the ensemble's and overwrite its scene.toml; --force would delete its fit/ and plots/.
std::string ensemble_folder_kind(const fs::path& dir) {
  if (fs::exists(dir / "sweep.json") || fs::is_directory(dir / "rows"))
    return "a sweep folder (sweep.json, rows/: written by `dem ensemble` with a sweep)";
  if (fs::is_directory(dir / "members") || fs::exists(dir / ".dem-ensemble.lock"))
    return "an ensemble folder (members/, .dem-ensemble.lock: written by `dem ensemble`)";
  return "";
}

// --force: remove what the rerun replaces, and say so.
void clear_replaced(const fs::path& dir, bool prep, const std::vector<std::string>& prep_names) {
  if (!fs::is_directory(dir)) return;
  std::vector<std::string> removed;
  auto drop = [&](const fs::path& p) {
    if (!fs::exists(p)) return;
    fs::remove_all(p);
    removed.push_back(fs::relative(p, dir).string() + (fs::path(p).has_extension() ? "" : "/"));
  };
  for (const char* sub : {"deviatoric", "fit", "plots"}) drop(dir / sub);
  if (prep)
    for (const char* sub : {"prep", "checkpoints", "vtk", "manifest.json"}) drop(dir / sub);
  std::vector<fs::path> files;
  for (auto& f : fs::directory_iterator(dir)) files.push_back(f.path());
  if (fs::is_directory(dir / "vtk"))
    for (auto& f : fs::directory_iterator(dir / "vtk")) {
      const std::string n = f.path().filename().string();
      if (std::none_of(prep_names.begin(), prep_names.end(), [&](const std::string& s) { return n.rfind(s, 0) == 0; }))
        files.push_back(f.path());
    }
  for (const auto& f : files)
    if (f.filename().string().rfind("failed_", 0) == 0 || f.parent_path().filename() == "vtk") drop(f);
  if (!removed.empty()) {
    std::string list;
    for (std::size_t i = 0; i < removed.size() && i < 12; ++i) list += (i ? ", " : "") + removed[i];
    if (removed.size() > 12) list += ", ... (" + std::to_string(removed.size()) + " in all)";
    std::cerr << "dem: --force: removed the earlier results this run replaces in " << dir.string() << ": " << list << "\n";
  }
}

// The checkpoints the modes start from: those the scene lists (mode_checkpoints) and, when a
// stress-controlled stage writes the series modes_from, every checkpoint of that series on disk
// (named by the volume fraction the stage reached, which the scene cannot list). Densest first.
std::vector<double> checkpoints_to_run(const Protocol& p, const fs::path& dir) {
  std::vector<double> phis = mode_checkpoints(p);
  const bool stress_series = std::any_of(p.preparation.begin(), p.preparation.end(), [&](const PrepStage& s) {
    return (s.kind == PrepStage::Kind::Pressure || s.kind == PrepStage::Kind::Uniaxial) &&
           s.checkpoint_name == p.modes_from;
  });
  if (!stress_series || !fs::is_directory(dir / "checkpoints")) return phis;
  const std::string prefix = p.modes_from + "_phi";
  for (auto& f : fs::directory_iterator(dir / "checkpoints")) {
    const std::string n = f.path().filename().string();
    if (f.path().extension() != ".ckpt" || n.rfind(prefix, 0) != 0) continue;
    char* end = nullptr;
    const std::string num = n.substr(prefix.size(), n.size() - prefix.size() - 5);
    const double phi = std::strtod(num.c_str(), &end);
    if (end == num.c_str() || *end != '\0') continue;
    if (std::none_of(phis.begin(), phis.end(), [&](double q) { return fmt_phi(q) == fmt_phi(phi); }))
      phis.push_back(phi);
  }
  std::sort(phis.begin(), phis.end(), std::greater<double>());
  return phis;
}

// The last preparation stage whose curve and end state exist ("" if none).
std::string last_finished_prep_stage(const fs::path& dir, const std::vector<std::string>& prep_names) {
  std::string last;
  for (const auto& st : prep_names)
    if (fs::exists(dir / "prep" / (st + ".csv")) && fs::exists(dir / "prep" / ("after_" + st + ".ckpt"))) last = st;
  return last;
}

// The state an interrupted preparation resumes from, after checking it is of this scene.
State resume_state(const Model& model, const fs::path& dir, const std::string& stage) {
  const fs::path ck = dir / "prep" / ("after_" + stage + ".ckpt");
  Checkpoint c = read_checkpoint(ck.string());
  const std::string d = physics_diff(preparation_physics(checkpoint_model(c, ck.string())),
                                     preparation_physics(model), "interrupted run", "this scene");
  if (!d.empty())
    throw SceneError(dir.string() + " holds an interrupted preparation of other physics: " + d + ". Run the scene it "
                     "was started with (" + (dir / "scene.toml").string() + ") to resume it, pass --force to start "
                     "afresh, or choose another --out");
  return std::move(c.state);
}

// The starting state of a fresh preparation: a packing file (checked against the scene) or placement.
State initial_state(const Model& model, const std::function<void(const std::string&)>& note) {
  State state;
  if (!model.packing_file.empty() && fs::path(model.packing_file).extension() == ".ckpt") {
    note("continuing from checkpoint " + model.packing_file);
    state = read_checkpoint(model.packing_file).state;
  } else if (!model.packing_file.empty()) {
    note("reading packing " + model.packing_file);
    state = read_packing(model.packing_file, model.density);
  } else {
    note("placing " + std::to_string(model.count) + " spheres at phi = " + std::to_string(model.protocol.initial_phi));
    return random_packing(model, model.protocol.initial_phi);
  }
  check_packing(model, state, model.packing_file);
  return state;
}

}  // namespace

void run_protocol(const Model& model, const RunOptions& opt) {
  if (model.sweep_rows > 0)
    throw SceneError("the scene has a [sweep] table of " + std::to_string(model.sweep_rows) + " rows: run the sweep "
                     "with `dem ensemble SCENE --out DIR` (one ensemble per row, docs/ensembles.md); to run the base "
                     "scene alone, remove its [sweep] section");
  if (model.ensemble_packings > 1)
    throw SceneError("ensemble.packings = " + std::to_string(model.ensemble_packings) +
                     ": this scene is an ensemble of independent packings; run it with `dem ensemble SCENE --out DIR` "
                     "(or pass --set ensemble.packings=1 for one packing)");
  const fs::path dir(opt.out_dir);
  const bool want_prep = opt.stages == "all" || opt.stages == "prep";
  const bool want_dev = opt.stages == "all" || opt.stages == "deviatoric";
  if (!want_prep && !want_dev)
    throw SceneError("--stages must be all, prep or deviatoric (got '" + opt.stages + "')");
  auto note = [&](const std::string& what) {
    if (!opt.quiet) std::cerr << "dem: " << what << "\n";
  };

  // 1. Checks, before anything is written.
  if (const std::string kind = ensemble_folder_kind(dir); !kind.empty())
    throw std::runtime_error(dir.string() + " is " + kind + ", not a run folder: `dem run` would overwrite its "
                             "scene.toml and, with --force, delete its fit/ and plots/ (the ensemble's fit tables and "
                             "figures): choose another --out for a single run; continue the ensemble with `dem ensemble "
                             "SCENE --out " + dir.string() + "`");
  const bool resume = want_prep && !opt.force && fs::exists(dir / "manifest.json");
  if (resume && manifest_complete(dir / "manifest.json"))
    throw std::runtime_error("results already exist in " + dir.string() + " (manifest.json: a finished run): choose "
                             "another --out, or pass --force to replace them");
  if (want_prep && !resume) check_memory(model);
  const std::vector<std::string> prep_names = prep_stage_names(model);
  const std::string resume_after = resume ? last_finished_prep_stage(dir, prep_names) : "";
  State start;   // the state the preparation starts from: read and checked before writing
  if (!resume_after.empty()) start = resume_state(model, dir, resume_after);
  if (!want_prep) check_checkpoints(model, dir);
  if (want_dev && !opt.force) check_kept_curves(model, dir);
  if (want_prep && resume_after.empty()) start = initial_state(model, note);
  if (opt.force) clear_replaced(dir, want_prep, prep_names);
  if (resume)
    std::cerr << "dem: " << dir.string() << " holds an interrupted run (manifest.json: complete: false): resuming "
              << (resume_after.empty() ? "the preparation from its start"
                                       : "after the finished stage " + resume_after + " (prep/after_" + resume_after + ".ckpt)")
              << "; finished deviatoric curves are kept\n";

  // 2. The folder, the scene and a manifest that says "not complete" until the end.
  fs::create_directories(dir / "prep");
  fs::create_directories(dir / "checkpoints");
  fs::create_directories(dir / "deviatoric");
  const std::string vtk_dir = model.output.vtk ? (dir / "vtk").string() : "";
  if (model.output.vtk) fs::create_directories(dir / "vtk");
  write_file_atomic((dir / "scene.toml").string(), opt.scene_toml);

  Manifest man{(dir / "manifest.json").string(), opt.scene_toml, opt.command_line, {}, false};
  const std::string prep_hash = physics_hash(preparation_physics(model)), shear_hash = physics_hash(shear_physics(model));
  const Protocol& p = model.protocol;
  auto record = [&](const std::string& sub, const std::string& name, const std::string& physics) {
    const std::string file = (fs::path(sub) / (name + ".csv")).string();
    for (auto& st : man.stages)
      if (st.file == file) { st.physics = physics; return; }
    man.stages.push_back({name, file, physics});
  };
  // Outputs of earlier invocations that this one keeps.
  std::size_t first_prep = 0;
  if (!resume_after.empty())
    first_prep = std::find(prep_names.begin(), prep_names.end(), resume_after) - prep_names.begin() + 1;
  for (const char* sub : {"prep", "deviatoric"})
    for (const auto& name : csv_stems(dir / sub)) {
      const bool rerun = want_prep && std::string(sub) == "prep" &&
                         std::find(prep_names.begin() + first_prep, prep_names.end(), name) != prep_names.end();
      if ((!want_prep || resume) && !rerun) record(sub, name, first_word(curve_physics_line(dir / sub / (name + ".csv"))));
    }
  man.save();

  auto stage_csv = [&](const std::string& sub, const std::string& name) {
    const fs::path f = dir / sub / (name + ".csv");
    if (fs::exists(f) && !opt.force && !resume)
      throw std::runtime_error(f.string() + " exists: pass --force to overwrite finished results");
    record(sub, name, sub == "deviatoric" ? shear_hash : prep_hash);
    return f.string();
  };
  auto record_time = [&](const std::string& stage, std::int64_t steps, double wall, int n) {
    for (auto& st : man.stages)
      if (st.stage == stage) {
        st.steps = steps;
        st.wall_s = wall;
        st.particle_steps_per_s = wall > 0 ? steps * double(n) / wall : 0.0;
      }
  };
  // Runs a stage and records its steps and wall time in the manifest entry of its CSV.
  auto timed_stage = [&](State& state, const StageSpec& s, const std::string& sub,
                         const std::function<void(double, const State&)>& on_checkpoint) {
    const std::string csv = stage_csv(sub, s.name);
    const auto t0 = std::chrono::steady_clock::now();
    const std::int64_t steps = run_stage(model, state, s, csv, vtk_dir, on_checkpoint, opt.quiet,
                                         (dir / ("failed_" + s.name + ".ckpt")).string());
    record_time(s.name, steps, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                state.count());
  };

  auto timed_path = [&](State& state, const DeformationMode& mode, const std::string& name) {
    const std::string csv = stage_csv("deviatoric", name);
    const auto t0 = std::chrono::steady_clock::now();
    const std::int64_t steps = run_path(model, state, mode, name, csv, opt.quiet, (dir / ("failed_" + name + ".ckpt")).string());
    record_time(name, steps, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), state.count());
  };

  // The scene embedded in checkpoints without integration.threads (the bits do not depend on it,
  // 1-4 threads): a run resumed with another thread count writes the same checkpoint bytes.
  const std::string ckpt_scene = scene_without_threads(opt.scene_toml);
  bool tilted_noted = false;
  if (want_prep) {
    State state = std::move(start);
    const SaveCheckpoint save = [&](const std::string& series, double phi, const State& st) {
      const std::string stem = checkpoint_stem(series, phi);
      write_checkpoint((dir / "checkpoints" / (stem + ".ckpt")).string(),
                       Checkpoint{ckpt_scene, series + " " + fmt_phi(phi), st});
      if (st.box.tilted()) {   // the YADE text format has no tilt: the .ckpt alone holds the state
        if (!tilted_noted)
          std::cerr << "dem: note: the cell is tilted (a sheared packing): checkpoints are written as .ckpt only, "
                       "without the .txt packing (its '##PERIODIC:: Lx Ly Lz' format cannot hold the tilt)\n";
        tilted_noted = true;
      } else {
        write_packing((dir / "checkpoints" / (stem + ".txt")).string(), st);
      }
      note("checkpoint " + stem);
    };
    const RunSpec run = [&](State& st, const StageSpec& s, const std::function<void(double, const State&)>& on_ck) {
      timed_stage(st, s, "prep", on_ck);
    };
    if (p.preparation_explicit &&
        std::find(prep_names.begin(), prep_names.end(), "cycle_unloading") == prep_names.end())
      std::cerr << "dem: note: no preparation stage is named cycle_unloading: `dem fit` and `dem model` read the "
                   "isotropic (unloading) branch from prep/cycle_unloading.csv, so they will have none; name the "
                   "unloading stage you want fitted so\n";
    const RunStress run_stress = [&](State& st, const PrepStage& s) {
      Model m = model;   // the stage's rate is its servo's rate limit
      m.protocol.servo.rate_max = s.rate;
      m.protocol.servo.rate_max_tc = s.rate * model.t_contact;
      const std::string csv = stage_csv("prep", s.name);
      const auto t0 = std::chrono::steady_clock::now();
      const std::int64_t steps = run_path(m, st, stress_stage_path(s), s.name, csv, opt.quiet,
                                          (dir / ("failed_" + s.name + ".ckpt")).string());
      record_time(s.name, steps, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                  st.count());
    };
    for (std::size_t i = first_prep; i < p.preparation.size(); ++i) {
      run_prep_stage(p.preparation[i], state, run, run_stress, save);
      write_checkpoint((dir / "prep" / ("after_" + prep_names[i] + ".ckpt")).string(),
                       Checkpoint{ckpt_scene, "end of stage " + prep_names[i], state});
      man.save();
    }
  }

  if (want_dev) {
    for (double phi : checkpoints_to_run(p, dir)) {
      const fs::path ck = dir / "checkpoints" / (checkpoint_stem(p.modes_from, phi) + ".ckpt");
      if (!fs::exists(ck))
        throw std::runtime_error("checkpoint " + ck.string() + " is missing: run --stages prep first");
      for (const auto& mode : p.modes) {
        const std::string name = mode.name + "_" + fmt_phi(phi);
        if ((!want_prep || resume) && !opt.force && fs::exists(dir / "deviatoric" / (name + ".csv"))) {
          note("deviatoric " + name + ": finished earlier, kept (--force recomputes it)");
          continue;
        }
        Checkpoint c = read_checkpoint(ck.string());
        State state = std::move(c.state);
        note("deviatoric " + name + " from " + ck.filename().string());
        if (mode.path.empty()) {
          StageSpec s{name, mode.rate_shape * p.deviatoric_rate, StopKind::DeviatoricStrain, p.eps_d_max, {}, 0, 0, mode_definition(model, mode),
                      mode.shear_shape * p.deviatoric_rate};
          timed_stage(state, s, "deviatoric", nullptr);
        } else {
          timed_path(state, mode, name);
        }
        man.save();
      }
    }
  }
  man.complete = true;
  man.save();
  note("done: results in " + dir.string());
}

}  // namespace dem
