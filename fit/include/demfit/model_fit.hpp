// Calibration of the incremental anisotropic model (demfit/model.hpp) with Ceres: one joint
// fit of the isotropic branch (p*, C against nu) and the D2 ensemble mean curves at every nu,
// the nu-dependence of each shear parameter a law inside the fit; prediction of curves it was
// not fitted on (D3) with errors against the DEM ensemble band. docs/model.md.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "demfit/jacobian_check.hpp"
#include "demfit/profile.hpp"
#include "demfit/model.hpp"

namespace demfit::model {

/// One ensemble mean curve (a row per eps_d): the columns `dem fit` writes to ensemble/*.csv.
struct CurveData {
  std::string mode;          ///< D2, D3, ...
  double nu = 0;             ///< volume fraction of the start state [-]
  int packings = 0;          ///< K
  std::vector<double> eps;   ///< eps_d [-], increasing from 0
  std::vector<double> p, s, F;            ///< means: p* [-], s_dev [-], F_dev [-]
  std::vector<double> se_p, se_s, se_F;   ///< between-packing standard errors of the means
  std::vector<double> hw_p, hw_s, hw_F;   ///< 95 % band half-widths (hi95 - mean)
  std::string source;        ///< file it came from
};

/// Reads an ensemble mean curve; throws std::runtime_error naming the file and the missing column.
CurveData read_curve(const std::string& path, const std::string& mode, double nu);

/// Isotropic (unloading) branch points, pooled over packings.
struct IsoData {
  std::vector<double> nu, p, C;   ///< nu [-], p* [-], C_nonrattler [-]
};
/// Reads `cycle_unloading.csv` files (columns nu, p_star, C_nonrattler; p* > 1e-7 kept).
IsoData read_isotropic(const std::vector<std::string>& paths);

struct CalibrationOptions {
  double nu_ref = 0;             ///< centre of the nu-laws [-]; 0: mean nu of the curves
  double eps_max = 1e9;          ///< fit only eps_d <= eps_max [-]
  double se_floor = 0.25;        ///< sigma of a point >= se_floor x the median SE of its quantity and curve
  int max_iterations = 1000;
  double max_step = 5e-4;        ///< RK4 step in eps_d [-]
  bool fit_isotropic = true;     ///< false: isotropic block held at `start` (e.g. synthetic tests)
  const Parameters* start = nullptr;   ///< start values (nullptr: from per-curve saturating fits)
  /// With `start`: the isotropic block starts from its values (true: a restart from a stored optimum starts there) or
  /// from the isotropic branch's own fit (false, `--start-isotropic branch`: a start from another material's laws,
  /// which miss this branch; every fit before the fifteenth round of issue 31 started so).
  bool start_iso_from_file = true;
  /// One jamming fraction for both isotropic laws (`--jamming shared`): nu_cC tied to nu_c (coordination_jamming), so
  /// that the stiffness B is bounded at every nu (no cusp, cusp_pressure). Needs the isotropic block fitted and nu_cC
  /// not held; the fit writes nu_cC = nu_c (docs/model.md, "One jamming fraction").
  bool shared_jamming = false;
  /// Paths: leave out (weight 0) the leading rows that are forward constant-volume shear from the
  /// start, up to the first turn: a D2 run from the same packings, which the D2 curves carry.
  bool skip_d2_prefix = true;
  /// The frictional family (docs/model.md, "The frictional extension"): the extension block
  /// fitted too (started from the group model's calibration unless `start` is given), the
  /// stress-ratio limit on `surface` at each test's Lode angle (lode_b_of).
  bool extended = false;
  Surface surface = Surface::LadeDuncan;
  /// The fabric limit's Lode rule of the frictional family (FabricLode; `Norm` before issue 31's
  /// second round, `Principal` since: the largest principal deviatoric fabric saturates).
  FabricLode fabric = FabricLode::Principal;
  /// The frictional family's state-dependent stress-ratio limit (issue 31, fifth round): n_psi(nu)
  /// fitted too (the extension block then has kNumExt entries, else kNumExtBase; off: the fourth
  /// round's fit exactly).
  bool state_limit = false;
  /// With state_limit: the exponent n_psi scaled by (c_3(b_ref)/c_3(b))^lambda_psi, lambda_psi fitted (needs a
  /// second Lode angle in the calibration; `--state-limit pressure-lode`, docs/model.md).
  bool state_lode = false;
  /// The volume-form state parameter psi = nu - nu_cs(p) (issue 31, tenth round; `--state-limit volume`, excludes
  /// state_limit): the peak s_lim e^{n_b psi}, the dilatancy d_D (r - e^{-n_d psi}) with chi_D held at 1, and the
  /// critical-state line nu_cs + lambda_cs ln(p*/1e-3) held at the calibration paths' end states (which it needs).
  /// docs/model.md, "The volume-form state parameter".
  bool state_volume = false;
  /// The critical-state line's form with state_volume (`--csl`): false, nu_cs + lambda_cs ln(p*/1e-3); true,
  /// nu_cs + c_cs (p* - 1e-3), linear in the pressure (docs/model.md, "The critical-state line of soft spheres").
  bool csl_linear = false;
  /// With state_volume (`--anisotropy-pressure relaxing`, eighteenth round): the anisotropy's pressure is an excess
  /// over the isotropic law at the elastic state that relaxes at beta_p (fitted: ln_beta_p_a; its slope held at 0), so
  /// that a constant-p path's volume is steady at psi = 0 whatever a_A F (Ext::excess_relaxes; docs/model.md).
  bool excess_relaxes = false;
  /// With excess_relaxes (`--anisotropy-pressure bounded`, nineteenth round): the excess within (-p, p) (Ext::excess_bounded).
  bool excess_bounded = false;
  /// The start's deviators unaligned with the loading (`--start-anisotropy unaligned`, twenty-eighth round): s and F
  /// integrated from 0, the data compared with sqrt(s^2 + s0^2), sqrt(F^2 + F0^2) (Ext::start_unaligned).
  bool start_unaligned = false;
  /// The plastic dilatancy gated by the mobilisation r (`--dilatancy-gate mobilisation`; Ext::dilatancy_gated).
  bool dilatancy_gated = false;
  /// With state_limit: the fabric's limit times the stress ratio's state factor (`--fabric-limit state`, thirtieth
  /// round; Ext::fabric_state).
  bool fabric_state = false;
  /// sigma_dev scales with p_ref under a volume change (`--deviator-volume reference`, thirtieth round;
  /// Ext::deviator_reference).
  bool deviator_reference = false;
  /// The coordination law rises with the density (`--coordination rising`, the default since issue 31's twenty-third
  /// round): C1 >= 0 wherever the isotropic block is fitted and C1 not held. false (`free`): C1 of either sign, as
  /// every fit before; a falling law can make the isotropic pressure peak below nu = 1 (docs/model.md).
  bool coordination_rises = true;
  /// Check the Jacobian at the optimum against central differences of the residuals (check_jacobian; a rough cost's
  /// covariance is not quoted: Calibration::rough). The jackknife's refits leave it out.
  bool check_jacobian = true;
  /// Profile intervals of the coefficients with a quoted covariance error (`--profile`; profile_intervals, issue 31's
  /// twenty-fourth round): each coefficient held at trial values and the rest refitted, 3-6 refits per end. Off by
  /// default (a few hundred refits); the jackknife's refits leave it out.
  bool profile = false;
  /// Evaluate only: chi^2 at `start` as a fit from it would begin (after the start is moved inside its bounds and the
  /// isotropic reach), no fit and no errors (Calibration::chi2 and n_residuals only; nan where it cannot be evaluated).
  /// The jackknife's basin check reads it (issue 31, thirty-fifth round).
  bool evaluate_only = false;
  /// With profile: only these coefficients (Calibration::names); empty: every one with a quoted covariance error.
  std::vector<std::string> profile_only;
  /// With profile: told after each coefficient (its name, its place from 0, how many, its interval), and once before
  /// the first (place -1); empty: silent.
  std::function<void(const std::string&, int, int, const ProfileInterval&)> profile_progress;
  /// Isotropic parameters (IsoIndex) held at their start values while the rest of the block is
  /// fitted: a laboratory's isotropic branch of a few pressure levels cannot fix all seven (issue 31,
  /// "Calibrated on drained triaxial tests"). Needs `start`.
  std::vector<int> hold_iso;
  /// Extension coefficients (ExtIndex) held at their start value (`--hold`, extended family only).
  std::vector<int> hold_ext;
  /// Where the held isotropic parameters take their values (nullptr: from `start`). A multi-start
  /// fit (`--start A,B,...` with `--hold-isotropic`) holds them at the first start's values in every
  /// start, so that the starts differ in the fitted parameters only.
  const Parameters* hold_from = nullptr;
  /// The stress Lode parameter of D2 curves and paths (Parameters::b_d2; `--d2-lode`), kLodeBD2 by default.
  double b_d2 = kLodeBD2;
};

/// Parameters from a `parameters.csv` of `dem model` (the names of its first column, the value
/// column, nu_ref; the extension block when its names are there, then `extended`). Throws
/// std::runtime_error naming the file and the missing parameter.
Parameters read_parameters(const std::string& path);

/// The same laws re-centred on another nu_ref: a' = a + b (nu_ref_new - nu_ref_old), b unchanged.
Parameters recentred(const Parameters& P, double nu_ref);

/// Index of an isotropic parameter name (p0, nu_c, gamma_p, C0, C1, nu_cC, alpha), -1 if none.
int iso_index(const std::string& name);
/// The index of a frictional-extension coefficient by its table name (ext_name), -1 if none.
int ext_index(const std::string& name);

/// Intermediate-stress ratio b the model assumes for a mode or path name: 0 for D3 and
/// triaxial paths (axisymmetric compression), and for the laboratory tests of data/geotech
/// (demkit/geotech_model.py: TC_* 0, TE_* 1, TT_bNNN NNN/100), b_d2 otherwise (D2 and paths made of D2: the
/// parameters' b_d2, kLodeBD2 unless `--d2-lode` says otherwise).
double lode_b_of(const std::string& mode, double b_d2 = kLodeBD2);
const char* surface_name(Surface s);
const char* fabric_lode_name(FabricLode f);   ///< "norm", "principal", "opening", "overlap" (the --fabric-lode words)

/// Result of a calibration. Parameter order: the 7 isotropic, the 12 shear coefficients, then
/// (frictional family) the 7 extension coefficients.
struct Calibration {
  Parameters params;
  std::vector<std::string> names;       ///< 19 names
  std::vector<double> value, se_cov;    ///< estimate; SE from the covariance x max(1, chi2/dof)
  std::vector<double> se_jackknife;     ///< SE from the jackknife over packings (empty when not run)
  /// Degrees of freedom of each jackknife error (jackknife_dof: K - 1 over one set of packings, Welch-Satterthwaite's
  /// over several; empty when the jackknife did not run): the t quantile of its 95 % interval
  std::vector<double> dof_jackknife;
  std::vector<std::vector<double>> corr;   ///< correlation matrix (covariance)
  double chi2 = 0;                      ///< weighted sum of squared residuals
  int n_residuals = 0, n_free = 0;
  double chi2_dof() const { return n_residuals > n_free ? chi2 / (n_residuals - n_free) : 0.0; }
  bool ok = false;
  std::string message;                  ///< Ceres' summary line
  /// Where Ceres stopped at its iteration limit with chi^2 settled (demfit/settle.hpp): why the fit counts as converged,
  /// and the coefficients still moving over the last window ("" otherwise)
  std::string settled;
  std::vector<std::string> warnings;
  /// "p0 raised from A to B" where the start was moved within the isotropic law's reach (start_within_reach); "" else.
  std::string start_moved;
  /// A fitted drained path along which the optimum sits against the drained control's margin ("" if none; set by
  /// `dem model`): the errors are then not determined (parameters.csv's se, lo95, hi95 nan)
  std::string against_margin;
  /// Where the cost is not smooth at the optimum ("" if it is; CalibrationOptions::check_jacobian): a Jacobian column
  /// that central differences of the residuals do not reproduce (kRoughAbove). Its errors are then not determined.
  std::string rough;
  /// Per reported coefficient, how far its Jacobian column and the difference quotient disagree (JacobianColumn::
  /// disagreement; nan where not checked: held, or the check off)
  std::vector<double> jacobian_disagreement;
  /// Per reported coefficient, the rise of chi^2 one quoted covariance error either way along its linearised profile
  /// over the quadratic model's (check_error_scale; nan where not checked: no covariance error, or the check off)
  std::vector<ErrorScale> error_scale;
  /// Per reported coefficient, its profile interval (CalibrationOptions::profile; empty where not asked for, default
  /// entries (nan ends) where the coefficient quotes no covariance error)
  std::vector<ProfileInterval> profile;
  bool shared_jamming = false;          ///< nu_cC tied to nu_c (CalibrationOptions::shared_jamming)
  /// Coefficients the covariance leaves undetermined (an error of 0 to rounding from the pseudo-inverse: se_cov nan);
  /// the jackknife still quotes their spread over packings.
  std::vector<bool> undetermined;
  /// The errors to quote: jackknife where it ran, else the covariance.
  const std::vector<double>& se() const { return se_jackknife.empty() ? se_cov : se_jackknife; }
  /// Why no error is quoted for any coefficient ("" if errors are): the optimum against the drained control's margin,
  /// or a cost that is not smooth there (rough)
  std::string errors_not_determined() const;
};

/// A Jacobian column that central differences of the residuals miss by more than this (relative) makes the cost rough
/// at the optimum (Calibration::rough). The 33 stored laboratory calibrations with separate jamming fractions whose
/// cost is smooth agree within 6e-8 to 1.5e-5 (the tied ones up to 0.006); the relaxing three-pressure mu = 0.5 ones,
/// whose output jumps with the last digit of nu_c, miss by 1.2-1.4 (docs/model.md, "A cost that is not smooth at its
/// optimum"; data/geotech/model/state_volume/smoothness.md).
constexpr double kRoughAbove = 1e-2;

/// A fitted coefficient within this of a bound of the calibration (relative to max(1, |value|)) ends on it: moved onto
/// it and held (solve_on_face); the warnings that a coefficient sits on its bound read nu_c and nu_cC so (2e-6 below
/// the lowest start state). At most kFacePasses fits on a face follow the first (twenty-fourth round), each after new
/// bounds are held or, when none is met, after held ones whose chi^2 falls into the box are set free (twenty-fifth).
constexpr double kNearBound = 2e-6;
constexpr int kFacePasses = 8;

/// The cost's rise over one quoted covariance error, relative to the quadratic model's (Calibration::error_scale),
/// outside [1/kQuadraticWithin, kQuadraticWithin]: the covariance interval is then off by more than sqrt(2) on that side
/// (a profile's one-error point moves by 1/sqrt(rise)); reported (error_scale.csv; docs/model.md, "The cost over one
/// quoted error").
constexpr double kQuadraticWithin = 2.0;

/// A covariance error at most 1e-9 max(1, |value|) (DENSE_SVD's pseudo-inverse on a direction the curves do not see)
/// becomes nan, flagged in cal.undetermined, with a warning per coefficient, or one when every quoted error is so
/// (a degenerate Jacobian at the optimum).
void null_directions(Calibration& cal);
/// Entries [pos, pos + n) of the reported parameters removed (names, values, errors, flags, correlations).
void drop_entries(Calibration& cal, int pos, int n);

/// The jackknife's covariance of two series of leave-one-out estimates over independent samples of packings:
/// sum over the samples of (n - 1)/n sum (x_k - mean x)(y_k - mean y), each about its own sample's mean; sample[k]
/// names estimate k's sample (empty: one sample, the usual jackknife). Two samples are the joint calibration's: the
/// friction study's packings behind D2 + D3, the laboratory's behind its triaxial paths (docs/model.md, "A jackknife
/// over two sets of packings").
double jackknife_covariance(const std::vector<double>& x, const std::vector<double>& y, const std::vector<int>& sample = {});
/// Welch-Satterthwaite's degrees of freedom of jackknife_covariance(x, x, sample): (sum v_s)^2 / sum v_s^2/(n_s - 1),
/// v_s one sample's part; n - 1 over one sample; nan where every part is 0.
double jackknife_dof(const std::vector<double>& x, const std::vector<int>& sample = {});
/// The jackknife's standard errors from the leave-one-out estimates est[k][i] of cal.value: sqrt(jackknife_covariance)
/// (one sample: sqrt((K-1)/K sum (e - mean)^2)) for every coefficient with a covariance error or one the covariance
/// left undetermined (cal.undetermined), and for the critical-state line's terms held at the data's end states (nu_cs,
/// and lambda_cs or c_cs, whichever --csl uses); nan for the held ones and those on a bound, and nan with a warning
/// for a coefficient with a covariance error whose every refit ends on the same value (a bound: no spread to quote).
/// dof (if given) gets each error's jackknife_dof.
std::vector<double> jackknife_errors(const std::vector<std::vector<double>>& est, const Calibration& cal,
                                     bool csl_linear, std::vector<std::string>* warnings = nullptr,
                                     const std::vector<int>& sample = {}, std::vector<double>* dof = nullptr);
/// Whether a leave-one-out refit can enter the jackknife: converged, with a chi2/dof not above 3 max(1, the full
/// fit's). A refit that failed at its start, or ended in a poor local optimum, would pass its start's values or that
/// optimum's off as the packings' scatter; `dem model` then quotes the covariance errors and says which refit failed
/// (twentieth round).
bool jackknife_refit_usable(const Calibration& refit, const Calibration& full);

/// An ensemble mean of a loading path (reversal, cyclic, isobaric; written by
/// demkit/path_ensemble.py): rows on the accumulated deviatoric strain, deviators signed along
/// the first loading direction (docs/model.md, "Paths").
struct PathData {
  std::string name;          ///< path name (reversal, isobaric, cyclic, ...)
  double nu = 0;             ///< volume fraction of the start state [-]
  int packings = 0;          ///< K
  std::string source;        ///< file it came from
  std::vector<double> acc;   ///< eps_d_accumulated [-], from 0, non-decreasing
  std::vector<double> eps_signed;             ///< signed eps_d since the path start [-]
  std::vector<int> direction, isobaric;       ///< per row: sign of the increment into it; control: 0 constant
                                              ///< volume, 1 p held, 2 side stress held (column `triaxial`)
  std::vector<double> nu_m, ev, p, s, F;      ///< means: nu [-], eps_v = tr(E)/3 [-], p* [-], s_dev and F_dev signed [-]
  std::vector<double> se_ev, se_p, se_s, se_F;   ///< between-packing standard errors of the means
  std::vector<double> hw_ev, hw_p, hw_s, hw_F;   ///< 95 % band half-widths (hi95 - mean)
  std::vector<double> ezz, sr;                ///< optional (empty if absent): means of the axial strain eps_zz [-]
                                              ///< and of the side stress (sigma_xx + sigma_yy)/2 over p(row 0) [-]
  bool has_isobaric() const;                  ///< any row under pressure control
  bool has_volume() const;                    ///< any row (after the first) at prescribed volume
};

/// The `Weighted` fabric rule's coefficients are identified by a second Lode angle only: throws
/// std::invalid_argument (naming `--calibrate-on D2,D3`) when every curve and path is at b = 1/2.
void check_weighted_lode(const std::vector<CurveData>& curves, const std::vector<PathData>& paths);
/// Throws std::invalid_argument naming `what` (a coefficient that acts only away from D2's Lode angle) when every
/// calibrated curve and path is at b = 1/2; `or_else` ends the message with the other way out.
void check_second_lode_angle(const std::vector<CurveData>& curves, const std::vector<PathData>& paths,
                             const std::string& what, const std::string& or_else, double b_d2 = kLodeBD2);

/// Reads a path ensemble CSV; throws std::runtime_error naming the file and a missing column.
PathData read_path(const std::string& path, const std::string& name, double nu);

/// The joint fit. Without curves the path ensembles alone are fitted (with the isotropic branch),
/// which needs `o.start` (a monotone mode gives the start values otherwise).
/// Throws std::invalid_argument for unusable input (no curves and no start, too few points,
/// curves that do not start at eps_d = 0, non-positive pressure) with a message naming the fix.
/// `paths`: path ensembles fitted as well (residuals of p* on constant-volume rows, eps_v on
/// isobaric rows, s and F signed on every row; sigma as for the curves).
Calibration calibrate(const std::vector<CurveData>& curves, const IsoData& iso, const CalibrationOptions& o = {},
                      const std::vector<PathData>& paths = {});

/// Model curves for the grid of `c` from its first row (the start state), eps_d <= eps_max.
struct ModelCurve {
  std::vector<double> eps, p, s, F, nu;
  /// How each point was reached from the one before (model::advance), as PathPrediction's: RK4's halvings (-1: no
  /// step held), graded from a singular start, the fabric's or the excess pressure's relaxation taken exactly
  std::vector<int> halvings;
  std::vector<bool> graded, split, relaxed;
  double gate_exponent_start = std::numeric_limits<double>::quiet_NaN();   ///< n_F at a graded start (NaN: none)
};
/// psi_seen (optional): [min, max] of psi over every right-hand-side evaluation (Ext::psi_seen; psi_range).
/// The extension a prediction by `params` runs with on a curve or path of mode (or path name) `mode`: its Lode
/// parameter b, the stress's b (Parameters::b_d2 for D2), the family's flags (predict_curve, predict_path).
Ext<double> prediction_ext(const Parameters& params, const std::string& mode, double* psi_seen = nullptr);
ModelCurve predict_curve(const Parameters& params, const CurveData& c, double eps_max = 1e9, double max_step = 5e-4,
                         double* psi_seen = nullptr);

/// Prediction error of one quantity of one curve against the DEM ensemble.
struct PredictionError {
  std::string quantity;            ///< p_star, s_dev, F_dev
  double rms = 0, max_abs = 0;     ///< RMS and max |model - DEM mean| [units of the quantity]
  double band = 0;                 ///< mean 95 % half-width of the DEM band [same units]
  double rms_over_band = 0, max_over_band = 0;   ///< the two above divided by the band
  double frac_in_band = 0;         ///< fraction of points where the model lies inside the band
  double bias = 0;                 ///< mean (model - DEM) [same units]
  int n = 0;
};
std::vector<PredictionError> prediction_errors(const ModelCurve& m, const CurveData& c);

/// The model along a path ensemble's rows from its first row (the start state, signed).
struct PathPrediction {
  std::vector<double> acc, p, s, F, nu, ev;   ///< as PathData; ev = eps_vol/3 (the curves' eps_v) [-]
  /// The pressure of the elastic state on the isotropic law, p_iso(nu_el) [p*], with the volume-form state parameter
  /// (p itself with the permanent law; p - q with the relaxing excess q); p elsewhere.
  std::vector<double> p_el;
  bool excess_relaxes = false;   ///< the relaxing excess (Ext::excess_relaxes): q = p - p_el is written out
  bool excess_bounded = false;   ///< the bounded excess (Ext::excess_bounded)
  /// The first row the drained triaxial control could not reach (State::lost, kTriaxialMargin: A = a_A B F came within
  /// 10 % of 3B); -1 where every row was reached. From there on every entry is NaN.
  int lost_row = -1;
  /// a_A F/3 (model::pole_ratio) on the rows reached under the drained triaxial control, NaN on the others: the
  /// control is lost from 1 - kTriaxialMargin on
  std::vector<double> pole;
  /// How often RK4's step was halved to reach each row (model::advance: the fixed step did not hold the path's drained
  /// control); 0 on every row where the fixed step did
  std::vector<int> halvings;
  /// The rows reached from a start where the fabric gate's exponent is negative, integrated on graded pieces
  /// (model::singular_start); the gate's exponent there in gate_exponent_start (NaN where no row was)
  std::vector<bool> graded;
  /// The rows reached from a start whose gate is not integrable, with the fabric's relaxation taken exactly
  /// (model::advance, split_step)
  std::vector<bool> split;
  /// The rows reached with the excess pressure's relaxation taken exactly on some step (model::first_held_try)
  std::vector<bool> relaxed;
  double gate_exponent_start = std::numeric_limits<double>::quiet_NaN();
};
PathPrediction predict_path(const Parameters& params, const PathData& d, double max_step = 5e-4,
                            double* psi_seen = nullptr);

/// A jamming fraction's start value inside its bound, the lowest volume fraction numin of the data (a start from another
/// calibration, or a jackknife refit from an optimum on that bound whose left-out mean dilates a little further, may lie
/// above it; Ceres refuses an infeasible start). The coordination law's nu_cC (cusp: also nu_c tied to it) is moved to
/// 0.005 below numin, not onto it, where (nu/nu_cC - 1)^alpha would put its cusp on the start state itself (an
/// unbounded B there; a held nu_cC would stay on it). The pressure law's nu_c, smooth there, is moved just inside
/// (numin (1 - 1e-5)): an optimum on that bound then restarts where it ended (thirty-fourth round: lab_dense's refit
/// without m2 had started 0.005 below it, at chi2/dof 349 against the full fit's 15.3, and stayed there).
double jamming_start_inside(double v, double numin, bool cusp);

/// Why a path prediction M is not a number ("" where every row is): " loses its drained control after
/// eps_d_accumulated = X (...the pole...)", " is not a number from eps_d_accumulated = X" (start_failure, and `dem
/// model`'s held-out paths a refit does not follow).
std::string path_not_a_number(const PathPrediction& m);

/// Why a calibration could not be evaluated at its start (Ceres stopped before its first step, a start of a multi-start
/// "failed"): the first fitted curve or path that is not a number at the start values P, named with its cause (a start
/// pressure above the isotropic law's reach, the drained control's pole, a start state the laws cannot hold); "" where
/// every one is a number. calibrate() adds it to the message (starts.md, jackknife.md) and the warnings.
std::string start_failure(const Parameters& P, const std::vector<CurveData>& curves, const std::vector<PathData>& paths);

/// The pressure p* at the coordination law's jamming fraction nu_cC on the isotropic law `iso` (kNumIso entries),
/// where nu_cC lies above the pressure's jamming fraction nu_c; NaN otherwise. There the law's stiffness
/// B = dp*/d ln nu is unbounded (the coordination's slope (nu/nu_cC - 1)^(alpha - 1), alpha < 1, times a pressure
/// factor that is not zero), and with the volume-form state parameter the elastic state follows p*: a path through
/// that pressure is held there, and where it leaves depends on the steps (sixteenth round; docs/model.md, "The
/// isotropic law's cusp").
double cusp_pressure(const double* iso);
/// Where a predicted path meets the isotropic law's cusp: the law is read at the path's own nu, or (the volume-form state
/// parameter) at the elastic state, so the path meets it where its nu crosses nu_cC, or where its elastic state's
/// pressure m.p_el crosses cusp_pressure: p* itself, or with the relaxing excess p* - q, which can cross it below the
/// path's own pressures (nineteenth round). Returns that nu_cC or pressure; NaN where the path does not meet it.
double cusp_crossed(const Parameters& P, const PathPrediction& m);
/// The largest relaxing excess over the pressure along a predicted path, max q/p* with q = p* - p_el (0 with the
/// permanent law, and where no row has p* > 0), and the accumulated strain of that row in *at. Above 1 the elastic state
/// lies below the isotropic law's jamming fraction: a negative isotropic pressure (nineteenth round).
double largest_excess_ratio(const PathPrediction& m, double* at = nullptr);

/// The range of psi = nu - nu_cs(p) the laws are read in: [-R, R], R the largest |psi| of the model's own states
/// along `curves` and `paths`, predicted unclamped with `params` (volume-form state parameter only; else both
/// infinite): the calibration's distance from the critical state, on either side (thirteenth round). Along those
/// curves the clamp changes nothing.
std::pair<double, double> psi_range(const Parameters& params, const std::vector<CurveData>& curves,
                                    const std::vector<PathData>& paths, double eps_max = 1e9, double max_step = 5e-4);

/// Throws std::invalid_argument (naming `source`) when nu0 lies at or below the isotropic law's
/// jamming fraction, where p_iso(nu0) <= 0 makes the start scale k = p0/p_iso(nu0) non-positive.
void check_start_scale(const std::vector<double>& iso, double nu0, const std::string& source);

/// Errors of a path prediction: s_dev and F_dev (signed), p_star where the volume was
/// prescribed, eps_v where p was held (the model's dilatancy); rows after the first.
std::vector<PredictionError> path_errors(const PathPrediction& m, const PathData& d);

}  // namespace demfit::model
