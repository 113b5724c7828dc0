// settling (demfit/settle.hpp): a fit that runs out of iterations while chi^2 still falls by more than 1 % of s over
// the window is not settled; where it falls by less, it is. The runaway valley r = A exp(-x): each Gauss-Newton step
// is 1 and the cost falls by about e^-2 per step without end, so Ceres' relative tolerance is never met (its gradient
// test ends it once A^2 e^{-2x} is below the last digit of x: A = 1e100 keeps it far from that in 60 iterations). WindowStart's values one window before the limit give, through the closed form
// chi^2 = A^2 exp(-2x), the fall the summary's costs give.
#include <gtest/gtest.h>

#include <ceres/ceres.h>

#include <cmath>
#include <vector>

#include "demfit/settle.hpp"

namespace {

struct Runaway {
  double A;
  template <class T>
  bool operator()(const T* x, T* r) const {
    using std::exp;
    r[0] = T(A) * exp(-x[0]);
    return true;
  }
};

struct Solved {
  ceres::Solver::Summary summary;
  double x_window = NAN, x_end = NAN;
};

Solved solve_runaway(double A, int max_iterations) {
  double x = 0.0;
  ceres::Problem problem;
  problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Runaway, 1, 1>(new Runaway{A}), nullptr, &x);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-300;   // the valley's gradient A^2 e^{-2x} would end it otherwise
  demfit::WindowStart watch(problem, {&x}, max_iterations - demfit::settle_window(max_iterations));
  so.update_state_every_iteration = true;
  so.callbacks.push_back(&watch);
  Solved r;
  ceres::Solve(so, &problem, &r.summary);
  if (!watch.values().empty()) r.x_window = watch.values()[0][0];
  r.x_end = x;
  return r;
}

TEST(Settle, WindowIsTheLastTenthAtLeastFifty) {
  EXPECT_EQ(demfit::settle_window(300), 50);
  EXPECT_EQ(demfit::settle_window(1000), 100);
  EXPECT_EQ(demfit::settle_window(20), 50);   // longer than the fit: never settled
}

TEST(Settle, AFallBelowOnePercentOfSIsSettledAboveIsNot) {
  // A = 1e100, 60 iterations (a window of 50): chi^2 = A^2 e^{-2x} still falls by a factor of about e^-2 per step
  const Solved r = solve_runaway(1e100, 60);
  ASSERT_EQ(r.summary.termination_type, ceres::NO_CONVERGENCE) << r.summary.FullReport();
  ASSERT_TRUE(std::isfinite(r.x_window));
  EXPECT_GT(r.x_end - r.x_window, 10.0);   // the coefficient runs on through the window
  const demfit::Settling s = demfit::settling(r.summary, demfit::settle_window(60), 1.0);
  EXPECT_EQ(s.window, 50);
  EXPECT_EQ(s.iterations, 60);
  // the summary's costs against the closed form at WindowStart's value one window before the limit
  const double closed = 1e200 * (std::exp(-2 * r.x_window) - std::exp(-2 * r.x_end));
  EXPECT_NEAR(s.fall, closed, 1e-9 * closed);
  EXPECT_FALSE(s.settled);   // at s = 1 a fall of ~1e150
  // the same fall against a scale s of 99 and of 101 times it: not settled, settled
  EXPECT_FALSE(demfit::settling(r.summary, 50, 99 * s.fall).settled);
  EXPECT_TRUE(demfit::settling(r.summary, 50, 101 * s.fall).settled);
  // a shorter window falls by less (the cost is monotone): 10 iterations
  EXPECT_LT(demfit::settling(r.summary, 10, 1.0).fall, s.fall);
}

TEST(Settle, AConvergedFitIsNotCalledSettled) {
  // a fit that meets Ceres' own tolerance converged; settled is only for the iteration limit
  const Solved r = solve_runaway(1e100, 60);
  ceres::Solver::Summary converged = r.summary;
  converged.termination_type = ceres::CONVERGENCE;
  EXPECT_TRUE(demfit::settling(r.summary, 50, 1e300).settled);   // at a scale where the iteration limit would be
  EXPECT_FALSE(demfit::settling(converged, 50, 1e300).settled);
  ceres::Solver::Summary failed = r.summary;
  failed.termination_type = ceres::FAILURE;
  EXPECT_FALSE(demfit::settling(failed, 50, 1e300).settled);
  // a window as long as the solve (iterations 0 to 60), and one longer
  EXPECT_TRUE(demfit::settling(r.summary, 60, 1e300).settled);
  EXPECT_FALSE(demfit::settling(r.summary, 61, 1e300).settled);
  EXPECT_EQ(demfit::settling(r.summary, 61, 1e300).window, 0);   // not measured: no fall to quote
  EXPECT_EQ(demfit::settling(converged, 50, 1e300).window, 0);
}

}  // namespace
