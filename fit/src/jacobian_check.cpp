#include "demfit/jacobian_check.hpp"

#include <Eigen/Dense>

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

}  // namespace

// The ambient entry of each tangent coordinate of a block: the identity, or a SubsetManifold's selection (its
// PlusJacobian holds one 1 per column); empty for any other manifold (not checked).
std::vector<int> free_entries(const ceres::Problem& problem, double* block) {
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

namespace {

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
    const std::vector<int> entries = free_entries(problem, blocks[b]);
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

std::vector<double> conditional_covariance(const std::vector<double>& covariance, const std::vector<int>& held) {
  const std::size_t n = static_cast<std::size_t>(std::llround(std::sqrt(static_cast<double>(covariance.size()))));
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const RowMajor S = Eigen::Map<const RowMajor>(covariance.data(), static_cast<Eigen::Index>(n),
                                                static_cast<Eigen::Index>(n));
  std::vector<int> h;
  for (int k : held)
    if (k >= 0 && static_cast<std::size_t>(k) < n && S(k, k) > 0) h.push_back(k);
  if (h.empty()) return covariance;
  const Eigen::Index m = static_cast<Eigen::Index>(h.size());
  Eigen::MatrixXd SH(S.rows(), m), SHH(m, m);
  for (Eigen::Index j = 0; j < m; ++j) {
    SH.col(j) = S.col(h[j]);
    for (Eigen::Index i = 0; i < m; ++i) SHH(i, j) = S(h[i], h[j]);
  }
  RowMajor C = S - SH * Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>(SHH).solve(SH.transpose());
  for (int k : h) { C.row(k).setZero(); C.col(k).setZero(); }
  return std::vector<double>(C.data(), C.data() + C.size());
}

double chi2_of(ceres::Problem& problem, const std::vector<double*>& blocks) {
  const Evaluated e = evaluate(problem, blocks, false);
  if (!e.ok) return std::numeric_limits<double>::infinity();
  double s = 0;
  for (double v : e.r) s += v * v;
  return s;
}

namespace {

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
                                          double scale, double fraction, const std::vector<int>& held) {
  std::vector<double> start;
  for (double* b : blocks) start.insert(start.end(), b, b + problem.ParameterBlockSize(b));
  const std::size_t n = start.size();
  const double chi0 = chi2_of(problem, blocks);
  if (!std::isfinite(chi0) || covariance.size() != n * n) return {};
  const std::vector<double> cond = conditional_covariance(covariance, held);
  std::vector<ErrorScale> out;
  for (int a : coordinates) {
    ErrorScale e;
    const double saa = cond[static_cast<std::size_t>(a) * n + a], full_aa = covariance[static_cast<std::size_t>(a) * n + a];
    if (saa > 0 && full_aa > 0) {
      e.conditional = std::sqrt(saa / full_aa);
      std::vector<double> d(n);
      for (std::size_t k = 0; k < n; ++k) d[k] = std::sqrt(scale / saa) * cond[k * n + a];
      const double t = fraction, expected = scale * t * t;
      if (move_to(problem, blocks, start, d, -t)) e.minus = (chi2_of(problem, blocks) - chi0) / expected;
      if (move_to(problem, blocks, start, d, +t)) e.plus = (chi2_of(problem, blocks) - chi0) / expected;
      std::size_t k = 0;   // restored bit for bit
      for (double* b : blocks)
        for (int i = 0; i < problem.ParameterBlockSize(b); ++i, ++k) b[i] = start[k];
    }
    out.push_back(e);
  }
  return out;
}

int hold_on_bounds(ceres::Problem& problem, const std::vector<double*>& blocks,
                   const std::vector<std::pair<double*, int>>& extra, double tolerance,
                   std::vector<std::pair<double*, int>>* added_entries) {
  int added = 0;
  for (double* b : blocks) {
    if (problem.IsParameterBlockConstant(b)) continue;
    const int n = problem.ParameterBlockSize(b);
    const std::vector<int> free = free_entries(problem, b);
    if (free.empty() && problem.GetManifold(b)) continue;   // another manifold: not ours to change
    std::vector<bool> hold(n, true);
    for (int i : free) hold[i] = false;
    int here = 0;
    for (int i : free) {
      const double v = b[i], tol = tolerance * std::max(1.0, std::fabs(v));
      const double lo = problem.GetParameterLowerBound(b, i), hi = problem.GetParameterUpperBound(b, i);
      bool on = std::fabs(v - lo) <= tol || std::fabs(v - hi) <= tol;
      if (on) b[i] = std::fabs(v - lo) <= std::fabs(v - hi) ? lo : hi;   // onto the bound it is near
      for (const auto& e : extra) on = on || (e.first == b && e.second == i);
      if (on) {
        hold[i] = true;
        ++here;
        if (added_entries) added_entries->emplace_back(b, i);
      }
    }
    if (here == 0) continue;
    std::vector<int> held;
    for (int i = 0; i < n; ++i)
      if (hold[i]) held.push_back(i);
    if (static_cast<int>(held.size()) == n) problem.SetParameterBlockConstant(b);
    else problem.SetManifold(b, new ceres::SubsetManifold(n, held));
    added += here;
  }
  return added;
}

namespace {

// Entry i of block b set free again: the block's SubsetManifold over the entries held without i (none: no manifold; a
// constant block, all of whose entries were held, made variable).
void free_entry(ceres::Problem& problem, double* b, int i) {
  const int n = problem.ParameterBlockSize(b);
  std::vector<bool> hold(n, true);
  if (!problem.IsParameterBlockConstant(b))
    for (int k : free_entries(problem, b)) hold[k] = false;
  hold[i] = false;
  std::vector<int> held;
  for (int k = 0; k < n; ++k)
    if (hold[k]) held.push_back(k);
  problem.SetParameterBlockVariable(b);
  problem.SetManifold(b, held.empty() ? nullptr : new ceres::SubsetManifold(n, held));
}

}  // namespace

std::vector<std::pair<double*, int>> release_from_bounds(ceres::Problem& problem, const std::vector<double*>& blocks,
                                                         const std::vector<std::pair<double*, int>>& on_bounds,
                                                         double step) {
  std::vector<std::pair<double*, int>> released;
  const double chi0 = chi2_of(problem, blocks);
  if (!std::isfinite(chi0)) return released;
  for (const auto& [b, i] : on_bounds) {
    const double v = b[i], lo = problem.GetParameterLowerBound(b, i), hi = problem.GetParameterUpperBound(b, i);
    if (v != lo && v != hi) continue;   // not on a bound (a kink held by the caller)
    const double inward = v == lo ? 1.0 : -1.0;
    const double h = std::min(step * std::max(1.0, std::fabs(v)), 0.5 * (hi - lo));
    b[i] = v + inward * h;
    const double chi1 = chi2_of(problem, blocks);
    b[i] = v;   // restored bit for bit
    if (chi1 < chi0 - 1e-10 * chi0) released.emplace_back(b, i);
  }
  for (const auto& [b, i] : released) free_entry(problem, b, i);
  return released;
}

bool release_once(ceres::Problem& problem, const std::vector<double*>& blocks, std::vector<std::pair<double*, int>>& face,
                  std::vector<std::pair<double*, int>>& released) {
  std::vector<std::pair<double*, int>> candidates;
  for (const auto& e : face)
    if (std::find(released.begin(), released.end(), e) == released.end()) candidates.push_back(e);
  const std::vector<std::pair<double*, int>> now = release_from_bounds(problem, blocks, candidates);
  for (const auto& e : now) {
    face.erase(std::find(face.begin(), face.end(), e));
    released.push_back(e);
  }
  return !now.empty();
}

}  // namespace demfit
