// The peak-and-soften law: a second model beside the saturating law for curves that overshoot
// their critical state and soften (dense frictional packings), or approach it at two rates.
//
// The saturating law dx/de = beta (x_max - x) lets x relax towards a fixed target. Here the
// target y itself relaxes towards the critical state: dx/de = beta (y - x), dy/de = gamma (x_cs - y),
// x(0) = x0, y(0) = y0, gamma < beta. The solution is
//   x(e) = x_cs - (x_cs - x0) exp(-beta e) + A (exp(-gamma e) - exp(-beta e)),
//   A = (y0 - x_cs) beta / (beta - gamma),
// and A = 0 (y0 = x_cs) is exactly the saturating law with x_max = x_cs: the models are nested.
// A > 0: x rises at rate beta towards the higher early target y0, peaks, and softens at rate
// gamma to x_cs (peak and softening). A < 0: a monotone approach with a slow second stage
// (the curve "still rises" where the saturating law says it is flat). docs/model_selection.md.
#pragma once
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "demfit/fit.hpp"

namespace demfit {

/// Parameters p = {x0, x_cs, beta, A, r} with the softening rate gamma = r beta (0 < r < 1 keeps
/// gamma < beta as a bound on r); residual = y - x(e).
struct PeakResidual {
  PeakResidual(double e, double y) : e_(e), y_(y) {}
  template <class T>
  bool operator()(const T* p, T* residual) const {
    using std::exp;
    const T fast = exp(-p[2] * T(e_)), slow = exp(-p[4] * p[2] * T(e_));
    residual[0] = T(y_) - (p[1] - (p[1] - p[0]) * fast + p[3] * (slow - fast));
    return true;
  }
  double e_, y_;
};

using PeakParams = std::array<double, 5>;   ///< x0, x_cs, beta, A, r = gamma/beta

/// Evaluates the law at strain e.
double peak_law(const PeakParams& p, double e);

/// What a user wants from a peaked curve, derived from the parameters.
struct PeakShape {
  bool has_peak = false;   ///< the curve passes beyond x_cs and comes back (an interior extremum)
  double eps_peak = NAN;   ///< strain of the extremum
  double x_peak = NAN;     ///< value there (the peak of a rising curve)
  double initial_slope = NAN;   ///< dx/de at e = 0: beta (x_cs - x0) + A (beta - gamma)
  /// The largest gap between this law and the saturating law with the same (x0, x_cs, beta)
  /// on [e_first, e_last], signed: A max (exp(-gamma e) - exp(-beta e)). Zero for the saturating law.
  double transient = 0;
};
PeakShape peak_shape(const PeakParams& p, double e_first, double e_last);

/// A fit of the peak law.
struct PeakFit {
  bool ok = false;                ///< the optimiser converged
  bool on_bound = false;          ///< beta or gamma/beta on a bound (said in warnings)
  bool critical_state_reached = false;   ///< the softening is 95 % complete within the data (ln 20/gamma <= e_last)
  PeakParams p{};
  double gamma = 0;               ///< r beta
  PeakShape shape;
  double rss = 0, rmse = 0, r_squared = 0;
  int n = 0;
  double e_first = 0, e_last = 0;
  std::vector<std::string> warnings;
};

/// Least-squares fit of the peak law (Ceres, analytic-free autodiff) in options' window, with
/// its rate bounds (beta in [beta_min, beta_max], r in [kPeakRatioMin, kPeakRatioMax]). Without
/// `start` several data-driven starts are tried and the lowest cost kept; with `start` (e.g. the
/// fit to the full ensemble, for its leave-one-out refits) only that one. Throws
/// std::invalid_argument for unusable input, as fit_saturating does.
PeakFit fit_peak(const std::vector<double>& e, const std::vector<double>& y, const FitOptions& options = {},
                 const PeakParams* start = nullptr);

constexpr double kPeakRatioMin = 1e-3;   ///< gamma/beta bounds: below, the softening is a constant
constexpr double kPeakRatioMax = 0.8;    ///< above, the two exponentials are indistinguishable

}  // namespace demfit
