// profile_intervals (demfit/profile.hpp): a linear least-squares cost's profile interval is exactly the covariance
// interval (with the other coefficient refitted, and with it held), a nonlinear one ends where its closed-form profile
// rises by the scale, a bound inside the interval ends it there, and a problem left short of its minimum is found out.
// The values and the holds (SubsetManifold, constant blocks) are as they were afterwards.
#include <gtest/gtest.h>

#include <ceres/ceres.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "demfit/profile.hpp"
#include "line_fit.hpp"

namespace {

bool solve(ceres::Problem& problem) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-15;
  so.max_num_iterations = 200;
  ceres::Solver::Summary sum;
  ceres::Solve(so, &problem, &sum);
  return sum.IsSolutionUsable();
}

TEST(ProfileIntervals, ALinearCostsIntervalIsTheCovariancesWithTheOtherRefittedOrHeld) {
  demfit_test::LineFit f;   // the straight line by hand
  std::vector<double>& x = f.x;
  ceres::Problem& problem = f.problem;
  const std::vector<double>& cov = f.cov;
  const std::vector<double> before = x;
  for (double scale : {1.0, 3.7}) {
    const auto got = demfit::profile_intervals(problem, {x.data()}, cov, {0, 1}, scale, solve, {}, 1e-6);
    ASSERT_EQ(got.size(), 2u);
    for (int a = 0; a < 2; ++a) {
      const double err = std::sqrt(scale * cov[a * 3]);
      SCOPED_TRACE(a);
      EXPECT_NEAR(got[a].lower.value, before[a] - err, 1e-6 * err) << scale;
      EXPECT_NEAR(got[a].upper.value, before[a] + err, 1e-6 * err) << scale;
      EXPECT_LE(got[a].lower.refits, 2) << "the first trial, one error away, is the end";
      EXPECT_FALSE(got[a].lower.bound || got[a].upper.bound || got[a].lower.failed);
      EXPECT_TRUE(std::isnan(got[a].below_optimum));
    }
  }
  EXPECT_EQ(std::memcmp(before.data(), x.data(), sizeof(double) * 2), 0) << "the values bit for bit";
  EXPECT_EQ(problem.GetManifold(x.data()), nullptr) << "no hold left behind";
  EXPECT_FALSE(problem.IsParameterBlockConstant(x.data()));

  // x1 held by a SubsetManifold: x0's profile is the line with x1 fixed, 1/(A^T A)_00 = 1/S1, whatever `held` says
  problem.SetManifold(x.data(), new ceres::SubsetManifold(2, {1}));
  const auto fixed = demfit::profile_intervals(problem, {x.data()}, cov, {0, 1}, 1.0, solve, {1}, 1e-6);
  EXPECT_NEAR(fixed[0].upper.value - before[0], 1 / std::sqrt(f.S1), 1e-6);
  EXPECT_NEAR(before[0] - fixed[0].lower.value, 1 / std::sqrt(f.S1), 1e-6);
  EXPECT_TRUE(std::isnan(fixed[1].lower.value)) << "a held coefficient has no profile";
  ASSERT_NE(problem.GetManifold(x.data()), nullptr);
  EXPECT_EQ(problem.GetManifold(x.data())->TangentSize(), 1) << "the hold as it was";
  EXPECT_EQ(std::memcmp(before.data(), x.data(), sizeof(double) * 2), 0);
}

// r = (e^th + ph - y1, ph - y2, e^th - y3): with u = e^th, min over ph leaves chi2_p(u) = (u - c)^2 / 2 + (u - y3)^2,
// c = y1 - y2, lowest at u* = (c + 2 y3) / 3 and rising by 3/2 (u - u*)^2: th's ends are ln(u* -+ sqrt(2 s / 3)),
// not the covariance's th* -+ sqrt(2 s / 3) / u*. ph's profile is quadratic (u free): ph* -+ sqrt(2 s / 3) exactly.
struct Coupled {
  double y1, y2, y3;
  template <class T>
  bool operator()(const T* x, T* r) const {
    using std::exp;
    r[0] = exp(x[0]) + x[1] - T(y1);
    r[1] = x[1] - T(y2);
    r[2] = exp(x[0]) - T(y3);
    return true;
  }
};

struct CoupledFixture {
  const double y1 = 3.1, y2 = 0.4, y3 = 1.65;
  const double c = y1 - y2, u = (c + 2 * y3) / 3;   // u* = 2
  std::vector<double> x;
  std::vector<double> cov;                          // (J^T J)^-1 at the optimum, J = [[u, 1], [0, 1], [u, 0]]
  ceres::Problem problem;
  CoupledFixture() {
    x = {std::log(u), (y1 - u + y2) / 2};
    cov = {2 / (3 * u * u), -1 / (3 * u), -1 / (3 * u), 2.0 / 3};
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Coupled, 3, 2>(new Coupled{y1, y2, y3}), nullptr,
                             x.data());
  }
};

TEST(ProfileIntervals, ANonlinearCostEndsWhereItsClosedFormProfileRisesByTheScale) {
  CoupledFixture f;
  for (double s : {1.0, 2.5}) {
    const double h = std::sqrt(2 * s / 3);
    const auto got = demfit::profile_intervals(f.problem, {f.x.data()}, f.cov, {0, 1}, s, solve, {}, 1e-5);
    ASSERT_EQ(got.size(), 2u);
    const double err = std::sqrt(s * f.cov[0]);
    EXPECT_NEAR(got[0].lower.value, std::log(f.u - h), 1e-4 * err) << s;
    EXPECT_NEAR(got[0].upper.value, std::log(f.u + h), 1e-4 * err) << s;
    EXPECT_GT(std::log(f.u) - got[0].lower.value, 1.05 * err) << "longer below than the covariance says";
    EXPECT_LT(got[0].upper.value - std::log(f.u), 0.95 * err) << "shorter above";
    EXPECT_NEAR(got[1].lower.value, f.x[1] - h, 1e-5 * h) << s;
    EXPECT_NEAR(got[1].upper.value, f.x[1] + h, 1e-5 * h) << s;
    EXPECT_NEAR(got[0].lower.rise, 1.0, 1e-5);
  }
}

TEST(ProfileIntervals, ABoundWithinTheIntervalEndsItAndAFitShortOfItsMinimumIsFoundOut) {
  CoupledFixture f;
  const double h = std::sqrt(2.0 / 3), lo = std::log(f.u - 0.5 * h);   // inside the lower end ln(u - h)
  f.problem.SetParameterLowerBound(f.x.data(), 0, lo);
  const auto got = demfit::profile_intervals(f.problem, {f.x.data()}, f.cov, {0}, 1.0, solve, {}, 1e-5);
  EXPECT_TRUE(got[0].lower.bound);
  EXPECT_EQ(got[0].lower.value, lo);
  EXPECT_NEAR(got[0].lower.rise, 0.25, 1e-9) << "3/2 (h/2)^2 over 1";
  EXPECT_FALSE(got[0].upper.bound);
  EXPECT_NEAR(got[0].upper.value, std::log(f.u + h), 1e-4);

  // ph left 0.3 above its optimum (the problem not solved): th's profile refits ph and ends below the starting chi2
  CoupledFixture g;
  g.x[1] += 0.3;
  const auto off = demfit::profile_intervals(g.problem, {g.x.data()}, g.cov, {0}, 1.0, solve);
  ASSERT_EQ(off.size(), 1u);
  ASSERT_FALSE(std::isnan(off[0].below_optimum));
  ceres::Problem::EvaluateOptions eo;
  double cost = 0;
  g.problem.Evaluate(eo, &cost, nullptr, nullptr, nullptr);
  EXPECT_LT(off[0].below_optimum, 2 * cost - 0.1) << "chi2 " << 2 * cost;
}

}  // namespace
