// dem: command-line front end. Each subcommand is a small struct: its options (add) and what
// it does (run); main parses and maps exceptions to the README's exit codes.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <thread>
#include <sys/wait.h>
#include <unistd.h>

#include "dem/contact/registry.hpp"
#include "dem/io/checks.hpp"
#include "dem/stages/collision.hpp"
#include "dem/engine/engine.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/plan.hpp"
#include "dem/io/preparation.hpp"
#include "dem/stages/protocol.hpp"
#include "dem/io/scene.hpp"
#include "dem/io/sweep.hpp"
#include "demfit/cli.hpp"
#include "demfit/ensemble.hpp"
#include "demfit/identifiability.hpp"
#include "demfit/model_cli.hpp"

namespace fs = std::filesystem;

namespace {

std::string join_args(int argc, char** argv) {
  std::string s;
  for (int i = 0; i < argc; ++i) s += (i ? " " : "") + std::string(argv[i]);
  return s;
}

// Python helpers live in <repo>/demkit; find them next to the executable's source tree.
int exec_python(const std::string& module, const std::vector<std::string>& args) {
  const char* py = std::getenv("DEM_PYTHON");
  std::string python = py ? py : "/usr/bin/python3";
  std::vector<std::string> argv_s = {python, "-m", module};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string root = DEM_SOURCE_DIR;
  const char* old = std::getenv("PYTHONPATH");
  setenv("PYTHONPATH", (root + (old ? ":" + std::string(old) : "")).c_str(), 1);
  execv(python.c_str(), argv.data());
  std::cerr << "dem: cannot start " << python << " (set DEM_PYTHON to a python3 with numpy and matplotlib)\n";
  return 1;
}

// The same, as a child: its exit status (127 when python cannot start).
int run_python(const std::string& module, const std::vector<std::string>& args) {
  std::cout.flush();
  const pid_t pid = fork();
  if (pid < 0) return 127;
  if (pid == 0) _exit(exec_python(module, args) == 0 ? 0 : 127);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  return WIFEXITED(status) ? WEXITSTATUS(status) : 127;
}

// Integration is stable for a single contact up to dt/t_c = 2/pi (refused above), but dense
// packings went unstable at 0.48-0.52 (docs/stability.md): warn before that.
void warn_time_step(const dem::Model& m) {
  if (m.dt_over_tc > 0.45)
    std::fprintf(stderr, "dem: warning: integration.dt_over_tc = %g is near the stability limit of dense packings "
                         "(0.48-0.52 measured, docs/stability.md); expect a blow-up, or use 0.1\n", m.dt_over_tc);
  // The pair loop's blocks fix the summation order; their default is max(4, threads).
  const int threads = m.threads > 0 ? m.threads : static_cast<int>(std::thread::hardware_concurrency());
  if (m.blocks == 0 && threads > 4)
    std::fprintf(stderr, "dem: note: %d threads run %d blocks of the pair loop, another summation order than 1-4 "
                         "threads (4 blocks): the curves differ from theirs in the last bits and then chaotically; "
                         "--set integration.blocks=4 gives the bits of 1-4 threads\n", threads, threads);
}

// --set takes one value per occurrence (repeatable), so `--set k=v SCENE` leaves SCENE to the positional.
CLI::Option* add_set_option(CLI::App& cmd, std::vector<std::string>& overrides, const std::string& text) {
  return cmd.add_option("--set", overrides, text)->allow_extra_args(false)->type_name("KEY=VALUE")->default_str("");
}

std::string g_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

// What bounds the tension of a contact: the no-tension clamp, nothing, or a normal law with history
// (Luding's adhesive limit: its own line says).
std::string tension_limit(const dem::ContactLaw& c) {
  if (dem::contact::find_submodel(dem::ContactSlot::Normal, c.model(dem::ContactSlot::Normal))->history > 0)
    return "tension as the normal law says (below)";
  return c.allow_attractive() ? "attractive allowed" : "clamped at zero";
}

void print_info(const dem::Model& m) {
  warn_time_step(m);
  const auto& p = m.protocol;
  std::printf("particles          N = %d, r in [%g, %g] m, rho = %g kg/m^3, memory ~%.3g MB (estimate)\n", m.count,
              m.radius_min, m.radius_max, m.density, dem::estimated_memory_bytes(m.count) / 1e6);
  std::printf("contact            gamma_b = %g kg/s (background damping), normal force %s; sub-models "
              "(dem info --contact-models lists every one with its keys):\n",
              m.background_damping, tension_limit(m.contact).c_str());
  const dem::contact::PairScale scale = dem::contact::pair_scale(m.contact, m.radius_min, m.density);
  for (const std::string& line : dem::contact::describe_contact(m.contact, scale)) std::printf("%s\n", line.c_str());
  std::printf("smallest pair      t_c = %.6g s, e = %.6g\n", m.t_contact, m.restitution);
  for (const std::string& line : dem::contact::stability_lines(m.contact, scale, m.dt))
    std::printf("stability          %s\n", line.c_str());
  std::printf("time step          dt = %.6g s (t_c / %.4g), %s\n", m.dt, 1.0 / m.dt_over_tc,
              m.integrator == dem::Integrator::VelocityVerlet ? "velocity Verlet" : "symplectic Euler");
  std::printf("neighbour list     skin = %.4g m = %.3g r_min (%s)\n", m.skin_over_rmin * m.radius_min, m.skin_over_rmin,
              m.skin_auto ? "auto: 0.4 (dt/t_c / 0.02)^0.4 above t_c/50, less in a box of few particles" : "set in the scene");
  const std::vector<double> prep_steps = dem::preparation_stage_steps(m);
  for (std::size_t i = 0; i < p.preparation.size(); ++i)
    std::printf("prep %-15s %s: %s%.3g steps\n", p.preparation[i].name.c_str(),
                dem::describe(p.preparation[i], m.t_contact).c_str(),
                p.preparation[i].kind == dem::PrepStage::Kind::Relax || p.preparation[i].kind == dem::PrepStage::Kind::Pressure ||
                        p.preparation[i].kind == dem::PrepStage::Kind::Uniaxial ? "at most " : "",
                prep_steps[i]);
  std::printf("modes              from the checkpoints %s, deviatoric rate %.4g /s (%.4g/t_c)\n", p.modes_from.c_str(),
              p.deviatoric_rate, p.deviatoric_rate * m.t_contact);
  for (auto& mode : p.modes) {
    if (!mode.path.empty()) {
      std::string stages;
      for (const auto& s : mode.path) stages += (stages.empty() ? "" : ", ") + s.name + (s.has_servo() ? " (servo)" : "");
      std::printf("path %-13s  %zu stages: %s; about %.3g steps\n", mode.name.c_str(), mode.path.size(), stages.c_str(),
                  dem::mode_steps(m, mode));
      continue;
    }
    if (mode.sheared())
      std::printf("mode %-13s  velocity gradient [[%g, %g, %g], [0, %g, %g], [0, 0, %g]]: %.3g steps to eps_d = %g\n",
                  mode.name.c_str(), mode.shape.diag.x, mode.shape.shear.x, mode.shape.shear.y, mode.shape.diag.y,
                  mode.shape.shear.z, mode.shape.diag.z, dem::mode_steps(m, mode), p.eps_d_max);
    else
      std::printf("mode %-13s  rate shape (%g, %g, %g): %.3g steps to eps_d = %g\n", mode.name.c_str(),
                  mode.shape.diag.x, mode.shape.diag.y, mode.shape.diag.z, dem::mode_steps(m, mode), p.eps_d_max);
  }
}

// The wall time of the scene's run from a short timed probe: about a second of D2 steps with the
// scene's physics and threads on the stored dense packing (N = 9261, phi = 0.70), scaled to the
// scene's mean radius; particle-steps from the run plan (the preparation's is a rough allowance).
void print_wall_time_estimate(const dem::Model& scene_model) {
  // An ensemble runs single-threaded tasks, one per core: probe one thread, divide by the cores.
  const bool ensemble = scene_model.ensemble_packings > 1;
  const int cores = ensemble ? std::max(1u, std::thread::hardware_concurrency()) : 1;
  dem::Model m = scene_model;
  if (ensemble) m.threads = 1;
  const std::string packing = std::string(DEM_SOURCE_DIR) + "/data/packings/n9261_phi0.70.txt";
  if (!fs::exists(packing)) {
    std::printf("wall time          (no estimate: %s is missing)\n", packing.c_str());
    return;
  }
  dem::State s = dem::read_packing(packing, m.density);
  double rsum = 0;
  for (double r : s.radius) rsum += r;
  const double scale = 0.5 * (m.radius_min + m.radius_max) / (rsum / s.count());
  for (auto& x : s.position) x *= scale;
  for (auto& r : s.radius) r *= scale;
  for (auto* v : {&s.box.length, &s.box.length0, &s.box.reference}) *v *= scale;
  for (int i = 0; i < s.count(); ++i) s.mass[i] = m.density * 4.0 / 3.0 * M_PI * std::pow(s.radius[i], 3);
  s.list_valid = false;
  const dem::Vec3 rate = dem::Vec3{1, 0, -1} * (m.protocol.deviatoric_rate > 0 ? m.protocol.deviatoric_rate : 1e-5 / m.t_contact);
  dem::Engine engine(m, s);
  for (int i = 0; i < 30; ++i) engine.step(rate);   // warm-up, first list build
  long steps = 0;
  const auto t0 = std::chrono::steady_clock::now();
  double wall = 0;
  while (wall < 1.0 || steps < 20) {
    for (int i = 0; i < 10; ++i) engine.step(rate);
    steps += 10;
    wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const double speed = steps * double(s.count()) / wall;
  const double per_member = dem::prep_particle_steps(m) + [&] {
    double t = 0;
    for (const auto& mode : m.protocol.modes) t += dem::mode_particle_steps(m, mode);
    return t * dem::mode_checkpoints(m.protocol).size();
  }();
  const double total = per_member * std::max(1, m.ensemble_packings);
  const double seconds = total / speed / cores;
  auto hms = [](double sec) {
    char b[64];
    if (sec < 120) std::snprintf(b, sizeof b, "%.0f s", sec);
    else if (sec < 7200) std::snprintf(b, sizeof b, "%.0f min", sec / 60);
    else std::snprintf(b, sizeof b, "%.1f h", sec / 3600);
    return std::string(b);
  };
  std::printf("wall time          about %s for %.3g particle-steps%s at %.3g M particle-steps/s (probe: %ld D2 steps "
              "on a dense packing of %d, %d thread%s; this machine now; the preparation's relaxations vary, so "
              "allow a factor 2)\n",
              hms(seconds).c_str(), total,
              ensemble ? (" (" + std::to_string(m.ensemble_packings) + " packings, one single-threaded task per core on " +
                          std::to_string(cores) + " cores)").c_str()
                       : "",
              speed / 1e6, steps, s.count(), engine.threads(), engine.threads() == 1 ? "" : "s");
}

// A command-line value that cannot be right (exit code 2).
struct ArgumentError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A positive finite option value as an exact TOML number (17 significant digits).
std::string exact_number(const char* option, double v) {
  if (!(v > 0) || !std::isfinite(v)) throw ArgumentError(std::string(option) + " must be a positive finite number");
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

// An output CSV path, checked before anything runs: not a folder, in a folder that exists.
void check_output_file(const std::string& out, bool force) {
  if (fs::is_directory(out)) throw ArgumentError("--out " + out + " is a folder: give a file name, e.g. " + out + "/D2.csv");
  const fs::path parent = fs::path(out).parent_path();
  if (!parent.empty() && !fs::is_directory(parent))
    throw ArgumentError("--out " + out + ": the folder " + parent.string() + " does not exist: create it first");
  if (fs::exists(out) && !force) throw std::runtime_error(out + " exists: pass --force to overwrite it");
}

// Every subcommand: `add` declares it and its options on the app, `run` does it (returns the
// exit code; throws for the codes main maps).
struct RunCommand {
  CLI::App* cmd = nullptr;
  std::string scene, out, stages = "all";
  bool force = false, quiet = false;
  int threads = -1;
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("run", "run a scene: preparation, checkpoints, deviatoric modes");
    cmd->add_option("scene", scene, "scene TOML file (see data/scenes/)")->required()->check(CLI::ExistingFile);
    cmd->add_option("--out", out, "results folder")->required();
    add_set_option(*cmd, overrides, "override a scene key: section.key=value (repeatable)");
    cmd->add_option("--stages", stages, "all | prep | deviatoric (deviatoric reuses DIR/checkpoints)");
    cmd->add_option("--threads", threads, "threads, 1 or more (default: integration.threads, whose 0 means all cores)")
        ->check(CLI::Range(1, 4096))->default_str("");
    cmd->add_flag("--force", force, "overwrite finished results in --out");
    cmd->add_flag("--quiet", quiet, "no progress lines on stderr");
  }
  int run(std::vector<std::string> overrides, const std::string& command_line) const {
    if (threads >= 1) overrides.push_back("integration.threads=" + std::to_string(threads));
    std::string resolved;
    dem::Model model = dem::load_scene_file(scene, overrides, &resolved);
    dem::RunOptions o;
    o.out_dir = out;
    o.stages = stages;
    o.force = force;
    o.quiet = quiet;
    o.scene_toml = resolved;
    o.command_line = command_line;
    if (!quiet) print_info(model);
    else warn_time_step(model);
    dem::run_protocol(model, o);
    return 0;
  }
};

// K packings through the Snakemake workflow; with a sweep, one such ensemble per row.
struct EnsembleCommand {
  CLI::App* cmd = nullptr;
  std::string scene, out, profile, sweep, group;
  int cores = 0;
  bool force = false;
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("ensemble", "run an ensemble scene ([ensemble] packings = K) through the Snakemake "
                                         "workflow (workflow/Snakefile): one task per preparation and per mode (a packing's "
                                         "short tasks as one job); "
                                         "run again to continue after an interruption");
    cmd->add_option("scene", scene, "scene TOML file (see data/scenes/)")->required()->check(CLI::ExistingFile);
    cmd->add_option("--out", out, "results folder")->required();
    add_set_option(*cmd, overrides, "override a scene key: section.key=value (repeatable)");
    cmd->add_option("--sweep", sweep, "parameter sweep: a table (header of section.key names, optional 'name' "
                                      "column, one row of --set values per ensemble; tabs or spaces): one ensemble "
                                      "per row in DIR/rows/NAME, and a summary in DIR/sweep (docs/ensembles.md); "
                                      "a scene's own [sweep] table runs without it")
        ->check(CLI::ExistingFile);
    cmd->add_option("--cores", cores, "single-threaded tasks at once (default: all cores; with --profile: the profile's)")
        ->default_str("");
    cmd->add_option("--profile", profile, "Snakemake profile: slurm (workflow/profiles/slurm) or a folder");
    cmd->add_option("--group", group, "auto (default): a packing's tasks run as one Snakemake job when they are short; "
                                      "member: always; task: every preparation and mode its own job")
        ->check(CLI::IsMember({"auto", "member", "task"}));
    cmd->add_flag("--force", force, "start afresh: remove the results in --out (without it a rerun continues "
                                    "where the last one stopped, and another scene's results are refused)");
  }
  int run(const std::vector<std::string>& overrides) const {
    std::string resolved;
    dem::load_scene_file(scene, overrides, &resolved);
    dem::Sweep sw = dem::scene_sweep(scene);
    if (!sweep.empty()) {
      if (!sw.rows.empty())
        throw ArgumentError("--sweep " + sweep + ", but " + scene + " has a [sweep] table of its own: give the sweep "
                            "in one place (remove the scene's [sweep], or drop --sweep)");
      sw = dem::read_sweep_table(sweep);
    }
    // A Slurm profile's controller must answer before the folder is touched: a refused run writes nothing.
    if (!profile.empty() && run_python("demkit.slurm_preflight", {profile}) != 0) return 2;
    int lock = -1;
    if (sw.rows.empty()) {
      lock = dem::prepare_ensemble_folder(out, resolved, force);
    } else {
      const std::vector<std::string> scenes = dem::resolve_sweep(scene, overrides, sw);   // every row, before anything runs
      std::vector<std::pair<std::string, std::string>> rows;
      for (std::size_t i = 0; i < sw.rows.size(); ++i) rows.emplace_back(sw.rows[i].name, scenes[i]);
      lock = dem::prepare_sweep_folder(out, dem::sweep_json(sw, overrides), rows, force);
    }
    setenv("DEM_ENSEMBLE_LOCK_FD", std::to_string(lock).c_str(), 1);   // held across exec by the driver
    std::vector<std::string> args = {out, "--dem", fs::canonical("/proc/self/exe").string()};
    if (cores > 0) args.insert(args.end(), {"--cores", std::to_string(cores)});
    if (!profile.empty()) args.insert(args.end(), {"--profile", profile});
    if (!group.empty()) args.insert(args.end(), {"--group", group});
    return exec_python("demkit.ensemble", args);
  }
};

// The column table (measure.hpp) for people (a Markdown table) or programs (JSON).
void print_columns(bool json) {
  if (json) {
    nlohmann::ordered_json j = nlohmann::ordered_json::array();
    for (const dem::CurveColumn& c : dem::column_table())
      j.push_back({{"name", c.name}, {"unit", c.unit}, {"meaning", c.meaning}, {"group", dem::group_name(c.group)}});
    std::printf("%s\n", j.dump(1).c_str());
    return;
  }
  std::printf("| column | unit | in | meaning |\n|---|---|---|---|\n");
  for (const dem::CurveColumn& c : dem::column_table())
    std::printf("| `%s` | %s | %s | %s |\n", c.name, c.unit, dem::group_name(c.group), c.meaning);
  std::printf("| `stage` | text | every | the stage or path-stage name |\n");
}

// The scene as yade_ref/run_mode.py options: the contact law from the registry, then the scene's
// scales. YADE's NewtonIntegrator is ours' symplectic_euler: another integrator is said on stderr.
std::string yade_run_mode_line(const dem::Model& model) {
  using dem::contact::exact_num;
  if (model.integrator != dem::Integrator::SymplecticEuler)
    std::fprintf(stderr, "dem info --yade: note: YADE integrates with NewtonIntegrator's leapfrog, ours' "
                         "integration.integrator = \"symplectic_euler\"; this scene uses another integrator\n");
  return dem::contact::yade_run_mode_options(model.contact) + " --density " + exact_num(model.density) +
         " --r-min " + exact_num(model.radius_min) + " --dt-over-tc " + exact_num(model.dt_over_tc) +
         " --rate-tc " + exact_num(model.protocol.deviatoric_rate * model.t_contact) + " --sample-strain " +
         exact_num(model.output.sample_strain) + " --gamma-b " + exact_num(model.background_damping);
}

struct InfoCommand {
  CLI::App* cmd = nullptr;
  std::string scene;
  bool json = false, no_probe = false, contact_models = false, columns = false, lammps = false, yade = false, liggghts = false;
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("info", "print derived quantities of a scene (t_c, dt, rates, each contact sub-model's "
                                     "values and stability limits); --contact-models: every contact sub-model");
    cmd->add_option("scene", scene, "scene TOML file (not needed with --contact-models)")->check(CLI::ExistingFile);
    cmd->add_flag("--contact-models", contact_models, "list every contact sub-model of the registry: its scene keys "
                                                      "(units, defaults, bounds, meaning), history, curve columns, "
                                                      "YADE, LAMMPS and LIGGGHTS counterparts (with --json: as JSON)");
    cmd->add_flag("--columns", columns, "list every curve column: name, unit, meaning and which curves have it "
                                        "(with --json: as JSON; docs/curve_columns.md is made from it)");
    add_set_option(*cmd, overrides, "override a scene key");
    cmd->add_flag("--json", json, "print the run plan as JSON instead: members (seeds), checkpoints, modes, "
                                  "estimated particle-steps per task (read by workflow/Snakefile)");
    cmd->add_flag("--no-probe", no_probe, "no wall-time estimate (it times about a second of steps on a dense packing)");
    cmd->add_flag("--lammps", lammps, "print the scene's contact law as a LAMMPS `pair granular` pair_coeff line, "
                                      "made from each sub-model's counterpart in the registry (bench/decks.py reads it)");
    cmd->add_flag("--liggghts", liggghts, "print the scene's contact law as LIGGGHTS lines (fix property/global, "
                                          "pair_style gran, pair_coeff) from the registry (bench/decks.py reads them)");
    cmd->add_flag("--yade", yade, "print the scene as options of yade_ref/run_mode.py (its YADE law from each "
                                  "sub-model's counterpart in the registry; density, t_c radius, dt, rate, sampling, "
                                  "background damping); run_mode.py --scene reads it");
  }
  int run(const std::vector<std::string>& overrides) const {
    if (contact_models) {
      if (json) std::printf("%s\n", dem::contact::registry_json().dump(1).c_str());
      else std::printf("%s", dem::contact::registry_text().c_str());
      return 0;
    }
    if (columns) {
      print_columns(json);
      return 0;
    }
    if (scene.empty()) throw ArgumentError("dem info needs a scene file (or --contact-models, --columns)");
    const dem::Model model = dem::load_scene_file(scene, overrides);
    if (lammps) {
      std::printf("%s\n", dem::contact::lammps_pair_coeff(model.contact).c_str());
      return 0;
    }
    if (liggghts) {
      std::printf("%s\n", dem::contact::liggghts_pair_style(model.contact).c_str());
      return 0;
    }
    if (yade) {
      std::printf("%s\n", yade_run_mode_line(model).c_str());
      return 0;
    }
    if (json) std::printf("%s", dem::plan_json(model).c_str());
    else {
      print_info(model);
      if (model.sweep_rows > 0)
        std::printf("sweep              %d rows ([sweep]): `dem ensemble` runs one ensemble of this scene per row; the "
                    "figures above are of the base scene\n", model.sweep_rows);
      if (!no_probe) print_wall_time_estimate(model);
    }
    return 0;
  }
};

struct BenchCommand {
  CLI::App* cmd = nullptr;
  std::string packing = std::string(DEM_SOURCE_DIR) + "/data/packings/n9261_phi0.70.txt";
  long steps = 20000;
  int threads = 1;
  double rate_tc = 5e-6;
  std::string kernel = "auto";
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("bench", "particle-steps per second on a packing under D2");
    cmd->add_option("--kernel", kernel, "pair kernel: auto, avx512, avx2, generic or reference (the same bits)");
    cmd->add_option("--packing", packing, "YADE-format packing, or a checkpoint (*.ckpt: its state, velocities "
                                          "included)")->check(CLI::ExistingFile);
    cmd->add_option("--steps", steps, "steps to time");
    cmd->add_option("--threads", threads, "threads, 1 or more")->check(CLI::Range(1, 4096));
    cmd->add_option("--rate-tc", rate_tc, "D2 strain rate times t_c");
    add_set_option(*cmd, overrides, "override a scene key");
  }
  int run(std::vector<std::string> overrides) const {
    overrides.push_back("integration.threads=" + std::to_string(threads));
    dem::Model model = dem::load_scene("", overrides, nullptr, "bench");
    // A checkpoint (.ckpt) starts from its bit-exact state, velocities included (a relaxed
    // production packing); a YADE text packing starts at rest.
    dem::State state = fs::path(packing).extension() == ".ckpt" ? dem::read_checkpoint(packing).state
                                                                : dem::read_packing(packing, model.density);
    const dem::Vec3 rate = dem::Vec3{1, 0, -1} * (rate_tc / model.t_contact);
    dem::Engine engine(model, state);
    engine.set_pair_kernel(dem::pair_kernel_from_name(kernel));
    for (int i = 0; i < 200; ++i) engine.step(rate);   // warm-up
    const long builds0 = engine.neighbor_list().builds;
    const dem::RebuildStats before = engine.rebuild_stats();
    const auto t0 = std::chrono::steady_clock::now();
    for (long i = 0; i < steps; ++i) engine.step(rate);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const dem::RebuildStats timed = engine.rebuild_stats().since(before);   // the timed steps only
    const dem::Measurement m = dem::measure(model, state, engine.neighbor_list(), rate);
    const double ps = static_cast<double>(steps) * state.count() / wall;
    std::printf("packing %s\nN = %d, phi = %.4f, C = %.3f, threads = %d, steps = %ld, pair kernel %s\n",
                packing.c_str(), state.count(), m.nu, m.C, engine.threads(), steps,
                dem::pair_kernel_name(engine.pair_kernel()));
    std::printf("wall %.3f s, %.3f M particle-steps/s, %.2f listed pairs per particle, %ld list rebuilds, "
                "skin %.3g r_min (%s)\n",
                wall, ps / 1e6, static_cast<double>(engine.neighbor_list().pair_count()) / state.count(),
                engine.neighbor_list().builds - builds0, model.skin_over_rmin, model.skin_auto ? "auto" : "set");
    // The state after warm-up + timed steps, for physics parity with the other codes' decks
    // (bench/run_benchmarks.py --parity): contact + kinetic stress, energies, sliding.
    std::printf("after %ld steps: p_Pa=%.8g sxx_Pa=%.8g syy_Pa=%.8g szz_Pa=%.8g E_kin_J=%.8g E_rot_J=%.8g "
                "sliding_fraction=%.6g contacts=%ld\n",
                steps + 200, m.p, m.stress.xx, m.stress.yy, m.stress.zz, m.E_kin, m.E_rot, m.sliding_fraction,
                m.contacts);
    std::printf("list rebuilds: %lld (%.4g per 10^4 steps), %.3f s = %.1f %% of the wall time; triggered by a "
                "displacement %lld (of those diagnosed: a rattler %lld, the packing %lld), by the box's stretch %lld, by "
                "flips %lld; packing's / largest displacement (median) %.3g\n",
                static_cast<long long>(timed.rebuilds), 1e4 * timed.rebuilds / static_cast<double>(steps), timed.seconds,
                100.0 * timed.seconds / wall, static_cast<long long>(timed.displacement_triggers),
                static_cast<long long>(timed.by_rattler),
                static_cast<long long>(timed.by_packing), static_cast<long long>(timed.by_deformation),
                static_cast<long long>(timed.by_flip), timed.median_nonrattler_ratio());
    std::printf("neighbor_list=%s\n", timed.json(wall, engine.skin()).c_str());
    std::printf("particle_steps_per_s=%.6g\n", ps);
    return 0;
  }
};

// RUN/scene.toml when `packing` is RUN/checkpoints/FILE (the resolved scene of the run that
// wrote it: `dem run` and the ensemble members), else "".
std::string run_folder_scene(const std::string& packing) {
  const fs::path p = fs::absolute(packing);
  if (p.parent_path().filename() != "checkpoints") return "";
  const fs::path s = p.parent_path().parent_path() / "scene.toml";
  return fs::is_regular_file(s) ? s.string() : "";
}

// One deformation stage from a packing at rest (the unit of the YADE cross-check and of the
// ensemble workflow's tasks).
struct ModeCommand {
  CLI::App* cmd = nullptr;
  CLI::Option* rate_opt = nullptr;
  CLI::Option* eps_opt = nullptr;
  std::string scene, packing, mode = "D2", out, stage_name;
  double rate_tc = -1, eps = -1;
  bool force = false, quiet = false;
  int threads = -1;
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("mode", "one deformation mode from a packing at rest, one CSV");
    cmd->add_option("--scene", scene, "scene TOML for the physics (default: RUN/scene.toml when the packing is "
                                      "RUN/checkpoints/*, else the built-in defaults, listed on stderr)")
        ->check(CLI::ExistingFile);
    cmd->add_option("--packing", packing, "YADE-format packing (our checkpoints/*.txt), or a checkpoint "
                                          "(*.ckpt: bit-exact state, the curve equals `dem run`'s)")->required()->check(CLI::ExistingFile);
    cmd->add_option("--threads", threads, "threads, 1 or more (default: integration.threads, whose 0 means all cores)")
        ->check(CLI::Range(1, 4096))->default_str("");
    cmd->add_option("--name", stage_name, "stage name in the CSV (default: the mode's name; `dem run` uses "
                                          "MODE_phiX.XXX)");
    cmd->add_option("--mode", mode, "D2, D3, iso_compress, iso_expand, uniaxial_x/y/z, SS_xy/xz/yz (simple shear), "
                                    "or a [modes] name");
    rate_opt = cmd->add_option("--rate-tc", rate_tc, "mode rate times t_c (default: protocol.deviatoric_rate_tc)")
                   ->default_str("");
    eps_opt = cmd->add_option("--eps-max", eps, "stop at this eps_d (default: protocol.eps_d_max)")->default_str("");
    cmd->add_option("--out", out, "output CSV")->required();
    add_set_option(*cmd, overrides, "override a scene key");
    cmd->add_flag("--force", force, "overwrite an existing output CSV");
    cmd->add_flag("--quiet", quiet, "no progress lines");
  }
  int run(std::vector<std::string> overrides) const {
    if (!stage_name.empty() && (stage_name.size() > 64 || !std::all_of(stage_name.begin(), stage_name.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
        })))
      throw ArgumentError("--name '" + stage_name + "' must be 1-64 letters, digits, _, - or . (it is written into the "
                          "curve's stage column), e.g. D2_phi0.800");
    if (rate_opt->count()) overrides.push_back("protocol.deviatoric_rate_tc=" + exact_number("--rate-tc", rate_tc));
    if (eps_opt->count()) overrides.push_back("protocol.eps_d_max=" + exact_number("--eps-max", eps));
    overrides.push_back("protocol.modes=[\"" + mode + "\"]");
    if (threads >= 1) overrides.push_back("integration.threads=" + std::to_string(threads));
    std::string resolved;
    const std::string physics_scene = scene.empty() ? run_folder_scene(packing) : scene;
    dem::Model model = physics_scene.empty() ? dem::load_scene("", overrides, &resolved, "defaults")
                                             : dem::load_scene_file(physics_scene, overrides, &resolved);
    if (scene.empty() && !physics_scene.empty())
      std::fprintf(stderr, "dem mode: physics from %s (the run that made the packing; --scene FILE for another)\n",
                   physics_scene.c_str());
    else if (scene.empty())
      std::fprintf(stderr,
                   "dem mode: no --scene, and %s is not in a run folder's checkpoints/ with a scene.toml: built-in "
                   "defaults: r in [%g, %g] m, rho = %g kg/m^3, k = %g N/m, gamma = %g kg/s, gamma_b = %g kg/s, "
                   "dt = t_c/%.4g, %s, deviatoric rate %g/t_c (`dem info` on a scene shows its values; give the "
                   "scene that made the packing with --scene)\n",
                   packing.c_str(), model.radius_min, model.radius_max, model.density, model.contact.reference_stiffness(),
                   model.contact.time_step_damping(), model.background_damping, 1.0 / model.dt_over_tc,
                   model.integrator == dem::Integrator::VelocityVerlet ? "velocity Verlet" : "symplectic Euler",
                   model.protocol.deviatoric_rate * model.t_contact);
    check_output_file(out, force);
    dem::State state = fs::path(packing).extension() == ".ckpt" ? dem::read_checkpoint(packing).state
                                                                : dem::read_packing(packing, model.density);
    dem::check_packing(model, state, packing);
    const auto& m = model.protocol.modes.front();
    if (!quiet) print_info(model);
    else warn_time_step(model);
    const auto t0 = std::chrono::steady_clock::now();
    dem::RebuildStats list_stats;
    const auto steps = dem::run_mode(model, state, m, stage_name, dem::StageOutput{out, "", "", quiet, &list_stats});
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // The run summary's neighbour-list entry (demkit.task copies this line into the task's JSON).
    std::fprintf(stderr, "dem mode: neighbor_list %s\n", list_stats.json(wall, model.skin_over_rmin * model.radius_min).c_str());
    std::fprintf(stderr, "dem mode: %lld steps of %d particles in %.2f s: %.3f M particle-steps/s -> %s\n",
                 static_cast<long long>(steps), state.count(), wall, steps * double(state.count()) / wall / 1e6,
                 out.c_str());
    return 0;
  }
};

// Two-sphere collision against the closed form.
struct CollideCommand {
  CLI::App* cmd = nullptr;
  double r1 = 0.5e-3, r2 = 0.5e-3, v0 = 0.1, angle_deg = -1;
  void add(CLI::App& app, std::vector<std::string>& overrides) {
    cmd = app.add_subcommand("collide", "two-sphere head-on collision: contact time and restitution (JSON); "
                                        "--angle-deg: an oblique impact (friction: --set contact.friction=MU)");
    cmd->add_option("--r1", r1, "radius of sphere 1 [m]");
    cmd->add_option("--r2", r2, "radius of sphere 2 [m]");
    cmd->add_option("--v0", v0, "approach speed [m/s]");
    cmd->add_option("--angle-deg", angle_deg,
                    "oblique impact: angle of the relative velocity from the line of centres [deg], in [0, 90); "
                    "prints the normal and tangential restitution, the spins and the impulses (yade_ref/collision.py); "
                    "default: head-on")
        ->default_str("");
    add_set_option(*cmd, overrides, "override a scene key (e.g. integration.dt_over_tc=0.0005)");
  }
  int run(std::vector<std::string> overrides) const {
    overrides.insert(overrides.begin(), {"contact.background_damping_kg_s=0", "integration.threads=1"});
    const dem::Model model = dem::load_scene("", overrides, nullptr, "collide");
    for (auto [name, v] : {std::pair{"--r1", r1}, {"--r2", r2}, {"--v0", v0}})
      if (!(v > 0) || !std::isfinite(v)) throw ArgumentError(std::string(name) + " must be a positive finite number");
    // dt is t_c / dt_over_tc of the scene's smallest pair: a smaller sphere is resolved by fewer steps.
    for (auto [name, r] : {std::pair{"--r1", r1}, {"--r2", r2}})
      if (r < model.radius_min || r > model.radius_max)
        throw ArgumentError(std::string(name) + " = " + std::to_string(r) + " m lies outside the scene's radius range [" +
                            std::to_string(model.radius_min) + ", " + std::to_string(model.radius_max) + "] m, "
                            "from which the time step is set: pass --set particles.radius_min_m=... and "
                            "--set particles.radius_max_m=... to cover it");
    if (cmd->count("--angle-deg") > 0) return oblique(model);
    const dem::CollisionResult r = dem::simulate_collision(model, r1, r2, v0);
    if (r.steps_in_contact < 20 || r.max_overlap > model.max_overlap_fraction)
      throw ArgumentError("the contact lasted " + std::to_string(r.steps_in_contact) + " time steps with an overlap of " +
                          std::to_string(r.max_overlap) + " x the smaller radius: --v0 is too large for this stiffness "
                          "(the spheres pass through each other, t_c and e are meaningless); lower --v0 so that the "
                          "overlap stays well below the radius (and the contact spans >= 20 steps)");
    const double m1 = dem::sphere_mass(r1, model.density), m2 = dem::sphere_mass(r2, model.density);
    const dem::PairCollision a = dem::pair_collision(model.contact.reference_stiffness(), model.contact.time_step_damping(),
                                                      m1 * m2 / (m1 + m2));   // the linear law's closed form
    const nlohmann::ordered_json j{{"t_contact_s", r.contact_time}, {"restitution", r.restitution},
                                   {"t_contact_analytic_s", a.t_contact}, {"restitution_analytic", a.restitution},
                                   {"dt_s", model.dt}, {"allow_attractive", model.contact.allow_attractive()}};
    std::printf("%s\n", j.dump().c_str());   // nlohmann-json: a non-finite number is written as null
    return 0;
  }
  // Oblique impact (dem::simulate_oblique_collision): line of centres z (0 -> 1), initial
  // tangential direction x, spins about y; the same JSON keys as yade_ref/collision.py --angle-deg.
  int oblique(const dem::Model& model) const {
    if (!(angle_deg >= 0 && angle_deg < 90)) throw ArgumentError("--angle-deg must lie in [0, 90)");
    const dem::ObliqueResult r = dem::simulate_oblique_collision(model, r1, r2, v0, angle_deg * M_PI / 180.0);
    const nlohmann::ordered_json j{{"angle_deg", angle_deg}, {"normal_restitution", r.normal_restitution},
                                   {"tangential_restitution", r.tangential_restitution},
                                   {"omega0_y_rad_s", r.omega[0].y}, {"omega1_y_rad_s", r.omega[1].y},
                                   {"normal_impulse_Ns", r.normal_impulse}, {"tangential_impulse_Ns", r.tangential_impulse},
                                   {"friction", model.contact.get_or("friction", 0.0)},
                                   {"dt_s", model.dt}};
    std::printf("%s\n", j.dump().c_str());
    return 0;
  }
};

// Identifiability map of the single-curve fit (synthetic curves, CSV).
struct FitMapCommand {
  CLI::App* cmd = nullptr;
  std::string out;
  demfit::IdentifiabilitySetup setup;
  std::vector<double> lengths{0.5, 1, 1.5, 2, 3, 5, 8, 13, 24}, noises{0.003, 0.01, 0.03, 0.1, 0.3}, rhos{0.0, 0.85};
  bool force = false;
  void add(CLI::App& app) {
    setup.fit.correct_autocorrelation = true;   // as `dem fit` does by default
    cmd = app.add_subcommand("fit-map", "identifiability map of the fit: seeded synthetic curves of known "
                                        "parameters, fitted over a grid of curve lengths and noise levels (CSV)");
    cmd->add_option("--out", out, "output CSV")->required();
    cmd->add_option("--lengths", lengths, "curve lengths beta * eps_last [-] (3 = 95% saturation)");
    cmd->add_option("--noises", noises, "noise standard deviation / amplitude |x_max - x0| [-]");
    cmd->add_option("--correlations", rhos, "lag-1 autocorrelations of the noise, in [0, 1)");
    cmd->add_option("--trials", setup.trials, "curves per cell");
    cmd->add_option("--points-per-approach", setup.points_per_approach,
                    "samples per approach strain 1/beta (8.3: sample_strain 0.002 at beta = 60)");
    cmd->add_option("--beta", setup.beta, "true rate beta");
    cmd->add_option("--x-max", setup.x_max, "true asymptote");
    cmd->add_option("--x0", setup.x0, "true initial value");
    cmd->add_option("--seed", setup.seed, "random seed (the same seed gives the same map)");
    cmd->add_flag("--force", force, "overwrite an existing output CSV");
  }
  int run() const {
    if (fs::exists(out) && !force) throw std::runtime_error(out + " exists: pass --force to overwrite it");
    std::ostringstream csv;
    csv << "# dem fit-map: fits of x = x_max - (x_max - x0) exp(-beta eps_d) to synthetic curves with "
        << setup.points_per_approach << " points per 1/beta on (0, eps_last], Gaussian AR(1) noise, " << setup.trials
        << " trials per cell, seed " << setup.seed << "\n# truth: x0 = " << setup.x0
        << ", x_max = " << setup.x_max << ", beta = " << setup.beta
        << "; errors relative to beta (rate) and to |x_max - x0| (asymptote); coverage = fraction of trials whose "
           "95% interval (1.96 SE, SEs inflated for correlated residuals as in dem fit) holds the truth\n"
           "length_beta_eps,noise_over_amplitude,noise_correlation,beta_rel_error_median,beta_rel_error_p90,"
           "xmax_rel_error_median,beta_coverage,xmax_coverage,beta_reported_rel_se_median,flagged_fraction,unsaturated_fraction,converged\n";
    for (double rho : rhos)
      for (double noise : noises)
        for (double length : lengths) {
          demfit::IdentifiabilitySetup s = setup;
          s.length = length; s.noise = noise; s.correlation = rho;
          const demfit::IdentifiabilityCell c = demfit::identifiability_cell(s);
          csv << length << "," << noise << "," << rho << "," << c.beta_rel_error_median << ","
              << c.beta_rel_error_p90 << "," << c.xmax_rel_error_median << "," << c.beta_coverage << ","
              << c.xmax_coverage << "," << c.beta_reported_rel_se_median << "," << c.flagged_fraction << ","
              << c.unsaturated_fraction << "," << c.converged << "\n";
        }
    dem::write_file_atomic(out, csv.str());
    std::fprintf(stderr, "dem fit-map: %zu cells -> %s\n", rhos.size() * noises.size() * lengths.size(), out.c_str());
    return 0;
  }
};

// Coverage of the ensemble fit's intervals on synthetic ensembles (CSV).
struct EnsembleCoverageCommand {
  CLI::App* cmd = nullptr;
  std::string out;
  demfit::EnsembleCoverageSetup setup;
  std::vector<int> ks{2, 4, 8, 16, 32};
  std::vector<double> lengths{3, 8}, rhos{0.85, 0.95};
  bool force = false;
  void add(CLI::App& app) {
    cmd = app.add_subcommand("ensemble-coverage", "coverage of the ensemble fit's 95% intervals and the false-rejection "
                                                  "rate of its D2/D3 test on synthetic ensembles of DEM-like curves (CSV)");
    cmd->add_option("--out", out, "output CSV")->required();
    cmd->add_option("--packings", ks, "ensemble sizes K")->delimiter(',');
    cmd->add_option("--lengths", lengths, "curve lengths beta * eps_last")->delimiter(',');
    cmd->add_option("--correlations", rhos, "lag-1 autocorrelations of the noise, in [0, 1)")->delimiter(',');
    cmd->add_option("--noise", setup.noise, "AR(1) noise sd / amplitude");
    cmd->add_option("--member-spread", setup.member_spread, "sd of the members' plateaus / amplitude");
    cmd->add_option("--trials", setup.trials, "synthetic ensembles per cell");
    cmd->add_option("--bootstrap", setup.bootstrap, "bootstrap resamples per trial (0: skip)");
    cmd->add_option("--seed", setup.seed, "random seed");
    cmd->add_flag("--force", force, "overwrite an existing output CSV");
  }
  int run() const {
    if (fs::exists(out) && !force) throw std::runtime_error(out + " exists: pass --force to overwrite it");
    dem::write_file_atomic(out, demfit::ensemble_coverage_csv(setup, ks, lengths, rhos));
    return 0;
  }
};

struct Commands {
  RunCommand run;
  EnsembleCommand ensemble;
  InfoCommand info;
  BenchCommand bench;
  ModeCommand mode;
  CollideCommand collide;
  demfit::FitCommandOptions fit_opts;
  CLI::App* fit = nullptr;
  demfit::ModelCommandOptions model_opts;
  CLI::App* model = nullptr;
  FitMapCommand fit_map;
  EnsembleCoverageCommand coverage;
  CLI::App* compare = nullptr;
  CLI::App* plot = nullptr;

  void add(CLI::App& app, std::vector<std::string>& overrides) {
    run.add(app, overrides);
    ensemble.add(app, overrides);
    info.add(app, overrides);
    bench.add(app, overrides);
    mode.add(app, overrides);
    collide.add(app, overrides);
    fit = app.add_subcommand("fit", "fit the anisotropy-evolution model to a run's curves");
    demfit::add_fit_options(*fit, fit_opts);
    model = app.add_subcommand("model", "calibrate the incremental anisotropic model on an ensemble's D2 curves "
                                        "and isotropic branch, predict D3 (docs/model.md)");
    demfit::add_model_options(*model, model_opts);
    fit_map.add(app);
    coverage.add(app);
    // compare and plot are demkit's (argparse): their options, --help included, go to it.
    compare = app.add_subcommand("compare", "compare two curve CSVs (e.g. ours vs YADE): differences and a verdict "
                                            "against tolerances, --plot overlay; `dem compare --help` for the options");
    compare->allow_extras();
    compare->set_help_flag();
    plot = app.add_subcommand("plot", "plot a run folder's curves (PNG/SVG in DIR/plots); `dem plot --help` for "
                                      "the options");
    plot->allow_extras();
    plot->set_help_flag();
  }

  // The parsed subcommand's exit code.
  int dispatch(const std::vector<std::string>& overrides, const std::string& command_line) const {
    if (*run.cmd) return run.run(overrides, command_line);
    if (*ensemble.cmd) return ensemble.run(overrides);
    if (*info.cmd) return info.run(overrides);
    if (*bench.cmd) return bench.run(overrides);
    if (*mode.cmd) return mode.run(overrides);
    if (*collide.cmd) return collide.run(overrides);
    if (*fit) {
      // An ensemble folder: the tasks its scene plans, so that an incomplete one is never fitted silently.
      demfit::FitCommandOptions o = fit_opts;
      const fs::path dir(o.run_dir);
      if (fs::is_directory(dir / "members") && !fs::exists(dir / "scene.toml")) {
        std::cerr << "dem fit: warning: " << dir.string() << " has members/ but no scene.toml (assembled by hand?): "
                  << "whether every planned task finished cannot be checked\n";
      } else if (fs::is_directory(dir / "members")) {
        try {
          o.planned_tasks = dem::planned_task_files(dem::load_scene_file((dir / "scene.toml").string(), {}));
        } catch (const std::exception& e) {
          o.plan_error = e.what();
        }
      }
      return demfit::run_fit_command(o);
    }
    if (*model) return demfit::run_model_command(model_opts);
    if (*fit_map.cmd) return fit_map.run();
    if (*coverage.cmd) return coverage.run();
    if (*compare) return exec_python("demkit.compare", compare->remaining());
    if (*plot) return exec_python("demkit.plots", plot->remaining());
    return 0;
  }
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"dem: DEM runner, fitter and YADE cross-check for polydisperse spheres (frictionless, frictional, adhesive)"};
  app.require_subcommand(1);
  app.option_defaults()->always_capture_default();   // --help shows each option's default (set before any option)
  std::vector<std::string> overrides;
  Commands commands;
  commands.add(app, overrides);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;   // --help: 0; any bad argument: 2 (README's catalogue)
  }
  try {
    return commands.dispatch(overrides, join_args(argc, argv));
  } catch (const dem::SceneError& e) {
    std::cerr << "dem: scene error: " << e.what() << "\n";
    return 2;
  } catch (const ArgumentError& e) {
    std::cerr << "dem: bad argument: " << e.what() << "\n";
    return 2;
  } catch (const dem::BlowUp& e) {
    std::cerr << "dem: simulation blew up: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    std::cerr << "dem: error: " << e.what() << "\n";
    return 1;
  }
}
