#include "test_support.hpp"

#include <algorithm>
#include <cstring>
#include <cmath>

#include "dem/io/io.hpp"

namespace dem_test {

dem::Model model_with(const std::vector<std::string>& overrides) {
  // One thread unless a test asks for more: ctest may run tests side by side, and OpenMP
  // threads spinning at barriers on an oversubscribed machine slow everything down.
  std::vector<std::string> all = {"integration.threads=1"};
  all.insert(all.end(), overrides.begin(), overrides.end());
  return dem::load_scene("", all, nullptr, "test");
}

dem::State make_state(const dem::Vec3& box, const std::vector<dem::Vec3>& x, const std::vector<double>& r,
                      double density) {
  dem::State s;
  s.resize(static_cast<int>(x.size()));
  s.box.length = s.box.length0 = box;
  for (std::size_t i = 0; i < x.size(); ++i) {
    s.position[i] = x[i];
    s.radius[i] = r[i];
    s.mass[i] = dem::sphere_mass(r[i], density);
  }
  return s;
}

dem::State random_state(int n, double phi, double v, unsigned seed, double rmin, double rmax) {
  // Non-overlapping placement at phi / 1.06, then radii inflated by 1.06^(1/3): the closest
  // pairs overlap by up to ~2% of their radii sum, giving elastic energy and real contacts.
  dem::Model m = model_with({"particles.count=" + std::to_string(n), "particles.seed=" + std::to_string(seed),
                             "particles.radius_min_m=" + std::to_string(rmin),
                             "particles.radius_max_m=" + std::to_string(rmax)});
  const double inflate = 1.06;
  dem::State s = dem::random_packing(m, phi / inflate);
  const double f = std::cbrt(inflate);
  for (int i = 0; i < n; ++i) { s.radius[i] *= f; s.mass[i] = dem::sphere_mass(s.radius[i], 2000.0); }
  std::mt19937_64 rng(seed + 1000);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (auto& vi : s.velocity) vi = dem::Vec3(v * (u(rng) - 0.5), v * (u(rng) - 0.5), v * (u(rng) - 0.5));
  return s;
}

double max_force(const dem::State& s) {
  double f = 0;
  for (auto& v : s.force) f = std::max(f, norm(v));
  return f;
}

double max_force_difference(const dem::State& a, const dem::State& b) {
  double worst = 0;
  for (int i = 0; i < a.count(); ++i) worst = std::max(worst, norm(a.force[i] - b.force[i]));
  return worst;
}

bool same_bits(const std::vector<dem::Vec3>& a, const std::vector<dem::Vec3>& b) {
  // An empty vector's data() may be null, which memcmp must not get even for 0 bytes (UBSan).
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(dem::Vec3)) == 0);
}

}  // namespace dem_test
