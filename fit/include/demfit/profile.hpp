#pragma once
// Profile intervals (issue 31, twenty-fourth round; docs/model.md, "Profile intervals"). A covariance error rests on
// the cost being quadratic over that error; where it is not (check_error_scale, jacobian_check.hpp), the interval the
// data support is the profile's: chi2_p(a) = min over the other free coefficients of chi2 with coefficient a held,
// and the interval's ends where chi2_p rises by `scale` above the optimum's chi2 (the likelihood-ratio interval;
// Venzon & Moolgavkar 1988, Bates & Watts 1988 ch. 6). With scale = max(1, chi2/dof) it is the interval the scaled
// covariance error quotes wherever the cost is quadratic. Each profile point is one refit of the problem.

#include <ceres/ceres.h>

#include <functional>
#include <limits>
#include <vector>

namespace demfit {

/// One end of a profile interval.
struct ProfileEnd {
  /// where chi2_p has risen by `scale` (within the tolerance); the coefficient's bound where `bound`; nan where the
  /// rise was not reached within `reach` quoted errors, or a refit failed
  double value = std::numeric_limits<double>::quiet_NaN();
  double rise = std::numeric_limits<double>::quiet_NaN();   ///< chi2_p's rise over `scale` at `value`
  bool bound = false;     ///< the coefficient's own bound reached with chi2_p still below the rise: the end is the bound
  bool failed = false;    ///< a refit was not usable (Ceres) or its residuals not numbers
  int refits = 0;
};

struct ProfileInterval {
  ProfileEnd lower, upper;
  /// The lowest chi2 a profile refit reached below the optimum's (nan if none did, within 1e-9 relative): the fit had
  /// not reached its minimum, and the ends are measured from a chi2 that is not the profile's lowest.
  double below_optimum = std::numeric_limits<double>::quiet_NaN();
};

/// One solve of the problem as it stands (the calibration's own solver options): false where its result is unusable.
using ProfileSolve = std::function<bool(ceres::Problem&)>;
/// Told after each coefficient: its place in `coordinates` (from 0), their number, and its interval.
using ProfileProgress = std::function<void(int, int, const ProfileInterval&)>;

/// For each of `coordinates` (indices into the concatenated entries of `blocks`, as in check_error_scale): the
/// coefficient held at trial values, every other free entry refitted by `solve` (and, where the refit ends on a bound
/// of the problem, again with that held: hold_on_bounds, and with a held one whose chi2 falls into the box set free:
/// release_once; at most 4 passes), until chi2_p - chi2_0 = scale within `tolerance` x scale
/// on each side. The trials start one conditional covariance error away along the linearised profile (`covariance`
/// unscaled, n x n row-major; `held` as in check_error_scale) and find the end by the secant rule on sqrt(rise), which
/// is linear in the coefficient where the cost is quadratic; at most `max_refits` refits per end, out to `reach`
/// errors. One more refit per coefficient, with it where it is, checks that the others were at their minimum
/// (ProfileInterval::below_optimum). The problem's values, manifolds and constant blocks are restored as they were (values bit for bit).
std::vector<ProfileInterval> profile_intervals(ceres::Problem& problem, const std::vector<double*>& blocks,
                                               const std::vector<double>& covariance,
                                               const std::vector<int>& coordinates, double scale,
                                               const ProfileSolve& solve, const std::vector<int>& held = {},
                                               double tolerance = 0.05, int max_refits = 10, double reach = 16,
                                               const ProfileProgress& progress = nullptr);

}  // namespace demfit
