// check_jacobian (demfit/jacobian_check.hpp): a smooth cost's Jacobian agrees with central differences, a jump within
// one difference step of the point is found in its own coefficient's column only, the values are restored bit for
// bit, a step beyond a bound is taken one-sided, and an entry a SubsetManifold holds is not checked. check_error_scale:
// a linear least-squares cost rises by exactly the quadratic model's over one error in each direction (with a
// coefficient held too, along the conditional covariance), an exponential
// model by its closed form, and a bound within the error gives nan on that side.
#include <gtest/gtest.h>

#include <ceres/ceres.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "demfit/jacobian_check.hpp"
#include "line_fit.hpp"

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

using demfit_test::Line;   // r_i = x0 + x1 t_i - y_i: chi^2 exactly quadratic (line_fit.hpp)

TEST(ErrorScale, ALinearCostRisesByTheQuadraticsOverOneErrorEitherWay) {
  demfit_test::LineFit f;
  std::vector<double>& x = f.x;
  const std::vector<double>& cov = f.cov;
  const double S1 = f.S1;
  ceres::Problem& problem = f.problem;
  const std::vector<double> before = x;
  for (double scale : {1.0, 3.7})
    for (double t : {1.0, 0.2}) {
      const auto got = demfit::check_error_scale(problem, {x.data()}, cov, {0, 1}, scale, t);
      ASSERT_EQ(got.size(), 2u);
      for (const auto& e : got) {
        EXPECT_NEAR(e.minus, 1.0, 1e-9) << scale << " " << t;
        EXPECT_NEAR(e.plus, 1.0, 1e-9) << scale << " " << t;
      }
    }
  EXPECT_EQ(std::memcmp(before.data(), x.data(), sizeof(double) * 2), 0) << "the values bit for bit";
  // x1 held (as on a bound): x0's conditional variance is 1/(A^T A)_00 = 1/S1, and x0 alone moves by that error
  const auto held = demfit::check_error_scale(problem, {x.data()}, cov, {0}, 2.0, 1.0, {1});
  ASSERT_EQ(held.size(), 1u);
  EXPECT_NEAR(held[0].conditional, std::sqrt((1 / S1) / cov[0]), 1e-12);
  EXPECT_LT(held[0].conditional, 0.9) << "the intercept and slope are correlated here";
  EXPECT_NEAR(held[0].minus, 1.0, 1e-9);
  EXPECT_NEAR(held[0].plus, 1.0, 1e-9);
  problem.SetParameterUpperBound(x.data(), 1, x[1] + 1e-3 * std::sqrt(cov[3]));   // within x1's reach, not x0's
  const auto free = demfit::check_error_scale(problem, {x.data()}, cov, {0}, 1.0);
  EXPECT_TRUE(std::isnan(free[0].minus)) << "unheld, x0's profile down raises x1 (cov < 0) across its bound";
  EXPECT_NEAR(free[0].plus, 1.0, 1e-9);
  const auto kept = demfit::check_error_scale(problem, {x.data()}, cov, {0}, 1.0, 1.0, {1});
  EXPECT_NEAR(kept[0].minus, 1.0, 1e-9) << "held, x1 stays";
}

// r_i = e^x - y_i: at the optimum e^x = mean(y) = m, J^T J = n m^2, sigma = 1/(sqrt(n) m), and chi^2 - chi^2_min =
// n (e^x - m)^2, so one error s sigma (scale s^2) either way rises by (e^{-+s sigma} - 1)^2 / (s sigma)^2 of s^2.
struct Exp {
  double y;
  template <class T>
  bool operator()(const T* x, T* r) const {
    using std::exp;
    r[0] = exp(x[0]) - T(y);
    return true;
  }
};

TEST(ErrorScale, AnExponentialRisesByItsClosedFormAndABoundWithinTheErrorIsNotCrossed) {
  const double ys[] = {0.6, 1.4};   // n = 2, m = 1: sigma = 1/sqrt(2), far from quadratic
  std::vector<double> x = {0.0};
  ceres::Problem problem;
  for (double y : ys)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Exp, 1, 1>(new Exp{y}), nullptr, x.data());
  const double sigma = 1 / std::sqrt(2.0);
  for (double scale : {1.0, 2.25}) {
    const double h = std::sqrt(scale) * sigma;
    const auto got = demfit::check_error_scale(problem, {x.data()}, {sigma * sigma}, {0}, scale);
    ASSERT_EQ(got.size(), 1u);
    EXPECT_NEAR(got[0].minus, std::pow(std::exp(-h) - 1, 2) / (h * h), 1e-12) << scale;
    EXPECT_NEAR(got[0].plus, std::pow(std::exp(h) - 1, 2) / (h * h), 1e-12) << scale;
  }
  EXPECT_LT(demfit::check_error_scale(problem, {x.data()}, {sigma * sigma}, {0}, 1.0)[0].minus, 0.6);
  EXPECT_GT(demfit::check_error_scale(problem, {x.data()}, {sigma * sigma}, {0}, 1.0)[0].plus, 2.0);
  const auto small = demfit::check_error_scale(problem, {x.data()}, {sigma * sigma}, {0}, 1.0, 1e-3);
  EXPECT_NEAR(small[0].minus, 1.0, 2e-3) << "quadratic at a thousandth of the error";
  EXPECT_NEAR(small[0].plus, 1.0, 2e-3);
  problem.SetParameterUpperBound(x.data(), 0, 0.5);   // within sigma = 0.71 above
  const auto bounded = demfit::check_error_scale(problem, {x.data()}, {sigma * sigma}, {0}, 1.0);
  EXPECT_TRUE(std::isnan(bounded[0].plus));
  EXPECT_NEAR(bounded[0].minus, std::pow(std::exp(-sigma) - 1, 2) / (sigma * sigma), 1e-12);
  EXPECT_EQ(x[0], 0.0);
}

}  // namespace


namespace {

// hold_on_bounds: an entry on its bound is held from then on (with those held before, and an extra one), a block all
// of whose entries are held becomes constant, and a second fit on that face reaches the closed-form minimum of the
// free entries with the bound's held: x0 = mean(y - b t) for r = x0 + x1 t - y with x1 held at b.
TEST(HoldOnBounds, EntriesOnABoundAreHeldAndTheFaceIsSolvedExactly) {
  const double ts[] = {0.0, 0.5, 1.0, 2.0, 3.5}, ys[] = {0.1, 0.9, 1.7, 4.2, 6.8};
  std::vector<double> x = {0.0, 1.0};
  const double b = 1.5;   // the unconstrained slope is 1.9: the bound is active
  ceres::Problem problem;
  for (int i = 0; i < 5; ++i)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Line, 1, 2>(new Line{ts[i], ys[i]}), nullptr, x.data());
  problem.SetParameterUpperBound(x.data(), 1, b);
  x[1] = b;
  EXPECT_EQ(demfit::hold_on_bounds(problem, {x.data()}), 1);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-15;
  ceres::Solver::Summary sum;
  ceres::Solve(so, &problem, &sum);
  double want = 0;
  for (int i = 0; i < 5; ++i) want += (ys[i] - b * ts[i]) / 5;
  EXPECT_NEAR(x[0], want, 1e-7);   // Levenberg-Marquardt's damping converges to it geometrically
  EXPECT_EQ(x[1], b) << "held bit for bit";
  EXPECT_EQ(demfit::hold_on_bounds(problem, {x.data()}), 0) << "nothing more on a bound";
  EXPECT_EQ(demfit::hold_on_bounds(problem, {x.data()}, {{x.data(), 0}}), 1) << "an extra entry";
  EXPECT_TRUE(problem.IsParameterBlockConstant(x.data())) << "every entry held: constant";

  std::vector<double> y3 = {2.0, 0.7, -0.3};   // a block held at {2} before, entry 0 on its lower bound
  ceres::Problem p3;
  for (int i = 0; i < 30; ++i) {
    const double t = 0.1 * i;
    p3.AddResidualBlock(new ceres::AutoDiffCostFunction<Decay, 1, 3>(
                            new Decay{t, 2.1 * std::exp(-0.65 * t) - 0.28 * t, 1e300, 0.0}),
                        nullptr, y3.data());
  }
  p3.SetManifold(y3.data(), new ceres::SubsetManifold(3, {2}));
  p3.SetParameterLowerBound(y3.data(), 0, 2.0);
  EXPECT_EQ(demfit::hold_on_bounds(p3, {y3.data()}), 1);
  ASSERT_NE(p3.GetManifold(y3.data()), nullptr);
  EXPECT_EQ(p3.GetManifold(y3.data())->TangentSize(), 1) << "entries 0 and 2 held, 1 free";

  // near a bound (twenty-fourth round): within the tolerance it is moved onto the bound and held; beyond, left alone
  std::vector<double> z = {0.0, 1.5 - 2.5e-6};
  ceres::Problem p4;
  for (int i = 0; i < 5; ++i)
    p4.AddResidualBlock(new ceres::AutoDiffCostFunction<Line, 1, 2>(new Line{ts[i], ys[i]}), nullptr, z.data());
  p4.SetParameterUpperBound(z.data(), 1, 1.5);
  EXPECT_EQ(demfit::hold_on_bounds(p4, {z.data()}), 0) << "2.5e-6 away: not on it at the default 1e-9";
  EXPECT_EQ(z[1], 1.5 - 2.5e-6);
  EXPECT_EQ(demfit::hold_on_bounds(p4, {z.data()}, {}, 1e-6), 0) << "nor within 1e-6";
  EXPECT_EQ(demfit::hold_on_bounds(p4, {z.data()}, {}, 2e-6), 1) << "within 2e-6 x max(1, 1.5)";
  EXPECT_EQ(z[1], 1.5) << "moved onto the bound";
  EXPECT_EQ(z[0], 0.0);
}

}  // namespace

namespace {

// release_from_bounds (twenty-fifth round): the line's slope held on an upper bound of 1.5 while the unconstrained
// slope is 1.9 stays held (chi^2 rises into the box: the multiplier's sign says the bound is active); held on a
// lower bound of 1.0 with the data's slope 1.9 above it, chi^2 falls into the box, so it is set free, and a refit
// reaches the closed-form least-squares line. A kink held off any bound is never released; values are restored.
TEST(ReleaseFromBounds, OnlyAnEntryWhoseCostFallsIntoTheBoxIsSetFree) {
  const double ts[] = {0.0, 0.5, 1.0, 2.0, 3.5}, ys[] = {0.1, 0.9, 1.7, 4.2, 6.8};
  const auto line = [&](std::vector<double>& x) {
    auto p = std::make_unique<ceres::Problem>();
    for (int i = 0; i < 5; ++i)
      p->AddResidualBlock(new ceres::AutoDiffCostFunction<Line, 1, 2>(new Line{ts[i], ys[i]}), nullptr, x.data());
    return p;
  };
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-15;
  ceres::Solver::Summary sum;

  std::vector<double> up = {0.0, 1.5};   // active upper bound: kept
  auto pu = line(up);
  pu->SetParameterUpperBound(up.data(), 1, 1.5);
  std::vector<std::pair<double*, int>> face;
  ASSERT_EQ(demfit::hold_on_bounds(*pu, {up.data()}, {}, 1e-9, &face), 1);
  ASSERT_EQ(face.size(), 1u);
  ceres::Solve(so, pu.get(), &sum);
  EXPECT_TRUE(demfit::release_from_bounds(*pu, {up.data()}, face).empty()) << "the bound is active";
  EXPECT_EQ(up[1], 1.5);
  EXPECT_EQ(pu->GetManifold(up.data())->TangentSize(), 1) << "still held";

  std::vector<double> lo = {0.0, 1.0};   // inactive lower bound, the fit stopped on it: released
  auto pl = line(lo);
  pl->SetParameterLowerBound(lo.data(), 1, 1.0);
  face.clear();
  ASSERT_EQ(demfit::hold_on_bounds(*pl, {lo.data()}, {{lo.data(), 0}}, 1e-9, &face), 2);
  ASSERT_EQ(face.size(), 2u);
  EXPECT_TRUE(pl->IsParameterBlockConstant(lo.data())) << "both held: entry 0 as a kink, entry 1 on its bound";
  const double x0 = lo[0];
  const auto freed = demfit::release_from_bounds(*pl, {lo.data()}, face);
  ASSERT_EQ(freed.size(), 1u);
  EXPECT_EQ(freed[0].second, 1);
  EXPECT_EQ(lo[0], x0);
  EXPECT_EQ(lo[1], 1.0) << "restored bit for bit";
  EXPECT_FALSE(pl->IsParameterBlockConstant(lo.data()));
  ASSERT_NE(pl->GetManifold(lo.data()), nullptr);
  EXPECT_EQ(pl->GetManifold(lo.data())->TangentSize(), 1) << "entry 0 (the kink) still held";
  EXPECT_TRUE(demfit::release_from_bounds(*pl, {lo.data()}, {{lo.data(), 0}}).empty()) << "a kink off any bound";
  ceres::Solve(so, pl.get(), &sum);
  // x0 held: the slope's conditional minimum is sum t (y - x0) / sum t^2
  double num = 0, den = 0;
  for (int i = 0; i < 5; ++i) { num += ts[i] * (ys[i] - x0); den += ts[i] * ts[i]; }
  EXPECT_NEAR(lo[1], num / den, 1e-7);   // Levenberg-Marquardt converges to it geometrically
  EXPECT_GT(lo[1], 1.0);

  std::vector<double> all = {0.0, 1.0};   // no kink: the whole block free again, no manifold left
  auto pa = line(all);
  pa->SetParameterLowerBound(all.data(), 1, 1.0);
  face.clear();
  ASSERT_EQ(demfit::hold_on_bounds(*pa, {all.data()}, {}, 1e-9, &face), 1);
  ASSERT_EQ(demfit::release_from_bounds(*pa, {all.data()}, face).size(), 1u);
  EXPECT_EQ(pa->GetManifold(all.data()), nullptr);
}

}  // namespace
