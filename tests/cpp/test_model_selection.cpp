// The peak law against its defining differential equations and a numerical extremum search,
// and the model selection on synthetic ensembles of known truth: a saturating truth keeps the
// simple law (false-choice rate near the nominal 1 %), a peaked truth picks the peak law, and the
// peak law's intervals cover the truth at their nominal rate.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "demfit/model_selection.hpp"

namespace {
// Trials per synthetic cell: DEM_SELECTION_TRIALS overrides (docs/model_selection.md used 400).
int trials(int fallback) {
  const char* v = std::getenv("DEM_SELECTION_TRIALS");
  return v ? std::atoi(v) : fallback;
}
}  // namespace

TEST(PeakLaw, IsTheSaturatingLawWhenTheTransientVanishes) {
  for (double e : {0.0, 0.01, 0.05, 0.3})
    EXPECT_NEAR(demfit::peak_law({0.02, 0.2, 40.0, 0.0, 0.3}, e), demfit::saturating(0.02, 0.2, 40.0, e), 1e-15);
}

TEST(PeakLaw, SolvesTheTwoStageRelaxation) {
  // dx/de = beta (y - x), dy/de = gamma (x_cs - y), x(0) = x0, y(0) = y0, integrated with RK4:
  // the closed form with A = (y0 - x_cs) beta / (beta - gamma).
  const double x0 = 0.0, y0 = 0.7, xcs = 0.4, beta = 60, gamma = 10;
  const double A = (y0 - xcs) * beta / (beta - gamma);
  double x = x0, y = y0, e = 0;
  const double h = 1e-5;
  auto fx = [&](double xx, double yy) { return beta * (yy - xx); };
  auto fy = [&](double yy) { return gamma * (xcs - yy); };
  for (int i = 1; i <= 40000; ++i) {
    const double k1x = fx(x, y), k1y = fy(y);
    const double k2x = fx(x + h / 2 * k1x, y + h / 2 * k1y), k2y = fy(y + h / 2 * k1y);
    const double k3x = fx(x + h / 2 * k2x, y + h / 2 * k2y), k3y = fy(y + h / 2 * k2y);
    const double k4x = fx(x + h * k3x, y + h * k3y), k4y = fy(y + h * k3y);
    x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    y += h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y);
    e = i * h;
    if (i % 5000 == 0) EXPECT_NEAR(x, demfit::peak_law({x0, xcs, beta, A, gamma / beta}, e), 1e-10) << "e = " << e;
  }
}

TEST(PeakLaw, PeakStrainValueAndSlopeMatchANumericalSearch) {
  const demfit::PeakParams p{0.01, 0.4, 60.0, 0.25, 1.0 / 6.0};
  const auto s = demfit::peak_shape(p, 0.0, 0.4);
  ASSERT_TRUE(s.has_peak);
  double best = -1, at = 0;
  for (int i = 0; i <= 400000; ++i) {
    const double e = 0.4 * i / 400000.0, v = demfit::peak_law(p, e);
    if (v > best) { best = v; at = e; }
  }
  EXPECT_NEAR(s.x_peak, best, 1e-10);   // the grid's maximum is below the true one by O(step^2)
  EXPECT_NEAR(s.eps_peak, at, 2e-6);
  const double h = 1e-7;
  EXPECT_NEAR(s.initial_slope, (demfit::peak_law(p, h) - demfit::peak_law(p, 0)) / h, 1e-4 * std::fabs(s.initial_slope));
  // The transient is the largest gap to the saturating law with the same x0, x_cs, beta.
  double gap = 0;
  for (int i = 0; i <= 40000; ++i) {
    const double e = 0.4 * i / 40000.0;
    gap = std::max(gap, demfit::peak_law(p, e) - demfit::saturating(p[0], p[1], p[2], e));
  }
  EXPECT_NEAR(s.transient, gap, 1e-8);
  // A monotone two-rate approach (A < 0) has no peak; neither has the saturating law.
  EXPECT_FALSE(demfit::peak_shape({0.0, 0.4, 60.0, -0.1, 0.1}, 0.0, 0.4).has_peak);
  EXPECT_FALSE(demfit::peak_shape({0.0, 0.4, 60.0, 0.0, 0.1}, 0.0, 0.4).has_peak);
}

TEST(PeakLaw, FitRecoversTheParametersOfANoiseFreeCurve) {
  const demfit::PeakParams truth{0.0, 0.4, 60.0, 0.25, 1.0 / 6.0};
  std::vector<double> e, y;
  for (int i = 1; i <= 200; ++i) {
    e.push_back(0.002 * i);
    y.push_back(demfit::peak_law(truth, e.back()));
  }
  const auto f = demfit::fit_peak(e, y);
  ASSERT_TRUE(f.ok);
  for (int a = 0; a < 5; ++a) EXPECT_NEAR(f.p[a], truth[a], 1e-5 * std::max(1.0, std::fabs(truth[a]))) << a;
  EXPECT_LT(f.rmse, 1e-8);
  EXPECT_TRUE(f.shape.has_peak);
}

TEST(ModelSelection, FewerThanThreePackingsKeepTheSimpleLawAndSaySo) {
  std::vector<double> e;
  std::vector<std::vector<double>> m(2);
  for (int i = 1; i <= 100; ++i) {
    e.push_back(0.004 * i);
    m[0].push_back(demfit::peak_law({0.0, 0.4, 60.0, 0.25, 0.15}, e.back()));
    m[1].push_back(m[0].back() + 0.001 * std::sin(i));
  }
  const auto c = demfit::choose_model(e, m, demfit::fit_ensemble(e, m), demfit::fit_peak_ensemble(e, m));
  EXPECT_EQ(c.model, "saturating");
  EXPECT_NE(c.reason.find("fewer than 3 packings"), std::string::npos);
}

TEST(ModelSelection, ASaturatingTruthKeepsTheSimpleLawAtAboutTheNominalRate) {
  demfit::PeakSelectionSetup s;
  s.truth = {0.0, 0.17, 60.0, 0.0, 0.2};   // the saturating law (A = 0), D2-like s_dev of frictionless spheres
  s.trials = trials(60);
  s.points = 100;
  s.seed = 21;
  for (int k : {8}) {
    s.packings = k;
    const auto c = demfit::peak_selection_experiment(s);
    std::printf("saturating truth, K = %d: peak law chosen in %.3f of %d trials (nominal %.2f); x_max coverage %.3f\n", k,
                c.chose_peak, s.trials, s.alpha, c.sat_xmax_coverage);
    // Nominal 0.01: 4 of 60 or more happens to a calibrated test with probability 0.003.
    EXPECT_LE(c.chose_peak, 0.05) << "K = " << k;
    // The saturating law's own intervals are untouched by the second model.
    EXPECT_GE(c.sat_xmax_coverage, 0.85) << "K = " << k;
  }
}

TEST(ModelSelection, APeakedTruthPicksThePeakLawAndItsIntervalsCoverTheTruth) {
  demfit::PeakSelectionSetup s;   // peak 0.55 at eps_d = 0.04, softening to 0.40 (frictional-like s_dev)
  s.trials = trials(60);   // 200 strains to eps_d = 0.4: the peak at 0.04 is sampled by 20 points
  s.seed = 5;
  for (int k : {8}) {
    s.packings = k;
    const auto c = demfit::peak_selection_experiment(s);
    std::printf("peaked truth, K = %d: peak law chosen in %.3f of %d trials; coverage x_cs %.3f, x_peak %.3f, eps_peak "
                "%.3f; saturating x_max vs the true x_cs %.3f\n",
                k, c.chose_peak, s.trials, c.xcs_coverage, c.xpeak_coverage, c.epspeak_coverage, c.sat_xmax_coverage);
    // Power: 0.995 in the 200-trial measurement (docs/model_selection.md; K = 4: 0.5, not tested).
    EXPECT_GE(c.chose_peak, 0.9) << "K = " << k;
    // Nominal 0.95; 60 trials give a binomial SE of 0.028.
    for (double cov : {c.xcs_coverage, c.xpeak_coverage, c.epspeak_coverage}) {
      EXPECT_GE(cov, 0.85) << "K = " << k;
      EXPECT_LE(cov, 1.0) << "K = " << k;
    }
    // What the second model fixes: the saturating law's plateau is not the critical state.
    EXPECT_LT(c.sat_xmax_coverage, 0.5) << "K = " << k;
  }
}
