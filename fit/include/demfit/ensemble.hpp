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
