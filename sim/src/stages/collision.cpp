#include "dem/stages/collision.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dem/engine/engine.hpp"

namespace dem {

CollisionResult simulate_collision(const Model& m, double r1, double r2, double v0, bool across) {
  for (double v : {r1, r2, v0})
    if (!(v > 0) || !std::isfinite(v))
      throw std::invalid_argument("simulate_collision: radii and approach speed must be positive and finite");
  const double L = 20e-3, gap = 2e-7;   // [m]
  const double x1 = across ? L - r1 - gap / 2 : 5e-3;
  const double x2 = across ? r2 + gap / 2 : x1 + r1 + r2 + gap;
  State s;
  s.resize(2);
  s.box.length = s.box.length0 = Vec3(L, L, L);
  s.position[0] = Vec3(x1, 10e-3, 10e-3);
  s.position[1] = Vec3(x2, 10e-3, 10e-3);
  s.radius = {r1, r2};
  s.mass = {sphere_mass(r1, m.density), sphere_mass(r2, m.density)};
  s.velocity[0] = Vec3(0.5 * v0, 0, 0);
  s.velocity[1] = Vec3(-0.5 * v0, 0, 0);
  Engine e(m, s);
  auto overlap = [&]() {
    double d = s.position[1].x - s.position[0].x;
    d -= L * std::round(d / L);
    return s.radius[0] + s.radius[1] - std::fabs(d);
  };
  double t_in = -1, t_out = -1, prev = overlap(), prev_t = s.time;
  CollisionResult res{0, 0};
  for (long k = 0; k < 10000000 && t_out < 0; ++k) {
    e.step(Vec3(0, 0, 0));
    const double now = overlap();
    if (now > 0) ++res.steps_in_contact;
    res.max_overlap = std::max(res.max_overlap, now / std::min(r1, r2));
    if (prev <= 0 && now > 0) t_in = prev_t + (s.time - prev_t) * (-prev) / (now - prev);
    if (prev > 0 && now <= 0 && t_in >= 0) t_out = prev_t + (s.time - prev_t) * prev / (prev - now);
    prev = now;
    prev_t = s.time;
  }
  if (t_out < 0) throw std::runtime_error("simulate_collision: the contact did not end within 1e7 steps");
  for (int k = 0; k < 10; ++k) e.step(Vec3(0, 0, 0));   // free flight
  const int a = s.id[0] == 0 ? 0 : 1, b = 1 - a;          // list rebuilds may reorder particles
  res.contact_time = t_out - t_in;
  res.restitution = std::fabs(s.velocity[b].x - s.velocity[a].x) / v0;
  return res;
}

}  // namespace dem
