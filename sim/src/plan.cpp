#include "dem/plan.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <sstream>
#include <vector>

#include "dem/measure.hpp"
#include "dem/protocol.hpp"

namespace dem {

double mode_particle_steps(const Model& m, const DeformationMode& mode) {
  const Vec3& r = mode.rate_shape;
  const double dev = deviatoric_magnitude(r.x, r.y, r.z);
  const double per_step = (dev > 0 ? dev : std::fabs(r.x + r.y + r.z) / 3) * m.protocol.deviatoric_rate * m.dt;
  return m.count * m.protocol.eps_d_max / per_step;
}

double prep_particle_steps(const Model& m) {
  const Protocol& p = m.protocol;
  // ln(phi) moves by 3 rate dt per step under isotropic compression.
  const double compress = std::max(0.0, std::log(p.target_phi / p.initial_phi)) / (3 * p.compress_rate * m.dt);
  const double cycle = 2 * std::log(p.cycle_phi_max / p.target_phi) / (3 * p.cycle_rate * m.dt);
  return 3.0 * m.count * (compress + cycle);
}

std::string plan_json(const Model& m) {
  std::ostringstream o;
  o.precision(17);
  o << "{\n  \"packings\": " << m.ensemble_packings << ",\n  \"members\": [";
  for (int k = 0; k < m.ensemble_packings; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "m%03d", k);
    o << (k ? ", " : "") << "{\"name\": \"" << name << "\", \"seed\": " << member_seed(m.seed, k) << "}";
  }
  std::vector<double> phis = m.protocol.checkpoints_unloading;
  std::sort(phis.begin(), phis.end(), std::greater<double>());
  o << "],\n  \"checkpoints\": [";
  for (std::size_t i = 0; i < phis.size(); ++i)
    o << (i ? ", " : "") << "{\"phi\": " << phis[i] << ", \"stem\": \"unloading_" << fmt_phi(phis[i]) << "\"}";
  o << "],\n  \"modes\": [";
  for (std::size_t i = 0; i < m.protocol.modes.size(); ++i) o << (i ? ", " : "") << "\"" << m.protocol.modes[i].name << "\"";
  o << "],\n  \"prep_particle_steps\": " << prep_particle_steps(m) << ",\n  \"mode_particle_steps\": {";
  for (std::size_t i = 0; i < m.protocol.modes.size(); ++i)
    o << (i ? ", " : "") << "\"" << m.protocol.modes[i].name << "\": " << mode_particle_steps(m, m.protocol.modes[i]);
  o << "},\n  \"threads\": " << m.threads << "\n}\n";
  return o.str();
}

}  // namespace dem
