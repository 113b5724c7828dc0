// check_jacobian (demfit/jacobian_check.hpp): a smooth cost's Jacobian agrees with central differences, a jump within
// one difference step of the point is found in its own coefficient's column only, the values are restored bit for
// bit, a step beyond a bound is taken one-sided, and an entry a SubsetManifold holds is not checked.
#include <gtest/gtest.h>

#include <ceres/ceres.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "demfit/jacobian_check.hpp"

namespace {

// r_i = a exp(-b t_i) + c t_i - y_i, plus `jump` where a > a_jump (a step in the residuals, none at its default)
struct Decay {
  double t, y, a_jump, jump;
  template <class T>
  bool operator()(const T* x, T* r) const {
    using std::exp;
    r[0] = x[0] * exp(-x[1] * T(t)) + x[2] * T(t) - T(y);
    if (x[0] > T(a_jump)) r[0] += T(jump);
    return true;
  }
};

struct Fixture {
  std::vector<double> x = {2.0, 0.7, -0.3};
  ceres::Problem problem;
  explicit Fixture(double a_jump = 1e300, double jump = 0.0) {
    for (int i = 0; i < 30; ++i) {
      const double t = 0.1 * i;
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Decay, 1, 3>(
                                   new Decay{t, 2.1 * std::exp(-0.65 * t) - 0.28 * t, a_jump, jump}),
                               nullptr, x.data());
    }
  }
};

TEST(JacobianCheck, ASmoothCostAgreesWithCentralDifferencesAndItsValuesAreRestored) {
  Fixture f;
  const std::vector<double> before = f.x;
  const auto cols = demfit::check_jacobian(f.problem, {f.x.data()});
  ASSERT_EQ(cols.size(), 3u);
  for (const auto& c : cols) {
    SCOPED_TRACE(c.index);
    EXPECT_EQ(c.block, 0);
    EXPECT_GT(c.norm_jacobian, 0.1);
    EXPECT_LT(c.disagreement, 1e-7);
    EXPECT_FALSE(c.one_sided);
    EXPECT_DOUBLE_EQ(c.step, 1e-6 * std::max(1.0, std::fabs(before[c.index])));
  }
  EXPECT_EQ(std::memcmp(before.data(), f.x.data(), sizeof(double) * 3), 0) << "the values bit for bit";
}

TEST(JacobianCheck, AJumpWithinOneStepIsFoundInItsOwnColumnOnly) {
  Fixture f(2.0 + 4e-7, 0.01);   // the step a +- 2e-6 straddles it; the Jacobian (autodiff) does not see it
  const auto cols = demfit::check_jacobian(f.problem, {f.x.data()});
  ASSERT_EQ(cols.size(), 3u);
  EXPECT_GT(cols[0].disagreement, 0.9) << "a's column: 0.01 / 4e-6 per residual against |t|-sized derivatives";
  EXPECT_LT(cols[1].disagreement, 1e-7);
  EXPECT_LT(cols[2].disagreement, 1e-7);
  Fixture far(2.1, 0.01);   // the same jump beyond the step: smooth at this point
  for (const auto& c : demfit::check_jacobian(far.problem, {far.x.data()})) EXPECT_LT(c.disagreement, 1e-7);
}

TEST(JacobianCheck, ABoundIsNotCrossedAndAHeldEntryIsLeftOut) {
  Fixture f;
  f.problem.SetParameterUpperBound(f.x.data(), 1, 0.7 + 1e-7);   // b: one-sided (backward) difference
  f.problem.SetParameterLowerBound(f.x.data(), 0, 2.0);           // a on its lower bound: forward
  f.problem.SetManifold(f.x.data(), new ceres::SubsetManifold(3, {2}));   // c held
  const auto cols = demfit::check_jacobian(f.problem, {f.x.data()});
  ASSERT_EQ(cols.size(), 2u);
  EXPECT_EQ(cols[0].index, 0);
  EXPECT_EQ(cols[1].index, 1);
  for (const auto& c : cols) {
    EXPECT_LT(c.disagreement, 1e-5) << c.index;   // first order: O(h)
    EXPECT_TRUE(c.one_sided) << c.index;
  }
  EXPECT_GT(cols[1].disagreement, 1e-9) << "b one-sided: O(h), not the central difference's O(h^2)";
  EXPECT_LT(cols[0].disagreement, 1e-9) << "a forward: the residuals are linear in a";
  f.problem.SetParameterBlockConstant(f.x.data());
  EXPECT_TRUE(demfit::check_jacobian(f.problem, {f.x.data()}).empty()) << "a constant block is not checked";
}

}  // namespace
