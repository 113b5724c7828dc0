// The identifiability map: a well-posed and an ill-posed cell on either side of the boundary,
// with the truth known by construction.
#include <gtest/gtest.h>

#include <stdexcept>

#include "demfit/identifiability.hpp"

namespace {
demfit::IdentifiabilitySetup cell(double length, double noise, double rho) {
  demfit::IdentifiabilitySetup s;
  s.length = length;
  s.noise = noise;
  s.correlation = rho;
  s.trials = 60;
  s.seed = 7;
  s.fit.correct_autocorrelation = true;
  return s;
}
}  // namespace

TEST(Identifiability, SaturatedLowNoiseCurvesRecoverTheTruthWithHonestIntervals) {
  const auto c = demfit::identifiability_cell(cell(8.0, 0.01, 0.0));
  EXPECT_EQ(c.converged, 60);
  EXPECT_LT(c.beta_rel_error_median, 0.03);
  EXPECT_LT(c.xmax_rel_error_median, 0.01);
  EXPECT_GT(c.beta_coverage, 0.85);   // nominal 0.95; 60 trials
  EXPECT_EQ(c.flagged_fraction, 0.0);
  EXPECT_EQ(c.unsaturated_fraction, 0.0);
}

TEST(Identifiability, ShortNoisyCurvesLoseTheRateAndTheFitterSaysSo) {
  const auto c = demfit::identifiability_cell(cell(0.5, 0.3, 0.0));
  EXPECT_GT(c.beta_rel_error_median, 0.5);
  EXPECT_GT(c.flagged_fraction, 0.6);
}

TEST(Identifiability, SameSeedSameCellAndBadSetupsAreRefused) {
  const auto a = demfit::identifiability_cell(cell(2.0, 0.1, 0.85));
  const auto b = demfit::identifiability_cell(cell(2.0, 0.1, 0.85));
  EXPECT_EQ(a.beta_rel_error_median, b.beta_rel_error_median);
  EXPECT_EQ(a.flagged_fraction, b.flagged_fraction);
  EXPECT_THROW(demfit::identifiability_cell(cell(0.0, 0.1, 0.0)), std::invalid_argument);
  EXPECT_THROW(demfit::identifiability_cell(cell(1.0, -0.1, 0.0)), std::invalid_argument);
  EXPECT_THROW(demfit::identifiability_cell(cell(1.0, 0.1, 1.0)), std::invalid_argument);
}
