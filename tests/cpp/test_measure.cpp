// Stress, fabric and coordination of hand-built configurations against hand calculations.
#include <gtest/gtest.h>

#include <cmath>

#include "dem/engine/engine.hpp"
#include "dem/measure/measure.hpp"
#include "test_support.hpp"

using dem::Vec3;

namespace {
dem::Measurement measure_static(const dem::Model& m, dem::State& s) {
  dem::Engine e(m, s);
  return dem::measure(m, s, e.neighbor_list(), Vec3(0, 0, 0));
}
}  // namespace

TEST(Measure, TwoSpheresAcrossPeriodicBoundaryOfAStretchedBox) {
  // Pair along x straddling the x boundary of a non-cubic box; overlap delta.
  const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0"});
  const double r = 1e-3, delta = 1e-5, L[3] = {10e-3, 12e-3, 15e-3};
  const double l = 2 * r - delta;   // branch length
  dem::State s = dem_test::make_state(Vec3(L[0], L[1], L[2]),
                                      {Vec3(L[0] - l / 2, 6e-3, 7e-3), Vec3(l / 2, 6e-3, 7e-3)}, {r, r});
  const auto q = measure_static(m, s);
  const double V = L[0] * L[1] * L[2];
  const double f = 1e8 * delta;
  EXPECT_EQ(q.contacts, 1);
  EXPECT_NEAR(q.stress.xx, f * l / V, 1e-9 * f * l / V);
  EXPECT_NEAR(q.stress.yy, 0, 1e-12);
  EXPECT_NEAR(q.stress.xy, 0, 1e-12);
  EXPECT_NEAR(q.p, f * l / (3 * V), 1e-9 * f * l / V);
  EXPECT_NEAR(q.sigma_dev, f * l / V, 1e-9 * f * l / V);   // diag (a,0,0): sqrt((a^2+0+a^2)/2) = a
  const double vp = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_NEAR(q.fabric.xx, 2 * vp / V, 1e-12);
  EXPECT_NEAR(q.fabric.yy, 0, 1e-15);
  EXPECT_NEAR(q.E_pot, 0.5 * 1e8 * delta * delta, 1e-12);
  EXPECT_NEAR(q.overlap_max_rel, delta / r, 1e-9);
  EXPECT_DOUBLE_EQ(q.C, 1.0);
  EXPECT_DOUBLE_EQ(q.rattler_fraction, 1.0);   // both have 1 < 4 contacts
}

TEST(Measure, DiagonalContactGivesShearStressAndFabric) {
  const dem::Model m = dem_test::model_with();
  const double r = 1e-3, delta = 2e-5, L = 10e-3;
  const double l = 2 * r - delta;
  const Vec3 n = Vec3(1, 1, 0) * (1 / std::sqrt(2.0));
  const Vec3 c(5e-3, 5e-3, 5e-3);
  dem::State s = dem_test::make_state(Vec3(L, L, L), {c - n * (l / 2), c + n * (l / 2)}, {r, r});
  const auto q = measure_static(m, s);
  const double a = 1e8 * delta * l / (L * L * L);
  EXPECT_NEAR(q.stress.xx, a / 2, 1e-9 * a);
  EXPECT_NEAR(q.stress.yy, a / 2, 1e-9 * a);
  EXPECT_NEAR(q.stress.xy, a / 2, 1e-9 * a);
  EXPECT_NEAR(q.stress.zz, 0, 1e-12 * a);
}

TEST(Measure, SimpleCubicLatticeIsIsotropicWithSixContacts) {
  // n^3 equal spheres on a cubic lattice of spacing a = 2r - delta: 6 contacts each,
  // sigma_ii = N k delta a / V, F_ii = 2 N V_p / V, tr F = phi C, no deviator.
  const dem::Model m = dem_test::model_with();
  const int n = 5;
  const double r = 1e-3, delta = 1e-5, a = 2 * r - delta, L = n * a;
  std::vector<Vec3> x;
  std::vector<double> rad;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) { x.emplace_back((i + 0.5) * a, (j + 0.5) * a, (k + 0.5) * a); rad.push_back(r); }
  dem::State s = dem_test::make_state(Vec3(L, L, L), x, rad);
  const auto q = measure_static(m, s);
  const int N = n * n * n;
  const double V = L * L * L, vp = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_EQ(q.contacts, 3 * N);
  EXPECT_DOUBLE_EQ(q.C, 6.0);
  EXPECT_DOUBLE_EQ(q.C_nonrattler, 6.0);
  EXPECT_DOUBLE_EQ(q.rattler_fraction, 0.0);
  const double sig = N * 1e8 * delta * a / V;
  EXPECT_NEAR(q.stress.xx / sig, 1, 1e-9);
  EXPECT_NEAR(q.stress.zz / sig, 1, 1e-9);
  EXPECT_NEAR(q.s_dev, 0, 1e-9);
  EXPECT_NEAR(q.fabric.xx, 2 * N * vp / V, 1e-12);
  EXPECT_NEAR(q.fabric.trace(), q.nu * q.C, 1e-12);
  EXPECT_NEAR(q.F_dev, 0, 1e-12);
  EXPECT_NEAR(q.p_star, 2 * r * sig / 1e8, 1e-9 * sig);
}

TEST(Measure, LayeredLatticeHasFabricAnisotropyAndRattlerChains) {
  // Lattice stretched along z so z-neighbours do not touch: 4 contacts each (not rattlers),
  // F_zz = 0 and F_dev = F_xx.
  const dem::Model m = dem_test::model_with();
  const int n = 5;
  const double r = 1e-3, delta = 1e-5, a = 2 * r - delta, az = 2.5 * r;
  std::vector<Vec3> x;
  std::vector<double> rad;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) { x.emplace_back((i + 0.5) * a, (j + 0.5) * a, (k + 0.5) * az); rad.push_back(r); }
  dem::State s = dem_test::make_state(Vec3(n * a, n * a, n * az), x, rad);
  const auto q = measure_static(m, s);
  EXPECT_DOUBLE_EQ(q.C, 4.0);
  EXPECT_DOUBLE_EQ(q.rattler_fraction, 0.0);
  EXPECT_NEAR(q.fabric.zz, 0, 1e-15);
  EXPECT_NEAR(q.F_dev, q.fabric.xx, 1e-12);
  // sigma_dev of diag (b, b, 0) is b; s_dev = b / (2b/3) = 1.5
  EXPECT_NEAR(q.s_dev, 1.5, 1e-9);
}

TEST(Measure, RemovingContactsMakesRattlersRecursively) {
  const dem::Model m = dem_test::model_with();
  const double r = 1e-3, delta = 1e-5, a = 2 * r - delta;
  std::vector<Vec3> x;
  std::vector<double> rad;
  // A straight chain of 6 particles in x: each has <= 2 contacts: all rattlers.
  for (int i = 0; i < 6; ++i) { x.emplace_back(2e-3 + i * a, 10e-3, 10e-3); rad.push_back(r); }
  dem::State s = dem_test::make_state(Vec3(30e-3, 20e-3, 20e-3), x, rad);
  const auto q = measure_static(m, s);
  EXPECT_EQ(q.contacts, 5);
  EXPECT_DOUBLE_EQ(q.rattler_fraction, 1.0);
  EXPECT_DOUBLE_EQ(q.C_nonrattler, 0.0);
}

// The frictional rattler rule (seventeenth round of issue 31; docs/friction.md, "Isostaticity"): with friction two
// contacts can hold a particle, so C_nonrattler_2 removes only particles with fewer than 2 contacts, recursively. By
// hand: a triangle of three touching spheres with a tail of two attached to one corner. The tail's end has 1 contact,
// its neighbour then 1: both go; the triangle's corners keep 2 each, so C_nonrattler_2 = 2, while the frictionless
// rule (fewer than 4) removes every particle. A straight chain goes from its ends inwards, all of it. Without friction
// the column is not measured.
TEST(Measure, FrictionalRattlerRuleKeepsParticlesWithTwoContacts) {
  const std::vector<std::pair<int, int>> pairs = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {3, 4}};
  EXPECT_EQ(dem::rattler_flags(5, pairs, 2), (std::vector<char>{0, 0, 0, 1, 1}));
  EXPECT_EQ(dem::rattler_flags(5, pairs), (std::vector<char>{1, 1, 1, 1, 1}));
  EXPECT_EQ(dem::rattler_flags(4, {{0, 1}, {1, 2}, {2, 3}}, 2), (std::vector<char>{1, 1, 1, 1}));

  const double r = 1e-3, delta = 1e-5, a = 2 * r - delta, h = a * std::sqrt(3.0) / 2;
  const Vec3 o(10e-3, 10e-3, 10e-3);
  std::vector<Vec3> x = {o, o + Vec3(a, 0, 0), o + Vec3(a / 2, h, 0), o - Vec3(a, 0, 0), o - Vec3(2 * a, 0, 0)};
  std::vector<double> rad(x.size(), r);
  dem::State s = dem_test::make_state(Vec3(30e-3, 30e-3, 30e-3), x, rad);
  const auto q = measure_static(dem_test::model_with({"contact.friction=0.5"}), s);
  EXPECT_EQ(q.contacts, 5);
  EXPECT_TRUE(q.frictional);
  EXPECT_DOUBLE_EQ(q.C_nonrattler_2, 2.0);
  EXPECT_DOUBLE_EQ(q.C_nonrattler, 0.0);
  EXPECT_DOUBLE_EQ(q.rattler_fraction, 1.0);
  dem::State s0 = dem_test::make_state(Vec3(30e-3, 30e-3, 30e-3), x, rad);
  const auto q0 = measure_static(dem_test::model_with(), s0);
  EXPECT_FALSE(q0.frictional);
  EXPECT_DOUBLE_EQ(q0.C_nonrattler_2, 0.0);
}
