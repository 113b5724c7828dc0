// The neighbour-list rebuild (pruned cell search, counting sort) against brute force: the
// same list, pair for pair, on any cell; the all-pairs oracle at every step across hundreds
// of rebuilds, frictionless and frictional (history carried); thread counts at the
// production time step; the rebuild statistics.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <tuple>
#include <vector>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/io/io.hpp"
#include "test_support.hpp"

using dem::Vec3;
using dem::VelGrad;

namespace {

// Every pair (i < j, image) with |x_j + image - x_i| < r_i + r_j + skin, by testing all 27
// images of every other particle: row by row, ascending (j, image).
std::vector<std::tuple<int, int, int>> brute_force_list(const dem::State& s, double skin) {
  Vec3 off[27];
  dem::image_offsets(s.box, off);
  std::vector<std::tuple<int, int, int>> pairs;
  for (int i = 0; i < s.count(); ++i)
    for (int j = i + 1; j < s.count(); ++j)
      for (int img = 0; img < 27; ++img) {
        const Vec3 d = s.position[j] + off[img] - s.position[i];
        const double reach = s.radius[i] + s.radius[j] + skin;
        if (dot(d, d) < reach * reach) pairs.emplace_back(i, j, img);
      }
  return pairs;
}

std::vector<std::tuple<int, int, int>> listed(const dem::NeighborList& list) {
  std::vector<std::tuple<int, int, int>> pairs;
  for (int i = 0; i + 1 < static_cast<int>(list.first.size()); ++i)
    for (int p = list.first[i]; p < list.first[i + 1]; ++p) pairs.emplace_back(i, list.partner[p], list.image[p]);
  return pairs;
}

// The contacts of the all-pairs minimum-image test (the oracle's geometry).
long contacts_all_pairs(const dem::State& s) {
  long c = 0;
  for (int i = 0; i < s.count(); ++i)
    for (int j = i + 1; j < s.count(); ++j) {
      const Vec3 d = dem::minimum_image(s.box, s.position[i], s.position[j]);
      c += dot(d, d) < (s.radius[i] + s.radius[j]) * (s.radius[i] + s.radius[j]);
    }
  return c;
}

long contacts_listed(const dem::State& s, const dem::NeighborList& list) {
  long c = 0;
  dem::for_each_contact(s, list, [&](int, int, const Vec3&, double, double) { ++c; });
  return c;
}

}  // namespace

TEST(Rebuild, ListEqualsTheBruteForceListOnStretchedTiltedAndSmallCells) {
  int cases = 0;
  for (unsigned seed : {1u, 2u, 3u}) {
    for (int shape = 0; shape < 4; ++shape) {
      // 0 cubic, 1 stretched (D2 by 20 %), 2 tilted (simple shear), 3 few particles (fewer than 3 cells an axis).
      const int n = shape == 3 ? 24 : 300;
      dem::State s = dem_test::random_state(n, 0.35, 1.0, seed, 0.5e-3, seed == 3 ? 2.0e-3 : 1.5e-3);
      if (shape == 1) { s.box.length.x *= 1.2; s.box.length.z /= 1.2; }
      if (shape == 2) s.box.tilt = Vec3{0.3 * s.box.length.x, -0.2 * s.box.length.x, 0.4 * s.box.length.y};
      for (double skin : {0.05e-3, 0.2e-3, 0.6e-3}) {
        // Unsorted: the general search; sorted: four candidates at a time, generic and AVX2 builds.
        for (int variant = 0; variant < 3; ++variant) {
          const bool sort = variant > 0;
          const bool was = dem::pair_search_avx2(variant == 2);
          dem::State t = s;
          dem::NeighborList list;
          bool refused = false;
          try {
            dem::rebuild_neighbor_list(t, list, skin, sort);
          } catch (const std::runtime_error&) {
            refused = true;   // the small box refuses the thickest skin (tested elsewhere)
          }
          dem::pair_search_avx2(was);
          if (refused) continue;
          const auto want = brute_force_list(t, skin);
          ASSERT_EQ(listed(list), want) << "seed " << seed << " shape " << shape << " skin " << skin << " variant " << variant;
          ASSERT_FALSE(want.empty());
          ++cases;
        }
      }
    }
  }
  EXPECT_GE(cases, 90);
}

// A run with a thin skin and fast particles (a rebuild every few steps): after every step the
// list holds every contact of the all-pairs test and gives the oracle's forces.
TEST(Rebuild, OracleAtEveryStepAcrossHundredsOfRebuilds) {
  for (const bool tilted : {false, true}) {
    dem::Model m = dem_test::model_with({"integration.threads=1", "integration.skin_over_rmin=0.1",
                                         "integration.dt_over_tc=0.2"});
    dem::State s = dem_test::random_state(200, 0.38, 4.0, tilted ? 21 : 22);
    const VelGrad rate = tilted ? VelGrad{Vec3{0, 0, 0}, Vec3{0, 5e-3 / m.t_contact, 0}}
                                : VelGrad{Vec3{1, 0, -1} * (2e-3 / m.t_contact), Vec3{0, 0, 0}};
    dem::Engine e(m, s);
    const int steps = tilted ? 1000 : 1200;
    for (int k = 1; k <= steps; ++k) {
      e.step(rate);
      ASSERT_EQ(contacts_listed(s, e.neighbor_list()), contacts_all_pairs(s)) << "step " << k;
      if (k % 10 != 0) continue;   // forces every 10th step (the contact sets above: every step)
      dem::State a = s, b = s;
      dem::ForceScratch scratch;
      dem::compute_forces(m, a, e.neighbor_list(), rate, 1, 1, scratch);
      dem::compute_forces_all_pairs(m, b, rate);
      const double scale = dem_test::max_force(b);
      ASSERT_GT(scale, 0);
      ASSERT_LT(dem_test::max_force_difference(a, b), 1e-12 * scale) << "step " << k;
    }
    std::printf("%s: %lld rebuilds in %d steps\n", tilted ? "simple shear" : "D2",
                static_cast<long long>(e.rebuild_stats().rebuilds), steps);
    EXPECT_GT(e.rebuild_stats().rebuilds, 200) << "the test must cross hundreds of rebuilds";
    EXPECT_EQ(e.rebuild_stats().steps, steps);
    if (tilted) EXPECT_GE(e.flips(), 1);
  }
}

// The same with friction: the springs carried across every rebuild by the particles' ids give
// the forces, torques and springs of the all-pairs oracle fed with the same springs.
TEST(Rebuild, FrictionalOracleAtEveryStepAcrossHundredsOfRebuilds) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "integration.threads=1",
                                             "integration.skin_over_rmin=0.1", "integration.dt_over_tc=0.2"});
  dem::State s = dem_test::random_state(160, 0.38, 4.0, 23);
  const VelGrad rate{Vec3{1, 0, -1} * (2e-3 / m.t_contact), Vec3{0, 0, 0}};
  dem::Engine e(m, s);
  std::size_t most_springs = 0;
  for (int k = 1; k <= 1000; ++k) {
    e.step(rate);
    dem::State a = s, b = s;
    dem::ForceScratch scratch;
    dem::compute_forces(m, a, e.neighbor_list(), rate, 1, 1, scratch);
    dem::PairHistoryMap oracle = dem::history_by_ids(s);
    dem::compute_forces_all_pairs(m, b, rate, &oracle);
    const double fscale = dem_test::max_force(b);
    ASSERT_GT(fscale, 0);
    ASSERT_LT(dem_test::max_force_difference(a, b), 1e-9 * fscale) << "step " << k;
    const dem::PairHistoryMap springs = dem::history_by_ids(a);
    ASSERT_EQ(springs.size(), oracle.size()) << "step " << k;
    most_springs = std::max(most_springs, springs.size());
    for (const auto& [key, h] : springs) {
      const auto it = oracle.find(key);
      ASSERT_NE(it, oracle.end()) << "step " << k;
      for (int c = 0; c < 3; ++c)
        ASSERT_LE(std::fabs(h[c] - it->second[c]), 1e-9 * (std::fabs(it->second[c]) + 1e-12)) << "step " << k;
    }
  }
  std::printf("%lld rebuilds, up to %zu springs\n", static_cast<long long>(e.rebuild_stats().rebuilds), most_springs);
  EXPECT_GT(most_springs, 20u);
  EXPECT_GT(e.rebuild_stats().rebuilds, 200) << "the test must cross hundreds of rebuilds";
}

// At the production time step (t_c/5) and with friction: 1, 2 and 4 threads, the same bits, at the
// thin skin of t_c/50 (rebuilt every few steps) and at the scenes' default "auto" skin (1 r_min here).
TEST(Rebuild, ThreadCountsGiveTheSameBitsAtTheProductionTimeStep) {
  for (const std::string skin : {"0.4", "auto"})
    for (const char* friction : {"0", "0.5"}) {
      const int steps = skin == "auto" ? 1500 : 400;
      auto run = [&](int threads) {
        dem::State s = dem_test::random_state(400, 0.38, 2.0, 5);
        const dem::Model m = dem_test::model_with({"integration.threads=" + std::to_string(threads),
                                                   "integration.dt_over_tc=0.2", std::string("contact.friction=") + friction,
                                                   "integration.adaptive_threads=false",
                                                   "integration.skin_over_rmin=" + (skin == "auto" ? "\"auto\"" : skin)});
        EXPECT_EQ(m.skin_auto, skin == "auto");
        const Vec3 rate = Vec3(1, 0, -1) * (1e-3 / m.t_contact);
        dem::Engine e(m, s);
        for (int k = 0; k < steps; ++k) e.step(rate);
        EXPECT_GT(e.rebuild_stats().rebuilds, 10) << "the test must cross list rebuilds (skin " << skin << ")";
        return s;
      };
      const dem::State one = run(1);
      for (int threads : {2, 4}) {
        const dem::State t = run(threads);
        ASSERT_EQ(t.id, one.id);
        const std::string what = std::to_string(threads) + " threads, friction " + friction + ", skin " + skin;
        EXPECT_TRUE(dem_test::same_bits(t.position, one.position)) << what;
        EXPECT_TRUE(dem_test::same_bits(t.velocity, one.velocity)) << what;
        EXPECT_TRUE(dem_test::same_bits(t.force, one.force)) << what;
      }
    }
}

// The statistics: every rebuild of a diagonal run is a displacement trigger; the diagnosed ones
// are split into rattlers and packing; a flip of a sheared cell is counted as a flip.
TEST(Rebuild, StatisticsCountTriggers) {
  dem::Model m = dem_test::model_with({"integration.threads=1", "integration.skin_over_rmin=0.1"});
  dem::State s = dem_test::random_state(300, 0.38, 3.0, 8);
  dem::Engine e(m, s);
  const long built = e.neighbor_list().builds;
  for (int k = 0; k < 3000; ++k) e.step(Vec3(1, 0, -1) * (1e-3 / m.t_contact));
  const dem::RebuildStats& st = e.rebuild_stats();
  EXPECT_EQ(st.rebuilds, e.neighbor_list().builds - built);
  EXPECT_EQ(st.rebuilds, st.displacement_triggers + st.by_deformation + st.by_flip);
  EXPECT_GT(st.displacement_triggers, 40);
  EXPECT_EQ(st.by_rattler + st.by_packing, static_cast<long>(st.nonrattler_ratio.size()));
  // Diagnosed: the first 32 displacement triggers, then the 40th, 48th, ...
  EXPECT_EQ(st.by_rattler + st.by_packing, 32 + st.displacement_triggers / 8 - 4);
  for (float r : st.nonrattler_ratio) EXPECT_TRUE(r >= 0 && r <= 1) << r;
  const dem::RebuildStats later = st;
  for (int k = 0; k < 10; ++k) e.step(Vec3(1, 0, -1) * (1e-3 / m.t_contact));
  const dem::RebuildStats d = e.rebuild_stats().since(later);
  EXPECT_EQ(d.steps, 10);
  EXPECT_NE(d.json(1.0, 1e-4).find("\"steps\": 10,"), std::string::npos) << d.json(1.0, 1e-4);
}

// Restart at t_c/5 with a thin skin, frictionless and frictional: a run split by a checkpoint
// written two steps before a rebuild equals the straight run bit for bit, across the rebuild and
// the ones after it (the checkpoint's build reference restores the same list; the springs travel
// by ids).
TEST(Rebuild, RestartFromACheckpointAcrossARebuildIsBitForBit) {
  for (const char* friction : {"0", "0.5"}) {
    const dem::Model m = dem_test::model_with({"integration.threads=1", "integration.skin_over_rmin=0.1",
                                               "integration.dt_over_tc=0.2", std::string("contact.friction=") + friction});
    const Vec3 rate = Vec3(1, 0, -1) * (1e-3 / m.t_contact);
    const dem::State start = dem_test::random_state(200, 0.38, 2.0, 31);
    // Where the straight run rebuilds: split two steps before the first rebuild after step 100.
    int split_at = -1;
    {
      dem::State s = start;
      dem::Engine e(m, s);
      for (int k = 1; k <= 400 && split_at < 0; ++k) {
        const long before = e.rebuild_stats().rebuilds;
        e.step(rate);
        if (k > 100 && e.rebuild_stats().rebuilds > before) split_at = k - 2;
      }
    }
    ASSERT_GT(split_at, 0);
    dem::State straight = start;
    long straight_rebuilds = 0;
    {
      dem::Engine e(m, straight);
      for (int k = 0; k < split_at + 200; ++k) e.step(rate);
      straight_rebuilds = e.rebuild_stats().rebuilds;
    }
    dem::State split = start;
    const std::string path = (std::filesystem::temp_directory_path() / "dem_rebuild_split.ckpt").string();
    {
      dem::Engine e(m, split);
      for (int k = 0; k < split_at; ++k) e.step(rate);
      dem::write_checkpoint(path, dem::Checkpoint{"", "two steps before a rebuild", split});
    }
    dem::Checkpoint c = dem::read_checkpoint(path);
    std::remove(path.c_str());
    dem::Engine e2(m, c.state, /*forces_are_current=*/true);
    for (int k = 0; k < 200; ++k) e2.step(rate);
    EXPECT_GT(e2.rebuild_stats().rebuilds, 5) << "the continuation must cross rebuilds";
    EXPECT_GT(straight_rebuilds, e2.rebuild_stats().rebuilds);
    ASSERT_EQ(c.state.id, straight.id) << "friction " << friction;
    EXPECT_TRUE(dem_test::same_bits(c.state.position, straight.position)) << "friction " << friction;
    EXPECT_TRUE(dem_test::same_bits(c.state.velocity, straight.velocity)) << "friction " << friction;
    EXPECT_TRUE(dem_test::same_bits(c.state.force, straight.force)) << "friction " << friction;
    EXPECT_EQ(c.state.history.values, straight.history.values) << "friction " << friction;
  }
}
