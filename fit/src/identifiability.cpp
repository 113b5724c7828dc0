#include "demfit/identifiability.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

namespace demfit {

namespace {

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const double pos = q * (v.size() - 1);
  const std::size_t lo = static_cast<std::size_t>(pos);
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - lo) * (v[hi] - v[lo]);
}

bool has_warning(const FitResult& r, const char* a, const char* b = nullptr) {
  for (const auto& w : r.warnings)
    if (w.find(a) != std::string::npos && (!b || w.find(b) != std::string::npos)) return true;
  return false;
}

// The fitter says x_max or beta is not determined by the data.
bool flags_xmax_or_beta(const FitResult& r) {
  return has_warning(r, "x_max is poorly") || has_warning(r, "beta is poorly") ||
         has_warning(r, "sits on its bound") || has_warning(r, "covariance");
}

}  // namespace

IdentifiabilityCell identifiability_cell(const IdentifiabilitySetup& s) {
  if (!(s.length > 0)) throw std::invalid_argument("identifiability: length must be > 0");
  if (!(s.points_per_approach > 0)) throw std::invalid_argument("identifiability: points_per_approach must be > 0");
  const int points = std::max(s.fit.min_points, static_cast<int>(std::lround(s.points_per_approach * s.length)));
  if (!(s.noise >= 0)) throw std::invalid_argument("identifiability: noise must be >= 0");
  if (!(s.correlation >= 0 && s.correlation < 1))
    throw std::invalid_argument("identifiability: correlation must be in [0, 1)");
  const double amplitude = std::fabs(s.x_max - s.x0);
  const double e_last = s.length / s.beta;
  std::mt19937_64 rng(s.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  // AR(1) with marginal standard deviation sigma: n_k = rho n_{k-1} + sqrt(1 - rho^2) sigma xi_k.
  const double sigma = s.noise * amplitude, rho = s.correlation, innov = std::sqrt(1 - rho * rho);
  std::vector<double> e(points), y(points);
  std::vector<double> beta_err, xmax_err, rel_se;
  int cover_beta = 0, cover_xmax = 0, flagged = 0, unsaturated = 0, converged = 0;
  for (int t = 0; t < s.trials; ++t) {
    double n = sigma * gauss(rng);
    for (int k = 0; k < points; ++k) {
      e[k] = e_last * (k + 1) / points;
      if (k > 0) n = rho * n + innov * sigma * gauss(rng);
      y[k] = saturating(s.x0, s.x_max, s.beta, e[k]) + n;
    }
    FitResult r;
    try {
      r = fit_saturating(e, y, s.fit);
    } catch (const std::invalid_argument&) {
      ++flagged;   // unusable input (e.g. flat) counts as not identifiable
      continue;
    }
    flagged += flags_xmax_or_beta(r);
    unsaturated += has_warning(r, "before saturation");
    if (!(std::isfinite(r.beta) && std::isfinite(r.x_max))) continue;
    ++converged;
    beta_err.push_back(std::fabs(r.beta - s.beta) / s.beta);
    xmax_err.push_back(std::fabs(r.x_max - s.x_max) / amplitude);
    if (std::isfinite(r.se_beta)) {
      rel_se.push_back(r.se_beta / r.beta);
      cover_beta += std::fabs(r.beta - s.beta) <= 1.96 * r.se_beta;
    }
    if (std::isfinite(r.se_x_max)) cover_xmax += std::fabs(r.x_max - s.x_max) <= 1.96 * r.se_x_max;
  }
  IdentifiabilityCell c;
  c.converged = converged;
  c.beta_rel_error_median = quantile(beta_err, 0.5);
  c.beta_rel_error_p90 = quantile(beta_err, 0.9);
  c.xmax_rel_error_median = quantile(xmax_err, 0.5);
  c.beta_reported_rel_se_median = quantile(rel_se, 0.5);
  c.beta_coverage = static_cast<double>(cover_beta) / s.trials;
  c.xmax_coverage = static_cast<double>(cover_xmax) / s.trials;
  c.flagged_fraction = static_cast<double>(flagged) / s.trials;
  c.unsaturated_fraction = static_cast<double>(unsaturated) / s.trials;
  return c;
}

}  // namespace demfit
