#include "demfit/jacobian_check.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace demfit {

namespace {

struct Evaluated {
  bool ok = false;
  std::vector<double> r;
  std::vector<std::vector<double>> cols;   // the Jacobian's columns (tangent coordinates), when asked for
};

Evaluated evaluate(ceres::Problem& problem, const std::vector<double*>& blocks, bool jacobian) {
  ceres::Problem::EvaluateOptions eo;
  eo.parameter_blocks = blocks;
  eo.num_threads = 1;
  Evaluated e;
  double cost = 0;
  ceres::CRSMatrix J;
  if (!problem.Evaluate(eo, &cost, &e.r, nullptr, jacobian ? &J : nullptr)) return e;
  e.ok = std::all_of(e.r.begin(), e.r.end(), [](double v) { return std::isfinite(v); });
  if (!jacobian) return e;
  e.cols.assign(J.num_cols, std::vector<double>(J.num_rows, 0.0));
  for (int row = 0; row < J.num_rows; ++row)
    for (int k = J.rows[row]; k < J.rows[row + 1]; ++k) e.cols[J.cols[k]][row] = J.values[k];
  return e;
}

// The ambient entry of each tangent coordinate of a block: the identity, or a SubsetManifold's selection (its
// PlusJacobian holds one 1 per column); empty for any other manifold (not checked).
std::vector<int> tangent_entries(const ceres::Problem& problem, double* block) {
  const int n = problem.ParameterBlockSize(block);
  const ceres::Manifold* m = problem.GetManifold(block);
  std::vector<int> out;
  if (!m) {
    for (int i = 0; i < n; ++i) out.push_back(i);
    return out;
  }
  const int t = m->TangentSize();
  std::vector<double> jp(static_cast<std::size_t>(n) * t);
  if (!m->PlusJacobian(block, jp.data())) return {};
  for (int k = 0; k < t; ++k) {
    int hit = -1, ones = 0;
    for (int i = 0; i < n; ++i) {
      const double v = jp[static_cast<std::size_t>(i) * t + k];
      if (v == 1.0) { hit = i; ++ones; } else if (v != 0.0) { return {}; }
    }
    if (ones != 1) return {};
    out.push_back(hit);
  }
  return out;
}

double distance(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(s);
}

double norm(const std::vector<double>& a) { return distance(a, std::vector<double>(a.size(), 0.0)); }

// The difference quotient of the residuals along entry i of block: central, or one-sided where a step would cross a
// bound of the problem. ok false where a stepped point gives non-finite residuals.
bool difference(ceres::Problem& problem, const std::vector<double*>& blocks, double* block, int i, double h,
                const std::vector<double>& r0, std::vector<double>& out, bool& one_sided) {
  const double x = block[i];
  const bool up = x + h <= problem.GetParameterUpperBound(block, i);
  const bool down = x - h >= problem.GetParameterLowerBound(block, i);
  one_sided = !(up && down);
  const double a = down ? x - h : x, b = up ? x + h : x;
  if (a == b) return false;
  Evaluated lo, hi;
  block[i] = b;
  hi = up ? evaluate(problem, blocks, false) : Evaluated{true, r0, {}};
  block[i] = a;
  lo = down ? evaluate(problem, blocks, false) : Evaluated{true, r0, {}};
  block[i] = x;
  if (!lo.ok || !hi.ok) return false;
  out.resize(r0.size());
  for (std::size_t k = 0; k < r0.size(); ++k) out[k] = (hi.r[k] - lo.r[k]) / (b - a);
  return true;
}

}  // namespace

std::vector<JacobianColumn> check_jacobian(ceres::Problem& problem, const std::vector<double*>& blocks_in,
                                           double rel_step) {
  std::vector<double*> blocks;
  std::vector<int> position;   // each checked block's place in blocks_in
  for (std::size_t b = 0; b < blocks_in.size(); ++b)
    if (!problem.IsParameterBlockConstant(blocks_in[b])) {
      blocks.push_back(blocks_in[b]);
      position.push_back(static_cast<int>(b));
    }
  std::vector<JacobianColumn> out;
  if (blocks.empty()) return out;
  const Evaluated e0 = evaluate(problem, blocks, true);
  if (!e0.ok) return out;
  std::size_t col = 0;
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const std::vector<int> entries = tangent_entries(problem, blocks[b]);
    const ceres::Manifold* m = problem.GetManifold(blocks[b]);
    const std::size_t width = m ? m->TangentSize() : problem.ParameterBlockSize(blocks[b]);
    for (std::size_t k = 0; k < entries.size() && col + k < e0.cols.size(); ++k) {
      JacobianColumn c;
      c.block = position[b];
      c.index = entries[k];
      c.step = rel_step * std::max(1.0, std::fabs(blocks[b][c.index]));
      const std::vector<double>& jc = e0.cols[col + k];
      c.norm_jacobian = norm(jc);
      std::vector<double> fd;
      if (!difference(problem, blocks, blocks[b], c.index, c.step, e0.r, fd, c.one_sided)) {
        c.disagreement = std::numeric_limits<double>::infinity();
      } else {
        c.norm_difference = norm(fd);
        const double scale = std::max(c.norm_jacobian, c.norm_difference);
        c.disagreement = scale > 0 ? distance(fd, jc) / scale : 0.0;
      }
      out.push_back(c);
    }
    col += width;
  }
  return out;
}

namespace {

// 2 cost at the current parameter values: +inf where the residuals are not numbers.
double chi2_here(ceres::Problem& problem, const std::vector<double*>& blocks) {
  const Evaluated e = evaluate(problem, blocks, false);
  if (!e.ok) return std::numeric_limits<double>::infinity();
  double s = 0;
  for (double v : e.r) s += v * v;
  return s;
}

// Every entry of blocks set to start + t d (false, nothing moved, where one would leave a bound of the problem).
bool move_to(ceres::Problem& problem, const std::vector<double*>& blocks, const std::vector<double>& start,
             const std::vector<double>& d, double t) {
  std::size_t k = 0;
  for (double* b : blocks)
    for (int i = 0; i < problem.ParameterBlockSize(b); ++i, ++k) {
      const double v = start[k] + t * d[k];
      if (v < problem.GetParameterLowerBound(b, i) || v > problem.GetParameterUpperBound(b, i)) return false;
    }
  k = 0;
  for (double* b : blocks)
    for (int i = 0; i < problem.ParameterBlockSize(b); ++i, ++k) b[i] = start[k] + t * d[k];
  return true;
}

}  // namespace

std::vector<ErrorScale> check_error_scale(ceres::Problem& problem, const std::vector<double*>& blocks,
                                          const std::vector<double>& covariance, const std::vector<int>& coordinates,
                                          double scale, double fraction) {
  std::vector<double> start;
  for (double* b : blocks) start.insert(start.end(), b, b + problem.ParameterBlockSize(b));
  const std::size_t n = start.size();
  const double chi0 = chi2_here(problem, blocks);
  if (!std::isfinite(chi0) || covariance.size() != n * n) return {};
  std::vector<ErrorScale> out;
  for (int a : coordinates) {
    ErrorScale e;
    const double saa = covariance[static_cast<std::size_t>(a) * n + a];
    if (saa > 0) {
      std::vector<double> d(n);
      for (std::size_t k = 0; k < n; ++k) d[k] = std::sqrt(scale / saa) * covariance[k * n + a];
      const double t = fraction, expected = scale * t * t;
      if (move_to(problem, blocks, start, d, -t)) e.minus = (chi2_here(problem, blocks) - chi0) / expected;
      if (move_to(problem, blocks, start, d, +t)) e.plus = (chi2_here(problem, blocks) - chi0) / expected;
      std::size_t k = 0;   // restored bit for bit
      for (double* b : blocks)
        for (int i = 0; i < problem.ParameterBlockSize(b); ++i, ++k) b[i] = start[k];
    }
    out.push_back(e);
  }
  return out;
}

}  // namespace demfit
