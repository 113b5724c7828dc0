#include "dem/stages/protocol.hpp"
#include "dem/io/preparation.hpp"

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
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"

namespace fs = std::filesystem;

namespace dem {

namespace {

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

// What run_protocol decided before writing anything: which parts run, whether it resumes an
// interrupted run and after which preparation stage, and the state the preparation starts from.
struct RunStart {
  bool want_prep = false, want_dev = false, resume = false;
  std::vector<std::string> prep_names;
  std::string resume_after;
  std::size_t first_prep = 0;   // the first preparation stage this invocation runs
  State start;
};

// The checks before anything is written (then --force's clearing): the folder is no ensemble's, a
// finished run is not overwritten, memory, the resume point's physics, the checkpoints and kept
// curves of a --stages deviatoric run; the starting state read and checked.
RunStart check_before_writing(const Model& model, const RunOptions& opt, const fs::path& dir,
                              const std::function<void(const std::string&)>& note) {
  RunStart r;
  r.want_prep = opt.stages == "all" || opt.stages == "prep";
  r.want_dev = opt.stages == "all" || opt.stages == "deviatoric";
  if (!r.want_prep && !r.want_dev)
    throw SceneError("--stages must be all, prep or deviatoric (got '" + opt.stages + "')");
  if (const std::string kind = ensemble_folder_kind(dir); !kind.empty())
    throw std::runtime_error(dir.string() + " is " + kind + ", not a run folder: `dem run` would overwrite its "
                             "scene.toml and, with --force, delete its fit/ and plots/ (the ensemble's fit tables and "
                             "figures): choose another --out for a single run; continue the ensemble with `dem ensemble "
                             "SCENE --out " + dir.string() + "`");
  r.resume = r.want_prep && !opt.force && fs::exists(dir / "manifest.json");
  if (r.resume && manifest_complete(dir / "manifest.json"))
    throw std::runtime_error("results already exist in " + dir.string() + " (manifest.json: a finished run): choose "
                             "another --out, or pass --force to replace them");
  if (r.want_prep && !r.resume) check_memory(model);
  r.prep_names = prep_stage_names(model);
  r.resume_after = r.resume ? last_finished_prep_stage(dir, r.prep_names) : "";
  if (!r.resume_after.empty()) r.start = resume_state(model, dir, r.resume_after);
  if (!r.want_prep) check_checkpoints(model, dir);
  if (r.want_dev && !opt.force) check_kept_curves(model, dir);
  if (r.want_prep && r.resume_after.empty()) r.start = initial_state(model, note);
  if (opt.force) clear_replaced(dir, r.want_prep, r.prep_names);
  if (r.resume)
    std::cerr << "dem: " << dir.string() << " holds an interrupted run (manifest.json: complete: false): resuming "
              << (r.resume_after.empty() ? "the preparation from its start"
                                         : "after the finished stage " + r.resume_after + " (prep/after_" +
                                               r.resume_after + ".ckpt)")
              << "; finished deviatoric curves are kept\n";
  if (!r.resume_after.empty())
    r.first_prep = std::find(r.prep_names.begin(), r.prep_names.end(), r.resume_after) - r.prep_names.begin() + 1;
  return r;
}

// The run folder being written: its manifest (which says "not complete" until the end), where
// each stage's files go, and the checkpoints.
struct RunFolder {
  const Model& model;
  const RunOptions& opt;
  const RunStart& run;
  fs::path dir;
  Manifest man;
  std::string vtk_dir, prep_hash, shear_hash;
  // The scene embedded in checkpoints without integration.threads (the bits do not depend on it,
  // 1-4 threads): a run resumed with another thread count writes the same checkpoint bytes.
  std::string ckpt_scene;
  bool tilted_noted = false;

  RunFolder(const Model& m, const RunOptions& o, const RunStart& r)
      : model(m), opt(o), run(r), dir(o.out_dir),
        man{(dir / "manifest.json").string(), o.scene_toml, o.command_line, {}, false},
        prep_hash(physics_hash(preparation_physics(m))), shear_hash(physics_hash(shear_physics(m))),
        ckpt_scene(scene_without_threads(o.scene_toml)) {
    fs::create_directories(dir / "prep");
    fs::create_directories(dir / "checkpoints");
    fs::create_directories(dir / "deviatoric");
    vtk_dir = model.output.vtk ? (dir / "vtk").string() : "";
    if (model.output.vtk) fs::create_directories(dir / "vtk");
    write_file_atomic((dir / "scene.toml").string(), opt.scene_toml);
    // Outputs of earlier invocations that this one keeps.
    for (const char* sub : {"prep", "deviatoric"})
      for (const auto& name : csv_stems(dir / sub)) {
        const bool rerun = run.want_prep && std::string(sub) == "prep" &&
                           std::find(run.prep_names.begin() + run.first_prep, run.prep_names.end(), name) !=
                               run.prep_names.end();
        if ((!run.want_prep || run.resume) && !rerun)
          record(sub, name, first_word(curve_physics_line(dir / sub / (name + ".csv"))));
      }
    man.save();
  }
  void note(const std::string& what) const {
    if (!opt.quiet) std::cerr << "dem: " << what << "\n";
  }
  void record(const std::string& sub, const std::string& name, const std::string& physics) {
    const std::string file = (fs::path(sub) / (name + ".csv")).string();
    for (auto& st : man.stages)
      if (st.file == file) { st.physics = physics; return; }
    man.stages.push_back({name, file, physics});
  }
  std::string stage_csv(const std::string& sub, const std::string& name) {
    const fs::path f = dir / sub / (name + ".csv");
    if (fs::exists(f) && !opt.force && !run.resume)
      throw std::runtime_error(f.string() + " exists: pass --force to overwrite finished results");
    record(sub, name, sub == "deviatoric" ? shear_hash : prep_hash);
    return f.string();
  }
  void record_time(const std::string& stage, std::int64_t steps, double wall, int n) {
    for (auto& st : man.stages)
      if (st.stage == stage) {
        st.steps = steps;
        st.wall_s = wall;
        st.particle_steps_per_s = wall > 0 ? steps * double(n) / wall : 0.0;
      }
  }
  // Runs a stage (run_prep_stage, run_mode) into DIR/sub/<name>.csv and records its steps and
  // wall time in the manifest entry of that CSV.
  void timed(const std::string& sub, const std::string& name, const State& state,
             const std::function<std::int64_t(const StageOutput&)>& stage) {
    const StageOutput out{stage_csv(sub, name), vtk_dir, (dir / ("failed_" + name + ".ckpt")).string(), opt.quiet,
                          nullptr};
    const auto t0 = std::chrono::steady_clock::now();
    const std::int64_t steps = stage(out);
    record_time(name, steps, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                state.count());
  }
  // checkpoints/<series>_phiX.XXX.ckpt and, for an untilted cell, its YADE text packing .txt.
  void save_checkpoint(const std::string& series, double phi, const State& st) {
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
  }
};

// The preparation stages from the first this invocation runs, each ending with its resume point.
void run_preparation(RunFolder& f, State state) {
  const Model& model = f.model;
  const std::vector<std::string>& names = f.run.prep_names;
  if (model.protocol.preparation_explicit && std::find(names.begin(), names.end(), "cycle_unloading") == names.end())
    std::cerr << "dem: note: no preparation stage is named cycle_unloading: `dem fit` and `dem model` read the "
                 "isotropic (unloading) branch from prep/cycle_unloading.csv, so they will have none; name the "
                 "unloading stage you want fitted so\n";
  const SaveCheckpoint save = [&](const std::string& series, double phi, const State& st) {
    f.save_checkpoint(series, phi, st);
  };
  for (std::size_t i = f.run.first_prep; i < model.protocol.preparation.size(); ++i) {
    const PrepStage& s = model.protocol.preparation[i];
    if (prep_stage_skipped(s, state.volume_fraction()))
      run_prep_stage(model, s, state, StageOutput{}, save);   // says so, writes nothing
    else
      f.timed("prep", s.name, state, [&](const StageOutput& out) { return run_prep_stage(model, s, state, out, save); });
    write_checkpoint((f.dir / "prep" / ("after_" + names[i] + ".ckpt")).string(),
                     Checkpoint{f.ckpt_scene, "end of stage " + names[i], state});
    f.man.save();
  }
}

// Every mode and path from every checkpoint of the series modes_from (curves finished by an
// earlier invocation kept unless --force).
void run_modes(RunFolder& f) {
  const Model& model = f.model;
  const Protocol& p = model.protocol;
  for (double phi : checkpoints_to_run(p, f.dir)) {
    const fs::path ck = f.dir / "checkpoints" / (checkpoint_stem(p.modes_from, phi) + ".ckpt");
    if (!fs::exists(ck))
      throw std::runtime_error("checkpoint " + ck.string() + " is missing: run --stages prep first");
    for (const auto& mode : p.modes) {
      const std::string name = mode.name + "_" + fmt_phi(phi);
      if ((!f.run.want_prep || f.run.resume) && !f.opt.force && fs::exists(f.dir / "deviatoric" / (name + ".csv"))) {
        f.note("deviatoric " + name + ": finished earlier, kept (--force recomputes it)");
        continue;
      }
      Checkpoint c = read_checkpoint(ck.string());
      State state = std::move(c.state);
      f.note("deviatoric " + name + " from " + ck.filename().string());
      f.timed("deviatoric", name, state, [&](const StageOutput& out) { return run_mode(model, state, mode, name, out); });
      f.man.save();
    }
  }
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
  auto note = [&](const std::string& what) {
    if (!opt.quiet) std::cerr << "dem: " << what << "\n";
  };
  RunStart run = check_before_writing(model, opt, fs::path(opt.out_dir), note);   // 1. before anything is written
  RunFolder folder(model, opt, run);                                               // 2. the folder and its manifest
  if (run.want_prep) run_preparation(folder, std::move(run.start));
  if (run.want_dev) run_modes(folder);
  folder.man.complete = true;
  folder.man.save();
  note("done: results in " + opt.out_dir);
}

}  // namespace dem
