#include "demfit/format.hpp"
#include "demfit/ensemble.hpp"

#include <gsl/gsl_cdf.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>

namespace demfit {

namespace {

// Mean over the members listed in `use` (indices, repeats allowed) at every grid point.
std::vector<double> mean_of(const std::vector<std::vector<double>>& members, const std::vector<int>& use) {
  std::vector<double> m(members.front().size(), 0.0);
  for (int k : use)
    for (std::size_t i = 0; i < m.size(); ++i) m[i] += members[k][i];
  for (double& v : m) v /= static_cast<double>(use.size());
  return m;
}

std::array<double, 3> params_of(const FitResult& r) { return {r.x0, r.x_max, r.beta}; }

// Jackknife standard error of a statistic from its leave-one-out values.
double jackknife_se(const std::vector<double>& loo) {
  const double k = static_cast<double>(loo.size());
  const double mean = std::accumulate(loo.begin(), loo.end(), 0.0) / k;
  double s = 0;
  for (double v : loo) s += (v - mean) * (v - mean);
  return std::sqrt((k - 1) / k * s);
}

double sample_sd(const std::vector<double>& v) {
  if (v.size() < 2) return kNaN;
  const double mean = std::accumulate(v.begin(), v.end(), 0.0) / v.size();
  double s = 0;
  for (double x : v) s += (x - mean) * (x - mean);
  return std::sqrt(s / (v.size() - 1));
}

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  const double pos = q * (v.size() - 1);
  const std::size_t i = static_cast<std::size_t>(pos);
  return i + 1 < v.size() ? v[i] + (pos - i) * (v[i + 1] - v[i]) : v.back();
}

// Least-squares slope of y over x.
double slope(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  const double mx = std::accumulate(x.begin(), x.end(), 0.0) / n, my = std::accumulate(y.begin(), y.end(), 0.0) / n;
  double sxy = 0, sxx = 0;
  for (std::size_t i = 0; i < x.size(); ++i) { sxy += (x[i] - mx) * (y[i] - my); sxx += (x[i] - mx) * (x[i] - mx); }
  return sxy / sxx;
}

// The law says the curve is flat beyond eps_95. On that stretch (fixed before looking at the
// trend, so no selection) each packing's least-squares slope is one independent number: a mean
// slope significant against their spread (t, K - 1 dof, two-sided 99.9 %) and material (a change
// above 5 % of the amplitude over the stretch) means the curve keeps rising or falls back after a
// peak, which the saturating law cannot follow.
void check_plateau(const std::vector<double>& e, const std::vector<std::vector<double>>& members, const FitResult& fit,
                   std::vector<std::string>& warnings) {
  std::vector<std::size_t> idx;
  for (std::size_t i = 0; i < e.size(); ++i)
    if (e[i] >= fit.eps_95) idx.push_back(i);
  if (idx.size() < 8) return;   // no plateau in the data ("stops before saturation" says so)
  std::vector<double> x;
  for (auto i : idx) x.push_back(e[i]);
  std::vector<double> slopes;
  for (const auto& m : members) {
    std::vector<double> y;
    for (auto i : idx) y.push_back(m[i]);
    slopes.push_back(slope(x, y));
  }
  const int K = static_cast<int>(members.size());
  const double mean = std::accumulate(slopes.begin(), slopes.end(), 0.0) / K;
  const double se = sample_sd(slopes) / std::sqrt(static_cast<double>(K));
  const double t = se > 0 ? mean / se : 0.0;
  const double change = mean * (x.back() - x.front()), amplitude = std::fabs(fit.x_max - fit.x0);
  if (std::fabs(t) > t_quantile(0.9995, K - 1) && std::fabs(change) > 0.05 * amplitude)
    warnings.push_back(std::string("beyond eps_95 = ") + fmt(fit.eps_95) + " the ensemble mean still " +
                       (change * (fit.x_max - fit.x0) > 0 ? "rises" : "falls back") + " by " + fmt(std::fabs(change)) +
                       " (" + fmt(100 * std::fabs(change) / amplitude) + "% of the amplitude; t = " + fmt(t) +
                       " against the spread between packings): the saturating law " +
                       (change * (fit.x_max - fit.x0) > 0 ? "saturates too early" : "misses a peak; x_max is the level it fits, below the peak"));
}

}  // namespace

std::vector<double> resample(const std::vector<double>& x, const std::vector<double>& y, const std::vector<double>& grid) {
  if (x.size() != y.size() || x.size() < 2) throw std::invalid_argument("resample: need >= 2 points of equal-length x and y");
  for (std::size_t i = 1; i < x.size(); ++i)
    if (!(x[i] > x[i - 1])) throw std::invalid_argument("resample: strain does not increase at row " + std::to_string(i));
  std::vector<double> out(grid.size());
  std::size_t j = 0;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    const double g = grid[i];
    if (g < x.front() || g > x.back()) throw std::invalid_argument("resample: grid point " + fmt(g) + " outside the curve");
    while (j + 2 < x.size() && x[j + 1] < g) ++j;
    const double w = (g - x[j]) / (x[j + 1] - x[j]);
    out[i] = w == 0 ? y[j] : w == 1 ? y[j + 1] : y[j] + w * (y[j + 1] - y[j]);
  }
  return out;
}

double t_quantile(double q, double dof) { return dof > 0 ? gsl_cdf_tdist_Pinv(q, dof) : kNaN; }

Band band(const std::vector<std::vector<double>>& members, double level) {
  Band b;
  b.n = static_cast<int>(members.size());
  if (b.n == 0) throw std::invalid_argument("band: no members");
  const std::size_t n = members.front().size();
  for (auto& m : members)
    if (m.size() != n) throw std::invalid_argument("band: members differ in length");
  const double t = t_quantile(0.5 * (1 + level), b.n - 1);
  std::vector<double> col(b.n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < b.n; ++k) col[k] = members[k][i];
    const double mean = std::accumulate(col.begin(), col.end(), 0.0) / b.n;
    const double sd = sample_sd(col), se = sd / std::sqrt(static_cast<double>(b.n));
    b.mean.push_back(mean);
    b.sd.push_back(sd);
    b.se.push_back(se);
    b.lo.push_back(mean - t * se);
    b.hi.push_back(mean + t * se);
  }
  return b;
}

namespace {

// Bootstrap over packings (cross-check; percentile interval): o.bootstrap resamples of the members.
void bootstrap_errors(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                      const FitOptions& fo, const EnsembleFitOptions& o, EnsembleFit& r) {
  if (o.bootstrap <= 0) return;
  const int K = static_cast<int>(members.size());
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<int> pick(0, K - 1);
  std::vector<std::vector<double>> bs(3);
  for (int b = 0; b < o.bootstrap; ++b) {
    std::vector<int> use(K);
    for (int& u : use) u = pick(rng);
    try {
      const FitResult f = fit_saturating(grid, mean_of(members, use), fo);
      if (!f.ok) continue;
      bs[0].push_back(f.x0); bs[1].push_back(f.x_max); bs[2].push_back(f.beta);
    } catch (const std::exception&) {
    }
  }
  if (bs[0].size() >= 10)
    for (int a = 0; a < 3; ++a) {
      r.boot_se[a] = sample_sd(bs[a]);
      r.boot_lo[a] = quantile(bs[a], 0.5 * (1 - o.level));
      r.boot_hi[a] = quantile(bs[a], 0.5 * (1 + o.level));
    }
}

// Each member alone: how much one packing scatters (reported, not used for the errors).
void member_scatter(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                    const FitOptions& fo, const EnsembleFitOptions& o, EnsembleFit& r) {
  if (!o.member_fits) return;
  std::vector<std::vector<double>> mf(3);
  for (const auto& m : members) {
    try {
      const FitResult f = fit_saturating(grid, m, fo);
      if (!f.ok) continue;
      mf[0].push_back(f.x0); mf[1].push_back(f.x_max); mf[2].push_back(f.beta);
    } catch (const std::exception&) {
    }
  }
  r.member_fits_ok = static_cast<int>(mf[0].size());
  for (int a = 0; a < 3 && !mf[a].empty(); ++a) {
    r.member_mean[a] = std::accumulate(mf[a].begin(), mf[a].end(), 0.0) / mf[a].size();
    r.member_sd[a] = sample_sd(mf[a]);
  }
}

// The warnings the ensemble supports: failed leave-one-out fits, two packings only, parameters
// poorly determined between packings, a curve without its plateau.
void ensemble_warnings(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                       const FitOptions& fo, int failed, const double se[4], EnsembleFit& r) {
  const int K = static_cast<int>(members.size());
  auto& w = r.fit.warnings;
  if (failed > 0)
    w.push_back(std::to_string(failed) + " of " + std::to_string(K) + " leave-one-out fits did not converge: the "
                "errors are unreliable");
  if (K == 2)
    w.push_back("only 2 packings: intervals use t_1 = 12.7 and are wide; 4 or more packings make them useful");
  const double amplitude = std::fabs(r.fit.x_max - r.fit.x0);
  const char* names[3] = {"x0", "x_max", "beta"};
  const double scales[3] = {amplitude, amplitude, r.fit.beta};
  for (int a = 0; a < 3; ++a)
    if (std::isfinite(se[a]) && scales[a] > 0 && se[a] / scales[a] > fo.max_relative_error)
      w.push_back(std::string(names[a]) + " is poorly determined (standard error between packings " +
                  fmt(100 * se[a] / scales[a]) + "% of " + (a < 2 ? "the amplitude |x_max - x0|" : "its value") + ")");
  std::vector<double> ew;
  std::vector<std::vector<double>> in_window(K);
  for (std::size_t i = 0; i < grid.size(); ++i)
    if (grid[i] >= fo.window_min && grid[i] <= fo.window_max) {
      ew.push_back(grid[i]);
      for (int k = 0; k < K; ++k) in_window[k].push_back(members[k][i]);
    }
  check_plateau(ew, in_window, r.fit, w);
}

}  // namespace

EnsembleFit fit_ensemble(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                         const EnsembleFitOptions& o) {
  const int K = static_cast<int>(members.size());
  if (K == 0) throw std::invalid_argument("fit_ensemble: no members");
  EnsembleFit r;
  r.packings = K;
  r.boot_se.fill(kNaN); r.boot_lo.fill(kNaN); r.boot_hi.fill(kNaN);
  r.member_mean.fill(kNaN); r.member_sd.fill(kNaN);
  if (K == 1) {   // one packing: the single-curve path with its limits stated
    FitOptions fo = o.fit;
    fo.correct_autocorrelation = true;
    r.fit = fit_saturating(grid, members[0], fo);
    r.error_method = "AR(1) residuals of one curve";
    const double z = t_quantile(0.5 * (1 + o.level), 1e9);
    const auto p = params_of(r.fit);
    const double se[3] = {r.fit.se_x0, r.fit.se_x_max, r.fit.se_beta};
    for (int a = 0; a < 3; ++a) { r.lo[a] = p[a] - z * se[a]; r.hi[a] = p[a] + z * se[a]; }
    r.fit.warnings.push_back("one packing: errors from the curve's own correlated residuals, which under-cover "
                             "(docs/fit_identifiability.md); set [ensemble] packings >= 4 for errors between packings");
    return r;
  }
  FitOptions fo = o.fit;
  fo.residual_diagnostics = false;   // the mean's residuals say nothing about the packings
  fo.correct_autocorrelation = false;
  std::vector<int> all(K);
  std::iota(all.begin(), all.end(), 0);
  const std::vector<double> mean = mean_of(members, all);
  r.fit = fit_saturating(grid, mean, fo);
  r.error_method = "jackknife over packings";
  const auto est = params_of(r.fit);

  // Jackknife: the same fit with each member left out.
  std::vector<std::vector<double>> loo(4);   // x0, x_max, beta, initial slope
  int failed = 0;
  for (int k = 0; k < K; ++k) {
    std::vector<int> use;
    for (int j = 0; j < K; ++j)
      if (j != k) use.push_back(j);
    FitResult f;
    try { f = fit_saturating(grid, mean_of(members, use), fo); } catch (const std::exception&) { f.ok = false; }
    if (!f.ok) ++failed;
    r.leave_one_out.push_back(params_of(f));
    loo[0].push_back(f.x0); loo[1].push_back(f.x_max); loo[2].push_back(f.beta);
    loo[3].push_back(f.beta * (f.x_max - f.x0));
  }
  const double t = t_quantile(0.5 * (1 + o.level), K - 1);
  double se[4];
  for (int a = 0; a < 4; ++a) se[a] = jackknife_se(loo[a]);
  r.fit.se_x0 = fo.fix_x0 ? kNaN : se[0];
  r.fit.se_x_max = se[1];
  r.fit.se_beta = se[2];
  r.fit.se_initial_slope = se[3];
  r.fit.se_inflation = 1;
  for (int a = 0; a < 3; ++a) {
    r.lo[a] = est[a] - t * se[a];
    r.hi[a] = est[a] + t * se[a];
    for (int b = 0; b < 3; ++b) {
      // jackknife covariance of the leave-one-out values about their mean
      double ma = std::accumulate(loo[a].begin(), loo[a].end(), 0.0) / K, mb = std::accumulate(loo[b].begin(), loo[b].end(), 0.0) / K;
      double c = 0;
      for (int k = 0; k < K; ++k) c += (loo[a][k] - ma) * (loo[b][k] - mb);
      c *= (K - 1.0) / K;
      r.fit.corr[a][b] = se[a] > 0 && se[b] > 0 ? c / (se[a] * se[b]) : kNaN;
    }
  }

  bootstrap_errors(grid, members, fo, o, r);
  member_scatter(grid, members, fo, o, r);
  ensemble_warnings(grid, members, fo, failed, se, r);
  return r;
}

EnsembleSharedPath test_shared_path_ensemble(const EnsembleFit& a, const EnsembleFit& b, double alpha) {
  EnsembleSharedPath t;
  const int K = a.packings;
  if (K < 2 || b.packings != K || a.leave_one_out.size() != static_cast<std::size_t>(K) ||
      b.leave_one_out.size() != static_cast<std::size_t>(K))
    throw std::invalid_argument("shared-path test needs the same K >= 2 packings in both modes");
  t.packings = K;
  const auto pa = params_of(a.fit), pb = params_of(b.fit);
  double pmin = 1;
  for (int j = 0; j < 3; ++j) {
    std::vector<double> d(K);
    for (int k = 0; k < K; ++k) d[k] = b.leave_one_out[k][j] - a.leave_one_out[k][j];
    t.difference[j] = pb[j] - pa[j];
    t.se[j] = jackknife_se(d);
    const double tj = t.se[j] > 0 ? std::fabs(t.difference[j]) / t.se[j] : (t.difference[j] == 0 ? 0 : 1e300);
    t.p[j] = 2 * gsl_cdf_tdist_Q(tj, K - 1);
    pmin = std::min(pmin, t.p[j]);
  }
  t.p_value = std::min(1.0, 3 * pmin);
  const double lo = 0, hi = std::min(a.fit.e_last, b.fit.e_last);
  for (int k = 0; k <= 200; ++k) {
    const double x = lo + (hi - lo) * k / 200.0;
    t.max_gap = std::max(t.max_gap, std::fabs(saturating(pb[0], pb[1], pb[2], x) - saturating(pa[0], pa[1], pa[2], x)));
  }
  t.same_path = t.p_value >= alpha;
  return t;
}

}  // namespace demfit

namespace demfit {

namespace {

// One synthetic member pair (modes A and B of the same packing) on grid e.
void synthetic_pair(const EnsembleCoverageSetup& s, const std::vector<double>& e, std::mt19937_64& rng,
                    std::vector<double>& a, std::vector<double>& b) {
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double amplitude = std::fabs(s.x_max - s.x0);
  const double sigma = s.noise * amplitude, rho = s.correlation, innov = std::sqrt(1 - rho * rho);
  const double xm = s.x_max + s.member_spread * amplitude * gauss(rng);
  const double shared = std::sqrt(0.5), own = std::sqrt(0.5);
  double n0 = sigma * gauss(rng), n1 = sigma * gauss(rng), n2 = sigma * gauss(rng);
  a.resize(e.size());
  b.resize(e.size());
  for (std::size_t k = 0; k < e.size(); ++k) {
    if (k > 0) {
      n0 = rho * n0 + innov * sigma * gauss(rng);
      n1 = rho * n1 + innov * sigma * gauss(rng);
      n2 = rho * n2 + innov * sigma * gauss(rng);
    }
    const double x = saturating(s.x0, xm, s.beta, e[k]);
    a[k] = x + shared * n0 + own * n1;
    b[k] = x + shared * n0 + own * n2;
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

EnsembleCoverageCell ensemble_coverage(const EnsembleCoverageSetup& s) {
  if (s.packings < 2) throw std::invalid_argument("ensemble coverage: packings must be >= 2");
  if (!(s.correlation >= 0 && s.correlation < 1)) throw std::invalid_argument("ensemble coverage: correlation in [0, 1)");
  const int points = std::max(6, static_cast<int>(std::lround(s.points_per_approach * s.length)));
  const double e_last = s.length / s.beta, amplitude = std::fabs(s.x_max - s.x0);
  std::vector<double> e(points);
  for (int k = 0; k < points; ++k) e[k] = e_last * (k + 1) / points;
  std::mt19937_64 rng(s.seed);
  EnsembleFitOptions eo;
  eo.bootstrap = s.bootstrap;
  eo.member_fits = false;
  EnsembleFitOptions eo_b = eo;
  eo_b.bootstrap = 0;
  FitOptions single;
  single.correct_autocorrelation = true;
  EnsembleCoverageCell c;
  int cx = 0, cb = 0, bx = 0, bb = 0, ax = 0, ab = 0, r01 = 0, r05 = 0;
  std::vector<double> hw_x, hw_b;
  auto inside = [](double v, double lo, double hi) { return std::isfinite(lo) && std::isfinite(hi) && lo <= v && v <= hi; };
  for (int t = 0; t < s.trials; ++t) {
    std::vector<std::vector<double>> ma(s.packings), mb(s.packings);
    for (int k = 0; k < s.packings; ++k) synthetic_pair(s, e, rng, ma[k], mb[k]);
    try {
      const EnsembleFit fa = fit_ensemble(e, ma, eo);
      if (!fa.fit.ok) continue;
      ++c.converged;
      cx += inside(s.x_max, fa.lo[1], fa.hi[1]);
      cb += inside(s.beta, fa.lo[2], fa.hi[2]);
      bx += inside(s.x_max, fa.boot_lo[1], fa.boot_hi[1]);
      bb += inside(s.beta, fa.boot_lo[2], fa.boot_hi[2]);
      hw_x.push_back(0.5 * (fa.hi[1] - fa.lo[1]) / amplitude);
      hw_b.push_back(0.5 * (fa.hi[2] - fa.lo[2]) / s.beta);
      const EnsembleFit fb = fit_ensemble(e, mb, eo_b);
      const EnsembleSharedPath sp = test_shared_path_ensemble(fa, fb);
      r01 += sp.p_value < 0.01;
      r05 += sp.p_value < 0.05;
    } catch (const std::exception&) {
    }
    try {
      const FitResult one = fit_saturating(e, ma[0], single);
      ax += std::fabs(one.x_max - s.x_max) <= 1.96 * one.se_x_max;
      ab += std::fabs(one.beta - s.beta) <= 1.96 * one.se_beta;
    } catch (const std::exception&) {
    }
  }
  const double n = s.trials;
  c.xmax_coverage = cx / n;
  c.beta_coverage = cb / n;
  c.boot_xmax_coverage = s.bootstrap > 0 ? bx / n : kNaN;
  c.boot_beta_coverage = s.bootstrap > 0 ? bb / n : kNaN;
  c.ar1_xmax_coverage = ax / n;
  c.ar1_beta_coverage = ab / n;
  c.false_rejection_01 = r01 / n;
  c.false_rejection_05 = r05 / n;
  c.xmax_halfwidth_median = median(hw_x);
  c.beta_halfwidth_median = median(hw_b);
  return c;
}

std::string ensemble_coverage_csv(const EnsembleCoverageSetup& base, const std::vector<int>& packings,
                                  const std::vector<double>& lengths, const std::vector<double>& correlations) {
  std::ostringstream csv;
  csv << "# dem ensemble-coverage: " << base.trials << " synthetic ensembles per cell, seed " << base.seed
      << "; members x0 = " << base.x0 << ", x_max = " << base.x_max << " + N(0, " << base.member_spread
      << " amplitude), beta = " << base.beta << ", AR(1) noise sd " << base.noise
      << " amplitude; coverage = fraction of trials whose 95% interval holds the truth (jackknife-t: what dem fit "
         "states; bootstrap percentile; ar1: one member alone, AR(1)-inflated); false_rejection: D2/D3 test on "
         "paths that are the same\n"
         "packings,length_beta_eps,noise_correlation,xmax_coverage,beta_coverage,boot_xmax_coverage,boot_beta_coverage,"
         "ar1_xmax_coverage,ar1_beta_coverage,false_rejection_01,false_rejection_05,xmax_halfwidth_over_amplitude,"
         "beta_halfwidth_over_beta,converged\n";
  for (double rho : correlations)
    for (double length : lengths)
      for (int k : packings) {
        EnsembleCoverageSetup s = base;
        s.packings = k;
        s.length = length;
        s.correlation = rho;
        const EnsembleCoverageCell c = ensemble_coverage(s);
        csv << k << "," << length << "," << rho << "," << c.xmax_coverage << "," << c.beta_coverage << ","
            << c.boot_xmax_coverage << "," << c.boot_beta_coverage << "," << c.ar1_xmax_coverage << ","
            << c.ar1_beta_coverage << "," << c.false_rejection_01 << "," << c.false_rejection_05 << ","
            << c.xmax_halfwidth_median << "," << c.beta_halfwidth_median << "," << c.converged << "\n";
        std::fprintf(stderr, "dem ensemble-coverage: K = %d, length %g, rho %g: coverage x_max %.3f beta %.3f\n", k,
                     length, rho, c.xmax_coverage, c.beta_coverage);
      }
  return csv.str();
}

}  // namespace demfit
