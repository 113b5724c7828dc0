// Contact-force functors plugged into the single pair loop (forces.hpp).
// To add a contact law: write a functor with the same call signature and an energy(); the
// reference pair loop is already templated on it, the callers that construct
// LinearSpringDashpot select it (ARCHITECTURE.md, "Where a new thing goes").
#pragma once
#include "dem/core/model.hpp"

namespace dem {

/// Linear spring-dashpot normal force.
/// Input: overlap delta [m] (> 0 in contact), overlap rate ddelta [m/s] (> 0 approaching).
/// Output: normal force magnitude [N], positive = repulsive.
struct LinearSpringDashpot {
  double k;        ///< [N/m]
  double gamma;    ///< [kg/s]
  bool allow_attractive;
  explicit LinearSpringDashpot(const ContactLaw& law)
      : k(law.stiffness), gamma(law.damping), allow_attractive(law.allow_attractive) {}
  inline double operator()(double delta, double ddelta) const {
    const double f = k * delta + gamma * ddelta;
    return (allow_attractive || f > 0.0) ? f : 0.0;
  }
  /// Elastic energy stored in a contact of overlap delta [J].
  inline double energy(double delta) const { return 0.5 * k * delta * delta; }
};

}  // namespace dem
