#include "dem/io/work.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "dem/core/errors.hpp"
#include "dem/io/preparation.hpp"
#include "dem/measure/measure.hpp"

namespace dem {

namespace {

// Steps of one path stage: exact for eps_d and time stops without servo; otherwise an estimate
// (a strain stop taken from 0, a stress or phi stop as eps_d_max of shear).
double path_stage_steps(const Model& m, const PathStage& s) {
  const Vec3& r = s.shape.diag;
  const double unit = m.protocol.deviatoric_rate * m.dt;   // strain per step of a unit rate shape
  const Vec3& g = s.shape.shear;
  const double dev = s.sheared() ? deviatoric_magnitude_eig(Sym3{r.x, r.y, r.z, 0.5 * g.x, 0.5 * g.y, 0.5 * g.z})
                                 : deviatoric_magnitude(r.x, r.y, r.z);
  const double comp[3] = {r.x, r.y, r.z};
  switch (s.stop) {
    case PathStop::EpsD: return s.until / (std::max(dev, 1e-3) * unit);
    case PathStop::Time: return s.until / m.dt;
    case PathStop::EpsV: return std::fabs(s.until) / (std::max(std::fabs(r.x + r.y + r.z) / 3, 1e-3) * unit);
    case PathStop::EpsXX: case PathStop::EpsYY: case PathStop::EpsZZ: {
      const int a = s.stop == PathStop::EpsXX ? 0 : s.stop == PathStop::EpsYY ? 1 : 2;
      return std::fabs(s.until) / (std::max(std::fabs(comp[a]), 1e-3) * unit);
    }
    default: return m.protocol.eps_d_max / (std::max(dev, 1.0) * unit);
  }
}

}  // namespace

double mode_steps(const Model& m, const DeformationMode& mode) {
  if (!mode.path.empty()) {
    double steps = 0;
    for (const auto& s : mode.path) steps += path_stage_steps(m, s);
    return steps;
  }
  const Vec3& r = mode.shape.diag;
  const Vec3& g = mode.shape.shear;
  // A shear: the eps_d rate of D = sym(L) (the log strain's eps_d grows a little slower at large
  // shear: an estimate).
  const double dev = mode.sheared() ? deviatoric_magnitude_eig(Sym3{r.x, r.y, r.z, 0.5 * g.x, 0.5 * g.y, 0.5 * g.z})
                                    : deviatoric_magnitude(r.x, r.y, r.z);
  const double per_step = (dev > 0 ? dev : std::fabs(r.x + r.y + r.z) / 3) * m.protocol.deviatoric_rate * m.dt;
  return m.protocol.eps_d_max / per_step;
}

double mode_particle_steps(const Model& m, const DeformationMode& mode) { return m.count * mode_steps(m, mode); }

double prep_particle_steps(const Model& m) {
  return 3.0 * preparation_particle_steps(m);
}

std::vector<double> preparation_stage_steps(const Model& m) {
  std::vector<double> steps;
  double phi = m.protocol.initial_phi;
  for (const auto& s : m.protocol.preparation) {
    if (s.kind == PrepStage::Kind::Relax || s.kind == PrepStage::Kind::Pressure ||
        s.kind == PrepStage::Kind::Uniaxial) {   // at most; a stress stage ends where it finds its target at rest
      steps.push_back(s.max_time / m.dt);
      continue;
    }
    const bool runs = s.kind == PrepStage::Kind::Compress ? s.phi > phi : s.phi < phi;
    steps.push_back(runs ? std::fabs(std::log(s.phi / phi)) / (3 * s.rate * m.dt) : 0.0);
    phi = s.phi;
  }
  return steps;
}

void check_work(const Model& m, const std::string& origin) {
  auto refuse = [&](const std::string& what, double steps, const std::string& fix) {
    if (std::isfinite(steps) && steps <= kMaxSteps) return;
    const double ps = steps * m.count;
    char b[600];
    std::snprintf(b, sizeof b, "%s: %s would take about %.3g time steps (%.3g particle-steps at N = %d, about %.3g "
                  "years at 25 M particle-steps/s), beyond the bound of %.0e steps: %s", origin.c_str(), what.c_str(),
                  steps, ps, m.count, ps / 25e6 / 3.15e7, kMaxSteps, fix.c_str());
    throw SceneError(b);
  };
  const auto prep = preparation_stage_steps(m);
  for (std::size_t i = 0; i < prep.size(); ++i)
    refuse("preparation stage '" + m.protocol.preparation[i].name + "'", prep[i],
           "raise its rate_tc (typical 1e-5 to 1e-3) or shorten its max_time_tc");
  for (const auto& mode : m.protocol.modes)
    refuse(std::string(mode.path.empty() ? "mode '" : "path '") + mode.name + "'", mode_steps(m, mode),
           "raise protocol.deviatoric_rate_tc (typical 1e-6 to 1e-4), or the rate entries of the mode");
}

}  // namespace dem
