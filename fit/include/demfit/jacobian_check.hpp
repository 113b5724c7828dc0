#pragma once
// Is a least-squares cost smooth where a fit stopped? Each Jacobian column against central differences of the
// residuals (twenty-second round; docs/model.md, "A cost that is not smooth at its optimum"). The covariance
// (J^T J)^-1 describes the data's hold on the coefficients only where J is the residuals' derivative at the scale of
// those errors; a model whose output jumps with the last digits of a coefficient (a fixed-step integration across a
// point where its right-hand side is singular) has a Jacobian that no difference quotient reproduces.

#include <ceres/ceres.h>

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

}  // namespace demfit
