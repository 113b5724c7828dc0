#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "dem/core/model.hpp"
#include "dem/core/state.hpp"

namespace dem {

double sphere_mass(double radius, double density) {
  return 4.0 / 3.0 * M_PI * radius * radius * radius * density;
}

PairCollision pair_collision(double k, double gamma, double m_r) {
  const double w0sq = k / m_r;
  const double eta = gamma / (2.0 * m_r);
  if (eta * eta >= w0sq)
    throw std::invalid_argument("contact is overdamped for the smallest pair (gamma^2 >= 4 k m_r): "
                                "lower contact.damping_kg_s or raise contact.stiffness_N_m");
  const double tc = M_PI / std::sqrt(w0sq - eta * eta);
  return {tc, std::exp(-eta * tc)};
}

unsigned long long member_seed(unsigned long long seed, int k) {
  if (k == 0) return seed;
  // SplitMix64 (Steele, Lea, Flood 2014) of seed and member index.
  unsigned long long z = seed + 0x9E3779B97F4A7C15ULL * static_cast<unsigned long long>(k + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  return z >> 11;   // 53 bits
}

double auto_skin_over_rmin(double dt_over_tc) {
  if (!(dt_over_tc > 0.02)) return 0.4;
  return 0.4 * std::pow(dt_over_tc / 0.02, 0.4);
}

double ContactLaw::get(const std::string& key) const {
  const auto it = values_.find(key);
  if (it == values_.end())
    throw std::logic_error("contact." + key + " is not a key of the chosen contact sub-models (normal '" +
                           model(ContactSlot::Normal) + "', tangential '" + model(ContactSlot::Tangential) + "')");
  return it->second;
}

double ContactLaw::get_or(const std::string& key, double fallback) const {
  const auto it = values_.find(key);
  return it == values_.end() ? fallback : it->second;
}

void Model::finalize() {
  const double m = sphere_mass(radius_min, density);
  const PairCollision c = pair_collision(contact.time_step_stiffness(), contact.time_step_damping(), 0.5 * m);
  t_contact = c.t_contact;
  restitution = c.restitution;
  dt = dt_over_tc * t_contact;
}

Vec3 Box::true_strain() const {
  return {std::log(length.x / length0.x), std::log(length.y / length0.y),
          std::log(length.z / length0.z)};
}

void Box::deformation_gradient(double F[3][3]) const {
  // H_u = H M^-1, M = [[1, m01, m02], [0, 1, m12], [0, 0, 1]]:
  // M^-1 = [[1, -m01, m01 m12 - m02], [0, 1, -m12], [0, 0, 1]].
  const double m01 = flips[0], m02 = flips[1], m12 = flips[2];
  const double H[3][3] = {{length.x, tilt.x, tilt.y}, {0, length.y, tilt.z}, {0, 0, length.z}};
  const double Mi[3][3] = {{1, -m01, m01 * m12 - m02}, {0, 1, -m12}, {0, 0, 1}};
  double Hu[3][3] = {};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) Hu[i][j] += H[i][k] * Mi[k][j];
  // H0^-1 of the upper-triangular [[a, d, e], [0, b, f], [0, 0, c]].
  const double a = length0.x, b = length0.y, c = length0.z, d = tilt0.x, e = tilt0.y, f = tilt0.z;
  const double H0i[3][3] = {{1 / a, -d / (a * b), (d * f - b * e) / (a * b * c)}, {0, 1 / b, -f / (b * c)}, {0, 0, 1 / c}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      F[i][j] = 0;
      for (int k = 0; k < 3; ++k) F[i][j] += Hu[i][k] * H0i[k][j];
    }
}

double State::particle_volume() const {
  double v = 0;
  for (double r : radius) v += r * r * r;
  return 4.0 / 3.0 * M_PI * v;
}

double State::kinetic_energy() const {
  double e = 0;
  for (std::size_t i = 0; i < velocity.size(); ++i) e += 0.5 * mass[i] * dot(velocity[i], velocity[i]);
  return e;
}

double State::rotational_energy() const {
  double e = 0;
  for (std::size_t i = 0; i < angular_velocity.size(); ++i)
    e += 0.5 * (0.4 * mass[i] * radius[i] * radius[i]) * dot(angular_velocity[i], angular_velocity[i]);
  return e;
}

void State::resize(int n) {
  position.assign(n, Vec3{});
  velocity.assign(n, Vec3{});
  force.assign(n, Vec3{});
  radius.assign(n, 0.0);
  mass.assign(n, 0.0);
  id.resize(n);
  for (int i = 0; i < n; ++i) id[i] = i;
  position_at_build.clear();
  list_valid = false;
  angular_velocity.clear();
  torque.clear();
  history = ContactHistory{};
  friction_dissipated = 0;
}

std::string fmt_phi(double phi) {
  char b[32];
  std::snprintf(b, sizeof b, "phi%.3f", phi);
  return b;
}

}  // namespace dem
