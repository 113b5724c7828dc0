#include "demfit/profile.hpp"

#include "demfit/jacobian_check.hpp"

#include <algorithm>
#include <cmath>

namespace demfit {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// How a block is held as the profile finds it: constant, or the entries a SubsetManifold holds. `ours` false for a
// block with another manifold (left alone).
struct BlockHold {
  bool constant = false, ours = true;
  std::vector<int> held;
};

std::vector<BlockHold> holds_of(const ceres::Problem& problem, const std::vector<double*>& blocks) {
  std::vector<BlockHold> out;
  for (double* b : blocks) {
    BlockHold h;
    h.constant = problem.IsParameterBlockConstant(b);
    const std::vector<int> free = free_entries(problem, b);
    h.ours = !(free.empty() && problem.GetManifold(b));
    std::vector<bool> is_free(problem.ParameterBlockSize(b), false);
    for (int i : free) is_free[i] = true;
    for (int i = 0; i < static_cast<int>(is_free.size()); ++i)
      if (!is_free[i]) h.held.push_back(i);
    out.push_back(h);
  }
  return out;
}

// Block b held as `h` says, and entry `extra` of it too (-1: none).
void apply_hold(ceres::Problem& problem, double* b, const BlockHold& h, int extra) {
  if (!h.ours) return;
  std::vector<int> held = h.held;
  if (extra >= 0 && std::find(held.begin(), held.end(), extra) == held.end()) held.push_back(extra);
  std::sort(held.begin(), held.end());
  const int n = problem.ParameterBlockSize(b);
  if (h.constant || static_cast<int>(held.size()) == n) {
    problem.SetParameterBlockConstant(b);
    return;
  }
  problem.SetParameterBlockVariable(b);
  problem.SetManifold(b, held.empty() ? nullptr : new ceres::SubsetManifold(n, held));
}

// One coefficient's profile: what stays fixed while its ends are sought.
struct Profile {
  ceres::Problem& problem;
  const std::vector<double*>& blocks;
  const std::vector<BlockHold>& holds;
  const std::vector<double>& start;
  const std::vector<bool>& movable;   // entries a refit moves (free where the profile began)
  const ProfileSolve& solve;
  std::vector<double> d;              // the linearised profile per quoted error (d[a]: the error)
  std::size_t a = 0;
  int block = 0, entry = 0;
  double chi0 = 0, scale = 1, tolerance = 0.05, reach = 16;
  int max_refits = 10;
  double below = kInf;                // the lowest chi2 a refit reached below chi0
};

// Passes of a refit on a bound's face: new bounds held, then those whose chi2 falls into the box released
// (hold_on_bounds, release_once; as the calibration's solve_on_face, twenty-fifth round), at most this many.
constexpr int kProfileFacePasses = 4;

// chi2_p with coefficient a at `value`: the other movable entries start from `from` moved by `shift` d (within their
// bounds), a is held, the problem refitted (and again on the face of any bound it ends on, in passes); `from` becomes the
// refitted values. +inf where a refit is unusable or its residuals not numbers.
double refit_at(Profile& p, double value, std::vector<double>& from, double shift) {
  std::size_t k = 0;
  for (double* b : p.blocks)
    for (int i = 0; i < p.problem.ParameterBlockSize(b); ++i, ++k) {
      double v = p.movable[k] ? from[k] + shift * p.d[k] : p.start[k];
      v = std::clamp(v, p.problem.GetParameterLowerBound(b, i), p.problem.GetParameterUpperBound(b, i));
      b[i] = k == p.a ? value : v;
    }
  apply_hold(p.problem, p.blocks[p.block], p.holds[p.block], p.entry);
  bool ok = p.solve(p.problem);
  std::vector<std::pair<double*, int>> face, released;   // the calibration's face fit, in a few passes
  for (int pass = 0; ok && pass < kProfileFacePasses; ++pass) {
    if (hold_on_bounds(p.problem, p.blocks, {}, 1e-9, &face) == 0 && !release_once(p.problem, p.blocks, face, released))
      break;
    ok = p.solve(p.problem);
  }
  const double chi = ok ? chi2_of(p.problem, p.blocks) : kInf;
  for (std::size_t b = 0; b < p.blocks.size(); ++b) apply_hold(p.problem, p.blocks[b], p.holds[b], -1);
  k = 0;
  for (double* b : p.blocks)
    for (int i = 0; i < p.problem.ParameterBlockSize(b); ++i, ++k) from[k] = b[i];
  return chi;
}

// The next trial (in quoted errors t) from the bracket [lo, hi] of sqrt(rise): the secant rule where both ends are
// known (bisection where it leaves the bracket), else the line through the origin (sqrt(rise) = t for a quadratic
// cost) stretched by 2 % and kept within [1.05, 4] times the last trial.
double next_trial(double lo_t, double lo_psi, double hi_t, double hi_psi) {
  if (!std::isnan(hi_t)) {
    const double t = lo_t + (1 - lo_psi) * (hi_t - lo_t) / (hi_psi - lo_psi);
    const double w = hi_t - lo_t;
    return (t > lo_t + 0.02 * w && t < hi_t - 0.02 * w) ? t : 0.5 * (lo_t + hi_t);
  }
  const double guess = lo_psi > 0 ? 1.02 * lo_t / lo_psi : 4 * lo_t;
  return std::clamp(guess, 1.05 * lo_t, 4 * lo_t);
}

// One end (sign -1: below the optimum, +1: above) of coefficient a's interval.
ProfileEnd profile_end(Profile& p, double sign) {
  ProfileEnd e;
  double* b = p.blocks[p.block];
  const double x = p.start[p.a], err = p.d[p.a];
  const double bound = sign < 0 ? p.problem.GetParameterLowerBound(b, p.entry) : p.problem.GetParameterUpperBound(b, p.entry);
  const double t_bound = std::isfinite(bound) ? (bound - x) / (sign * err) : kInf;
  std::vector<double> from = p.start;
  double t_from = 0, t = std::min(1.0, t_bound), lo_t = 0, lo_psi = 0, hi_t = NAN, hi_psi = NAN, best = kInf;
  while (e.refits < p.max_refits) {
    const bool at_bound = t >= t_bound;
    const double value = at_bound ? bound : x + sign * t * err;
    const double chi = refit_at(p, value, from, sign * (t - t_from));
    ++e.refits;
    t_from = t;
    if (!std::isfinite(chi)) { e.failed = true; e.value = e.rise = NAN; return e; }
    if (chi < p.chi0 - 1e-9 * std::max(1.0, std::fabs(p.chi0))) p.below = std::min(p.below, chi);
    const double g = (chi - p.chi0) / p.scale;
    if (std::fabs(g - 1) < best) { best = std::fabs(g - 1); e.value = value; e.rise = g; }
    if (std::fabs(g - 1) <= p.tolerance) return e;
    if (g < 1 && at_bound) { e.bound = true; e.value = bound; e.rise = g; return e; }
    const double psi = std::sqrt(std::max(g, 0.0));
    if (g < 1) { lo_t = t; lo_psi = psi; } else { hi_t = t; hi_psi = psi; }
    if (std::isnan(hi_t) && lo_t >= p.reach) { e.value = NAN; return e; }   // not reached within `reach` errors
    t = std::min({next_trial(lo_t, lo_psi, hi_t, hi_psi), p.reach, t_bound});
  }
  if (std::isnan(hi_t)) e.value = NAN;   // never past the rise: no end found
  return e;
}

}  // namespace

std::vector<ProfileInterval> profile_intervals(ceres::Problem& problem, const std::vector<double*>& blocks,
                                               const std::vector<double>& covariance,
                                               const std::vector<int>& coordinates, double scale,
                                               const ProfileSolve& solve, const std::vector<int>& held,
                                               double tolerance, int max_refits, double reach,
                                               const ProfileProgress& progress) {
  std::vector<double> start;
  std::vector<std::pair<int, int>> where;   // (block, entry) of each concatenated entry
  const std::vector<BlockHold> holds = holds_of(problem, blocks);
  std::vector<bool> movable;
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const int n = problem.ParameterBlockSize(blocks[b]);
    for (int i = 0; i < n; ++i) {
      start.push_back(blocks[b][i]);
      where.emplace_back(static_cast<int>(b), i);
      const auto& h = holds[b].held;
      movable.push_back(holds[b].ours && !holds[b].constant && std::find(h.begin(), h.end(), i) == h.end());
    }
  }
  const std::size_t n = start.size();
  const double chi0 = chi2_of(problem, blocks);
  if (!std::isfinite(chi0) || covariance.size() != n * n) return {};
  const std::vector<double> cond = conditional_covariance(covariance, held);
  std::vector<ProfileInterval> out;
  for (int a : coordinates) {
    ProfileInterval pi;
    const double saa = cond[static_cast<std::size_t>(a) * n + a];
    if (saa > 0 && movable[a]) {
      Profile p{problem, blocks, holds, start, movable, solve, std::vector<double>(n)};
      for (std::size_t k = 0; k < n; ++k) p.d[k] = movable[k] ? std::sqrt(scale / saa) * cond[k * n + a] : 0.0;
      p.a = static_cast<std::size_t>(a);
      p.block = where[a].first;
      p.entry = where[a].second;
      p.chi0 = chi0;
      p.scale = scale;
      p.tolerance = tolerance;
      p.reach = reach;
      p.max_refits = max_refits;
      std::vector<double> from = start;   // the others refitted with a where it is: the fit's own minimum?
      const double centre = refit_at(p, start[a], from, 0.0);
      if (centre < chi0 - 1e-9 * std::max(1.0, std::fabs(chi0))) p.below = centre;
      pi.lower = profile_end(p, -1);
      pi.upper = profile_end(p, +1);
      if (p.below < kInf) pi.below_optimum = p.below;
      for (std::size_t k = 0; k < n; ++k) blocks[where[k].first][where[k].second] = start[k];   // bit for bit
    }
    out.push_back(pi);
    if (progress) progress(static_cast<int>(out.size()) - 1, static_cast<int>(coordinates.size()), pi);
  }
  return out;
}

}  // namespace demfit
