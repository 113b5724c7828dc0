// The cell/Verlet path against the all-pairs oracle.
#include <gtest/gtest.h>

#include <cstring>

#include <cmath>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/measure/measure.hpp"
#include "test_support.hpp"

using dem::Vec3;

namespace {
int contacts_all_pairs(const dem::State& s) {
  int c = 0;
  const Vec3 L = s.box.length;
  for (int i = 0; i < s.count(); ++i)
    for (int j = i + 1; j < s.count(); ++j) {
      Vec3 d = s.position[j] - s.position[i];
      for (int k = 0; k < 3; ++k) d[k] -= L[k] * std::round(d[k] / L[k]);
      c += norm(d) < s.radius[i] + s.radius[j];
    }
  return c;
}
}  // namespace

TEST(NeighborList, ForcesEqualAllPairsOracleOnShearedConfigurations) {
  for (unsigned seed : {1u, 2u, 3u}) {
    for (const char* mode : {"D2", "D3", "uniaxial_z"}) {
      dem::Model m = dem_test::model_with({"integration.threads=1"});
      dem::State s = dem_test::random_state(400, 0.38, 2.0, seed);
      dem::DeformationMode dm;
      ASSERT_TRUE(dem::builtin_mode(mode, &dm));
      const Vec3 rate = dm.shape.diag * (2e-3 / m.t_contact);   // fast: the box deforms by 10%
      dem::Engine e(m, s);
      for (int k = 0; k < 2500; ++k) e.step(rate);
      // Same positions and velocities for both paths (the engine's stored forces belong to
      // the half-step velocity).
      dem::ForceScratch scratch;
      dem::compute_forces(m, s, e.neighbor_list(), rate, 1, 1, scratch);
      dem::State oracle = s;
      dem::compute_forces_all_pairs(m, oracle, rate);
      const double scale = dem_test::max_force(oracle);
      ASSERT_GT(scale, 0);
      EXPECT_LT(dem_test::max_force_difference(s, oracle) / scale, 1e-12) << mode << " seed " << seed;
      EXPECT_GT(e.neighbor_list().builds, 2);
      EXPECT_GT(std::fabs(std::log(s.box.length.z / s.box.length0.z)), 0.05);
    }
  }
}

TEST(NeighborList, NeverMissesAContactUnderFastDeformation) {
  dem::Model m = dem_test::model_with({"integration.skin_over_rmin=0.1"});
  dem::State s = dem_test::random_state(300, 0.38, 5.0, 9);
  const Vec3 rate = Vec3(1, 0, -1) * (5e-3 / m.t_contact);
  dem::Engine e(m, s);
  for (int k = 0; k < 3000; ++k) {
    e.step(rate);
    if (k % 100 == 0) {
      const auto meas = dem::measure(m, s, e.neighbor_list(), rate);
      ASSERT_EQ(meas.contacts, contacts_all_pairs(s)) << "step " << k;
    }
  }
}

TEST(NeighborList, BlockSplitPairLoopEqualsAllPairsOracle) {
  // The threaded loop splits particles into blocks and queues forces on later blocks
  // ("spills"); every block count must give the oracle's forces.
  dem::Model m = dem_test::model_with({"integration.threads=1"});
  dem::State s = dem_test::random_state(600, 0.40, 2.0, 11);
  dem::DeformationMode dm;
  ASSERT_TRUE(dem::builtin_mode("D2", &dm));
  const Vec3 rate = dm.shape.diag * (1e-3 / m.t_contact);
  dem::Engine e(m, s);
  for (int k = 0; k < 500; ++k) e.step(rate);
  dem::State oracle = s;
  dem::compute_forces_all_pairs(m, oracle, rate);
  const double scale = dem_test::max_force(oracle);
  for (int blocks : {2, 3, 5, 12})
    for (int threads : {1, 2, 3}) {
      dem::State t = s;
      dem::ForceScratch scratch;
      dem::compute_forces(m, t, e.neighbor_list(), rate, threads, blocks, scratch);
      ASSERT_EQ(scratch.blocks(), blocks);
      std::size_t spilled = 0;
      for (int from = 0; from < blocks; ++from)
        for (int to = 0; to < blocks; ++to) {
          spilled += scratch.spill[from][to].size();
          if (to <= from) EXPECT_TRUE(scratch.spill[from][to].empty()) << "spills go to later blocks only";
          for (const auto& sp : scratch.spill[from][to])
            ASSERT_TRUE(sp.j >= scratch.bounds[to] && sp.j < scratch.bounds[to + 1]) << "bucket of the wrong block";
        }
      EXPECT_GT(spilled, 0u) << "the test must cross block boundaries";
      const double worst = dem_test::max_force_difference(t, oracle);
      EXPECT_LT(worst / scale, 1e-12) << blocks << " blocks, " << threads << " threads";
    }
}

TEST(NeighborList, FixedBlocksGiveTheSameBitsForEveryThreadCount) {
  // integration.blocks fixes the summation order: 1-4 threads (and more threads than a block
  // count divides evenly) must give identical positions, velocities and forces across rebuilds.
  // A dense start (compressed to phi ~ 0.66: ~6 contacts a particle, so the order of the
  // force terms matters to the last bit).
  dem::State start = dem_test::random_state(500, 0.40, 1.0, 4);
  {
    const dem::Model m = dem_test::model_with({"integration.threads=1"});
    dem::Engine e(m, start);
    for (int k = 0; k < 2800; ++k) e.step(Vec3(-1, -1, -1) * (3e-3 / m.t_contact));
    ASSERT_GT(start.volume_fraction(), 0.64);
  }
  auto run = [&](int threads) {
    dem::State s = start;
    dem::Model m = dem_test::model_with({"integration.threads=" + std::to_string(threads), "integration.blocks=6"});
    const Vec3 rate = Vec3(1, 0, -1) * (1e-3 / m.t_contact);
    dem::Engine e(m, s);
    for (int k = 0; k < 300; ++k) e.step(rate);
    EXPECT_GT(e.neighbor_list().builds, 2) << "the test must cross list rebuilds";
    return s;
  };
  const dem::State one = run(1);
  for (int threads : {2, 3, 4}) {
    const dem::State t = run(threads);
    ASSERT_EQ(t.id, one.id);
    EXPECT_EQ(0, std::memcmp(t.position.data(), one.position.data(), one.position.size() * sizeof(Vec3))) << threads;
    EXPECT_EQ(0, std::memcmp(t.velocity.data(), one.velocity.data(), one.velocity.size() * sizeof(Vec3))) << threads;
    EXPECT_EQ(0, std::memcmp(t.force.data(), one.force.data(), one.force.size() * sizeof(Vec3))) << threads;
  }
  // Another block count is another summation order: the test above would catch a thread
  // count that changed the blocks.
  dem::State d1 = start, d5 = start;
  dem::Model m1 = dem_test::model_with({"integration.threads=1"});
  dem::Model m5 = dem_test::model_with({"integration.threads=1", "integration.blocks=5"});
  dem::Engine e1(m1, d1), e5(m5, d5);
  const Vec3 rate = Vec3(1, 0, -1) * (1e-3 / m1.t_contact);
  for (int k = 0; k < 300; ++k) { e1.step(rate); e5.step(rate); }
  EXPECT_NE(0, std::memcmp(d1.velocity.data(), d5.velocity.data(), d1.velocity.size() * sizeof(Vec3)))
      << "one and five blocks summed in the same order: the test above proves nothing";
}

TEST(NeighborList, ThreadedStepsMatchOneThreadToRoundOff) {
  const dem::State start = dem_test::random_state(500, 0.38, 1.0, 4);
  dem::State s1 = start;
  dem::Model m1 = dem_test::model_with({"integration.threads=1"});
  const Vec3 rate = Vec3(1, 0, -1) * (1e-3 / m1.t_contact);
  dem::Engine e1(m1, s1);
  for (int k = 0; k < 200; ++k) e1.step(rate);
  ASSERT_GT(e1.neighbor_list().builds, 2) << "the test must cross list rebuilds";
  double scale = 0;
  for (auto& f : s1.force) scale = std::max(scale, norm(f));
  for (int threads : {2, 3, 4}) {
    dem::State s2 = start;
    dem::Model m2 = dem_test::model_with({"integration.threads=" + std::to_string(threads)});
    dem::Engine e2(m2, s2);
    for (int k = 0; k < 200; ++k) e2.step(rate);
    ASSERT_EQ(s2.id, s1.id);
    EXPECT_LT(dem_test::max_force_difference(s1, s2) / scale, 1e-9) << threads << " threads";
  }
}

TEST(NeighborList, TooSmallBoxIsRefusedWithAClearMessage) {
  dem::Model m = dem_test::model_with();
  dem::State s = dem_test::make_state(Vec3(4e-3, 4e-3, 4e-3), {Vec3(1e-3, 1e-3, 1e-3), Vec3(3e-3, 3e-3, 3e-3)},
                                      {1.5e-3, 1.5e-3});
  try {
    dem::Engine e(m, s);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& err) {
    EXPECT_NE(std::string(err.what()).find("shorter than twice the neighbour cutoff"), std::string::npos);
  }
}

// A box very many cutoffs wide: n_x n_y n_z cells overflowed the int cell index (UBSan in
// fuzz_demtk; without the sanitizer a wrapped, possibly negative count sized the cell arrays). The
// grid is capped at 2^24 cells; wider cells must still find every pair the oracle finds.
TEST(NeighborList, ABoxOfVeryManyCutoffsIsBinnedIntoBoundedCellsAndFindsEveryPair) {
  dem::Model m = dem_test::model_with({"integration.threads=1"});
  for (const Vec3 L : {Vec3(100, 100, 100), Vec3(1e4, 1e-2, 1e-2), Vec3(3e3, 3e3, 1e-2)}) {
    const double r = 1e-3;
    // Two touching pairs (one across the periodic boundary in x) and a loner.
    dem::State s = dem_test::make_state(
        L, {Vec3(0.5 * L.x, 4e-3, 4e-3), Vec3(0.5 * L.x + 1.9 * r, 4e-3, 4e-3), Vec3(0.2 * r, 5e-3, 6e-3),
            Vec3(L.x - 1.5 * r, 5e-3, 6e-3), Vec3(0.25 * L.x, 3e-3, 3e-3)},
        {r, r, r, r, r});
    dem::Engine e(m, s);
    EXPECT_EQ(contacts_all_pairs(s), 2);
    dem::ForceScratch scratch;
    dem::compute_forces(m, s, e.neighbor_list(), Vec3(0, 0, 0), 1, 1, scratch);
    dem::State oracle = s;
    dem::compute_forces_all_pairs(m, oracle, Vec3(0, 0, 0));
    const double scale = dem_test::max_force(oracle);
    ASSERT_GT(scale, 0) << L.x;
    // Not 1e-12 as above: at x = 5000 m a position carries 1e-12 m of rounding, 1e-8 of the
    // 1e-4 m overlap, and the two paths form the branch vector in another order. A missed or
    // doubled pair is an error of order 1.
    EXPECT_LT(dem_test::max_force_difference(s, oracle) / scale, 1e-6) << L.x;
    e.step(Vec3(0, 0, 0));
  }
}
