// dem: command-line front end. Subcommands: run, info, bench, fit, compare, plot.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <unistd.h>

#include "dem/checks.hpp"
#include "dem/collision.hpp"
#include "dem/engine.hpp"
#include "dem/io.hpp"
#include "dem/measure.hpp"
#include "dem/plan.hpp"
#include "dem/preparation.hpp"
#include "dem/protocol.hpp"
#include "dem/scene.hpp"
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

// Integration is stable for a single contact up to dt/t_c = 2/pi (refused above), but dense
// packings went unstable at 0.48-0.52 (docs/stability.md): warn before that.
void warn_time_step(const dem::Model& m) {
  if (m.dt_over_tc > 0.45)
    std::fprintf(stderr, "dem: warning: integration.dt_over_tc = %g is near the stability limit of dense packings "
                         "(0.48-0.52 measured, docs/stability.md); expect a blow-up, or use 0.1\n", m.dt_over_tc);
}

void print_info(const dem::Model& m) {
  warn_time_step(m);
  const auto& p = m.protocol;
  std::printf("particles          N = %d, r in [%g, %g] m, rho = %g kg/m^3, memory ~%.3g MB (estimate)\n", m.count,
              m.radius_min, m.radius_max, m.density, dem::estimated_memory_bytes(m.count) / 1e6);
  std::printf("contact            k = %g N/m, gamma = %g kg/s, gamma_b = %g kg/s, %s\n",
              m.contact.stiffness, m.contact.damping, m.background_damping,
              m.contact.allow_attractive ? "attractive allowed" : "clamped at zero");
  std::printf("smallest pair      t_c = %.6g s, e = %.6g\n", m.t_contact, m.restitution);
  std::printf("time step          dt = %.6g s (t_c / %.4g), %s\n", m.dt, 1.0 / m.dt_over_tc,
              m.integrator == dem::Integrator::VelocityVerlet ? "velocity Verlet" : "symplectic Euler");
  for (const auto& st : p.preparation)
    std::printf("prep %-15s %s\n", st.name.c_str(), dem::describe(st, m.t_contact).c_str());
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
                  mode.name.c_str(), mode.rate_shape.x, mode.shear_shape.x, mode.shear_shape.y, mode.rate_shape.y,
                  mode.shear_shape.z, mode.rate_shape.z, dem::mode_steps(m, mode), p.eps_d_max);
    else
      std::printf("mode %-13s  rate shape (%g, %g, %g): %.3g steps to eps_d = %g\n", mode.name.c_str(),
                  mode.rate_shape.x, mode.rate_shape.y, mode.rate_shape.z, dem::mode_steps(m, mode), p.eps_d_max);
  }
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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"dem: DEM runner, fitter and YADE cross-check for frictionless polydisperse spheres"};
  app.require_subcommand(1);
  std::vector<std::string> overrides;

  // run
  auto* run = app.add_subcommand("run", "run a scene: preparation, checkpoints, deviatoric modes");
  std::string scene, out, stages = "all";
  bool force = false, quiet = false;
  int threads = -1;
  run->add_option("scene", scene, "scene TOML file (see data/scenes/)")->required()->check(CLI::ExistingFile);
  run->add_option("--out", out, "results folder")->required();
  run->add_option("--set", overrides, "override a scene key: section.key=value (repeatable)");
  run->add_option("--stages", stages, "all | prep | deviatoric (deviatoric reuses DIR/checkpoints)");
  run->add_option("--threads", threads, "OpenMP threads (overrides integration.threads)");
  run->add_flag("--force", force, "overwrite finished results in --out");
  run->add_flag("--quiet", quiet, "no progress lines on stderr");

  // ensemble: K packings through the Snakemake workflow
  auto* ens = app.add_subcommand("ensemble", "run an ensemble scene ([ensemble] packings = K) through the Snakemake "
                                             "workflow (workflow/Snakefile): one task per preparation and per mode; "
                                             "run again to continue after an interruption");
  std::string ens_scene, ens_out, ens_profile;
  int ens_cores = 0;
  bool ens_force = false;
  ens->add_option("scene", ens_scene, "scene TOML file (see data/scenes/)")->required()->check(CLI::ExistingFile);
  ens->add_option("--out", ens_out, "results folder")->required();
  ens->add_option("--set", overrides, "override a scene key: section.key=value (repeatable)");
  ens->add_option("--cores", ens_cores, "single-threaded tasks at once (default: all cores; with --profile: the profile's)");
  ens->add_option("--profile", ens_profile, "Snakemake profile: slurm (workflow/profiles/slurm) or a folder");
  ens->add_flag("--force", ens_force, "start afresh: remove the results in --out (without it a rerun continues "
                                     "where the last one stopped, and another scene's results are refused)");

  // info
  auto* info = app.add_subcommand("info", "print derived quantities of a scene (t_c, dt, rates)");
  std::string info_scene;
  bool info_json = false;
  info->add_option("scene", info_scene, "scene TOML file")->required()->check(CLI::ExistingFile);
  info->add_option("--set", overrides, "override a scene key");
  info->add_flag("--json", info_json, "print the run plan as JSON instead: members (seeds), checkpoints, modes, "
                                      "estimated particle-steps per task (read by workflow/Snakefile)");

  // bench
  auto* bench = app.add_subcommand("bench", "particle-steps per second on a packing under D2");
  std::string bench_packing = std::string(DEM_SOURCE_DIR) + "/data/packings/n9261_phi0.70.txt";
  long bench_steps = 20000;
  int bench_threads = 1;
  double bench_rate_tc = 5e-6;
  bench->add_option("--packing", bench_packing, "YADE-format packing")->check(CLI::ExistingFile);
  bench->add_option("--steps", bench_steps, "steps to time");
  bench->add_option("--threads", bench_threads, "OpenMP threads");
  bench->add_option("--rate-tc", bench_rate_tc, "D2 strain rate times t_c");
  bench->add_option("--set", overrides, "override a scene key");

  // mode: one deformation stage from a packing at rest (the unit of the YADE cross-check)
  auto* mode_cmd = app.add_subcommand("mode", "one deformation mode from a packing at rest, one CSV");
  std::string mode_scene, mode_packing, mode_name = "D2", mode_out;
  double mode_rate_tc = -1, mode_eps = -1;
  bool mode_force = false, mode_quiet = false;
  mode_cmd->add_option("--scene", mode_scene, "scene TOML for the physics (default: built-in defaults)")->check(CLI::ExistingFile);
  int mode_threads = -1;
  mode_cmd->add_option("--packing", mode_packing, "YADE-format packing (our checkpoints/*.txt), or a checkpoint "
                                                   "(*.ckpt: bit-exact state, the curve equals `dem run`'s)")->required()->check(CLI::ExistingFile);
  mode_cmd->add_option("--threads", mode_threads, "OpenMP threads (overrides integration.threads)");
  std::string mode_stage_name;
  mode_cmd->add_option("--name", mode_stage_name, "stage name in the CSV (default: the mode's name; `dem run` uses "
                                                  "MODE_phiX.XXX)");
  mode_cmd->add_option("--mode", mode_name, "D2, D3, iso_compress, iso_expand, uniaxial_x/y/z, SS_xy/xz/yz (simple shear), or a [modes] name");
  auto* mode_rate_opt = mode_cmd->add_option("--rate-tc", mode_rate_tc, "mode rate times t_c (default: protocol.deviatoric_rate_tc)");
  auto* mode_eps_opt = mode_cmd->add_option("--eps-max", mode_eps, "stop at this eps_d (default: protocol.eps_d_max)");
  mode_cmd->add_option("--out", mode_out, "output CSV")->required();
  mode_cmd->add_option("--set", overrides, "override a scene key");
  mode_cmd->add_flag("--force", mode_force, "overwrite an existing output CSV");
  mode_cmd->add_flag("--quiet", mode_quiet, "no progress lines");

  // collide: two-sphere collision against the closed form
  auto* collide = app.add_subcommand("collide", "two-sphere head-on collision: contact time and restitution (JSON)");
  double col_r1 = 0.5e-3, col_r2 = 0.5e-3, col_v0 = 0.1;
  collide->add_option("--r1", col_r1, "radius of sphere 1 [m]");
  collide->add_option("--r2", col_r2, "radius of sphere 2 [m]");
  collide->add_option("--v0", col_v0, "approach speed [m/s]");
  collide->add_option("--set", overrides, "override a scene key (e.g. integration.dt_over_tc=0.0005)");

  // fit, compare, plot
  demfit::FitCommandOptions fit_opts;
  auto* fit = app.add_subcommand("fit", "fit the anisotropy-evolution model to a run's curves");
  demfit::add_fit_options(*fit, fit_opts);
  demfit::ModelCommandOptions model_opts;
  auto* modelcmd = app.add_subcommand("model", "calibrate the incremental anisotropic model on an ensemble's D2 curves "
                                               "and isotropic branch, predict D3 (docs/model.md)");
  demfit::add_model_options(*modelcmd, model_opts);
  auto* fitmap = app.add_subcommand("fit-map", "identifiability map of the fit: seeded synthetic curves of known "
                                                "parameters, fitted over a grid of curve lengths and noise levels (CSV)");
  std::string map_out;
  demfit::IdentifiabilitySetup map_setup;
  map_setup.fit.correct_autocorrelation = true;   // as `dem fit` does by default
  std::vector<double> map_lengths{0.5, 1, 1.5, 2, 3, 5, 8, 13, 24}, map_noises{0.003, 0.01, 0.03, 0.1, 0.3},
      map_rhos{0.0, 0.85};
  bool map_force = false;
  fitmap->add_option("--out", map_out, "output CSV")->required();
  fitmap->add_option("--lengths", map_lengths, "curve lengths beta * eps_last [-] (3 = 95% saturation)");
  fitmap->add_option("--noises", map_noises, "noise standard deviation / amplitude |x_max - x0| [-]");
  fitmap->add_option("--correlations", map_rhos, "lag-1 autocorrelations of the noise, in [0, 1)");
  fitmap->add_option("--trials", map_setup.trials, "curves per cell");
  fitmap->add_option("--points-per-approach", map_setup.points_per_approach,
                     "samples per approach strain 1/beta (8.3: sample_strain 0.002 at beta = 60)");
  fitmap->add_option("--beta", map_setup.beta, "true rate beta");
  fitmap->add_option("--x-max", map_setup.x_max, "true asymptote");
  fitmap->add_option("--x0", map_setup.x0, "true initial value");
  fitmap->add_option("--seed", map_setup.seed, "random seed (the same seed gives the same map)");
  fitmap->add_flag("--force", map_force, "overwrite an existing output CSV");
  auto* ecov = app.add_subcommand("ensemble-coverage", "coverage of the ensemble fit's 95% intervals and the false-rejection "
                                                      "rate of its D2/D3 test on synthetic ensembles of DEM-like curves (CSV)");
  std::string ecov_out;
  demfit::EnsembleCoverageSetup ecov_setup;
  std::vector<int> ecov_ks{2, 4, 8, 16, 32};
  std::vector<double> ecov_lengths{3, 8}, ecov_rhos{0.85, 0.95};
  bool ecov_force = false;
  ecov->add_option("--out", ecov_out, "output CSV")->required();
  ecov->add_option("--packings", ecov_ks, "ensemble sizes K")->delimiter(',');
  ecov->add_option("--lengths", ecov_lengths, "curve lengths beta * eps_last")->delimiter(',');
  ecov->add_option("--correlations", ecov_rhos, "lag-1 autocorrelations of the noise, in [0, 1)")->delimiter(',');
  ecov->add_option("--noise", ecov_setup.noise, "AR(1) noise sd / amplitude");
  ecov->add_option("--member-spread", ecov_setup.member_spread, "sd of the members' plateaus / amplitude");
  ecov->add_option("--trials", ecov_setup.trials, "synthetic ensembles per cell");
  ecov->add_option("--bootstrap", ecov_setup.bootstrap, "bootstrap resamples per trial (0: skip)");
  ecov->add_option("--seed", ecov_setup.seed, "random seed");
  ecov->add_flag("--force", ecov_force, "overwrite an existing output CSV");
  auto* compare = app.add_subcommand("compare", "compare two curve CSVs (e.g. ours vs YADE)");
  compare->allow_extras();
  auto* plot = app.add_subcommand("plot", "plot a run folder's curves (PNG/SVG)");
  plot->allow_extras();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;   // --help: 0; any bad argument: 2 (README's catalogue)
  }

  try {
    if (*run) {
      if (threads >= 0) overrides.push_back("integration.threads=" + std::to_string(threads));
      std::string resolved;
      dem::Model model = dem::load_scene_file(scene, overrides, &resolved);
      dem::RunOptions o;
      o.out_dir = out;
      o.stages = stages;
      o.force = force;
      o.quiet = quiet;
      o.scene_toml = resolved;
      o.command_line = join_args(argc, argv);
      if (!quiet) print_info(model);
      else warn_time_step(model);
      dem::run_protocol(model, o);
      return 0;
    }
    if (*ens) {
      std::string resolved;
      dem::load_scene_file(ens_scene, overrides, &resolved);
      dem::prepare_ensemble_folder(ens_out, resolved, ens_force);
      std::vector<std::string> args = {ens_out, "--dem", fs::canonical("/proc/self/exe").string()};
      if (ens_cores > 0) args.insert(args.end(), {"--cores", std::to_string(ens_cores)});
      if (!ens_profile.empty()) args.insert(args.end(), {"--profile", ens_profile});
      return exec_python("demkit.ensemble", args);
    }
    if (*info) {
      const dem::Model model = dem::load_scene_file(info_scene, overrides);
      if (info_json) std::printf("%s", dem::plan_json(model).c_str());
      else print_info(model);
      return 0;
    }
    if (*bench) {
      overrides.push_back("integration.threads=" + std::to_string(bench_threads));
      dem::Model model = dem::load_scene("", overrides, nullptr, "bench");
      dem::State state = dem::read_packing(bench_packing, model.density);
      const dem::Vec3 rate = dem::Vec3{1, 0, -1} * (bench_rate_tc / model.t_contact);
      dem::Engine engine(model, state);
      for (int i = 0; i < 200; ++i) engine.step(rate);   // warm-up
      const long builds0 = engine.neighbor_list().builds;
      const auto t0 = std::chrono::steady_clock::now();
      for (long i = 0; i < bench_steps; ++i) engine.step(rate);
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const dem::Measurement m = dem::measure(model, state, engine.neighbor_list(), rate);
      const double ps = static_cast<double>(bench_steps) * state.count() / wall;
      std::printf("packing %s\nN = %d, phi = %.4f, C = %.3f, threads = %d, steps = %ld\n", bench_packing.c_str(),
                  state.count(), m.nu, m.C, engine.threads(), bench_steps);
      std::printf("wall %.3f s, %.3f M particle-steps/s, %.2f listed pairs per particle, %ld list rebuilds\n",
                  wall, ps / 1e6, static_cast<double>(engine.neighbor_list().pair_count()) / state.count(),
                  engine.neighbor_list().builds - builds0);
      std::printf("particle_steps_per_s=%.6g\n", ps);
      return 0;
    }
    if (*mode_cmd) {
      if (mode_rate_opt->count()) overrides.push_back("protocol.deviatoric_rate_tc=" + exact_number("--rate-tc", mode_rate_tc));
      if (mode_eps_opt->count()) overrides.push_back("protocol.eps_d_max=" + exact_number("--eps-max", mode_eps));
      overrides.push_back("protocol.modes=[\"" + mode_name + "\"]");
      if (mode_threads >= 0) overrides.push_back("integration.threads=" + std::to_string(mode_threads));
      std::string resolved;
      dem::Model model = mode_scene.empty() ? dem::load_scene("", overrides, &resolved, "defaults")
                                            : dem::load_scene_file(mode_scene, overrides, &resolved);
      check_output_file(mode_out, mode_force);
      dem::State state = fs::path(mode_packing).extension() == ".ckpt"
                             ? dem::read_checkpoint(mode_packing).state
                             : dem::read_packing(mode_packing, model.density);
      dem::check_packing(model, state, mode_packing);
      const auto& m = model.protocol.modes.front();
      dem::StageSpec spec{mode_stage_name.empty() ? m.name : mode_stage_name, m.rate_shape * model.protocol.deviatoric_rate, dem::StopKind::DeviatoricStrain,
                          model.protocol.eps_d_max, {}, 0, 0, dem::mode_definition(model, m),
                          m.shear_shape * model.protocol.deviatoric_rate};
      if (!mode_quiet) print_info(model);
      else warn_time_step(model);
      const auto t0 = std::chrono::steady_clock::now();
      const auto steps = m.path.empty() ? dem::run_stage(model, state, spec, mode_out, "", nullptr, mode_quiet)
                                        : dem::run_path(model, state, m, spec.name, mode_out, mode_quiet);
      const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::fprintf(stderr, "dem mode: %lld steps of %d particles in %.2f s: %.3f M particle-steps/s -> %s\n",
                   static_cast<long long>(steps), state.count(), wall, steps * double(state.count()) / wall / 1e6,
                   mode_out.c_str());
      return 0;
    }
    if (*collide) {
      overrides.insert(overrides.begin(), {"contact.background_damping_kg_s=0", "integration.threads=1"});
      const dem::Model model = dem::load_scene("", overrides, nullptr, "collide");
      for (auto [name, v] : {std::pair{"--r1", col_r1}, {"--r2", col_r2}, {"--v0", col_v0}})
        if (!(v > 0) || !std::isfinite(v)) throw ArgumentError(std::string(name) + " must be a positive finite number");
      // dt is t_c / dt_over_tc of the scene's smallest pair: a smaller sphere is resolved by fewer steps.
      for (auto [name, r] : {std::pair{"--r1", col_r1}, {"--r2", col_r2}})
        if (r < model.radius_min || r > model.radius_max)
          throw ArgumentError(std::string(name) + " = " + std::to_string(r) + " m lies outside the scene's radius range [" +
                              std::to_string(model.radius_min) + ", " + std::to_string(model.radius_max) + "] m, "
                              "from which the time step is set: pass --set particles.radius_min_m=... and "
                              "--set particles.radius_max_m=... to cover it");
      const dem::CollisionResult r = dem::simulate_collision(model, col_r1, col_r2, col_v0);
      if (r.steps_in_contact < 20 || r.max_overlap > model.max_overlap_fraction)
        throw ArgumentError("the contact lasted " + std::to_string(r.steps_in_contact) + " time steps with an overlap of " +
                            std::to_string(r.max_overlap) + " x the smaller radius: --v0 is too large for this stiffness "
                            "(the spheres pass through each other, t_c and e are meaningless); lower --v0 so that the "
                            "overlap stays well below the radius (and the contact spans >= 20 steps)");
      const double m1 = dem::sphere_mass(col_r1, model.density), m2 = dem::sphere_mass(col_r2, model.density);
      const dem::PairCollision a = dem::pair_collision(model.contact.stiffness, model.contact.damping, m1 * m2 / (m1 + m2));
      std::printf("{\"t_contact_s\": %.12g, \"restitution\": %.12g, \"t_contact_analytic_s\": %.12g, "
                  "\"restitution_analytic\": %.12g, \"dt_s\": %.12g, \"allow_attractive\": %s}\n",
                  r.contact_time, r.restitution, a.t_contact, a.restitution, model.dt,
                  model.contact.allow_attractive ? "true" : "false");
      return 0;
    }
    if (*fit) return demfit::run_fit_command(fit_opts);
    if (*modelcmd) return demfit::run_model_command(model_opts);
    if (*fitmap) {
      if (fs::exists(map_out) && !map_force) throw std::runtime_error(map_out + " exists: pass --force to overwrite it");
      std::ostringstream csv;
      csv << "# dem fit-map: fits of x = x_max - (x_max - x0) exp(-beta eps_d) to synthetic curves with "
          << map_setup.points_per_approach << " points per 1/beta on (0, eps_last], Gaussian AR(1) noise, " << map_setup.trials
          << " trials per cell, seed " << map_setup.seed << "\n# truth: x0 = " << map_setup.x0
          << ", x_max = " << map_setup.x_max << ", beta = " << map_setup.beta
          << "; errors relative to beta (rate) and to |x_max - x0| (asymptote); coverage = fraction of trials whose "
             "95% interval (1.96 SE, SEs inflated for correlated residuals as in dem fit) holds the truth\n"
             "length_beta_eps,noise_over_amplitude,noise_correlation,beta_rel_error_median,beta_rel_error_p90,"
             "xmax_rel_error_median,beta_coverage,xmax_coverage,beta_reported_rel_se_median,flagged_fraction,unsaturated_fraction,converged\n";
      for (double rho : map_rhos)
        for (double noise : map_noises)
          for (double length : map_lengths) {
            demfit::IdentifiabilitySetup s = map_setup;
            s.length = length; s.noise = noise; s.correlation = rho;
            const demfit::IdentifiabilityCell c = demfit::identifiability_cell(s);
            csv << length << "," << noise << "," << rho << "," << c.beta_rel_error_median << ","
                << c.beta_rel_error_p90 << "," << c.xmax_rel_error_median << "," << c.beta_coverage << ","
                << c.xmax_coverage << "," << c.beta_reported_rel_se_median << "," << c.flagged_fraction << "," << c.unsaturated_fraction << ","
                << c.converged << "\n";
          }
      dem::write_file_atomic(map_out, csv.str());
      std::fprintf(stderr, "dem fit-map: %zu cells -> %s\n", map_rhos.size() * map_noises.size() * map_lengths.size(),
                   map_out.c_str());
      return 0;
    }
    if (*ecov) {
      if (fs::exists(ecov_out) && !ecov_force) throw std::runtime_error(ecov_out + " exists: pass --force to overwrite it");
      dem::write_file_atomic(ecov_out, demfit::ensemble_coverage_csv(ecov_setup, ecov_ks, ecov_lengths, ecov_rhos));
      return 0;
    }
    if (*compare) return exec_python("demkit.compare", compare->remaining());
    if (*plot) return exec_python("demkit.plots", plot->remaining());
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
  return 0;
}
