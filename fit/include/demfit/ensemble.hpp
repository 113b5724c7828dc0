// Ensembles of independent packings: member curves on a common strain grid, pointwise
// statistics (mean, standard error, 95 % band), fits of the saturating law to the ensemble
// mean with uncertainties from the spread between packings, and the D2/D3 shared-path test on
// paired members.
//
// Why between-packing errors: one packing's curve stands for the material only to the spread
// between packings (docs/accuracy_cost.md), and the residuals of one curve are strongly
// correlated (lag-1 0.7-0.95), so errors taken from them under-cover (0.6-0.75 for a nominal
// 0.95, docs/fit_identifiability.md). Members are independent by construction, so the jackknife
// over members with Student's t on K - 1 degrees of freedom gives intervals whose coverage is
// measured in docs/ensembles.md (bench/ensemble_coverage.py, `dem ensemble-coverage`).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <string>
#include <vector>

#include "demfit/fit.hpp"

namespace demfit {

/// y(x) linearly interpolated at each grid point; x strictly increasing, grid inside [x.front(), x.back()].
/// Throws std::invalid_argument otherwise.
std::vector<double> resample(const std::vector<double>& x, const std::vector<double>& y,
                             const std::vector<double>& grid);

/// Pointwise statistics over K members (members[k][i]: member k at grid point i).
/// sd: sample standard deviation (K - 1 in the denominator); se = sd / sqrt(K);
/// lo/hi: confidence band of the mean, mean -/+ t_{K-1, (1+level)/2} se (NaN for K = 1).
struct Band {
  std::vector<double> mean, sd, se, lo, hi;
  int n = 0;   ///< members
};
Band band(const std::vector<std::vector<double>>& members, double level = 0.95);

/// Student's t quantile t_{dof, q} (two-sided level L: q = (1 + L)/2).
double t_quantile(double q, double dof);

struct EnsembleFitOptions {
  FitOptions fit;                 ///< window, bounds, loss of every fit (residual diagnostics are replaced)
  int bootstrap = 200;            ///< resamples of the members for the bootstrap cross-check (0: none)
  unsigned long long seed = 1;    ///< bootstrap seed (the same seed gives the same numbers)
  double level = 0.95;            ///< confidence level of the intervals
  bool member_fits = true;        ///< also fit each member alone (spread reported, not used for errors)
};

/// The saturating law fitted to the ensemble mean; its errors come from the packings.
struct EnsembleFit {
  FitResult fit;                  ///< fit to the mean curve; its se_* and warnings are the ensemble's
  int packings = 0;               ///< K
  std::string error_method;       ///< "jackknife over packings" (K >= 2) or "AR(1) residuals of one curve"
  std::array<double, 3> lo{}, hi{};        ///< interval (x0, x_max, beta): estimate -/+ t_{K-1} se
  std::array<double, 3> boot_se{}, boot_lo{}, boot_hi{};   ///< bootstrap over packings (percentile interval)
  std::array<double, 3> member_mean{}, member_sd{};        ///< fits of single members: mean and spread
  int member_fits_ok = 0;
  std::vector<std::array<double, 3>> leave_one_out;       ///< jackknife estimates (member k left out)
};

/// Fits the mean of `members` (on `grid`) and estimates errors from the packings.
/// K = 1 falls back to the single-curve errors (AR(1) inflation) with a warning that says so.
EnsembleFit fit_ensemble(const std::vector<double>& grid, const std::vector<std::vector<double>>& members,
                         const EnsembleFitOptions& options = {});

/// D2 vs D3 from the same checkpoints: members k of both modes start from the same packing, so
/// the test uses paired jackknife differences of (x0, x_max, beta), each against t_{K-1};
/// p_value is the Bonferroni-adjusted minimum of the three (holds the nominal false-rejection
/// rate; docs/ensembles.md measures it). Needs K >= 2 in both, the same members in the same order.
struct EnsembleSharedPath {
  int packings = 0;
  std::array<double, 3> difference{}, se{}, p{};   ///< second - first, its jackknife SE, two-sided p
  double p_value = 1;             ///< min(1, 3 min p)
  double max_gap = 0;             ///< max |x_second(e) - x_first(e)| of the fitted laws on the common window
  bool same_path = true;          ///< p_value >= alpha
};
EnsembleSharedPath test_shared_path_ensemble(const EnsembleFit& first, const EnsembleFit& second, double alpha = 0.01);

}  // namespace demfit

namespace demfit {

/// Coverage experiment: synthetic ensembles of K DEM-like curves with known parameters.
/// Member k of mode A is x(e; x0, x_max + d_k, beta) + AR(1) noise, d_k ~ N(0, member_spread)
/// (packings differ in their plateau); mode B (the "D3" of the same packings) shares d_k and
/// half of each member's noise (correlation 0.5), so the true paths are identical.
struct EnsembleCoverageSetup {
  int packings = 8;                       ///< K
  double x0 = 0.0, x_max = 0.17, beta = 60.0;   ///< truth (s_dev of D2 at nu = 0.70)
  double length = 5.0;                    ///< beta * eps_last
  double points_per_approach = 8.3;       ///< samples per 1/beta (sample_strain 0.002 at beta = 60)
  double noise = 0.1;                     ///< AR(1) marginal sd / amplitude |x_max - x0|
  double correlation = 0.85;              ///< lag-1 autocorrelation of the noise
  double member_spread = 0.05;            ///< sd of the members' plateaus / amplitude
  int trials = 200;
  int bootstrap = 0;                      ///< bootstrap resamples per trial (0: skip its coverage)
  std::uint64_t seed = 1;
};

struct EnsembleCoverageCell {
  double xmax_coverage = 0, beta_coverage = 0;           ///< jackknife-t 95 % intervals (what dem fit states)
  double boot_xmax_coverage = 0, boot_beta_coverage = 0;  ///< bootstrap percentile intervals (NaN if skipped)
  double ar1_xmax_coverage = 0, ar1_beta_coverage = 0;   ///< one member alone, AR(1)-inflated 1.96 SE (single-curve path)
  double false_rejection_01 = 0, false_rejection_05 = 0; ///< shared-path test rejecting the true shared law at 1 %, 5 %
  double xmax_halfwidth_median = 0;                      ///< median 95 % half-width of x_max / amplitude
  double beta_halfwidth_median = 0;                      ///< median 95 % half-width of beta / beta
  int converged = 0;                                     ///< trials whose mean fit converged
};

/// Runs setup.trials synthetic ensembles (failed fits count as not covering).
EnsembleCoverageCell ensemble_coverage(const EnsembleCoverageSetup& setup);

/// `dem ensemble-coverage`: the cells of every (correlation, length, K) as a CSV text with a
/// comment header saying what was done; progress on stderr.
std::string ensemble_coverage_csv(const EnsembleCoverageSetup& base, const std::vector<int>& packings,
                                  const std::vector<double>& lengths, const std::vector<double>& correlations);

}  // namespace demfit
