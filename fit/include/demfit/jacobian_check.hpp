#pragma once
// Is a least-squares cost smooth where a fit stopped? Each Jacobian column against central differences of the
// residuals (twenty-second round; docs/model.md, "A cost that is not smooth at its optimum"). The covariance
// (J^T J)^-1 describes the data's hold on the coefficients only where J is the residuals' derivative at the scale of
// those errors; a model whose output jumps with the last digits of a coefficient (a fixed-step integration across a
// point where its right-hand side is singular) has a Jacobian that no difference quotient reproduces.

#include <ceres/ceres.h>

#include <limits>
#include <utility>
#include <vector>

namespace demfit {

/// One checked coordinate: parameter block `block` (its position in the list given), entry `index` of it.
struct JacobianColumn {
  int block = 0, index = 0;
  double step = 0;          ///< the difference step (relative step x max(1, |value|)), one-sided next to a bound
  bool one_sided = false;   ///< a bound of the problem within one step: a forward or backward difference
  double norm_jacobian = 0; ///< |J e| over the residuals
  double norm_difference = 0;
  /// |difference quotient - J e| / max(the two norms): 0 where they agree, up to 2; +inf where a stepped point could
  /// not be evaluated (non-finite residuals)
  double disagreement = 0;
};

/// Every free entry of `blocks` (those a SubsetManifold holds, and constant blocks, are left out) stepped by
/// rel_step x max(1, |value|) each way; the problem's parameter values are restored bit for bit. Empty if the problem
/// cannot be evaluated at its current values.
std::vector<JacobianColumn> check_jacobian(ceres::Problem& problem, const std::vector<double*>& blocks,
                                           double rel_step = 1e-6);

/// The entries of `block` a fit moves: all of them, or those a SubsetManifold leaves free. Empty for a block with any
/// other manifold (whose tangent coordinates are not entries). A constant block's entries are listed all the same.
std::vector<int> free_entries(const ceres::Problem& problem, double* block);

/// Every free entry of `blocks` that sits on a bound of the problem (within `tolerance` max(1, |value|); one that is
/// within that but not on it is first set onto the bound), and the `extra` (block, entry) pairs, held from now on: each such block gets a SubsetManifold over the entries held before (by a
/// SubsetManifold) and these. Constant blocks and blocks with another manifold are left alone. Returns how many entries
/// it added. Levenberg-Marquardt with bounds projects its steps onto the box, and where a coefficient sits on a bound
/// with the cost falling beyond it, the projected steps can shrink until the cost's relative change passes the function
/// tolerance with the free coefficients short of their minimum (twenty-third round); a second fit on that face, with
/// the bound's coefficients held, reaches it.
/// `added_entries`, when given, gets each (block, entry) it held appended.
int hold_on_bounds(ceres::Problem& problem, const std::vector<double*>& blocks,
                   const std::vector<std::pair<double*, int>>& extra = {}, double tolerance = 1e-9,
                   std::vector<std::pair<double*, int>>* added_entries = nullptr);

/// The active set's other half (Nocedal & Wright, Numerical Optimization, ch. 16.5): of the `on_bounds` entries (held on
/// a bound by hold_on_bounds), those where chi^2 falls one step h = `step` max(1, |value|) into the box (by more than
/// 1e-10 chi^2; the other free coefficients at their minimum, so this is the profile's slope, whose sign is the bound's
/// Lagrange multiplier's) are set free again, and returned. A held entry is otherwise never released, and a fit that
/// touched a bound on its way could stay on that face with a lower cost inside (twenty-fourth round: the three-pressure
/// mu = 1 joint calibration, 25.67 -> 25.41 on a restart with C1 leaving 0). Values are restored bit for bit; entries
/// not on a bound (kinks) are skipped.
std::vector<std::pair<double*, int>> release_from_bounds(ceres::Problem& problem, const std::vector<double*>& blocks,
                                                         const std::vector<std::pair<double*, int>>& on_bounds,
                                                         double step = 1e-5);

/// release_from_bounds over the entries of `face` not in `released`, each released one moved from `face` to
/// `released`: an active set in which an entry is released once (a fit that takes it back onto its bound holds it
/// again, for good), so the passes end. False when none is released.
bool release_once(ceres::Problem& problem, const std::vector<double*>& blocks, std::vector<std::pair<double*, int>>& face,
                  std::vector<std::pair<double*, int>>& released);

/// The cost over one quoted error (twenty-third round; docs/model.md, "The cost over one quoted error"). A covariance
/// error rests on the cost being quadratic over that error, not only smooth at the optimum's step. Along coordinate
/// a's linearised profile, d = sqrt(scale) Sigma e_a / sqrt(Sigma_aa) (the other coefficients at their conditional
/// optimum of the quadratic model), the quoted error is sqrt(scale Sigma_aa) in a and the quadratic model's chi^2 rises
/// by exactly `scale` (Sigma = (J^T J)^-1 of chi^2 = 2 cost). `minus` and `plus` are the rise of 2 cost at x -/+ d over
/// that: 1 where the quadratic holds, below 1 where the cost is flatter than its curvature at the optimum (the error
/// too small), above 1 where it is steeper. NaN where x -/+ d leaves a bound of the problem; +inf where the residuals
/// there are not numbers.
struct ErrorScale {
  double minus = std::numeric_limits<double>::quiet_NaN(), plus = std::numeric_limits<double>::quiet_NaN();
  /// sqrt(Sigma'_aa / Sigma_aa): the error with the `held` coordinates fixed over the one quoted (1 with none held)
  double conditional = std::numeric_limits<double>::quiet_NaN();
};

/// The covariance with the `held` coordinates fixed: Sigma_FF - Sigma_FH Sigma_HH^+ Sigma_HF (the Gaussian's conditional
/// covariance; the pseudo-inverse by a complete orthogonal decomposition), the held rows and columns 0. n x n row-major
/// in and out; held coordinates with no variance are left out of H.
std::vector<double> conditional_covariance(const std::vector<double>& covariance, const std::vector<int>& held);

/// 2 cost (chi^2) of the problem at its current values, over `blocks`: +inf where the residuals are not numbers.
double chi2_of(ceres::Problem& problem, const std::vector<double*>& blocks);

/// `covariance` is n x n, row-major, over the concatenated entries of `blocks` (n their total size), unscaled
/// ((J^T J)^-1); each of `coordinates` (indices into that concatenation, with a positive diagonal) is stepped as above.
/// With `fraction` t the steps are x -/+ t d and the rises are divided by t^2 (-> 1 as t -> 0 wherever the Jacobian is
/// the residuals' derivative and their second derivatives are small). `held` coordinates (e.g. coefficients on a bound
/// of the problem) stay where they are: Sigma is then their conditional covariance Sigma_FF - Sigma_FH Sigma_HH^+
/// Sigma_HF, and d and the expected rise are built from it (ErrorScale::conditional says how much smaller that error
/// is). The problem's parameter values are restored bit for bit. Empty if the problem cannot be evaluated where it is.
std::vector<ErrorScale> check_error_scale(ceres::Problem& problem, const std::vector<double*>& blocks,
                                          const std::vector<double>& covariance, const std::vector<int>& coordinates,
                                          double scale, double fraction = 1.0, const std::vector<int>& held = {});

}  // namespace demfit
