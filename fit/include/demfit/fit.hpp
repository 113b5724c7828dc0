// Least-squares fits of the saturating anisotropy-evolution law (Imole et al. 2013,
// Kumar et al. 2014):  dx/d eps_d = beta (x_max - x)  =>  x(e) = x_max - (x_max - x0) exp(-beta e)
// with Ceres (automatic differentiation) and, as an independent cross-check, GSL.
#pragma once
#include <cmath>
#include <map>
#include <string>
#include <vector>

namespace ceres { class Problem; }

namespace demfit {

/// True when the residuals and the Jacobian of `problem` at its current parameters are finite and
/// below sqrt(DBL_MAX) in magnitude (their squares do not overflow). ceres::Covariance's dense SVD
/// must only be asked on such a problem: Eigen's SVD of a matrix with NaN or inf in it crashes
/// (SIGSEGV) instead of failing, which took a Python session down with it (tests/fuzz/fuzz_demtk.py).
bool covariance_safe(ceres::Problem& problem);

/// The model as a small templated functor usable by Ceres' autodiff.
/// Parameters p = {x0, x_max, beta}; residual = y - x(e).
struct SaturatingResidual {
  SaturatingResidual(double e, double y) : e_(e), y_(y) {}
  template <class T>
  bool operator()(const T* p, T* residual) const {
    using std::exp;
    residual[0] = T(y_) - (p[1] - (p[1] - p[0]) * exp(-p[2] * T(e_)));
    return true;
  }
  double e_, y_;
};

/// Evaluates the law at strain e.
double saturating(double x0, double x_max, double beta, double e);

enum class Loss { None, Huber, Cauchy };

struct FitOptions {
  double window_min = -1e300;     ///< fit only points with e >= window_min
  double window_max = 1e300;      ///< and e <= window_max
  Loss loss = Loss::None;         ///< robust loss (changes the optimum; errors then approximate)
  double loss_scale = 0.0;        ///< residual scale of the robust loss; 0: 3 x MAD estimate
  bool nonnegative_asymptote = true;   ///< x_max >= 0 (physical for s_dev, F_dev)
  double beta_min = 1e-6;         ///< lower bound of the rate (beta > 0)
  double beta_max = 1e4;          ///< upper bound of the rate
  int min_points = 6;             ///< fewer points is an error
  /// Inflate the standard errors for serially correlated residuals (DEM curves fluctuate on
  /// strain scales longer than the sampling): factor sqrt((1 + rho)/(1 - rho)) with rho the
  /// lag-1 autocorrelation of the residuals (AR(1) effective sample size), when rho > 0.
  bool correct_autocorrelation = false;
  bool fix_x0 = false;            ///< hold x0 at x0_value (e.g. a curve known to start at 0)
  double x0_value = 0.0;
  /// Judge the fit by its own residuals: autocorrelation, point-to-point noise (non-monotone
  /// data) and residual-based standard errors (poorly determined). Off for ensemble means,
  /// whose errors come from the spread between packings (fit_ensemble).
  bool residual_diagnostics = true;
  double max_relative_error = 0.5;  ///< warn when SE exceeds this fraction of |x_max - x0| (x0, x_max) or of beta
  /// Below this reciprocal condition number of the scaled Jacobian the fit is refused
  /// (ok = false, no standard errors): the data do not determine the parameters.
  double min_jacobian_rcond = 1e-4;
};

/// Result of one fit. Standard errors are from the Jacobian at the optimum scaled by the
/// residual variance s^2 = RSS/(n - 3) (Ceres' covariance assumes unit variance).
struct FitResult {
  bool ok = false;                ///< the optimiser converged and the covariance is available
  double x0 = 0, x_max = 0, beta = 0;
  double se_x0 = 0, se_x_max = 0, se_beta = 0;   ///< standard errors (NaN where unavailable)
  double corr[3][3] = {};         ///< correlation matrix of (x0, x_max, beta)
  double initial_slope = 0;       ///< beta (x_max - x0): dx/de at e = 0 (G/p for s_dev)
  double se_initial_slope = 0;
  double eps_95 = 0;              ///< ln(20)/beta: strain at which 95% of x_max - x0 is reached
  double rmse = 0, r_squared = 0, cost = 0;
  double residual_autocorrelation = 0;   ///< lag-1 autocorrelation of the residuals
  double se_inflation = 1;        ///< factor applied to the standard errors (1: none)
  int n = 0;                      ///< points used
  double e_last = 0;              ///< largest strain among the points used
  double e_first = 0;             ///< smallest strain among the points used
  double jacobian_rcond = 0;      ///< reciprocal condition number of the scaled Jacobian (0..1)
  std::vector<std::string> warnings;   ///< reasons to distrust a number (see fit_saturating)
  bool non_monotone = false;      ///< the data reverse after their extreme (residual diagnostics)
};

/// The one rule for a usable fit, applied by every table, figure and summary line (`usable`
/// column of parameters.csv; README, "Errors"): "" when the fitted numbers are determined by the
/// data, else the reason, printed beside the fit. Not usable: the optimiser did not converge or
/// the covariance is rank deficient or ill-conditioned (ok false), x_max or beta has no finite
/// standard error (a bound, or no error estimate), or the data are not monotone (the saturating
/// law does not describe the curve). Other warnings (an extrapolated x_max, large relative
/// errors, correlated residuals) keep a fit usable: its error bars carry them.
std::string unusable_reason(const FitResult& r);
/// The summary line's words: "3 of 12 fits usable (9 not: 9 not monotone: ...)".
std::string usable_summary(int usable, std::size_t total, const std::map<std::string, int>& not_usable);

/// Ceres' logging (glog) initialised once, errors only; every Ceres solve in demfit calls it.
void init_glog();

/// Fits x(e) to (e, y). Throws std::invalid_argument for unusable input (sizes differ,
/// non-finite values, fewer than min_points in the window, a flat curve). Adds warnings when
/// the data do not determine a parameter: no saturation reached (eps_95 beyond the data),
/// relative standard error above max_relative_error, a parameter on its bound (no standard
/// error quoted), non-monotone data, a failed covariance.
FitResult fit_saturating(const std::vector<double>& e, const std::vector<double>& y,
                         const FitOptions& options = {});

/// The same least-squares problem solved with GSL's trust-region Levenberg-Marquardt
/// (gsl_multifit_nlinear), unconstrained, from the given start. Returns {x0, x_max, beta}
/// and the residual sum of squares in *rss. Throws std::runtime_error if GSL fails.
std::vector<double> fit_saturating_gsl(const std::vector<double>& e, const std::vector<double>& y,
                                       const std::vector<double>& start, double* rss = nullptr);

/// Do two curves (e.g. D2 and D3 from one volume fraction) follow the same law?
struct SharedPathTest {
  FitResult shared;               ///< one law for both curves (3 parameters)
  FitResult first, second;        ///< separate laws (3 + 3 parameters)
  double f_statistic = 0;         ///< ((RSS_shared - RSS_sep)/k) / (RSS_sep/(n - 2k)), k = 3 (2 with fix_x0), divided by the
                                  ///< squared SE inflation when correct_autocorrelation is on
  double p_value = 1;             ///< upper tail of F(k, n - 2k)
  double max_gap = 0;             ///< max |x_first(e) - x_second(e)| over the strains both fits used
  bool same_path = false;         ///< the paper's claim accepted: p >= 0.01 or max_gap < tolerance
};
SharedPathTest test_shared_path(const std::vector<double>& e1, const std::vector<double>& y1,
                                const std::vector<double>& e2, const std::vector<double>& y2,
                                double gap_tolerance, const FitOptions& options = {});

/// Generic small nonlinear fit y = f(x; p) for the nu-dependence laws. `model` names one of:
///   "linear"     p0 + p1 (nu - nu_ref)
///   "power"      p0 + p1 (nu/p2 - 1)^p3          (C(nu) of Goncu et al.; p2 = nu_c)
///   "pressure"   p0 (nu/p1) (-e)(1 - p2 e), e = ln(p1/nu)   (p*(nu) isotropic law, p1 = nu_c)
struct CurveFit {
  std::string model;
  std::vector<double> params, errors;
  double rmse = 0, r_squared = 0;
  int n = 0;
  bool ok = false;
  std::vector<std::string> warnings;
};
CurveFit fit_law(const std::string& model, const std::vector<double>& x, const std::vector<double>& y,
                 const std::vector<double>& start, const std::vector<double>& sigma = {},
                 double nu_ref = 0.0);
double eval_law(const std::string& model, const std::vector<double>& p, double x, double nu_ref = 0.0);

}  // namespace demfit
