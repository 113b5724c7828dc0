// `dem model ENSEMBLE_DIR`: calibrate the incremental anisotropic model on the D2 ensemble
// curves and the isotropic branch, predict the D3 curves, write tables and plots (docs/model.md).
#pragma once
#include <string>
#include <vector>

namespace CLI { class App; }

namespace demfit {

struct ModelCommandOptions {
  std::string dir;                        ///< ensemble folder reduced by `dem fit` (ensemble/D2_phiX.csv ...)
  std::string out;                        ///< output folder (default DIR/model)
  std::vector<std::string> isotropic;     ///< cycle_unloading.csv files (default: DIR/members/*/[prep/]cycle_unloading.csv)
  std::string calibrate_mode = "D2";      ///< the mode fitted; every other mode is predicted
  std::string paths;                      ///< folder of path ensembles PATH_phiX.csv (default DIR/paths if it exists)
  std::vector<std::string> calibrate_on;  ///< modes and paths fitted (default: {calibrate_mode}); the rest is predicted
  double eps_max = 1e9;                   ///< fit and compare only eps_d <= eps_max [-]
  bool jackknife = true;                  ///< errors from the jackknife over packings (needs DIR/members)
  bool basin_check = true;                ///< the jackknife's basin check (basin_check, full_fit_basin; --no-basin-check)
  bool no_plots = false;
  bool force = false;                     ///< overwrite an existing output folder
  /// --profile: "" (none, the default), `all`, or comma-separated coefficient names: their profile intervals
  /// (CalibrationOptions::profile; profile.csv)
  std::string profile;
  std::string family = "group";           ///< group, extended or auto (docs/model.md, "The frictional extension")
  std::string surface = "ld";             ///< Lode surface of the extended family: ld, mn, none
  int max_iterations = 1000;              ///< Ceres iterations of each fit
  /// Start values: parameters.csv files of other `dem model` runs, or `default` (the start from the data's own
  /// saturating fits). More than one: the fit is made from each, the lowest chi2/dof is kept (starts.{csv,md}).
  std::vector<std::string> start;
  /// Where the isotropic block of a --start fit starts: `file` (the file's values) or `branch` (the isotropic branch's
  /// own fit: for a start from another material's laws; every fit before the fifteenth round of issue 31 started so).
  std::string start_isotropic = "file";
  /// The isotropic laws' jamming fractions: `separate` (nu_c and nu_cC, the default) or `shared` (nu_cC = nu_c:
  /// no cusp in the stiffness; docs/model.md, "One jamming fraction")
  std::string jamming = "separate";
  std::string coordination = "rising";
  /// With --state-limit volume, the anisotropy's pressure (eighteenth round): `permanent` (the elastic state carries it,
  /// never relaxed: the tenth to seventeenth rounds) or `relaxing` (an excess over the isotropic law that relaxes at
  /// beta_p, fitted) or `bounded` (the same, its source gated by 1 - (q/p)^2: q within (-p, p), nineteenth round);
  /// empty: permanent, or with --predict-with the file's (row anisotropy_excess)
  std::string anisotropy_pressure;
  /// The start's deviators (twenty-eighth round): `aligned` (the measured s0, F0 taken as aligned with the loading and
  /// integrated from, every calibration before) or `unaligned` (s and F the aligned parts from 0, compared with the data
  /// as sqrt(x^2 + x0^2)); empty: aligned, or with --predict-with the file's (row start_anisotropy)
  std::string start_anisotropy;
  /// The extended family's plastic dilatancy (twenty-eighth round): `none` (ungated, every calibration before) or
  /// `mobilisation` (times r); empty: none, or with --predict-with the file's (row dilatancy_gate)
  std::string dilatancy_gate;
  /// With the pressure-form state limit (thirtieth round): `fixed` (F_lim, every calibration before) or `state` (F_lim
  /// times the stress ratio's state factor); empty: fixed, or with --predict-with the file's (row fabric_limit)
  std::string fabric_limit;
  /// The deviatoric stress under a volume change (thirtieth round): `fixed` (through A alone, every calibration before)
  /// or `reference` (also scaling with p_ref(nu)); empty: fixed, or with --predict-with the file's (row deviator_volume)
  std::string deviator_volume;
  std::vector<std::string> hold_isotropic;   ///< isotropic parameters held at the start values (needs one start file)
  std::vector<std::string> hold;             ///< extension coefficients held at their start values (--hold)
  std::string state_limit = "none";     ///< extended family's stress-ratio limit: none (default), pressure (n_psi fitted), pressure-lode (+ lambda_psi)
  /// The critical-state line's form with --state-limit volume: linear (the default: nu_cs + c_cs (p* - 1e-3)) or
  /// log (nu_cs + lambda_cs ln(p*/1e-3))
  std::string csl = "linear";
  std::string fabric_lode = "overlap";  ///< Lode rule of the extended family's fabric: overlap (default), principal, norm, opening, extension
  /// parameters.csv of another `dem model` run: no calibration, every curve and path predicted with it (the family,
  /// surface and fabric rule from --family/--surface/--fabric-lode as that run was given them; the state limit from the file)
  std::string predict_with;
  /// --d2-lode: the stress Lode parameter b of D2 curves and paths: "" (a calibration 1/2, --predict-with the file's
  /// b_D2), a number in (0, 1), or "normal" (the plane-strain b of the surface through the calibrated limit s_max_a,
  /// plane_strain_lode_b; docs/model.md, thirteenth round)
  std::string d2_lode;
  /// With --state-limit volume: keep the laws of psi within the calibration's own states (psi_range; rows psi_min,
  /// psi_max); false (--no-psi-range): unbounded, as before the thirteenth round
  bool psi_range = true;
};

void add_model_options(CLI::App& app, ModelCommandOptions& o);

/// Returns the exit code: 0 ok, 2 bad input (message says what and how to fix), 1 other failure.
int run_model_command(const ModelCommandOptions& o);

}  // namespace demfit
