#include "demfit/format.hpp"
#include "demfit/fit.hpp"

#include <ceres/ceres.h>
#include <gsl/gsl_blas.h>
#include <gsl/gsl_cdf.h>
#include <gsl/gsl_errno.h>
#include <gsl/gsl_linalg.h>
#include <gsl/gsl_multifit_nlinear.h>
#include <gsl/gsl_vector.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <numeric>
#include <sstream>
#include <stdexcept>

namespace demfit {

// GSL's default error handler aborts the process (a Python session with it): every GSL call here
// checks its status instead. Set once when a process loads demfit (the CLI, the tests, demtk).
[[maybe_unused]] const bool kGslErrorsReturned = [] {
  gsl_set_error_handler_off();
  return true;
}();

void init_glog() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (!google::IsGoogleLoggingInitialized()) google::InitGoogleLogging("demfit");
    FLAGS_minloglevel = 2;   // errors only
  });
}

namespace {

void select_window(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& o,
                   std::vector<double>& ew, std::vector<double>& yw) {
  if (e.size() != y.size()) throw std::invalid_argument("fit: strain and value arrays differ in length");
  for (std::size_t i = 0; i < e.size(); ++i) {
    if (!std::isfinite(e[i]) || !std::isfinite(y[i]))
      throw std::invalid_argument("fit: non-finite value at point " + std::to_string(i) +
                                  " (NaN or inf in the curve): the run probably blew up; check its log");
    if (e[i] >= o.window_min && e[i] <= o.window_max) { ew.push_back(e[i]); yw.push_back(y[i]); }
  }
  if (static_cast<int>(ew.size()) < o.min_points)
    throw std::invalid_argument("fit: only " + std::to_string(ew.size()) + " points in the window [" +
                                fmt(o.window_min, 4) + ", " + fmt(o.window_max, 4) + "]; need at least " +
                                std::to_string(o.min_points) + " (sample the run more finely or widen the window)");
  const auto [lo, hi] = std::minmax_element(yw.begin(), yw.end());
  const double scale = std::max(std::fabs(*lo), std::fabs(*hi));
  if (*hi - *lo <= 1e-12 * scale || *hi == *lo)
    throw std::invalid_argument("fit: the curve is flat (all values equal " + fmt(*lo, 4) +
                                "): no evolution to fit; was the run deformed at all?");
}

std::vector<double> start_values(const std::vector<double>& e, const std::vector<double>& y) {
  const std::size_t n = e.size();
  const std::size_t tail = std::max<std::size_t>(1, n / 5);
  const double x0 = y.front();
  double xmax = 0;
  for (std::size_t i = n - tail; i < n; ++i) xmax += y[i];
  xmax /= tail;
  const double half = 0.5 * (x0 + xmax);
  double e_half = 0;
  for (std::size_t i = 0; i < n; ++i)
    if ((xmax > x0 && y[i] >= half) || (xmax < x0 && y[i] <= half)) { e_half = e[i] - e.front(); break; }
  const double range = e.back() - e.front();
  const double beta = e_half > 0 ? std::log(2.0) / e_half : 5.0 / std::max(range, 1e-12);
  return {x0, xmax, beta};
}

// Reciprocal condition number of the Jacobian at the optimum, its columns scaled to the
// parameters' natural units (x0 and x_max by the amplitude |x_max - x0|, beta by beta):
// near 0 when the data cannot separate the parameters (e.g. a curve saturated at its first
// point, where beta, and x0 with it, are free).
double jacobian_rcond(const std::vector<double>& e, double x0, double x_max, double beta, bool fix_x0) {
  const double amp = std::fabs(x_max - x0);
  const std::size_t n = e.size(), p = fix_x0 ? 2 : 3;
  if (!(amp > 0) || !(beta > 0) || n < p) return 0.0;
  gsl_matrix* J = gsl_matrix_alloc(n, p);
  gsl_matrix* V = gsl_matrix_alloc(p, p);
  gsl_vector* S = gsl_vector_alloc(p);
  gsl_vector* work = gsl_vector_alloc(p);
  for (std::size_t i = 0; i < n; ++i) {
    const double ex = std::exp(-beta * e[i]);
    std::size_t c = 0;
    if (!fix_x0) gsl_matrix_set(J, i, c++, ex * amp);
    gsl_matrix_set(J, i, c++, (1 - ex) * amp);
    gsl_matrix_set(J, i, c, (x_max - x0) * e[i] * ex * beta);
  }
  bool finite = true;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < p; ++c) finite = finite && std::isfinite(gsl_matrix_get(J, i, c));
  // A failed SVD (no convergence on absurd data) reads as "not determined": rcond 0.
  const int status = finite ? gsl_linalg_SV_decomp(J, V, S, work) : GSL_EDOM;
  const double smax = gsl_vector_get(S, 0), smin = gsl_vector_get(S, p - 1);
  gsl_matrix_free(J); gsl_matrix_free(V); gsl_vector_free(S); gsl_vector_free(work);
  return status == GSL_SUCCESS && smax > 0 && std::isfinite(smin) ? smin / smax : 0.0;
}

double mad_scale(std::vector<double> r) {
  for (auto& v : r) v = std::fabs(v);
  std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
  return 1.4826 * r[r.size() / 2];
}

}  // namespace

double saturating(double x0, double x_max, double beta, double e) {
  return x_max - (x_max - x0) * std::exp(-beta * e);
}

namespace {

// The fit's residual statistics: cost, lag-1 autocorrelation and the error inflation it implies,
// rmse, R^2, eps_95 and the initial slope. Returns the residual sum of squares.
double residual_statistics(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& o,
                           FitResult& r) {
  double rss = 0, mean = std::accumulate(y.begin(), y.end(), 0.0) / y.size(), tss = 0;
  for (std::size_t i = 0; i < e.size(); ++i) {
    const double res = y[i] - saturating(r.x0, r.x_max, r.beta, e[i]);
    rss += res * res;
    tss += (y[i] - mean) * (y[i] - mean);
  }
  r.cost = 0.5 * rss;
  {
    std::vector<double> res(e.size());
    for (std::size_t i = 0; i < e.size(); ++i) res[i] = y[i] - saturating(r.x0, r.x_max, r.beta, e[i]);
    double num = 0;
    for (std::size_t i = 1; i < res.size(); ++i) num += res[i] * res[i - 1];
    r.residual_autocorrelation = rss > 0 ? num / rss : 0.0;
    // The lag-1 estimate is biased low on short series, by about (1 + 4 rho)/n (Kendall 1954;
    // Marriott & Pope 1954); without the correction the inflated intervals of 30-point DEM
    // curves held the truth in only 65 % of trials (docs/fit_identifiability.md).
    const double rho_hat = r.residual_autocorrelation;
    const double rho = std::min(rho_hat + (1 + 4 * rho_hat) / static_cast<double>(res.size()), 0.95);
    if (o.correct_autocorrelation && rho > 0) r.se_inflation = std::sqrt((1 + rho) / (1 - rho));
  }
  r.rmse = std::sqrt(rss / r.n);
  r.r_squared = tss > 0 ? 1.0 - rss / tss : 0.0;
  r.eps_95 = std::log(20.0) / r.beta;
  r.initial_slope = r.beta * (r.x_max - r.x0);

  return rss;
}

// Standard errors from Ceres' covariance (times s^2 = RSS / (n - free), inflated for correlated
// residuals), the correlations, the initial slope's error (delta method); none on a bound, and
// none when the scaled Jacobian is ill-conditioned.
void standard_errors(ceres::Problem& problem, std::vector<double>& p, double rss, int n_free, bool beta_on_bound,
                     bool xmax_on_bound, const std::vector<double>& e, const FitOptions& o, FitResult& r) {
  // Standard errors: unit-variance covariance times s^2 = RSS / (n - 3).
  r.se_x0 = r.se_x_max = r.se_beta = r.se_initial_slope = kNaN;
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{p.data(), p.data()}};
  double c[9];
  if (r.n > n_free && covariance_safe(problem) && cov.Compute(blocks, &problem) &&
      cov.GetCovarianceBlock(p.data(), p.data(), c)) {
    const double s2 = rss / (r.n - n_free) * r.se_inflation * r.se_inflation;
    for (double& v : c) v *= s2;
    const double se[3] = {std::sqrt(std::max(c[0], 0.0)), std::sqrt(std::max(c[4], 0.0)),
                          std::sqrt(std::max(c[8], 0.0))};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) r.corr[a][b] = (se[a] > 0 && se[b] > 0) ? c[3 * a + b] / (se[a] * se[b]) : kNaN;
    r.se_x0 = o.fix_x0 ? kNaN : se[0];
    r.se_x_max = xmax_on_bound ? kNaN : se[1];
    r.se_beta = beta_on_bound ? kNaN : se[2];
    // Delta method for beta (x_max - x0): gradient (-beta, beta, x_max - x0).
    const double g[3] = {-r.beta, r.beta, r.x_max - r.x0};
    double var = 0;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) var += g[a] * c[3 * a + b] * g[b];
    r.se_initial_slope = std::sqrt(std::max(var, 0.0));
  } else {
    r.ok = false;
    r.warnings.push_back("covariance could not be computed (the Jacobian is rank deficient, or not finite for absurd data): "
                         "the data do not determine all three parameters");
  }
  r.jacobian_rcond = jacobian_rcond(e, r.x0, r.x_max, r.beta, o.fix_x0);
  if (r.ok && !beta_on_bound && !xmax_on_bound && r.jacobian_rcond < o.min_jacobian_rcond) {
    r.ok = false;
    r.se_x0 = r.se_x_max = r.se_beta = r.se_initial_slope = kNaN;
    r.warnings.push_back("ill-conditioned covariance (reciprocal condition number " + fmt(r.jacobian_rcond, 4) +
                         " of the scaled Jacobian): the data do not determine all parameters (e.g. the curve saturates "
                         "within its first points); the values are not supported by the data (sample more finely or "
                         "fit a longer curve)");
  }
}

// The warnings about what the data support: correlated residuals, parameters on their bounds, a
// curve that stops before saturating, poorly determined parameters.
void support_warnings(const FitOptions& o, bool beta_on_bound, bool xmax_on_bound, FitResult& r) {
  if (o.residual_diagnostics && r.residual_autocorrelation > 0.5)
    r.warnings.push_back("residuals are strongly correlated (lag-1 autocorrelation " + fmt(r.residual_autocorrelation, 4) +
                         (o.correct_autocorrelation ? "): standard errors inflated by " + fmt(r.se_inflation, 4)
                                                    : "): standard errors assume independent points and are too small"));
  if (beta_on_bound)
    r.warnings.push_back("rate beta sits on its bound " + fmt(r.beta, 4) + ": no standard error quoted; " +
                         (r.beta >= o.beta_max * 0.9999
                              ? "the curve saturates before its first sampled strains (sample more finely)"
                              : "the curve shows no saturation in this window"));
  if (xmax_on_bound) r.warnings.push_back("asymptote x_max sits on its bound 0: no standard error quoted");
  if (r.eps_95 > r.e_last)
    r.warnings.push_back("curve stops before saturation: 95% of the approach is reached only at eps_d = " +
                         fmt(r.eps_95, 4) + " but the data end at " + fmt(r.e_last, 4) +
                         "; x_max and beta are extrapolations (run to larger eps_d)");
  // x0 and x_max are judged against the amplitude |x_max - x0| (a value near zero can be
  // well determined), beta against itself.
  const double amplitude = std::fabs(r.x_max - r.x0);
  const char* names[3] = {"x0", "x_max", "beta"};
  const double scales[3] = {amplitude, amplitude, r.beta}, ses[3] = {r.se_x0, r.se_x_max, r.se_beta};
  for (int a = 0; a < 3 && o.residual_diagnostics; ++a)
    if (std::isfinite(ses[a]) && scales[a] > 0 && ses[a] / scales[a] > o.max_relative_error)
      r.warnings.push_back(std::string(names[a]) + " is poorly determined (standard error " +
                           fmt(100 * ses[a] / scales[a], 4) + "% of " + (a < 2 ? "the amplitude |x_max - x0|" : "its value") + ")");
}

// Non-monotone: a reversal after the extreme much larger than the point-to-point noise
// (estimated from second differences: var(y[i+1] - 2y[i] + y[i-1]) = 6 sigma^2 for white noise).
void check_monotone(const std::vector<double>& y, const FitOptions& o, FitResult& r) {
  if (!o.residual_diagnostics || y.size() < 5) return;
  const bool rising = r.x_max >= r.x0;
  double sum2 = 0;
  for (std::size_t i = 1; i + 1 < y.size(); ++i) {
    const double d2 = y[i + 1] - 2 * y[i] + y[i - 1];
    sum2 += d2 * d2;
  }
  const double noise = std::sqrt(sum2 / (y.size() - 2) / 6.0);
  double extreme = y[0], worst = 0;
  for (double v : y) {
    extreme = rising ? std::max(extreme, v) : std::min(extreme, v);
    worst = std::max(worst, rising ? extreme - v : v - extreme);
  }
  const double range = *std::max_element(y.begin(), y.end()) - *std::min_element(y.begin(), y.end());
  r.non_monotone = worst > 5 * noise && worst > 0.2 * range;
  if (r.non_monotone)
    r.warnings.push_back("data are not monotone (a reversal of " + fmt(worst, 4) + " after the extreme, " +
                         fmt(worst / std::max(noise, 1e-300), 4) +
                         " x the point-to-point noise): the saturating law does not describe this curve");
}

}  // namespace

bool covariance_safe(ceres::Problem& problem) {
  constexpr double kMax = 1e150;   // below sqrt(DBL_MAX): squares and sums of squares stay finite
  double cost = 0;
  std::vector<double> residuals;
  ceres::CRSMatrix J;
  if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, &residuals, nullptr, &J)) return false;
  auto ok = [](double v) { return std::isfinite(v) && std::fabs(v) < kMax; };
  return std::isfinite(cost) && std::all_of(residuals.begin(), residuals.end(), ok) &&
         std::all_of(J.values.begin(), J.values.end(), ok);
}

FitResult fit_saturating(const std::vector<double>& e_in, const std::vector<double>& y_in,
                         const FitOptions& o) {
  init_glog();
  std::vector<double> e, y;
  select_window(e_in, y_in, o, e, y);
  FitResult r;
  r.n = static_cast<int>(e.size());
  r.e_last = *std::max_element(e.begin(), e.end());
  r.e_first = *std::min_element(e.begin(), e.end());
  std::vector<double> p = start_values(e, y);
  p[2] = std::clamp(p[2], o.beta_min * 1.01, o.beta_max * 0.99);
  if (o.nonnegative_asymptote) p[1] = std::max(p[1], 0.0);

  ceres::Problem problem;
  double loss_scale = o.loss_scale;
  if (o.loss != Loss::None && loss_scale <= 0) {
    std::vector<double> res(e.size());
    for (std::size_t i = 0; i < e.size(); ++i) res[i] = y[i] - saturating(p[0], p[1], p[2], e[i]);
    loss_scale = 3.0 * std::max(mad_scale(res), 1e-12);
  }
  for (std::size_t i = 0; i < e.size(); ++i) {
    ceres::LossFunction* loss = nullptr;
    if (o.loss == Loss::Huber) loss = new ceres::HuberLoss(loss_scale);
    if (o.loss == Loss::Cauchy) loss = new ceres::CauchyLoss(loss_scale);
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<SaturatingResidual, 1, 3>(new SaturatingResidual(e[i], y[i])), loss,
        p.data());
  }
  problem.SetParameterLowerBound(p.data(), 2, o.beta_min);
  problem.SetParameterUpperBound(p.data(), 2, o.beta_max);
  if (o.nonnegative_asymptote) problem.SetParameterLowerBound(p.data(), 1, 0.0);
  if (o.fix_x0) {
    p[0] = o.x0_value;
    problem.SetManifold(p.data(), new ceres::SubsetManifold(3, {0}));
  }
  const int n_free = o.fix_x0 ? 2 : 3;
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 500;
  so.function_tolerance = 1e-15;
  so.parameter_tolerance = 1e-14;
  so.gradient_tolerance = 1e-16;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  r.x0 = p[0]; r.x_max = p[1]; r.beta = p[2];
  r.ok = summary.IsSolutionUsable();
  if (!r.ok) r.warnings.push_back("optimiser did not converge: " + summary.message);

  const double rss = residual_statistics(e, y, o, r);

  const bool beta_on_bound = r.beta <= o.beta_min * 1.0001 || r.beta >= o.beta_max * 0.9999;
  const bool xmax_on_bound = o.nonnegative_asymptote && r.x_max <= 1e-14;
  standard_errors(problem, p, rss, n_free, beta_on_bound, xmax_on_bound, e, o, r);
  support_warnings(o, beta_on_bound, xmax_on_bound, r);
  check_monotone(y, o, r);
  return r;
}

std::string unusable_reason(const FitResult& r) {
  if (!r.ok) {
    for (const auto& w : r.warnings)
      if (w.rfind("optimiser did not converge", 0) == 0) return "not converged";
    return "ill-conditioned: the data do not determine x0, x_max and beta";
  }
  if (!std::isfinite(r.se_x_max) || !std::isfinite(r.se_beta))
    return "no standard error of " + std::string(!std::isfinite(r.se_x_max) ? "x_max" : "beta") + " (a bound)";
  if (r.non_monotone) return "not monotone: the saturating law does not describe the curve";
  return "";
}

std::string usable_summary(int usable, std::size_t total, const std::map<std::string, int>& not_usable) {
  std::string s = std::to_string(usable) + " of " + std::to_string(total) + " fits usable";
  if (!not_usable.empty()) {
    s += " (not usable:";
    bool first = true;
    for (const auto& [why, n] : not_usable) {
      s += (first ? " " : "; ") + std::to_string(n) + " " + why;
      first = false;
    }
    s += ")";
  }
  return s;
}

// ---- GSL cross-check ----
namespace {
struct GslData { const std::vector<double>* e; const std::vector<double>* y; };
int gsl_f(const gsl_vector* p, void* data, gsl_vector* f) {
  auto* d = static_cast<GslData*>(data);
  const double x0 = gsl_vector_get(p, 0), xm = gsl_vector_get(p, 1), b = gsl_vector_get(p, 2);
  for (std::size_t i = 0; i < d->e->size(); ++i)
    gsl_vector_set(f, i, (*d->y)[i] - saturating(x0, xm, b, (*d->e)[i]));
  return GSL_SUCCESS;
}
int gsl_df(const gsl_vector* p, void* data, gsl_matrix* J) {
  auto* d = static_cast<GslData*>(data);
  const double x0 = gsl_vector_get(p, 0), xm = gsl_vector_get(p, 1), b = gsl_vector_get(p, 2);
  for (std::size_t i = 0; i < d->e->size(); ++i) {
    const double e = (*d->e)[i], ex = std::exp(-b * e);
    gsl_matrix_set(J, i, 0, -ex);             // d r / d x0
    gsl_matrix_set(J, i, 1, -(1.0 - ex));     // d r / d x_max
    gsl_matrix_set(J, i, 2, -(xm - x0) * e * ex);   // d r / d beta
  }
  return GSL_SUCCESS;
}
}  // namespace

std::vector<double> fit_saturating_gsl(const std::vector<double>& e, const std::vector<double>& y,
                                       const std::vector<double>& start, double* rss) {
  const std::size_t n = e.size();
  GslData data{&e, &y};
  gsl_multifit_nlinear_fdf fdf{};
  fdf.f = gsl_f; fdf.df = gsl_df; fdf.fvv = nullptr; fdf.n = n; fdf.p = 3; fdf.params = &data;
  gsl_multifit_nlinear_parameters params = gsl_multifit_nlinear_default_parameters();
  gsl_multifit_nlinear_workspace* w = gsl_multifit_nlinear_alloc(gsl_multifit_nlinear_trust, &params, n, 3);
  gsl_vector_const_view x = gsl_vector_const_view_array(start.data(), 3);
  gsl_multifit_nlinear_init(&x.vector, &fdf, w);
  int info = 0;
  const int status = gsl_multifit_nlinear_driver(1000, 1e-14, 1e-14, 1e-14, nullptr, nullptr, &info, w);
  std::vector<double> out(3);
  for (int k = 0; k < 3; ++k) out[k] = gsl_vector_get(w->x, k);
  if (rss) { double c; gsl_blas_ddot(w->f, w->f, &c); *rss = c; }
  gsl_multifit_nlinear_free(w);
  if (status != GSL_SUCCESS) throw std::runtime_error("GSL nonlinear least squares failed (status " + std::to_string(status) + ")");
  return out;
}

SharedPathTest test_shared_path(const std::vector<double>& e1, const std::vector<double>& y1,
                                const std::vector<double>& e2, const std::vector<double>& y2,
                                double gap_tolerance, const FitOptions& o) {
  SharedPathTest t;
  t.first = fit_saturating(e1, y1, o);
  t.second = fit_saturating(e2, y2, o);
  std::vector<double> e = e1, y = y1;
  e.insert(e.end(), e2.begin(), e2.end());
  y.insert(y.end(), y2.begin(), y2.end());
  std::vector<std::size_t> idx(e.size());
  std::iota(idx.begin(), idx.end(), 0);
  std::stable_sort(idx.begin(), idx.end(), [&](auto a, auto b) { return e[a] < e[b]; });
  std::vector<double> es, ys;
  for (auto i : idx) { es.push_back(e[i]); ys.push_back(y[i]); }
  t.shared = fit_saturating(es, ys, o);
  const double rss_sep = 2 * (t.first.cost + t.second.cost), rss_sh = 2 * t.shared.cost;
  const int n = t.first.n + t.second.n;
  const int k = o.fix_x0 ? 2 : 3;   // free parameters per law
  if (n > 2 * k && rss_sep > 0) {
    t.f_statistic = std::max(0.0, (rss_sh - rss_sep) / k / (rss_sep / (n - 2 * k)));
    // Correlated residuals: the residual variance per independent point is larger by the
    // same factor that inflates the standard errors (1 unless correct_autocorrelation).
    const double infl = std::max(t.first.se_inflation, t.second.se_inflation);
    t.f_statistic /= infl * infl;
    t.p_value = gsl_cdf_fdist_Q(t.f_statistic, k, n - 2 * k);
  }
  // The gap over the strains both curves were fitted on (the fit window, not from eps = 0).
  const double lo = std::max(t.first.e_first, t.second.e_first), hi = std::min(t.first.e_last, t.second.e_last);
  for (int k = 0; k <= 200; ++k) {
    const double x = lo + (hi - lo) * k / 200.0;
    t.max_gap = std::max(t.max_gap, std::fabs(saturating(t.first.x0, t.first.x_max, t.first.beta, x) -
                                              saturating(t.second.x0, t.second.x_max, t.second.beta, x)));
  }
  t.same_path = t.p_value >= 0.01 || t.max_gap <= gap_tolerance;
  return t;
}

// ---- laws of the volume fraction ----
namespace {
template <class T>
T law_value(const std::string& model, const T* p, double x, double aux, double nu_ref) {
  using std::exp; using std::log; using std::pow;
  if (model == "linear") return p[0] + p[1] * T(x - nu_ref);
  if (model == "power") {
    T base = T(x) / p[2] - T(1.0);
    if (base <= T(0)) return p[0];
    return p[0] + p[1] * pow(base, p[3]);
  }
  if (model == "pressure") {   // p0 (nu C / nu_c) (-eps)(1 - g eps), eps = ln(nu_c / nu); aux = C
    T eps = log(p[1] / T(x));
    return p[0] * (T(x) * T(aux) / p[1]) * (-eps) * (T(1.0) - p[2] * eps);
  }
  throw std::invalid_argument("unknown law '" + model + "' (linear, power, pressure)");
}
int law_params(const std::string& model) {
  if (model == "linear") return 2;
  if (model == "power") return 4;
  if (model == "pressure") return 3;
  throw std::invalid_argument("unknown law '" + model + "' (linear, power, pressure)");
}
struct LawResidual {
  std::string model; double x, y, w, aux, nu_ref;
  template <class T> bool operator()(T const* const* p, T* r) const {
    r[0] = (T(y) - law_value(model, p[0], x, aux, nu_ref)) * T(w);
    return true;
  }
};
}  // namespace

double eval_law(const std::string& model, const std::vector<double>& p, double x, double nu_ref) {
  return law_value(model, p.data(), x, 1.0, nu_ref);
}

CurveFit fit_law(const std::string& model, const std::vector<double>& x, const std::vector<double>& y,
                 const std::vector<double>& start, const std::vector<double>& sigma, double nu_ref) {
  init_glog();
  const int np = law_params(model);
  CurveFit out;
  out.model = model;
  out.n = static_cast<int>(x.size());
  if (static_cast<int>(start.size()) != np) throw std::invalid_argument("fit_law: wrong number of start values");
  if (out.n < np + 1)
    throw std::invalid_argument("law '" + model + "' has " + std::to_string(np) + " parameters but only " +
                                std::to_string(out.n) + " points: add volume fractions (checkpoints)");
  std::vector<double> p = start;
  ceres::Problem problem;
  // For "pressure" the aux column (C) is passed through sigma's slot when sigma has 2n entries.
  for (int i = 0; i < out.n; ++i) {
    const double w = (sigma.size() == x.size() && sigma[i] > 0) ? 1.0 / sigma[i] : 1.0;
    const double aux = sigma.size() == 2 * x.size() ? sigma[x.size() + i] : 1.0;
    auto* f = new ceres::DynamicAutoDiffCostFunction<LawResidual>(new LawResidual{model, x[i], y[i], w, aux, nu_ref});
    f->AddParameterBlock(np);
    f->SetNumResiduals(1);
    problem.AddResidualBlock(f, nullptr, p.data());
  }
  if (model == "power") {
    problem.SetParameterLowerBound(p.data(), 2, 0.3);
    problem.SetParameterUpperBound(p.data(), 2, *std::min_element(x.begin(), x.end()) * (1 - 1e-9));
    problem.SetParameterLowerBound(p.data(), 3, 0.05);
    problem.SetParameterUpperBound(p.data(), 3, 3.0);
  }
  if (model == "pressure") {
    problem.SetParameterLowerBound(p.data(), 1, 0.3);
    problem.SetParameterUpperBound(p.data(), 1, *std::min_element(x.begin(), x.end()) * (1 - 1e-9));
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 1000;
  so.function_tolerance = 1e-15;
  so.parameter_tolerance = 1e-14;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  out.ok = summary.IsSolutionUsable();
  out.params = p;
  double rss = 0, tss = 0, mean = std::accumulate(y.begin(), y.end(), 0.0) / y.size();
  for (int i = 0; i < out.n; ++i) {
    const double aux = sigma.size() == 2 * x.size() ? sigma[x.size() + i] : 1.0;
    const double r = y[i] - law_value(model, p.data(), x[i], aux, nu_ref);
    rss += r * r;
    tss += (y[i] - mean) * (y[i] - mean);
  }
  out.rmse = std::sqrt(rss / out.n);
  out.r_squared = tss > 0 ? 1 - rss / tss : 0;
  out.errors.assign(np, kNaN);
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<double> c(np * np);
  std::vector<std::pair<const double*, const double*>> blocks = {{p.data(), p.data()}};
  if (out.n > np && covariance_safe(problem) && cov.Compute(blocks, &problem) &&
      cov.GetCovarianceBlock(p.data(), p.data(), c.data())) {
    // With sigma given, residuals are weighted: the cost is a chi^2 and needs no rescaling
    // only if sigma is trusted; we rescale by the reduced chi^2 in both cases (conservative).
    double wrss = 2 * summary.final_cost;
    const double s2 = wrss / (out.n - np);
    for (int k = 0; k < np; ++k) out.errors[k] = std::sqrt(std::max(c[k * np + k] * s2, 0.0));
  } else {
    out.warnings.push_back("covariance unavailable: parameters not identifiable from these points");
  }
  if (out.n <= np + 1) out.warnings.push_back("as many parameters as points minus one: the fit interpolates");
  return out;
}

}  // namespace demfit
