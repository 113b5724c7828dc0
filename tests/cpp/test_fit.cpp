// The fitter against certified answers (NIST StRD), synthetic truth, and a second solver.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "demfit/fit.hpp"

namespace {
bool has_warning(const demfit::FitResult& r, const std::string& part) {
  for (auto& w : r.warnings)
    if (w.find(part) != std::string::npos) return true;
  return false;
}
}  // namespace

TEST(Fit, NistMisra1aCertifiedValues) {
  // NIST StRD Misra1a: y = b1 (1 - exp(-b2 x)), i.e. our law with x0 = 0 held fixed.
  // Data and certified values from https://www.itl.nist.gov/div898/strd/nls/data/misra1a.shtml
  const std::vector<double> y = {10.07, 14.73, 17.94, 23.93, 29.61, 35.18, 40.02,
                                 44.82, 50.76, 55.05, 61.01, 66.40, 75.47, 81.78};
  const std::vector<double> x = {77.6, 114.9, 141.1, 190.8, 239.9, 289.0, 332.8,
                                 378.4, 434.8, 477.3, 536.8, 593.1, 689.1, 760.0};
  demfit::FitOptions o;
  o.fix_x0 = true;
  o.x0_value = 0.0;
  o.beta_min = 1e-8;
  const auto r = demfit::fit_saturating(x, y, o);
  EXPECT_NEAR(r.x_max / 2.3894212918E+02, 1.0, 1e-8);
  EXPECT_NEAR(r.beta / 5.5015643181E-04, 1.0, 1e-8);
  EXPECT_NEAR(r.se_x_max / 2.7070075241E+00, 1.0, 1e-6);
  EXPECT_NEAR(r.se_beta / 7.2668688436E-06, 1.0, 1e-6);
  EXPECT_NEAR(2 * r.cost / 1.2455138894E-01, 1.0, 1e-8);
  // The data are far from saturation: the fitter must say so.
  EXPECT_TRUE(has_warning(r, "before saturation"));
}

TEST(Fit, RecoversKnownParametersWithHonestIntervals) {
  // 200 seeded trials of s_dev-like curves with noise: the true values lie inside the 95%
  // intervals (+-1.96 SE) in about 95% of the trials (binomial: 90%..99% accepted).
  const double x0 = 0.02, xm = 0.15, beta = 12.0, noise = 0.004;
  std::mt19937_64 rng(12345);
  std::normal_distribution<double> gauss(0.0, noise);
  int cover[3] = {0, 0, 0};
  const int trials = 200;
  for (int t = 0; t < trials; ++t) {
    std::vector<double> e, y;
    for (int i = 0; i <= 100; ++i) {
      e.push_back(0.004 * i);
      y.push_back(demfit::saturating(x0, xm, beta, e.back()) + gauss(rng));
    }
    const auto r = demfit::fit_saturating(e, y);
    ASSERT_TRUE(r.ok);
    cover[0] += std::fabs(r.x0 - x0) <= 1.96 * r.se_x0;
    cover[1] += std::fabs(r.x_max - xm) <= 1.96 * r.se_x_max;
    cover[2] += std::fabs(r.beta - beta) <= 1.96 * r.se_beta;
  }
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(cover[k], 0.90 * trials) << "parameter " << k;
    EXPECT_LE(cover[k], 0.99 * trials) << "parameter " << k;
  }
}

TEST(Fit, CeresAndGslAgreeOnTheOptimum) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> gauss(0.0, 0.002);
  for (double beta : {3.0, 10.0, 30.0}) {
    std::vector<double> e, y;
    for (int i = 0; i <= 80; ++i) {
      e.push_back(0.005 * i);
      y.push_back(demfit::saturating(0.3, 0.12, beta, e.back()) + gauss(rng));   // decreasing curve
    }
    demfit::FitOptions o;
    const auto r = demfit::fit_saturating(e, y, o);
    double rss_gsl = 0;
    const auto g = demfit::fit_saturating_gsl(e, y, {0.25, 0.1, 5.0}, &rss_gsl);
    EXPECT_NEAR(r.x0, g[0], 1e-6 * std::fabs(g[0]) + 1e-9);
    EXPECT_NEAR(r.x_max, g[1], 1e-6 * std::fabs(g[1]) + 1e-9);
    EXPECT_NEAR(r.beta, g[2], 1e-5 * g[2]);
    EXPECT_NEAR(2 * r.cost, rss_gsl, 1e-9 * rss_gsl);
  }
}

TEST(Fit, IllPosedInputsAreRefusedOrFlagged) {
  std::vector<double> e, y;
  for (int i = 0; i < 50; ++i) { e.push_back(0.002 * i); y.push_back(0.1); }
  EXPECT_THROW(demfit::fit_saturating(e, y), std::invalid_argument);   // flat
  y[10] = std::nan("");
  for (int i = 0; i < 50; ++i) y[i] = 0.1 * i;
  y[10] = std::nan("");
  try {
    demfit::fit_saturating(e, y);
    FAIL();
  } catch (const std::invalid_argument& ex) {
    EXPECT_NE(std::string(ex.what()).find("non-finite"), std::string::npos);
  }
  EXPECT_THROW(demfit::fit_saturating({0, 0.1, 0.2}, {0, 0.1, 0.15}), std::invalid_argument);   // too few
  // No saturation reached: a straight line.
  std::vector<double> lin;
  for (double v : e) lin.push_back(0.01 + 0.5 * v);
  const auto r = demfit::fit_saturating(e, lin);
  EXPECT_TRUE(has_warning(r, "before saturation") || has_warning(r, "on its bound")) << r.warnings.size();
  // Peak then strong softening: not monotone.
  std::vector<double> peak;
  for (double v : e) peak.push_back(v < 0.05 ? 2 * v : 0.1 - 1.5 * (v - 0.05));
  const auto rp = demfit::fit_saturating(e, peak);
  EXPECT_TRUE(has_warning(rp, "not monotone"));
}

TEST(Fit, OneRuleForUsable) {
  // A saturating curve with noise, sampled well past saturation: usable.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> gauss(0.0, 0.002);
  std::vector<double> e, good, peak, line;
  for (int i = 0; i <= 80; ++i) {
    e.push_back(0.005 * i);
    good.push_back(demfit::saturating(0.02, 0.15, 15.0, e.back()) + gauss(rng));
    // peak at 0.05, then softening to 60 % of it: the saturating law does not describe it
    peak.push_back(e.back() < 0.05 ? 2 * e.back() : 0.04 + 0.06 * std::exp(-(e.back() - 0.05) / 0.05));
    line.push_back(0.01 + 0.5 * e.back() + gauss(rng));   // no curvature: x_max and beta not determined
  }
  const auto rg = demfit::fit_saturating(e, good);
  EXPECT_EQ(demfit::unusable_reason(rg), "") << rg.warnings.size();
  const auto rp = demfit::fit_saturating(e, peak);
  EXPECT_NE(demfit::unusable_reason(rp).find("not monotone"), std::string::npos) << demfit::unusable_reason(rp);
  const auto rl = demfit::fit_saturating(e, line);
  EXPECT_NE(demfit::unusable_reason(rl), "") << "a straight line determines no asymptote";
  // the summary line counts the reasons
  EXPECT_EQ(demfit::usable_summary(1, 3, {{"not monotone", 1}, {"ill-conditioned", 1}}),
            "1 of 3 fits usable (not usable: 1 ill-conditioned; 1 not monotone)");
  EXPECT_EQ(demfit::usable_summary(2, 2, {}), "2 of 2 fits usable");
}

TEST(Fit, SharedPathTestSeparatesSameAndDifferentLaws) {
  std::mt19937_64 rng(99);
  std::normal_distribution<double> gauss(0.0, 0.002);
  std::vector<double> e, a, b, c;
  for (int i = 0; i <= 100; ++i) {
    e.push_back(0.004 * i);
    a.push_back(demfit::saturating(0.0, 0.15, 10.0, e.back()) + gauss(rng));
    b.push_back(demfit::saturating(0.0, 0.15, 10.0, e.back()) + gauss(rng));
    c.push_back(demfit::saturating(0.0, 0.10, 25.0, e.back()) + gauss(rng));
  }
  const auto same = demfit::test_shared_path(e, a, e, b, 0.005);
  EXPECT_TRUE(same.same_path);
  const auto diff = demfit::test_shared_path(e, a, e, c, 0.005);
  EXPECT_FALSE(diff.same_path);
  EXPECT_LT(diff.p_value, 1e-6);
}

TEST(Fit, PowerLawOfTheVolumeFraction) {
  // C(nu) = 6 + 8 (nu/0.66 - 1)^0.6, noise-free: parameters recovered.
  std::vector<double> nu, c;
  for (int i = 0; i < 30; ++i) {
    nu.push_back(0.67 + 0.005 * i);
    c.push_back(6 + 8 * std::pow(nu.back() / 0.66 - 1, 0.6));
  }
  const auto f = demfit::fit_law("power", nu, c, {5.0, 5.0, 0.64, 0.5});
  ASSERT_TRUE(f.ok);
  EXPECT_NEAR(f.params[0], 6.0, 1e-4);
  EXPECT_NEAR(f.params[2], 0.66, 1e-6);
  EXPECT_NEAR(f.params[3], 0.6, 1e-4);
}

TEST(Fit, CorrelatedResidualsInflateTheStandardErrors) {
  // AR(1) noise with rho = 0.8 on top of the law: the plain SEs are too small; the corrected
  // ones are larger by about sqrt((1+rho)/(1-rho)) = 3 and a warning names the correlation.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> gauss(0.0, 0.003);
  std::vector<double> e, y;
  double ar = 0;
  for (int i = 0; i <= 150; ++i) {
    ar = 0.8 * ar + gauss(rng);
    e.push_back(0.002 * i);
    y.push_back(demfit::saturating(0.0, 0.15, 15.0, e.back()) + ar);
  }
  demfit::FitOptions plain, corrected;
  corrected.correct_autocorrelation = true;
  const auto a = demfit::fit_saturating(e, y, plain), b = demfit::fit_saturating(e, y, corrected);
  EXPECT_GT(a.residual_autocorrelation, 0.6);
  EXPECT_NEAR(b.se_x_max / a.se_x_max, b.se_inflation, 1e-9);
  EXPECT_GT(b.se_inflation, 2.0);
  EXPECT_TRUE(has_warning(b, "strongly correlated"));
  EXPECT_DOUBLE_EQ(a.x_max, b.x_max);   // the optimum itself does not change
}

// Found by tests/fuzz/fuzz_demtk.py (seed 1, input 547): finite but absurd values (1e308, a strain
// out of order) crashed the fit (SIGSEGV inside the optimiser's aftermath) and with it a Python
// session. Such input must give an exception or a fit marked not usable, never a crash.
TEST(Fit, AbsurdButFiniteInputsDoNotCrash) {
  const std::vector<double> e = {0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, -1.0, 0.09, 0.1, 0.11};
  const std::vector<double> y = {-1e308, 0.0952, 0.1813, 0.2592, 0.3297, 0.3935, 0.4512, 3, -22025.47, 0.5934,
                                 0.6321, 0.6671};
  demfit::FitOptions o;
  o.window_min = -2147483648.0;
  o.window_max = 1e308;
  try {
    const auto r = demfit::fit_saturating(e, y, o);
    EXPECT_FALSE(demfit::unusable_reason(r).empty());
  } catch (const std::invalid_argument&) {
  }
}

// Found by tests/fuzz/fuzz_demtk.py (seed 2, input 22759): one point at 1e308 made GSL's SVD of the
// scaled Jacobian fail to converge, and GSL's default error handler aborted the process (SIGABRT).
// GSL errors are returned in every process that links demfit; a failed SVD reads as "not determined".
TEST(Fit, AGslFailureIsNotAnAbort) {
  std::vector<double> e, y;
  for (int i = 0; i < 12; ++i) { e.push_back(0.01 * i); y.push_back(1 - std::exp(-0.1 * i)); }
  y[10] = 1e308;
  demfit::FitOptions o;
  o.window_min = -1e308;
  o.window_max = 9.2e18;
  try {
    const auto r = demfit::fit_saturating(e, y, o);
    EXPECT_FALSE(demfit::unusable_reason(r).empty());
  } catch (const std::invalid_argument&) {
  }
}
