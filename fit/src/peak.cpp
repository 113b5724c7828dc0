#include "demfit/format.hpp"
#include "demfit/peak.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>

namespace demfit {

namespace {

// The points inside the window; the same refusals as fit_saturating (sizes, non-finite, too few, flat).
void window(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& o, std::vector<double>& ew,
            std::vector<double>& yw) {
  if (e.size() != y.size()) throw std::invalid_argument("peak fit: strain and value arrays differ in length");
  for (std::size_t i = 0; i < e.size(); ++i) {
    if (!std::isfinite(e[i]) || !std::isfinite(y[i]))
      throw std::invalid_argument("peak fit: non-finite value at point " + std::to_string(i) +
                                  " (NaN or inf in the curve): the run probably blew up; check its log");
    if (e[i] >= o.window_min && e[i] <= o.window_max) { ew.push_back(e[i]); yw.push_back(y[i]); }
  }
  const int need = std::max(o.min_points, 8);
  if (static_cast<int>(ew.size()) < need)
    throw std::invalid_argument("peak fit: only " + std::to_string(ew.size()) + " points in the window; the five "
                                "parameters need at least " + std::to_string(need) + " (sample the run more finely)");
  const auto [lo, hi] = std::minmax_element(yw.begin(), yw.end());
  if (!(*hi > *lo)) throw std::invalid_argument("peak fit: the curve is flat: no evolution to fit");
}

// Data-driven starts: x0 from the first point, x_cs from the last fifth, the extreme of the
// curve (a peak if there is one) fixing beta and A for a few rate ratios; and two small
// transients of either sign around a one-rate start (for curves without a peak).
std::vector<PeakParams> starts(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& o) {
  const std::size_t n = e.size(), tail = std::max<std::size_t>(2, n / 5);
  const double x0 = y.front();
  double xcs = 0;
  for (std::size_t i = n - tail; i < n; ++i) xcs += y[i] / tail;
  const double sign = xcs >= x0 ? 1.0 : -1.0;
  std::size_t im = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (sign * y[i] > sign * y[im]) im = i;
  const double range = std::max(e.back() - e.front(), 1e-12);
  const double em = std::max(e[im] - e.front(), range / n);
  std::vector<PeakParams> s;
  for (double r : {0.05, 0.15, 0.4})
    for (double k : {1.5, 4.0}) {
      const double beta = std::clamp(k / em, o.beta_min * 1.01, o.beta_max * 0.99), g = r * beta;
      const double bump = std::exp(-g * em) - std::exp(-beta * em);
      const double sat = xcs - (xcs - x0) * std::exp(-beta * em);
      const double A = bump > 1e-9 ? (y[im] - sat) / bump : 0.0;
      s.push_back({x0, xcs, beta, A, r});
    }
  const double half = 0.5 * (x0 + xcs);
  double eh = range / 4;
  for (std::size_t i = 0; i < n; ++i)
    if (sign * (y[i] - half) >= 0) { eh = std::max(e[i] - e.front(), range / n); break; }
  const double beta = std::clamp(std::log(2.0) / eh, o.beta_min * 1.01, o.beta_max * 0.99);
  for (double f : {0.1, -0.1}) s.push_back({x0, xcs, beta, f * (xcs - x0), 0.2});
  return s;
}

PeakFit solve(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& o, PeakParams p) {
  init_glog();
  p[2] = std::clamp(p[2], o.beta_min * 1.0001, o.beta_max * 0.9999);
  p[4] = std::clamp(p[4], kPeakRatioMin * 1.0001, kPeakRatioMax * 0.9999);
  ceres::Problem problem;
  for (std::size_t i = 0; i < e.size(); ++i)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PeakResidual, 1, 5>(new PeakResidual(e[i], y[i])), nullptr,
                             p.data());
  problem.SetParameterLowerBound(p.data(), 2, o.beta_min);
  problem.SetParameterUpperBound(p.data(), 2, o.beta_max);
  problem.SetParameterLowerBound(p.data(), 4, kPeakRatioMin);
  problem.SetParameterUpperBound(p.data(), 4, kPeakRatioMax);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 300;
  so.function_tolerance = 1e-14;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-16;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  PeakFit f;
  f.p = p;
  f.ok = summary.IsSolutionUsable();
  f.rss = 2 * summary.final_cost;
  return f;
}

}  // namespace

double peak_law(const PeakParams& p, double e) {
  const double fast = std::exp(-p[2] * e), slow = std::exp(-p[4] * p[2] * e);
  return p[1] - (p[1] - p[0]) * fast + p[3] * (slow - fast);
}

PeakShape peak_shape(const PeakParams& p, double e_first, double e_last) {
  PeakShape s;
  const double x0 = p[0], xcs = p[1], beta = p[2], A = p[3], gamma = p[4] * p[2];
  s.initial_slope = beta * (xcs - x0) + A * (beta - gamma);
  // The gap to the saturating law, A (exp(-gamma e) - exp(-beta e)), is largest at
  // ln(beta/gamma)/(beta - gamma); within the data at that point clamped to the window.
  const double eh = std::clamp(std::log(beta / gamma) / (beta - gamma), e_first, e_last);
  s.transient = A * (std::exp(-gamma * eh) - std::exp(-beta * eh));
  // x'(e) = beta (x_cs - x0 + A) exp(-beta e) - A gamma exp(-gamma e) vanishes at
  // e* = ln(beta (x_cs - x0 + A) / (gamma A)) / (beta - gamma) when the argument exceeds 1.
  if (A != 0) {
    const double arg = beta * (xcs - x0 + A) / (gamma * A);
    if (arg > 1) {
      const double es = std::log(arg) / (beta - gamma), xs = peak_law(p, es);
      if ((xs - xcs) * (xcs - x0) > 0 && es <= e_last) {
        s.has_peak = true;
        s.eps_peak = es;
        s.x_peak = xs;
      }
    }
  }
  return s;
}

PeakFit fit_peak(const std::vector<double>& e_in, const std::vector<double>& y_in, const FitOptions& o,
                 const PeakParams* start) {
  std::vector<double> e, y;
  window(e_in, y_in, o, e, y);
  PeakFit best;
  best.rss = std::numeric_limits<double>::infinity();
  const std::vector<PeakParams> tries = start ? std::vector<PeakParams>{*start} : starts(e, y, o);
  for (const auto& s : tries) {
    PeakFit f = solve(e, y, o, s);
    if (f.ok && f.rss < best.rss) best = f;
  }
  if (!std::isfinite(best.rss)) {
    best = PeakFit{};
    best.warnings.push_back("the peak law's optimiser did not converge from any start");
    return best;
  }
  PeakFit& r = best;
  r.n = static_cast<int>(e.size());
  r.e_first = *std::min_element(e.begin(), e.end());
  r.e_last = *std::max_element(e.begin(), e.end());
  r.gamma = r.p[4] * r.p[2];
  r.shape = peak_shape(r.p, r.e_first, r.e_last);
  const double mean = std::accumulate(y.begin(), y.end(), 0.0) / y.size();
  double tss = 0;
  for (double v : y) tss += (v - mean) * (v - mean);
  r.rmse = std::sqrt(r.rss / r.n);
  r.r_squared = tss > 0 ? 1 - r.rss / tss : 0.0;
  const bool beta_bound = r.p[2] <= o.beta_min * 1.001 || r.p[2] >= o.beta_max * 0.999;
  const bool ratio_bound = r.p[4] <= kPeakRatioMin * 1.001 || r.p[4] >= kPeakRatioMax * 0.999;
  if (beta_bound) r.warnings.push_back("peak law: rate beta on its bound " + fmt(r.p[2]));
  if (ratio_bound)
    r.warnings.push_back("peak law: gamma/beta = " + fmt(r.p[4]) + " on its bound [" + fmt(kPeakRatioMin) + ", " +
                         fmt(kPeakRatioMax) + "]: the two stages are not separated by the data");
  r.critical_state_reached = std::log(20.0) / r.gamma <= r.e_last;
  if (!r.critical_state_reached)
    r.warnings.push_back("peak law: the softening (rate gamma = " + fmt(r.gamma) + ") is 95% complete only at eps_d = " +
                         fmt(std::log(20.0) / r.gamma) + ", beyond the data (" + fmt(r.e_last) +
                         "): x_cs is an extrapolation");
  r.on_bound = beta_bound || ratio_bound;
  return r;
}

}  // namespace demfit
