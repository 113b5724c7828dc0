// Ensemble statistics against hand computation and closed forms, and the coverage of the
// ensemble intervals on synthetic ensembles whose truth is known by construction.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "demfit/ensemble.hpp"

namespace {
std::vector<double> grid(int n, double last) {
  std::vector<double> e(n);
  for (int k = 0; k < n; ++k) e[k] = last * (k + 1) / n;
  return e;
}
std::vector<double> law(const std::vector<double>& e, double x0, double xm, double beta) {
  std::vector<double> y;
  for (double v : e) y.push_back(demfit::saturating(x0, xm, beta, v));
  return y;
}
}  // namespace

TEST(Ensemble, BandMatchesHandComputation) {
  // Three members at two points. Point 0: 1, 2, 6 -> mean 3, sd sqrt(7), se sqrt(7/3).
  const auto b = demfit::band({{1.0, 5.0}, {2.0, 5.0}, {6.0, 5.0}});
  EXPECT_EQ(b.n, 3);
  EXPECT_DOUBLE_EQ(b.mean[0], 3.0);
  EXPECT_NEAR(b.sd[0], std::sqrt(7.0), 1e-14);
  EXPECT_NEAR(b.se[0], std::sqrt(7.0 / 3.0), 1e-14);
  const double t2 = 4.302652729911275;   // Student's t, 2 dof, 0.975 (statistical tables)
  EXPECT_NEAR(b.hi[0], 3.0 + t2 * std::sqrt(7.0 / 3.0), 1e-9);
  EXPECT_NEAR(b.lo[0], 3.0 - t2 * std::sqrt(7.0 / 3.0), 1e-9);
  EXPECT_DOUBLE_EQ(b.sd[1], 0.0);   // identical members: no spread
  EXPECT_THROW(demfit::band({{1.0}, {1.0, 2.0}}), std::invalid_argument);
}

TEST(Ensemble, ResampleIsLinearInterpolationAndRefusesBadGrids) {
  const std::vector<double> x{0.0, 1.0, 3.0}, y{0.0, 2.0, 0.0};
  const auto r = demfit::resample(x, y, {0.0, 0.5, 1.0, 2.0, 3.0});
  const std::vector<double> want{0.0, 1.0, 2.0, 1.0, 0.0};
  for (std::size_t i = 0; i < want.size(); ++i) EXPECT_NEAR(r[i], want[i], 1e-15);
  EXPECT_THROW(demfit::resample(x, y, {3.5}), std::invalid_argument);
  EXPECT_THROW(demfit::resample({0.0, 1.0, 1.0}, y, {0.5}), std::invalid_argument);
}

TEST(Ensemble, JackknifeErrorOfNoiseFreeMembersIsTheSpreadOfTheirPlateaus) {
  // Members differ only in x_max: the mean curve is the law with the mean plateau, every
  // leave-one-out mean is exact too, so the jackknife SE equals sd(x_max_k)/sqrt(K) (a linear
  // statistic) and beta has no spread at all.
  const auto e = grid(80, 0.1);
  const std::vector<double> plateaus{0.15, 0.17, 0.18, 0.16, 0.19};
  std::vector<std::vector<double>> members;
  for (double xm : plateaus) members.push_back(law(e, 0.01, xm, 60.0));
  demfit::EnsembleFitOptions o;
  o.bootstrap = 0;
  const auto f = demfit::fit_ensemble(e, members, o);
  double mean = 0, ss = 0;
  for (double v : plateaus) mean += v / plateaus.size();
  for (double v : plateaus) ss += (v - mean) * (v - mean);
  const double se = std::sqrt(ss / (plateaus.size() - 1) / plateaus.size());
  EXPECT_EQ(f.packings, 5);
  EXPECT_EQ(f.error_method, "jackknife over packings");
  EXPECT_NEAR(f.fit.x_max, mean, 1e-8);
  EXPECT_NEAR(f.fit.beta, 60.0, 1e-5);
  EXPECT_NEAR(f.fit.se_x_max, se, 1e-6 * se);
  EXPECT_LT(f.fit.se_beta, 1e-4);
  const double t4 = 2.776445105197793;   // t, 4 dof, 0.975
  EXPECT_NEAR(f.hi[1] - f.lo[1], 2 * t4 * se, 1e-6 * se);
  EXPECT_TRUE(f.fit.warnings.empty()) << f.fit.warnings.front();
}

TEST(Ensemble, OnePackingFallsBackToTheSingleCurveErrorsAndSaysSo) {
  const auto e = grid(60, 0.1);
  auto y = law(e, 0.0, 0.17, 60.0);
  for (std::size_t i = 0; i < y.size(); ++i) y[i] += 0.003 * std::sin(7.0 * i);
  const auto f = demfit::fit_ensemble(e, {y});
  EXPECT_EQ(f.error_method, "AR(1) residuals of one curve");
  bool said = false;
  for (const auto& w : f.fit.warnings) said |= w.find("one packing") != std::string::npos;
  EXPECT_TRUE(said);
}

TEST(Ensemble, AFallOnThePlateauIsFlaggedOnlyWhenTheSpreadBetweenPackingsMakesItSignificant) {
  // A curve that peaks and falls by 20 % of its rise: with tiny member noise the fall is
  // significant; the same fall buried in member-to-member noise of the same size is not.
  const auto e = grid(100, 0.2);
  auto peaked = [&](double noise, int k) {
    std::vector<double> y;
    for (std::size_t i = 0; i < e.size(); ++i)
      y.push_back(0.2 * std::min(1.0, e[i] / 0.1) - 0.4 * std::max(0.0, e[i] - 0.1) + noise * std::sin(3.0 * k + 0.1 * i));
    return y;
  };
  auto warned = [&](double noise) {
    std::vector<std::vector<double>> m;
    for (int k = 0; k < 6; ++k) m.push_back(peaked(noise, k));
    demfit::EnsembleFitOptions o;
    o.bootstrap = 0;
    for (const auto& w : demfit::fit_ensemble(e, m, o).fit.warnings)
      if (w.find("falls back") != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(warned(0.001));
  EXPECT_FALSE(warned(0.2));
}

TEST(Ensemble, IntervalsCoverTheTruthWhereSingleCurveErrorsDoNot) {
  // DEM-like members: AR(1) noise with lag-1 correlation 0.85 and plateaus that differ.
  for (int k : {4, 8}) {
    demfit::EnsembleCoverageSetup s;
    s.packings = k;
    s.length = 5.0;
    s.correlation = 0.85;
    s.trials = 200;
    s.seed = 11;
    const auto c = demfit::ensemble_coverage(s);
    EXPECT_GE(c.converged, 198) << "K = " << k;
    // Nominal 0.95; 200 trials give a binomial SE of 0.015.
    EXPECT_GE(c.xmax_coverage, 0.90) << "K = " << k;
    EXPECT_LE(c.xmax_coverage, 0.99) << "K = " << k;
    EXPECT_GE(c.beta_coverage, 0.90) << "K = " << k;
    EXPECT_LE(c.beta_coverage, 0.99) << "K = " << k;
    // The D2/D3 test holds its nominal false-rejection rate on paths that are the same.
    EXPECT_LE(c.false_rejection_01, 0.03) << "K = " << k;
    EXPECT_LE(c.false_rejection_05, 0.09) << "K = " << k;
    // What the ensemble fixes: one curve's AR(1)-inflated interval misses the plateau often.
    EXPECT_LT(c.ar1_xmax_coverage, 0.85) << "K = " << k;
  }
}

TEST(Ensemble, IntervalsNarrowAsOneOverRootK) {
  demfit::EnsembleCoverageSetup s;
  s.trials = 60;
  s.seed = 3;
  s.packings = 4;
  const double w4 = demfit::ensemble_coverage(s).xmax_halfwidth_median;
  s.packings = 16;
  const double w16 = demfit::ensemble_coverage(s).xmax_halfwidth_median;
  // sqrt(16/4) = 2 from the standard error, times t_3/t_15 = 3.18/2.13 from the quantile.
  EXPECT_NEAR(w4 / w16, 2.0 * 3.182446305284263 / 2.131449545559323, 0.6);
}

TEST(Ensemble, SharedPathTestFindsARealDifference) {
  const auto e = grid(60, 0.1);
  std::vector<std::vector<double>> a, b;
  for (int k = 0; k < 6; ++k) {
    auto ya = law(e, 0.0, 0.17 + 0.005 * std::sin(k), 60.0), yb = law(e, 0.0, 0.20 + 0.005 * std::cos(k), 60.0);
    for (std::size_t i = 0; i < e.size(); ++i) { ya[i] += 0.002 * std::sin(k + 0.3 * i); yb[i] += 0.002 * std::cos(k + 0.2 * i); }
    a.push_back(ya);
    b.push_back(yb);
  }
  demfit::EnsembleFitOptions o;
  o.bootstrap = 0;
  const auto t = demfit::test_shared_path_ensemble(demfit::fit_ensemble(e, a, o), demfit::fit_ensemble(e, b, o));
  EXPECT_FALSE(t.same_path);
  EXPECT_LT(t.p_value, 1e-3);
  EXPECT_NEAR(t.difference[1], 0.03, 0.01);
  a.pop_back();
  EXPECT_THROW(demfit::test_shared_path_ensemble(demfit::fit_ensemble(e, a, o), demfit::fit_ensemble(e, b, o)),
               std::invalid_argument);
}
