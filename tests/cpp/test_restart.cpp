// A run split by a checkpoint equals the straight run bit for bit.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "dem/engine/engine.hpp"
#include "dem/io/io.hpp"
#include "test_support.hpp"

using dem::Vec3;

TEST(Restart, SplitRunEqualsStraightRunBitForBit) {
  for (int threads : {1, 2}) {
    const dem::Model m = dem_test::model_with({"integration.threads=" + std::to_string(threads)});
    const Vec3 rate = Vec3(1, 0, -1) * (2e-3 / m.t_contact);   // fast, so the list is rebuilt
    dem::State straight = dem_test::random_state(300, 0.38, 1.0, 21);
    dem::State split = straight;
    {
      dem::Engine e(m, straight);
      for (int k = 0; k < 3000; ++k) e.step(rate);
    }
    const std::string path = (std::filesystem::temp_directory_path() / "dem_split_test.ckpt").string();
    long builds_first = 0;
    {
      dem::Engine e(m, split);
      for (int k = 0; k < 1500; ++k) e.step(rate);
      builds_first = e.neighbor_list().builds;
      dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split});
    }
    dem::Checkpoint c = dem::read_checkpoint(path);
    std::remove(path.c_str());
    dem::Engine e2(m, c.state, /*forces_are_current=*/true);
    for (int k = 0; k < 1500; ++k) e2.step(rate);
    EXPECT_GT(builds_first + e2.neighbor_list().builds, 3);
    EXPECT_EQ(c.state.step, straight.step);
    EXPECT_TRUE(dem_test::same_bits(c.state.position, straight.position)) << "threads " << threads;
    EXPECT_TRUE(dem_test::same_bits(c.state.velocity, straight.velocity)) << "threads " << threads;
    EXPECT_EQ(0, std::memcmp(&c.state.box.length, &straight.box.length, sizeof(Vec3)));
  }
}

TEST(Restart, TruncatedOrForeignCheckpointIsRejected) {
  const std::string path = (std::filesystem::temp_directory_path() / "dem_trunc_test.ckpt").string();
  dem::State s = dem_test::random_state(50, 0.3, 0.0, 2);
  dem::write_checkpoint(path, dem::Checkpoint{"", "x", s});
  std::filesystem::resize_file(path, std::filesystem::file_size(path) / 2);
  EXPECT_THROW(dem::read_checkpoint(path), std::runtime_error);
  { std::ofstream(path) << "not a checkpoint at all"; }
  try {
    dem::read_checkpoint(path);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("not a dem checkpoint"), std::string::npos);
  }
  std::remove(path.c_str());
}

TEST(Restart, PackingRoundTripKeepsEveryDigit) {
  const std::string path = (std::filesystem::temp_directory_path() / "dem_pack_test.txt").string();
  dem::State s = dem_test::random_state(50, 0.3, 0.0, 2);
  dem::write_packing(path, s);
  dem::State r = dem::read_packing(path, 2000);
  std::remove(path.c_str());
  ASSERT_EQ(r.count(), s.count());
  for (int i = 0; i < s.count(); ++i) {
    EXPECT_EQ(r.radius[s.id[i]], s.radius[i]);
    EXPECT_EQ(r.position[s.id[i]].x, s.position[i].x);
  }
  EXPECT_EQ(r.box.length.x, s.box.length.x);
}
