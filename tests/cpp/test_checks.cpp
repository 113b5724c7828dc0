// Issue 10: inputs that used to crash or give silently wrong results are refused, naming the
// problem. Checkpoint corruption, packing and scene validation, fit conditioning.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/io/preparation.hpp"
#include "dem/io/scene.hpp"
#include "demfit/fit.hpp"
#include "test_support.hpp"

namespace {

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

std::string scene_error(const std::string& text) {
  return error_of([&] { dem::load_scene(text, {}, nullptr, "t.toml"); });
}

// FNV-1a 64, written out here from its definition (the checkpoint's documented checksum).
std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 14695981039346656037ULL;
  for (unsigned char c : s) { h ^= c; h *= 1099511628211ULL; }
  return h;
}

std::string checkpoint_bytes(const dem::State& s) {
  const std::string path = (std::filesystem::temp_directory_path() / "dem_checks.ckpt").string();
  dem::write_checkpoint(path, dem::Checkpoint{"", "x", s});
  std::ifstream in(path, std::ios::binary);
  std::string b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::remove(path.c_str());
  return b;
}

// Offsets in a version-3 checkpoint with empty scene text and label "x" (io.cpp's layout):
// magic 8, two strings (8 + size), then the arrays, each 8 bytes of length then the data.
std::size_t radius_offset(int n) { return 8 + 8 + (8 + 1) + 3 * (8 + 24 * n) + 8; }
std::size_t mass_offset(int n) { return radius_offset(n) + 8 * n + 8; }
std::size_t id_offset(int n) { return mass_offset(n) + 8 * n + 8; }

// Replaces bytes and recomputes the checksum: a well-formed file with a bad value.
std::string with_value(std::string b, std::size_t at, const void* v, std::size_t size) {
  std::memcpy(&b[at], v, size);
  const std::uint64_t h = fnv1a(b.substr(0, b.size() - 8));
  std::memcpy(&b[b.size() - 8], &h, 8);
  return b;
}

std::string parse_error(const std::string& bytes) {
  return error_of([&] { dem::parse_checkpoint(bytes, "c.ckpt"); });
}

}  // namespace

TEST(Checkpoint, LayoutAsDocumentedAndFlippedBitsAreCaught) {
  const dem::State s = dem_test::random_state(40, 0.3, 0.1, 3);
  const std::string b = checkpoint_bytes(s);
  ASSERT_EQ(b.substr(0, 8), "DEMCKPT3");
  double r0;
  std::memcpy(&r0, &b[radius_offset(40)], 8);
  ASSERT_EQ(r0, s.radius[0]);   // the offsets below address what they claim
  EXPECT_EQ(parse_error(b), "");
  std::string flipped = b;
  flipped[radius_offset(40) - 100] ^= 0x10;   // a bit of a velocity
  EXPECT_TRUE(has(parse_error(flipped), "checksum")) << parse_error(flipped);
  std::string old = b;
  old[7] = '1';
  EXPECT_TRUE(has(parse_error(old), "rerun the preparation")) << parse_error(old);
}

TEST(Checkpoint, InvalidValuesBehindAValidChecksumAreRefused) {
  const dem::State s = dem_test::random_state(40, 0.3, 0.1, 3);
  const std::string b = checkpoint_bytes(s);
  const double nan = std::nan(""), neg = -1e-3, zero = 0;
  const std::int32_t big = 1000000, dup = s.id[1];
  EXPECT_TRUE(has(parse_error(with_value(b, radius_offset(40) + 8 * 5, &nan, 8)), "radius")) << "NaN radius";
  EXPECT_TRUE(has(parse_error(with_value(b, radius_offset(40), &neg, 8)), "radius")) << "negative radius";
  EXPECT_TRUE(has(parse_error(with_value(b, mass_offset(40) + 8 * 7, &zero, 8)), "mass")) << "zero mass";
  EXPECT_TRUE(has(parse_error(with_value(b, id_offset(40), &big, 4)), "outside [0, 40)"));
  EXPECT_TRUE(has(parse_error(with_value(b, id_offset(40), &dup, 4)), "appears twice"));
  EXPECT_TRUE(has(parse_error(with_value(b, 8 + 8 + 9 + 8 + 24 * 3, &nan, 8)), "non-finite position"));
}

TEST(Checkpoint, ExportRefusesIdsThatAreNotAPermutation) {
  // Used to write out of bounds (heap-buffer-overflow in write_packing) or export a sphere twice.
  dem::State s = dem_test::random_state(30, 0.3, 0.0, 4);
  const std::string path = (std::filesystem::temp_directory_path() / "dem_checks_ids.txt").string();
  s.id[3] = 1000;
  EXPECT_TRUE(has(error_of([&] { dem::write_packing(path, s); }), "outside [0, 30)"));
  s.id[3] = s.id[4];
  EXPECT_TRUE(has(error_of([&] { dem::write_packing(path, s); }), "appears twice"));
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(Packing, TrailingCharactersAreRefused) {
  std::istringstream in("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003 0.00063abc\n0.005 0.005 0.005 0.001\n");
  EXPECT_TRUE(has(error_of([&] { dem::parse_packing(in, 2000, "p.txt"); }), "p.txt:2:"));
}

TEST(Packing, OtherSizesOverlapsAndCoincidentSpheresAreRefusedBeforeRunning) {
  const dem::Model m = dem_test::model_with();   // radii in [0.5, 1.5] mm
  auto check = [&](const dem::State& s) { return error_of([&] { dem::check_packing(m, s, "p.txt"); }); };
  const dem::Vec3 box{0.01, 0.01, 0.01};
  EXPECT_EQ(check(dem_test::make_state(box, {{0.002, 0.005, 0.005}, {0.006, 0.005, 0.005}}, {1e-3, 1e-3})), "");
  const auto small = check(dem_test::make_state(box, {{0.002, 0.005, 0.005}, {0.006, 0.005, 0.005}}, {1e-4, 1e-4}));
  EXPECT_TRUE(has(small, "particles.radius_min_m")) << small;
  const auto large = check(dem_test::make_state(box, {{0.002, 0.005, 0.005}, {0.006, 0.005, 0.005}}, {1e-3, 1e-2}));
  EXPECT_TRUE(has(large, "particles.radius_max_m")) << large;
  // centres 0.47 r apart: overlap 1.53 r
  const auto overlap = check(dem_test::make_state(box, {{0.002, 0.005, 0.005}, {0.00247, 0.005, 0.005}}, {1e-3, 1e-3}));
  EXPECT_TRUE(has(overlap, "spheres 0 and 1 overlap by 1.53")) << overlap;
  const auto same = check(dem_test::make_state(box, {{0.002, 0.005, 0.005}, {0.002, 0.005, 0.005}}, {1e-3, 1e-3}));
  EXPECT_TRUE(has(same, "same centre")) << same;
}

TEST(Scene, NonFiniteOutOfRangeAndDuplicateValuesAreRefused) {
  EXPECT_TRUE(has(scene_error("[particles]\ncount = 4294967596\n"), "out of range")) << "wrapped to 300 before";
  EXPECT_TRUE(has(scene_error("[contact]\nstiffness_N_m = inf\n"), "stiffness_N_m must be positive and finite"));
  EXPECT_TRUE(has(scene_error("[particles]\nradius_max_m = inf\n"), "radius_max_m"));
  EXPECT_TRUE(has(scene_error("[particles]\nradius_min_m = inf\nradius_max_m = inf\n"), "radius_min_m"));
  EXPECT_TRUE(has(scene_error("[protocol]\ncheckpoints_unloading = [nan]\n"), "checkpoints_unloading value nan"));
  EXPECT_TRUE(has(scene_error("[protocol]\ncheckpoints_unloading = [0.7, 0.7]\n"), "twice"));
  EXPECT_TRUE(has(scene_error("[protocol]\ncheckpoints_unloading = [0.7001, 0.6999]\n"), "phi0.700"));
  EXPECT_TRUE(has(scene_error("[protocol]\nmodes = [\"D2\", \"D2\"]\n"), "'D2' twice"));
  EXPECT_TRUE(has(scene_error("[output]\nsample_strain = inf\n"), "sample_strain"));
  EXPECT_TRUE(has(scene_error("[output]\nprogress_seconds = -1\n"), "progress_seconds"));
  for (const char* v : {"inf", "nan", "0", "-1"})   // named as itself, not through servo.rate_max_tc's default
    EXPECT_TRUE(has(scene_error(std::string("[protocol]\ndeviatoric_rate_tc = ") + v + "\n"),
                    "protocol.deviatoric_rate_tc must be a positive number")) << v;
}

TEST(Scene, SpelledOutPreparationHasTheBuiltInRecordAndAStageChangeChangesIt) {
  const std::string builtin = "[protocol]\ncheckpoints_loading = [0.7]\n";
  const std::string spelled =
      "[protocol]\npreparation = [\n"
      "{ name = \"compress\", kind = \"compress\", rate_tc = 1e-4, until = { phi = 0.64 } },\n"
      "{ name = \"relax\", kind = \"relax\", until = { ke_ratio = 1e-8 }, max_time_tc = 2e5 },\n"
      "{ name = \"cycle_loading\", kind = \"compress\", rate_tc = 2e-5, until = { phi = 0.82 }, "
      "checkpoint_name = \"loading\", checkpoints = [0.7] },\n"
      "{ name = \"cycle_unloading\", kind = \"expand\", rate_tc = 2e-5, until = { phi = 0.64 }, "
      "checkpoint_name = \"unloading\", checkpoints = [0.80, 0.75, 0.70, 0.68] } ]\n";
  const dem::Model a = dem::load_scene(builtin), b = dem::load_scene(spelled);
  EXPECT_EQ(dem::physics_line(dem::preparation_physics(a)), dem::physics_line(dem::preparation_physics(b)));
  EXPECT_EQ(dem::mode_checkpoints(a.protocol), dem::mode_checkpoints(b.protocol));
  std::string slower = spelled;
  slower.replace(slower.find("rate_tc = 2e-5"), 14, "rate_tc = 1e-5");
  const std::string d = dem::physics_diff(dem::preparation_physics(dem::load_scene(slower)),
                                          dem::preparation_physics(b), "a", "b");
  EXPECT_TRUE(has(d, "protocol.preparation") && has(d, "cycle_loading:compress:rate_tc=1.0000000000000001e-05")) << d;
  // Without any keys of its own, a file of section headers would run the built-in paper scene.
  const std::string path = (std::filesystem::temp_directory_path() / "dem_headers_only.toml").string();
  { std::ofstream(path) << "[particles]\n[protocol]\n"; }
  const auto e = error_of([&] { dem::load_scene_file(path); });
  std::remove(path.c_str());
  EXPECT_TRUE(has(e, "empty")) << e;
}

TEST(Scene, EmptyFileAndHugeCountAreRefusedBeforeRunning) {
  const std::string path = (std::filesystem::temp_directory_path() / "dem_empty_scene.toml").string();
  { std::ofstream(path) << "# only a comment\n"; }
  const auto e = error_of([&] { dem::load_scene_file(path); });
  std::remove(path.c_str());
  EXPECT_TRUE(has(e, "empty") && has(e, "data/scenes/")) << e;
  const dem::Model huge = dem::load_scene("[particles]\ncount = 2000000000\n");
  const auto m = error_of([&] { dem::check_memory(huge); });
  EXPECT_TRUE(has(m, "GB") && has(m, "particles.count")) << m;
  EXPECT_EQ(error_of([&] { dem::check_memory(dem::load_scene("[particles]\ncount = 1000\n")); }), "");
}

TEST(Fit, ShortNoisyCurvesThatDoNotDetermineTheLawAreNotFitted) {
  // 11 points of a noisy straight line: seed 27 ends at beta ~ 1e4 inside its bounds, seed 16
  // at x_max ~ 3300; both used to come with standard errors near 0 (null-space directions
  // of the pseudo-inverse covariance). The data determine a slope, not three parameters.
  for (int seed : {27, 16}) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> gauss(0.0, 0.01);
    std::vector<double> e, y;
    for (int i = 0; i <= 10; ++i) {
      e.push_back(0.003 * i);
      y.push_back(0.02 + 0.5 * e.back() + gauss(rng));
    }
    const auto r = demfit::fit_saturating(e, y);
    EXPECT_FALSE(r.ok) << "seed " << seed << ": beta " << r.beta << " x_max " << r.x_max;
    EXPECT_TRUE(std::isnan(r.se_beta) && std::isnan(r.se_x_max)) << "seed " << seed;
    bool flagged = false;
    for (const auto& w : r.warnings) flagged |= has(w, "ill-conditioned");
    EXPECT_TRUE(flagged) << "seed " << seed;
  }
}

TEST(Fit, SharedPathGapIsMeasuredInsideTheFitWindow) {
  // Two laws that differ in x0 only: their gap is 0.05 exp(-10 e), 0.05 at e = 0 but
  // 0.05 exp(-3) = 0.0025 at the window start e = 0.3.
  std::vector<double> e, a, b;
  for (int i = 0; i <= 200; ++i) {
    e.push_back(0.005 * i);
    a.push_back(demfit::saturating(0.0, 0.15, 10.0, e.back()));
    b.push_back(demfit::saturating(0.05, 0.15, 10.0, e.back()));
  }
  demfit::FitOptions o;
  o.window_min = 0.3;
  const auto t = demfit::test_shared_path(e, a, e, b, 0.01, o);
  EXPECT_NEAR(t.max_gap, 0.05 * std::exp(-3.0), 2e-4);
}

TEST(Fit, SharedPathDegreesOfFreedomFollowFixX0) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> gauss(0.0, 0.003);
  std::vector<double> e, a, b;
  for (int i = 0; i <= 60; ++i) {
    e.push_back(0.005 * i);
    a.push_back(demfit::saturating(0.0, 0.15, 10.0, e.back()) + gauss(rng));
    b.push_back(demfit::saturating(0.0, 0.14, 12.0, e.back()) + gauss(rng));
  }
  demfit::FitOptions o;
  o.fix_x0 = true;
  const auto t = demfit::test_shared_path(e, a, e, b, 0.0, o);
  // Two free parameters per law: F = ((RSS_shared - RSS_sep)/2) / (RSS_sep/(n - 4)).
  const double sep = 2 * (t.first.cost + t.second.cost), sh = 2 * t.shared.cost;
  const int n = t.first.n + t.second.n;
  EXPECT_NEAR(t.f_statistic, (sh - sep) / 2 / (sep / (n - 4)), 1e-9 * t.f_statistic);
}

TEST(Scene, NonAsciiOutsideCommentsAndStringsIsRefusedBeforeTomlParsesIt) {
  // Found by tests/fuzz/fuzz_scene: toml++ 3.3.0 reaches __builtin_unreachable (undefined
  // behaviour) on a non-ASCII character where it expects a value, e.g. a pasted 'Σ'.
  EXPECT_TRUE(has(scene_error("[protocol]\ncycle_rate_tc = \xce\xa3-5.\n"), "t.toml:2: TOML syntax error: a non-ASCII"));
  EXPECT_TRUE(has(scene_error("[particles]\ncount = 300 \xce\xbd\n"), "non-ASCII"));
  EXPECT_TRUE(has(error_of([] { dem::load_scene("", {"particles.count=3\xce\xa3"}); }), "non-ASCII"));
  // the second finding: an unclosed string with a non-ASCII character in it
  EXPECT_TRUE(has(scene_error("n = 0.;;;;J;;;;'\xef\xbb\x82;;;"), "string is not closed"));
  // the third: a NUL byte before a string holding a non-ASCII character
  EXPECT_TRUE(has(scene_error(std::string("n = 0.00\0;;';\xef\xbb\xaf*'", 18)), "control character"));
  // ... but they are fine in comments; in strings they are refused (toml++ misbehaves there too).
  EXPECT_EQ(scene_error("# target \xce\xbd = 0.64\n[particles]\ncount = 300 # \xce\xa3\n[modes]\n'x' = [1.0, 0.0, -1.0]\n"), "");
  EXPECT_TRUE(has(scene_error("[particles]\npacking_file = \"\xce\xbd.txt\"\n"), "t.toml:2: TOML syntax error: a non-ASCII character in a string"));
  // the fourth: a string after a syntax error
  EXPECT_TRUE(has(scene_error("n = 0.0;3;;eps_d;;';;\xef\xbb\x9f-e_\xd6\xa5'_\n"), "non-ASCII"));
}
