#include "demfit/format.hpp"
#include "demfit/model_selection.hpp"

#include <gsl/gsl_cdf.h>

#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>

namespace demfit {

namespace {

std::vector<double> mean_without(const std::vector<std::vector<double>>& members, int skip) {
  std::vector<double> m(members.front().size(), 0.0);
  int used = 0;
  for (int k = 0; k < static_cast<int>(members.size()); ++k) {
    if (k == skip) continue;
    ++used;
    for (std::size_t i = 0; i < m.size(); ++i) m[i] += members[k][i];
  }
  for (double& v : m) v /= used;
  return m;
}

// Jackknife SE from leave-one-out values; NaN when any is NaN (e.g. no peak without one packing).
double jackknife_se(const std::vector<double>& loo) {
  const double k = static_cast<double>(loo.size());
  double mean = 0;
  for (double v : loo) {
    if (!std::isfinite(v)) return kNaN;
    mean += v / k;
  }
  double s = 0;
  for (double v : loo) s += (v - mean) * (v - mean);
  return std::sqrt((k - 1) / k * s);
}

}  // namespace

PeakValues peak_values(const PeakFit& f) {
  return {f.p[0], f.p[1], f.p[2], f.p[3], f.p[4] * f.p[2], f.shape.x_peak, f.shape.eps_peak, f.shape.initial_slope,
          f.shape.transient};
}

PeakEnsembleFit fit_peak_ensemble(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                                  const EnsembleFitOptions& o) {
  const int K = static_cast<int>(members.size());
  if (K < 2) throw std::invalid_argument("peak fit of an ensemble: needs >= 2 packings for errors between them");
  PeakEnsembleFit r;
  r.packings = K;
  r.fit = fit_peak(grid, mean_without(members, -1), o.fit);
  r.value = peak_values(r.fit);
  r.se.fill(kNaN); r.lo.fill(kNaN); r.hi.fill(kNaN);
  r.warnings = r.fit.warnings;
  if (!r.fit.ok) return r;
  std::vector<std::vector<double>> loo(kPeakQuantities);
  for (int k = 0; k < K; ++k) {
    PeakFit f;
    try { f = fit_peak(grid, mean_without(members, k), o.fit, &r.fit.p); } catch (const std::exception&) { f.ok = false; }
    if (!f.ok) ++r.failed;
    PeakValues v = peak_values(f);
    if (!f.ok) v.fill(kNaN);
    r.leave_one_out.push_back(v);
    for (int a = 0; a < kPeakQuantities; ++a) loo[a].push_back(v[a]);
  }
  const double t = t_quantile(0.5 * (1 + o.level), K - 1);
  for (int a = 0; a < kPeakQuantities; ++a) {
    r.se[a] = jackknife_se(loo[a]);
    r.lo[a] = r.value[a] - t * r.se[a];
    r.hi[a] = r.value[a] + t * r.se[a];
  }
  if (r.failed > 0)
    r.warnings.push_back("peak law: " + std::to_string(r.failed) + " of " + std::to_string(K) +
                         " leave-one-out fits did not converge: no errors");
  if (r.fit.shape.has_peak && !std::isfinite(r.se[kPkXpeak]))
    r.warnings.push_back("peak law: without one of the packings the fitted curve has no peak: no error for the peak");
  return r;
}

namespace {
// Over the window of w: held-out MSE of both laws on member y and the projection z_k.
struct HeldOut { double mse_sat = 0, mse_peak = 0, z = 0; };
HeldOut held_out(const std::vector<double>& grid, const std::vector<double>& y, const FitOptions& w,
                 const std::array<double, 3>& a, const PeakParams& p) {
  HeldOut h;
  double gr = 0, gg = 0;
  int n = 0;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    if (grid[i] < w.window_min || grid[i] > w.window_max) continue;
    const double s = saturating(a[0], a[1], a[2], grid[i]), g = peak_law(p, grid[i]) - s, r = y[i] - s;
    h.mse_sat += r * r;
    h.mse_peak += (r - g) * (r - g);
    gr += g * r;
    gg += g * g;
    ++n;
  }
  h.mse_sat /= n;
  h.mse_peak /= n;
  h.z = gg > 0 ? gr / std::sqrt(n * gg) : 0.0;
  return h;
}
}  // namespace

ModelChoice choose_model(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                         const EnsembleFit& sat, const PeakEnsembleFit& pk, const FitOptions& window, double alpha) {
  ModelChoice c;
  c.alpha = alpha;
  const int K = static_cast<int>(members.size());
  if (K < 3) {
    c.reason = "fewer than 3 packings: no model selection (the saturating law is kept)";
    return c;
  }
  if (!sat.fit.ok || !pk.fit.ok || pk.failed > 0 || static_cast<int>(sat.leave_one_out.size()) != K ||
      static_cast<int>(pk.leave_one_out.size()) != K) {
    c.reason = "a fit of the mean or of K - 1 packings failed: no model selection (the saturating law is kept)";
    return c;
  }
  std::vector<double> z;
  double ms = 0, mp = 0;
  for (int k = 0; k < K; ++k) {
    const auto& a = sat.leave_one_out[k];
    const auto& b = pk.leave_one_out[k];
    if (!(a[2] > 0) || !std::isfinite(b[kPkBeta])) {
      c.reason = "a leave-one-out fit failed: no model selection (the saturating law is kept)";
      return c;
    }
    const HeldOut h = held_out(grid, members[k], window, a, {b[kPkX0], b[kPkXcs], b[kPkBeta], b[kPkA], b[kPkGamma] / b[kPkBeta]});
    ms += h.mse_sat / K;
    mp += h.mse_peak / K;
    z.push_back(h.z);
  }
  c.mse_saturating = ms;
  c.mse_peak = mp;
  c.shown = std::accumulate(z.begin(), z.end(), 0.0) / K;
  double s2 = 0;
  for (double v : z) s2 += (v - c.shown) * (v - c.shown) / (K - 1);
  c.se_shown = std::sqrt((1.0 / K + 1.0 / (K - 1)) * s2);
  c.t = c.se_shown > 0 ? c.shown / c.se_shown : (c.shown > 0 ? 1e300 : 0.0);
  c.p_value = gsl_cdf_tdist_Q(c.t, K - 1);
  const std::string what = "the left-out packings show " + fmt(c.shown) + " +- " + fmt(c.se_shown) +
                           " of the transient (t = " + fmt(c.t) + ", p = " + fmt(c.p_value);
  c.reason = c.p_value < alpha ? "the peak law: " + what + " < " + fmt(alpha) + ")"
                               : "the saturating law suffices: " + what + " >= " + fmt(alpha) + ")";
  if (c.p_value < alpha) c.model = pk.fit.shape.has_peak ? "peak" : "two-rate";
  return c;
}

PeakSelectionCell peak_selection_experiment(const PeakSelectionSetup& s) {
  if (s.packings < 3) throw std::invalid_argument("peak selection experiment: packings must be >= 3");
  if (!(s.correlation >= 0 && s.correlation < 1)) throw std::invalid_argument("peak selection experiment: correlation in [0, 1)");
  std::vector<double> e(s.points);
  for (int i = 0; i < s.points; ++i) e[i] = s.e_last * (i + 1) / s.points;
  const double amplitude = std::fabs(s.truth[1] - s.truth[0]);
  const double sigma = s.noise * amplitude, innov = std::sqrt(1 - s.correlation * s.correlation);
  const PeakShape truth = peak_shape(s.truth, e.front(), e.back());
  std::mt19937_64 rng(s.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  EnsembleFitOptions eo;
  eo.bootstrap = 0;
  eo.member_fits = false;
  PeakSelectionCell c;
  int peak = 0, cx = 0, cp = 0, ce = 0, cs = 0;
  auto inside = [](double v, double lo, double hi) { return std::isfinite(lo) && std::isfinite(hi) && lo <= v && v <= hi; };
  for (int t = 0; t < s.trials; ++t) {
    std::vector<std::vector<double>> members(s.packings, std::vector<double>(e.size()));
    for (auto& m : members) {
      PeakParams p = s.truth;
      p[1] += s.member_spread * amplitude * gauss(rng);
      double noise = sigma * gauss(rng);
      for (std::size_t i = 0; i < e.size(); ++i) {
        if (i > 0) noise = s.correlation * noise + innov * sigma * gauss(rng);
        m[i] = peak_law(p, e[i]) + noise;
      }
    }
    try {
      const PeakEnsembleFit pk = fit_peak_ensemble(e, members, eo);
      const EnsembleFit sat = fit_ensemble(e, members, eo);
      const ModelChoice mc = choose_model(e, members, sat, pk, eo.fit, s.alpha);
      if (pk.fit.ok) ++c.converged;
      peak += mc.model != "saturating";
      cx += inside(s.truth[1], pk.lo[kPkXcs], pk.hi[kPkXcs]);
      cp += inside(truth.x_peak, pk.lo[kPkXpeak], pk.hi[kPkXpeak]);
      ce += inside(truth.eps_peak, pk.lo[kPkEpsPeak], pk.hi[kPkEpsPeak]);
      cs += inside(s.truth[1], sat.lo[1], sat.hi[1]);
    } catch (const std::exception&) {
    }
  }
  const double n = s.trials;
  c.chose_peak = peak / n;
  c.xcs_coverage = cx / n;
  c.xpeak_coverage = truth.has_peak ? cp / n : kNaN;
  c.epspeak_coverage = truth.has_peak ? ce / n : kNaN;
  c.sat_xmax_coverage = cs / n;
  return c;
}

}  // namespace demfit
