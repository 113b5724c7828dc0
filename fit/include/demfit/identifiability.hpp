// Where does the saturating-law fit stop determining its parameters? Seeded synthetic curves
// with known parameters, a chosen length and noise, fitted as `dem fit` fits them.
#pragma once
#include <cstdint>
#include <vector>

#include "demfit/fit.hpp"

namespace demfit {

/// One cell of the identifiability map.
struct IdentifiabilitySetup {
  double x0 = 0.0, x_max = 0.17, beta = 60.0;   ///< true law (defaults: s_dev of D2 at nu = 0.70, N = 9261)
  double length = 6.0;        ///< curve length in units of the approach strain: beta * eps_last [-]
  double noise = 0.03;        ///< standard deviation of the noise / amplitude |x_max - x0| [-]
  double correlation = 0.0;   ///< lag-1 autocorrelation of the noise (AR(1)); DEM curves: 0.8-0.9
  double points_per_approach = 8.3;   ///< samples per approach strain 1/beta, uniform in eps_d on
                                      ///< (0, eps_last] (at least fit.min_points); 8.3 = the runner's
                                      ///< sample_strain 0.002 on a curve with beta = 60
  int trials = 100;           ///< curves per cell
  std::uint64_t seed = 1;     ///< reproducible: the same seed gives the same map
  FitOptions fit;             ///< as `dem fit` uses them (correct_autocorrelation on by default there)
};

struct IdentifiabilityCell {
  // Errors of the estimates against the truth, over the converged trials.
  double beta_rel_error_median = 0;    ///< median |beta_hat - beta| / beta
  double beta_rel_error_p90 = 0;       ///< 90th percentile of the same
  double xmax_rel_error_median = 0;    ///< median |x_max_hat - x_max| / amplitude
  double beta_coverage = 0;            ///< fraction of trials with |beta_hat - beta| <= 1.96 se_beta
  double xmax_coverage = 0;            ///< same for x_max
  double beta_reported_rel_se_median = 0;   ///< median se_beta / beta_hat (what a user sees)
  double flagged_fraction = 0;         ///< fraction of trials the fitter flagged x_max or beta as not
                                       ///< determined (poorly determined, on a bound, no covariance)
  double unsaturated_fraction = 0;     ///< fraction with the "stops before saturation" warning (the law
                                       ///< is extrapolated past the data: a model risk, even when precise)
  int converged = 0;                   ///< trials where the optimiser converged
};

/// Runs setup.trials fits and summarises them. Throws std::invalid_argument for a
/// non-positive length or sampling density, noise < 0 or correlation outside [0, 1).
IdentifiabilityCell identifiability_cell(const IdentifiabilitySetup& setup);

}  // namespace demfit
