#pragma once
// Has a fit that ran out of iterations reached its minimum as far as the statistics can tell? Ceres stops a
// calibration when chi^2 changes by less than 1e-12 of itself from one step to the next (`function_tolerance`). A fit
// creeping along a flat valley (a coefficient running away where the cost levels off, or a long curved valley that
// Levenberg-Marquardt follows in small steps) can fall by 1e-4 of one error's worth of chi^2 per step for thousands of
// steps: it hits the iteration limit, although nothing the statistics read is still moving. An error is read off a
// rise of chi^2 by s = max(1, chi^2/dof), so a fall of far less than s is not a change of any interval (Press et al.,
// Numerical Recipes, ch. 15.5: "it is never worthwhile to iterate to machine accuracy", a change of chi^2 well below 1
// being statistically meaningless). Issue 31, twenty-sixth round; docs/model.md, "A fit that settles".

#include <ceres/ceres.h>

#include <string>
#include <vector>

namespace demfit {

/// The fraction of s = max(1, chi^2/dof) that chi^2 may fall by over the last window of iterations of a fit stopped
/// at its limit for the fit to count as settled.
inline constexpr double kSettleFraction = 0.01;

/// The window of a fit of at most `max_iterations` iterations: its last tenth, at least 50. A fit of fewer iterations
/// than its window (a short restart, --max-iterations below 51) is never called settled: a few steps say nothing of
/// a creep.
int settle_window(int max_iterations);

/// Keeps the parameter values of `blocks` at iteration `at` (set update_state_every_iteration in the solver's options,
/// or the blocks hold the start until the end): where a fit stopped at its limit stood one window before.
class WindowStart : public ceres::IterationCallback {
 public:
  WindowStart(ceres::Problem& problem, std::vector<double*> blocks, int at);
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override;
  /// One vector per block; empty until iteration `at` was passed.
  const std::vector<std::vector<double>>& values() const { return values_; }

 private:
  std::vector<double*> blocks_;
  std::vector<int> sizes_;
  int at_;
  std::vector<std::vector<double>> values_;
};

/// What a solve that stopped at its iteration limit did over its last `window` iterations.
struct Settling {
  bool settled = false;   ///< stopped at the limit (NO_CONVERGENCE), and chi^2 fell by < kSettleFraction x scale
  double fall = 0;        ///< chi^2 = 2 cost at the window's start minus at the end
  int window = 0;         ///< iterations in the window; 0 where the fall was not measured (not settled)
  int iterations = 0;     ///< iterations of the solve
};

/// The judgment for `summary`, a solve with chi^2's scale s = `scale` (max(1, chi^2/dof)). Not settled unless Ceres
/// stopped at its iteration limit with a usable solution and the window fits in the solve.
Settling settling(const ceres::Solver::Summary& summary, int window, double scale);

/// "chi2 fell by F over the last W iterations, F/s of s": a measured window's fall, for messages and warnings.
std::string fall_phrase(const Settling& s, double scale);

/// The sentence a settled fit's tables carry: the limit, the fall over the window against s.
std::string settle_note(const Settling& s, double scale);

}  // namespace demfit
