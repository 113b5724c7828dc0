#include "dem/stages/collision.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"

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

ObliqueResult simulate_oblique_collision(const Model& m, double r1, double r2, double v0, double theta, bool across,
                                         double shear_rate) {
  for (double v : {r1, r2, v0})
    if (!(v > 0) || !std::isfinite(v))
      throw std::invalid_argument("simulate_oblique_collision: radii and speed must be positive and finite");
  const double L = 20e-3, gap = 2e-7;   // [m]
  State s;
  s.resize(2);
  s.box.length = s.box.length0 = Vec3(L, L, L);
  // The line of centres is z (across: sphere 1 sits just above z = 0, sphere 0 just below L).
  const double z0 = across ? L - r1 - gap / 2 : 5e-3;
  const double z1 = across ? r2 + gap / 2 : z0 + r1 + r2 + gap;
  s.position[0] = Vec3(10e-3, 10e-3, z0);
  s.position[1] = Vec3(10e-3, 10e-3, z1);
  s.radius = {r1, r2};
  s.mass = {sphere_mass(r1, m.density), sphere_mass(r2, m.density)};
  const Vec3 n{0, 0, 1}, t{1, 0, 0};
  const Vec3 v_rel = n * (-v0 * std::cos(theta)) + t * (v0 * std::sin(theta));   // 1 relative to 0
  const VelGrad rate = across ? VelGrad{Vec3{0, 0, 0}, Vec3{0, shear_rate, 0}} : VelGrad{};
  // Full relative velocity = (v1' - v0') + L d, d = the branch vector to the image of 1.
  const Vec3 d{0, 0, r1 + r2 + gap};
  const Vec3 fluct = v_rel - rate.apply(d);
  const double M = s.mass[0] + s.mass[1];
  s.velocity[0] = fluct * (-s.mass[1] / M);
  s.velocity[1] = fluct * (s.mass[0] / M);
  Engine e(m, s);
  auto index_of = [&](int id) { return s.id[0] == id ? 0 : 1; };   // list rebuilds may reorder particles
  auto branch = [&]() { return minimum_image(s.box, s.position[index_of(0)], s.position[index_of(1)]); };
  auto separated = [&]() { return norm(branch()) > r1 + r2; };
  bool touched = false;
  for (long k = 0; k < 10000000; ++k) {
    e.step(rate);
    if (!separated()) touched = true;
    else if (touched) break;
  }
  if (!touched) throw std::runtime_error("simulate_oblique_collision: the spheres never touched");
  for (int k = 0; k < 10; ++k) e.step(rate);
  const int a = index_of(0), b = index_of(1);
  const Vec3 after = (s.velocity[b] - s.velocity[a]) + rate.apply(branch());
  ObliqueResult r{};
  r.normal_restitution = -dot(after, n) / dot(v_rel, n);
  r.tangential_restitution = dot(after, t) / dot(v_rel, t);
  r.omega[0] = s.angular_velocity.empty() ? Vec3{0, 0, 0} : s.angular_velocity[a];
  r.omega[1] = s.angular_velocity.empty() ? Vec3{0, 0, 0} : s.angular_velocity[b];
  const Vec3 J = (after - v_rel) * (s.mass[0] * s.mass[1] / M);   // on sphere 1: m_r times its relative change
  r.normal_impulse = dot(J, n);
  r.tangential_impulse = -dot(J, t);
  return r;
}

}  // namespace dem
