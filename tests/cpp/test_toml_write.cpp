// The resolved-scene writer (dem/io/toml_write.hpp): the bytes toml++ 3.3.0 writes, without the
// undefined behaviour of its array-width estimate (tests/SANITIZE.md, finding 1). The oracle is
// toml++'s own writer, on random tables and on every stored scene; under the sanitizers the oracle
// is called only where it is defined (no float below 0.1 in magnitude, none non-finite).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "dem/io/toml_write.hpp"

#if defined(__SANITIZE_ADDRESS__)
#define DEM_UNDER_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define DEM_UNDER_SANITIZER 1
#endif
#endif
#ifndef DEM_UNDER_SANITIZER
#define DEM_UNDER_SANITIZER 0
#endif

namespace {

std::string tomlpp_text(const toml::table& t) {
  std::ostringstream o;
  o << t;
  return o.str();
}

// Random tables of the shapes scenes have, and more: nested sections, [[section arrays]], inline
// tables, arrays nested in arrays, long arrays that wrap, keys that need quotes, every scalar type.
class TableMaker {
 public:
  TableMaker(unsigned seed, bool tiny_floats) : rng_(seed), tiny_(tiny_floats) {}

  toml::table table(int depth) {
    toml::table t;
    for (int i = pick(0, 5); i > 0; --i) put(t, key(), depth);
    if (depth < 3)
      for (int i = pick(0, 2); i > 0; --i) t.insert_or_assign(key(), table(depth + 1));
    if (depth < 2 && pick(0, 5) == 0) {
      toml::array sections;
      for (int i = pick(1, 3); i > 0; --i) sections.push_back(table(depth + 1));
      t.insert_or_assign(key(), std::move(sections));
    }
    return t;
  }

 private:
  int pick(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }

  std::string key() {
    static const char* const keys[] = {"a", "rate_tc", "x y", "k.v", "friction", "D2", "phi_0.80", "\"q\"", "b-c"};
    return keys[pick(0, 8)] + std::to_string(pick(0, 30));
  }

  double real() {   // magnitudes from 1e-320 (1e-1 under the sanitizers) to 1e12, zero, +-inf
    const double mag = std::pow(10.0, std::uniform_real_distribution<double>(tiny_ ? -320 : -1, 12)(rng_));
    switch (pick(0, 9)) {
      case 0: return 0.0;
      case 1: return tiny_ ? std::numeric_limits<double>::infinity() : 1.5;
      case 2: return tiny_ ? -std::numeric_limits<double>::infinity() : -2.5;
      default: return pick(0, 1) ? mag : -mag;
    }
  }

  std::int64_t integer() { return std::int64_t(pick(-100000, 100000)) * (pick(0, 1) ? 1 : 1000003); }
  std::string text() { return std::string(std::size_t(pick(0, 12)), "ab\"\\\n x"[pick(0, 6)]); }

  // A value of kind 0-5 (float, integer, string, bool, array, inline table) handed to add(...).
  template <typename Add>
  void any(int kind, int depth, Add&& add) {
    if (depth >= 4 && kind >= 4) kind = 1;
    switch (kind) {
      case 0: add(real()); break;
      case 1: add(integer()); break;
      case 2: add(text()); break;
      case 3: add(pick(0, 1) == 1); break;
      case 4: add(array(depth + 1)); break;
      default: add(inline_table(depth + 1)); break;
    }
  }

  void put(toml::table& t, const std::string& k, int depth) {
    any(pick(0, 7) > 5 ? 4 : pick(0, 5), depth, [&](auto&& v) { t.insert_or_assign(k, std::forward<decltype(v)>(v)); });
  }

  toml::array array(int depth) {
    toml::array a;
    const int n = pick(0, 3) == 0 ? pick(20, 60) : pick(0, 6);
    const int kind = pick(0, 6);   // 6: mixed kinds
    for (int i = 0; i < n; ++i)
      any(kind == 6 ? pick(0, 5) : kind, depth, [&](auto&& v) { a.push_back(std::forward<decltype(v)>(v)); });
    return a;
  }

  toml::table inline_table(int depth) {
    toml::table t;
    for (int i = pick(0, 3); i > 0; --i) put(t, key(), depth + 1);
    t.is_inline(true);
    return t;
  }

  std::mt19937 rng_;
  bool tiny_;
};

}  // namespace

TEST(TomlWrite, RandomTablesAreWrittenAsTomlppWritesThem) {
  int arrays = 0, multiline = 0;
  for (unsigned seed = 1; seed <= 1500; ++seed) {
    TableMaker maker(seed, !DEM_UNDER_SANITIZER);
    const toml::table t = maker.table(0);
    const std::string ours = dem::toml_write(t);
    ASSERT_EQ(ours, tomlpp_text(t)) << "seed " << seed;
    arrays += int(ours.find('[') != std::string::npos);
    multiline += int(ours.find("[\n") != std::string::npos);
  }
  EXPECT_GT(arrays, 500);      // the generator reached the arrays and the wrapped layout
  EXPECT_GT(multiline, 100);
}

// Every scene the repository stores, parsed and written: toml++'s bytes (where toml++ itself is
// defined under the sanitizers: its writer is not, on the small floats these scenes hold).
TEST(TomlWrite, EveryStoredSceneIsWrittenAsTomlppWritesIt) {
  int scenes = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(DEM_SOURCE_DIR "/data/scenes")) {
    if (e.path().extension() != ".toml") continue;
    const toml::table t = toml::parse_file(e.path().string());
    const std::string ours = dem::toml_write(t);
    EXPECT_EQ(toml::parse(ours), t) << e.path();
    if (!DEM_UNDER_SANITIZER) EXPECT_EQ(ours, tomlpp_text(t)) << e.path();
    ++scenes;
  }
  EXPECT_GT(scenes, 10);
}

// The spellings of finding 1 (and the widths x86 gives toml++'s estimate): each written and read
// back to the same table, under the sanitizers too, where toml++'s writer stops on them.
TEST(TomlWrite, SmallFloatsInArraysAreWrittenWithoutCastingANegativeLog) {
  for (const char* text : {"x = [0.7]", "x = [1e-300]", "x = [-0.5, 2]", "x = [5e-324, -0.001]",
                           "[a]\ny = [[0.01, 0.02], {b = [1e-9]}]", "z = {c = [0.09, inf, nan]}"}) {
    const toml::table t = toml::parse(text);
    const std::string ours = dem::toml_write(t);
    const toml::table back = toml::parse(ours);
    EXPECT_EQ(back.size(), t.size()) << text;
    if (text[0] != 'z') EXPECT_EQ(back, t) << text << " -> " << ours;   // nan != nan
    if (!DEM_UNDER_SANITIZER) EXPECT_EQ(ours, tomlpp_text(t)) << text;
  }
  // The estimate as x86-64 computes toml++'s casts: "[ ]" 3 + (2 + trunc(log10 0.001) + 1) + ", " 2
  // = 5 modulo 2^64; 1e-300 makes it wrap below zero, i.e. "wider than the line": one per line.
  EXPECT_EQ(dem::toml_inline_columns(*toml::parse("x = [0.001]").get("x")), 5u);
  EXPECT_EQ(dem::toml_write(toml::parse("x = [1e-300]")).find("x = [\n"), 0u);
  EXPECT_EQ(dem::toml_inline_columns(*toml::parse("x = [12.5, -3]").get("x")), 3u + 4u + 2u + 2u + 2u);
}
