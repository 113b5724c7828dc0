#include "dem/protocol.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>

#include "dem/contact_law.hpp"
#include "dem/engine.hpp"
#include "dem/io.hpp"
#include "dem/measure.hpp"
#include "dem/scene.hpp"

namespace fs = std::filesystem;

namespace dem {

namespace {

std::string csv_header() {
  std::string h;
  for (auto& c : curve_columns()) h += (h.empty() ? "" : ",") + c;
  return h;
}

// Comment lines of every curve CSV: what the columns mean.
std::string csv_preamble(const Model& m, const std::string& stage) {
  std::ostringstream o;
  o << "# dem curve: stage=" << stage << "\n"
    << "# units: SI; *_Pa pascal, *_J joule, time_s second; other columns dimensionless\n"
    << "# strains: true (log) box strains ln(L/L0) since the stage start, extension positive\n"
    << "# eps_v=(eps_xx+eps_yy+eps_zz)/3; eps_d, sigma_dev, F_dev = sqrt(((a-b)^2+(b-c)^2+(c-a)^2)/2) of the diagonal\n"
    << "# stress: compression positive, contact + kinetic (fluctuation) parts; p=tr/3; p_star=2<r>p/k; s_dev=sigma_dev/p\n"
    << "# fabric: F=(1/V) sum_p V_p sum_c n(x)n; C=2*contacts/N; rattlers: <4 contacts, removed recursively\n"
    << "# overlap_*_rel: overlap / smaller radius of the pair; inertial_number=max|rate| 2<r> sqrt(rho/p)\n"
    << "# t_c=" << m.t_contact << " s, dt=" << m.dt << " s, k=" << m.contact.stiffness
    << " N/m, gamma=" << m.contact.damping << " kg/s, gamma_b=" << m.background_damping << " kg/s\n";
  return o.str();
}

std::vector<int> contact_counts(const State& s, const NeighborList& list) {
  std::vector<int> c(s.count(), 0);
  for_each_contact(s, list, [&](int i, int j, const Vec3&, double, double) { ++c[i]; ++c[j]; });
  return c;
}

double potential_energy(const Model& m, const State& s, const NeighborList& list) {
  const LinearSpringDashpot law(m.contact);
  double e = 0;
  for_each_contact(s, list, [&](int, int, const Vec3&, double, double delta) { e += law.energy(delta); });
  return e;
}

// Energy of a 0.1%-of-r_min overlap per particle: the floor of the relaxation criterion [J].
double energy_floor(const Model& m, const State& s) {
  const double d = 1e-3 * m.radius_min;
  return s.count() * 0.5 * m.contact.stiffness * d * d;
}

// Above this inertial number the deviatoric response depends visibly on the strain rate.
constexpr double kQuasiStaticInertial = 1e-3;

}  // namespace

std::string fmt_phi(double phi) {
  char b[32];
  std::snprintf(b, sizeof b, "phi%.3f", phi);
  return b;
}

std::int64_t run_stage(const Model& model, State& state, const StageSpec& spec,
                       const std::string& csv_path, const std::string& vtk_dir,
                       const std::function<void(double, const State&)>& on_checkpoint,
                       bool quiet) {
  using clock = std::chrono::steady_clock;
  // Strains from the stage start; lengths re-based so that opposite rates cancel exactly.
  state.box.length0 = state.box.length;
  state.box.reference = state.box.length;
  state.box.log_strain = Vec3{0, 0, 0};
  Engine engine(model, state);
  const double dt = model.dt;
  const double vol_rate = spec.rate.x + spec.rate.y + spec.rate.z;
  const double dev_shape = deviatoric_magnitude(spec.rate.x, spec.rate.y, spec.rate.z);
  const bool isotropic_shape = dev_shape < 1e-12 * (std::fabs(vol_rate) + 1e-300);

  // Progress variable x and its increment per full step (linear in the step's rate scale).
  auto progress_value = [&]() -> double {
    switch (spec.stop) {
      case StopKind::VolumeFractionUp:
      case StopKind::VolumeFractionDown: return std::log(state.volume_fraction());
      case StopKind::DeviatoricStrain: {
        const Vec3 e = state.box.true_strain();
        return isotropic_shape ? std::fabs(e.x + e.y + e.z) / 3.0 : deviatoric_magnitude(e.x, e.y, e.z);
      }
      case StopKind::Relaxed: return state.time;
    }
    return 0;
  };
  double step_increment = 0;
  std::vector<double> events;   // progress values to land on exactly, in order
  switch (spec.stop) {
    case StopKind::VolumeFractionUp:
    case StopKind::VolumeFractionDown: {
      step_increment = -vol_rate * dt;
      for (double phi : spec.checkpoint_phis) events.push_back(std::log(phi));
      events.push_back(std::log(spec.target));
      const bool up = spec.stop == StopKind::VolumeFractionUp;
      std::sort(events.begin(), events.end());
      if (!up) std::reverse(events.begin(), events.end());
      if ((up && !(vol_rate < 0)) || (!up && !(vol_rate > 0)))
        throw std::logic_error("stage " + spec.name + ": rate does not move phi toward the target");
      break;
    }
    case StopKind::DeviatoricStrain:
      step_increment = (isotropic_shape ? std::fabs(vol_rate) / 3.0 : dev_shape) * dt;
      events.push_back(spec.target);
      break;
    case StopKind::Relaxed: step_increment = dt; break;
  }
  const std::size_t n_checkpoint_events = spec.stop == StopKind::DeviatoricStrain ? 0 : events.size() - 1;

  std::ofstream csv(csv_path + ".part", std::ios::trunc);
  if (!csv) throw std::runtime_error("cannot write " + csv_path + ".part");
  csv << csv_preamble(model, spec.name) << csv_header() << ",stage\n";

  Measurement last_m = measure(model, state, engine.neighbor_list(), spec.rate);
  auto write_row = [&](const Measurement& m) { csv << curve_row(m) << "," << spec.name << "\n"; };
  write_row(last_m);
  State last_good = state;
  double last_sample_x = progress_value();
  std::vector<std::pair<double, std::string>> vtk_files;
  auto snapshot = [&]() {
    if (!model.output.vtk || vtk_dir.empty()) return;
    char name[256];
    std::snprintf(name, sizeof name, "%s_%04zu.vtu", spec.name.c_str(), vtk_files.size());
    write_vtu(vtk_dir + "/" + name, state, contact_counts(state, engine.neighbor_list()));
    vtk_files.emplace_back(state.time, name);
    write_pvd(vtk_dir + "/" + spec.name + ".pvd", vtk_files);
  };
  snapshot();

  const double x_start = progress_value();
  const double x_end = spec.stop == StopKind::Relaxed ? state.time + model.protocol.relax_max_time : events.back();
  const double vtk_dx = model.output.vtk_per_stage > 0 ? (x_end - x_start) / (model.output.vtk_per_stage + 1) : 0;
  double next_vtk_x = x_start + vtk_dx;
  const double sample_dx = spec.stop == StopKind::VolumeFractionUp || spec.stop == StopKind::VolumeFractionDown
                               ? 3.0 * model.output.sample_strain   // ln(phi) changes 3x the axis strain
                               : model.output.sample_strain;
  const double e_floor = energy_floor(model, state);
  std::size_t next_event = 0;
  std::int64_t steps = 0;
  const std::int64_t step0 = state.step;
  auto wall0 = clock::now(), last_progress = wall0;
  double prev_sample_ekin = last_m.E_kin;
  double max_inertial = 0;
  bool done = false;

  try {
    while (!done) {
      // Shorten the step to land exactly on the next event.
      double scale = 1.0;
      if (spec.stop != StopKind::Relaxed && next_event < events.size()) {
        const double remaining = std::fabs(events[next_event] - progress_value());
        if (remaining < std::fabs(step_increment)) scale = remaining / std::fabs(step_increment);
      }
      engine.step(spec.rate * scale);
      ++steps;
      bool sample = false;
      if (spec.stop == StopKind::Relaxed) {
        if (steps % model.output.relax_sample_steps == 0) sample = true;
        if (steps % 100 == 0) {
          const double ek = state.kinetic_energy();
          if (ek < model.protocol.relax_ke_ratio *
                       std::max(potential_energy(model, state, engine.neighbor_list()), e_floor))
            done = true;
        }
        if (state.time >= x_end) done = true;
      } else {
        const double x = progress_value();
        while (next_event < events.size() && scale < 1.0) {
          // landed on events[next_event]
          if (next_event < n_checkpoint_events && on_checkpoint) {
            const double phi = std::exp(events[next_event]);
            last_m = measure(model, state, engine.neighbor_list(), spec.rate);
            write_row(last_m);
            last_sample_x = x;
            on_checkpoint(phi, state);
          }
          if (next_event == events.size() - 1) done = true;
          ++next_event;
          scale = 1.0;   // only one event per step
        }
        if (std::fabs(x - last_sample_x) >= sample_dx * (1 - 1e-9)) sample = true;
        if (vtk_dx > 0 && ((vtk_dx > 0 && x >= next_vtk_x) || (vtk_dx < 0 && x <= next_vtk_x))) {
          snapshot();
          next_vtk_x += vtk_dx;
        }
      }
      if (sample || done) {
        engine.check_sanity();
        last_m = measure(model, state, engine.neighbor_list(), spec.rate);
        const double e_ref = std::max(last_m.E_pot, e_floor);
        if (last_m.E_kin > 1e3 * e_ref && last_m.E_kin > 10 * prev_sample_ekin)
          throw BlowUp("kinetic energy exploded to " + std::to_string(last_m.E_kin) + " J (" +
                       std::to_string(last_m.E_kin / e_ref) + " x the elastic energy) at step " +
                       std::to_string(state.step) + ": the time step (dt_over_tc = " +
                       std::to_string(model.dt_over_tc) + ") or the strain rate is too large");
        prev_sample_ekin = last_m.E_kin;
        max_inertial = std::max(max_inertial, last_m.inertial_number);
        write_row(last_m);
        csv.flush();
        last_sample_x = progress_value();
        last_good = state;
      }
      if (!quiet) {
        auto now = clock::now();
        const double since = std::chrono::duration<double>(now - last_progress).count();
        if (since >= model.output.progress_seconds || done) {
          last_progress = now;
          const double wall = std::chrono::duration<double>(now - wall0).count();
          const double frac = std::clamp((progress_value() - x_start) / (x_end - x_start), 0.0, 1.0);
          const double rate = steps * static_cast<double>(state.count()) / std::max(wall, 1e-9);
          const double eta = frac > 0 ? wall * (1 - frac) / frac : 0;
          char line[400];
          std::snprintf(line, sizeof line,
                        "[%s] step %lld  eps_d %.4f  phi %.4f  p %.3e Pa  s_dev %.4f  C %.2f  "
                        "%.2f M particle-steps/s  %3.0f%%  ~%.0f s left\n",
                        spec.name.c_str(), static_cast<long long>(state.step - step0), last_m.eps_d,
                        state.volume_fraction(), last_m.p, last_m.s_dev, last_m.C, rate / 1e6,
                        100 * frac, eta);
          std::cerr << line << std::flush;
        }
      }
    }
  } catch (const BlowUp&) {
    csv.close();
    // Keep the partial curve visibly partial (.part) and save the last good state.
    Checkpoint c{"", "last good state of stage " + spec.name, last_good};
    const fs::path dir = fs::path(csv_path).parent_path().parent_path();
    write_checkpoint((dir / ("failed_" + spec.name + ".ckpt")).string(), c);
    throw;
  }
  snapshot();
  csv.close();
  fs::rename(csv_path + ".part", csv_path);
  if (spec.stop == StopKind::DeviatoricStrain && max_inertial > kQuasiStaticInertial)
    std::cerr << "dem: warning: stage " << spec.name << " reached an inertial number of " << max_inertial
              << " (> " << kQuasiStaticInertial << "): not quasi-static; the curves depend on the rate. "
              << "Lower protocol.deviatoric_rate_tc (see docs/stability.md)\n";
  return steps;
}

// ---------------------------------------------------------------------------------------

namespace {

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') { o += '\\'; o += c; }
    else if (c == '\n') o += "\\n";
    else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
    else o += c;
  }
  return o;
}

struct Manifest {
  struct Output {
    std::string stage, file;
    std::int64_t steps = -1;   // -1: produced by an earlier invocation
    double wall_s = 0, particle_steps_per_s = 0;
  };
  std::string path, scene, command;
  std::vector<Output> stages;
  bool complete = false;
  void save() const {
    std::ostringstream o;
    o << "{\n  \"tool\": \"dem\",\n  \"version\": \"" DEM_VERSION "\",\n  \"command\": \""
      << json_escape(command) << "\",\n  \"complete\": " << (complete ? "true" : "false")
      << ",\n  \"outputs\": [";
    for (std::size_t i = 0; i < stages.size(); ++i) {
      const Output& st = stages[i];
      o << (i ? ",\n    " : "\n    ") << "{\"stage\": \"" << json_escape(st.stage) << "\", \"file\": \""
        << json_escape(st.file) << "\"";
      if (st.steps >= 0)
        o << ", \"steps\": " << st.steps << ", \"wall_s\": " << st.wall_s
          << ", \"particle_steps_per_s\": " << st.particle_steps_per_s;
      o << "}";
    }
    o << "\n  ]\n}\n";
    write_file_atomic(path, o.str());
  }
};

}  // namespace

void run_protocol(const Model& model, const RunOptions& opt) {
  if (model.ensemble_packings > 1)
    throw SceneError("ensemble.packings = " + std::to_string(model.ensemble_packings) +
                     ": this scene is an ensemble of independent packings; run it with `dem ensemble SCENE --out DIR` "
                     "(or pass --set ensemble.packings=1 for one packing)");
  const fs::path dir(opt.out_dir);
  const bool want_prep = opt.stages == "all" || opt.stages == "prep";
  const bool want_dev = opt.stages == "all" || opt.stages == "deviatoric";
  if (!want_prep && !want_dev)
    throw std::runtime_error("--stages must be all, prep or deviatoric (got '" + opt.stages + "')");
  if (fs::exists(dir / "manifest.json") && !opt.force && want_prep)
    throw std::runtime_error("results already exist in " + dir.string() +
                             " (manifest.json): choose another --out, or pass --force to overwrite");
  if (opt.force && fs::is_directory(dir))   // stale failure states of an earlier attempt
    for (auto& f : fs::directory_iterator(dir))
      if (f.path().filename().string().rfind("failed_", 0) == 0) fs::remove(f.path());
  fs::create_directories(dir / "prep");
  fs::create_directories(dir / "checkpoints");
  fs::create_directories(dir / "deviatoric");
  const std::string vtk_dir = model.output.vtk ? (dir / "vtk").string() : "";
  if (model.output.vtk) fs::create_directories(dir / "vtk");
  write_file_atomic((dir / "scene.toml").string(), opt.scene_toml);

  Manifest man{(dir / "manifest.json").string(), opt.scene_toml, opt.command_line, {}, false};
  const Protocol& p = model.protocol;
  auto note = [&](const std::string& what) {
    if (!opt.quiet) std::cerr << "dem: " << what << "\n";
  };
  auto record = [&](const std::string& sub, const std::string& name) {
    const std::string file = (fs::path(sub) / (name + ".csv")).string();
    for (const auto& st : man.stages)
      if (st.file == file) return;
    man.stages.push_back({name, file});
  };
  auto stage_csv = [&](const std::string& sub, const std::string& name) {
    const fs::path f = dir / sub / (name + ".csv");
    if (fs::exists(f) && !opt.force)
      throw std::runtime_error(f.string() + " exists: pass --force to overwrite finished results");
    record(sub, name);
    return f.string();
  };
  // Runs a stage and records its steps and wall time in the manifest entry of its CSV.
  auto timed_stage = [&](State& state, const StageSpec& s, const std::string& sub,
                         const std::function<void(double, const State&)>& on_checkpoint) {
    const std::string csv = stage_csv(sub, s.name);
    const auto t0 = std::chrono::steady_clock::now();
    const std::int64_t steps = run_stage(model, state, s, csv, vtk_dir, on_checkpoint, opt.quiet);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (auto& st : man.stages)
      if (st.stage == s.name) {
        st.steps = steps;
        st.wall_s = wall;
        st.particle_steps_per_s = wall > 0 ? steps * double(state.count()) / wall : 0.0;
      }
  };
  if (!want_prep) {   // keep the outputs of earlier invocations in the manifest
    for (const char* sub : {"prep", "deviatoric"}) {
      std::vector<std::string> names;
      for (auto& f : fs::directory_iterator(dir / sub))
        if (f.path().extension() == ".csv") names.push_back(f.path().stem().string());
      std::sort(names.begin(), names.end());
      for (const auto& name : names) record(sub, name);
    }
  }

  if (want_prep) {
    State state;
    if (!model.packing_file.empty() && fs::path(model.packing_file).extension() == ".ckpt") {
      note("continuing from checkpoint " + model.packing_file);
      state = read_checkpoint(model.packing_file).state;
    } else if (!model.packing_file.empty()) {
      note("reading packing " + model.packing_file);
      state = read_packing(model.packing_file, model.density);
    } else {
      note("placing " + std::to_string(model.count) + " spheres at phi = " + std::to_string(p.initial_phi));
      state = random_packing(model, p.initial_phi);
    }
    const double phi0 = state.volume_fraction();
    // 1. isotropic compression to target_phi (skipped when the packing is already denser)
    if (phi0 < p.target_phi) {
      StageSpec s{"compress", Vec3{-1, -1, -1} * p.compress_rate, StopKind::VolumeFractionUp, p.target_phi, {}};
      timed_stage(state, s, "prep", nullptr);
    }
    // 2. relaxation at constant volume
    {
      StageSpec s{"relax", Vec3{0, 0, 0}, StopKind::Relaxed, 0, {}};
      timed_stage(state, s, "prep", nullptr);
    }
    man.save();
    // 3. cycle: load to cycle_phi_max, unload to target_phi, checkpoints on the way
    auto save_ckpt = [&](const std::string& branch) {
      return [&, branch](double phi, const State& st) {
        const std::string stem = branch + "_" + fmt_phi(phi);
        write_checkpoint((dir / "checkpoints" / (stem + ".ckpt")).string(),
                         Checkpoint{opt.scene_toml, branch + " " + fmt_phi(phi), st});
        write_packing((dir / "checkpoints" / (stem + ".txt")).string(), st);
        note("checkpoint " + stem);
      };
    };
    {
      StageSpec s{"cycle_loading", Vec3{-1, -1, -1} * p.cycle_rate, StopKind::VolumeFractionUp,
                  p.cycle_phi_max, {}};
      for (double phi : p.checkpoints_loading)
        if (phi > state.volume_fraction() && phi < p.cycle_phi_max) s.checkpoint_phis.push_back(phi);
      timed_stage(state, s, "prep", save_ckpt("loading"));
    }
    {
      StageSpec s{"cycle_unloading", Vec3{1, 1, 1} * p.cycle_rate, StopKind::VolumeFractionDown,
                  p.target_phi, {}};
      bool top_checkpoint = false;
      for (double phi : p.checkpoints_unloading) {
        if (phi < p.cycle_phi_max && phi > p.target_phi) s.checkpoint_phis.push_back(phi);
        else top_checkpoint |= phi >= p.cycle_phi_max;
      }
      if (top_checkpoint) save_ckpt("unloading")(p.cycle_phi_max, state);
      const bool bottom = std::any_of(p.checkpoints_unloading.begin(), p.checkpoints_unloading.end(),
                                      [&](double f) { return f <= p.target_phi; });
      timed_stage(state, s, "prep", save_ckpt("unloading"));
      if (bottom) save_ckpt("unloading")(p.target_phi, state);
    }
    man.save();
  }

  if (want_dev) {
    std::vector<double> phis = p.checkpoints_unloading;
    std::sort(phis.begin(), phis.end(), std::greater<double>());
    for (double phi : phis) {
      const fs::path ck = dir / "checkpoints" / ("unloading_" + fmt_phi(phi) + ".ckpt");
      if (!fs::exists(ck))
        throw std::runtime_error("checkpoint " + ck.string() + " is missing: run --stages prep first");
      for (const auto& mode : p.modes) {
        const std::string name = mode.name + "_" + fmt_phi(phi);
        if (!want_prep && !opt.force && fs::exists(dir / "deviatoric" / (name + ".csv"))) {
          note("deviatoric " + name + ": finished earlier, kept (--force recomputes it)");
          continue;
        }
        Checkpoint c = read_checkpoint(ck.string());
        State state = std::move(c.state);
        note("deviatoric " + name + " from " + ck.filename().string());
        StageSpec s{name, mode.rate_shape * p.deviatoric_rate, StopKind::DeviatoricStrain, p.eps_d_max, {}};
        timed_stage(state, s, "deviatoric", nullptr);
        man.save();
      }
    }
  }
  man.complete = true;
  man.save();
  note("done: results in " + dir.string());
}

}  // namespace dem
