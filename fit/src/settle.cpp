#include "demfit/settle.hpp"

#include "demfit/format.hpp"

#include <algorithm>

namespace demfit {

int settle_window(int max_iterations) { return std::max(50, max_iterations / 10); }

WindowStart::WindowStart(ceres::Problem& problem, std::vector<double*> blocks, int at)
    : blocks_(std::move(blocks)), at_(at) {
  for (double* b : blocks_) sizes_.push_back(problem.ParameterBlockSize(b));
}

ceres::CallbackReturnType WindowStart::operator()(const ceres::IterationSummary& summary) {
  if (summary.iteration == at_) {
    values_.clear();
    for (std::size_t i = 0; i < blocks_.size(); ++i) values_.emplace_back(blocks_[i], blocks_[i] + sizes_[i]);
  }
  return ceres::SOLVER_CONTINUE;
}

Settling settling(const ceres::Solver::Summary& summary, int window, double scale) {
  Settling s;
  const auto& it = summary.iterations;
  s.iterations = it.empty() ? 0 : it.back().iteration;
  if (summary.termination_type != ceres::NO_CONVERGENCE || !summary.IsSolutionUsable() || window < 1 ||
      static_cast<int>(it.size()) <= window)
    return s;   // window 0: not measured
  s.window = window;
  // iterations[k].cost is the cost after iteration k (an unsuccessful step leaves it); the start of the window is
  // `window` iterations before the last
  const double before = 2 * it[it.size() - 1 - static_cast<std::size_t>(window)].cost;
  s.fall = before - 2 * summary.final_cost;
  s.settled = s.fall < kSettleFraction * scale;
  return s;
}

std::string fall_phrase(const Settling& s, double scale) {
  return "chi2 fell by " + fmt(s.fall, 3) + " over the last " + std::to_string(s.window) + " iterations, " +
         fmt(s.fall / scale, 3) + " of s";
}

std::string settle_note(const Settling& s, double scale) {
  return "Ceres stopped at its limit of " + std::to_string(s.iterations) +
         " iterations short of its relative tolerance (1e-12), but chi2 fell by " + fmt(s.fall, 3) + " over the last " +
         std::to_string(s.window) + ", " + fmt(s.fall / scale, 3) + " of s = max(1, chi2/dof) (below " +
         fmt(kSettleFraction, 2) + "): settled, taken as converged (docs/model.md, \"A fit that settles\")";
}

}  // namespace demfit
