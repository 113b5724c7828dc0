// `dem fit RUN_DIR`: fit every deviatoric curve of a run and write parameter tables.
#pragma once
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "demfit/fit.hpp"

namespace CLI { class App; }

namespace demfit {

struct FitCommandOptions {
  std::string run_dir;               ///< a `dem run` results folder (or any folder with deviatoric/*.csv)
  double window_min = 0.0;           ///< eps_d window of the fits
  double window_max = 1e9;
  std::string loss = "none";         ///< none | huber | cauchy
  double gap_tolerance = 0.02;       ///< "same path" when the D2/D3 fits differ by less than this
  bool no_plots = false;             ///< skip the matplotlib plots
  bool independent_errors = false;   ///< no standard-error inflation for correlated residuals
  bool force = false;                ///< overwrite an existing RUN_DIR/fit
  bool partial = false;              ///< fit an incomplete ensemble (its tables say so)
  /// An ensemble folder: the status file of every task its scene plans (relative to RUN_DIR;
  /// set by the caller from RUN_DIR/scene.toml). A missing one makes the ensemble incomplete.
  std::vector<std::string> planned_tasks;
  std::string plan_error;            ///< why the plan could not be read (the ensemble is then refused)
};

void add_fit_options(CLI::App& app, FitCommandOptions& o);

/// Fits of one run, per (mode, quantity): (nu, fit) pairs.
using FitsByModeQuantity = std::map<std::pair<std::string, std::string>, std::vector<std::pair<double, FitResult>>>;
/// OUT_DIR/nu_laws.*: each fitted parameter as a linear law of nu, weighted by its standard error.
void write_nu_laws(const FitsByModeQuantity& fits, const std::string& out_dir);
/// OUT_DIR/isotropic.*: C*(nu) and p*(nu) laws of the unloading branch (points of all files pooled).
void write_isotropic(const std::vector<std::string>& unloading_csvs, const std::string& out_dir);

/// `dem fit` of an ensemble folder (RUN_DIR/members/*, written by `dem ensemble`): averages
/// the members per (mode, nu) into RUN_DIR/ensemble/, fits the mean with errors between
/// packings, writes the tables of run_fit_command and the ensemble plots.
int run_ensemble_fit_command(const FitCommandOptions& o);

/// Writes RUN_DIR/fit/{parameters,shared_path,nu_laws,isotropic}.{csv,json,md,tex} and plots.
/// Returns the process exit code (0 ok, 1 error); prints warnings on stderr.
int run_fit_command(const FitCommandOptions& o);

}  // namespace demfit
