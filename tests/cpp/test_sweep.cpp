// Parameter sweeps: a table and a scene's [sweep] are one list of rows, each row's value reaches
// the Model exactly as the TOML literal says, and bad sweeps are refused naming the row.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "dem/io/scene.hpp"
#include "dem/io/sweep.hpp"
#include "dem/stages/plan.hpp"

namespace {
std::string write_temp(const std::string& name, const std::string& content) {
  const std::string p = (std::filesystem::temp_directory_path() / name).string();
  std::ofstream(p) << content;
  return p;
}
const char* kScene = "[particles]\ncount = 100\n";
}  // namespace

TEST(Sweep, TabsAndSpacesGiveTheSameRows) {
  const auto tabs = dem::read_sweep_table(write_temp("sw_tabs.tsv", "# c\nname\tcontact.friction\tcontact.stiffness_N_m\n"
                                                                    "a\t0.1\t1e6\n\nb\t0.25\t3e6\n"));
  const auto spaces = dem::read_sweep_table(write_temp("sw_sp.txt", "name contact.friction   contact.stiffness_N_m\n"
                                                                    "a 0.1 1e6\nb    0.25 3e6\n"));
  ASSERT_EQ(tabs.rows.size(), 2u);
  EXPECT_EQ(tabs.keys, spaces.keys);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(tabs.rows[i].name, spaces.rows[i].name);
    EXPECT_EQ(tabs.rows[i].values, spaces.rows[i].values);
  }
  EXPECT_EQ(tabs.rows[1].where.substr(tabs.rows[1].where.size() - 2), ":5");   // line numbers count comments
}

TEST(Sweep, SceneValuesReachTheModelAsTheirTomlLiterals) {
  const std::string scene = write_temp("sw_scene.toml", std::string(kScene) +
      "[sweep]\nkeys = [\"contact.friction\", \"contact.stiffness_N_m\", \"protocol.modes\"]\n"
      "values = [[0.1, 1e6, [\"D2\"]], [0.30000000000000004, 123456789.0, [\"D2\", \"D3\"]]]\n");
  const dem::Sweep s = dem::scene_sweep(scene);
  ASSERT_EQ(s.rows.size(), 2u);
  EXPECT_EQ(s.rows[0].name, "row00");
  const auto resolved = dem::resolve_sweep(scene, {}, s);
  const double mu[2] = {0.1, 0.30000000000000004}, k[2] = {1e6, 123456789.0};
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(resolved[i].find("[sweep]"), std::string::npos);
    const dem::Model m = dem::load_scene(resolved[i]);
    EXPECT_EQ(m.contact.get("friction"), mu[i]);
    EXPECT_EQ(m.contact.get("stiffness_N_m"), k[i]);
    EXPECT_EQ(m.protocol.modes.size(), std::size_t(i + 1));
    EXPECT_EQ(m.sweep_rows, 0);
  }
  EXPECT_EQ(dem::load_scene_file(scene).sweep_rows, 2);
}

TEST(Sweep, BadRowsAreRefusedNamingTheRow) {
  auto error = [](const std::string& table) {
    try {
      const auto s = dem::read_sweep_table(write_temp("sw_bad.tsv", table));
      dem::resolve_sweep(write_temp("sw_base.toml", kScene), {}, s);
    } catch (const dem::SceneError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error("name\tcontact.friction\nok\t0.1\nbad\t-1\n").find("sweep row 'bad'"), std::string::npos);
  EXPECT_NE(error("contact.nothing\n1\n").find("unknown key 'contact.nothing'"), std::string::npos);
  EXPECT_NE(error("name\tcontact.friction\n../x\t0.1\n").find("row name '../x'"), std::string::npos);
  EXPECT_NE(error("contact.friction\tcontact.friction\n0.1\t0.2\n").find("given twice"), std::string::npos);
  EXPECT_NE(error("contact.friction\n0.1\t\n").find("ragged row"), std::string::npos);
  EXPECT_NE(error("sweep.keys\n1\n").find("its own [sweep]"), std::string::npos);
}

TEST(Sweep, JsonOfThePlanAndTheSweepParsesBack) {
  const dem::Model m = dem::load_scene(std::string(kScene) + "[ensemble]\npackings = 2\n");
  const auto plan = nlohmann::json::parse(dem::plan_json(m));
  EXPECT_EQ(plan["packings"], 2);
  EXPECT_EQ(plan["members"][1]["name"], "m001");
  EXPECT_EQ(plan["tasks"].size(), dem::planned_task_files(m).size());
  const auto s = dem::read_sweep_table(write_temp("sw_q.tsv", "name\tparticles.packing_file\nq\t\"a \\\"b\\\" c\"\n"));
  const auto j = nlohmann::json::parse(dem::sweep_json(s, {"output.vtk=false"}));
  EXPECT_EQ(j["rows"][0]["values"]["particles.packing_file"], "\"a \\\"b\\\" c\"");   // escaped and read back
  EXPECT_EQ(j["rows"][0]["folder"], "rows/q");
  EXPECT_EQ(j["base_overrides"][0], "output.vtk=false");
}

// fuzz_sweep finding (2026-12-02, UBSan): scene_sweep handed the raw scene text to toml++, which
// reaches __builtin_unreachable on non-ASCII bytes (the loader's ASCII guard was not on this door).
// Each spelling must be a SceneError from the guard; under the sanitizer build (tests/sanitize.sh)
// the old path stops with "execution reached an unreachable program point".
TEST(Sweep, ASceneSweepIsReadThroughTheAsciiGuard) {
  const std::string sweep = "[sweep]\nkeys = [\"contact.friction\"]\n";
  const std::pair<std::string, std::string> cases[] = {
      {"\xd0\x8e\x13\n", "control character"},                                  // the fuzzer's input
      {std::string(kScene) + sweep + "values = [[\xce\xa3" "0.5]]\n", "non-ASCII"},      // after '='
      {std::string(kScene) + sweep + "values = [[0.5]]\nnames = [\"\xc2\xb5\"]\n", "non-ASCII"},   // in a string
      {std::string(kScene) + sweep + "values = [[0.5]]\nnames = [\"a\n", "not closed"}};
  for (const auto& [text, why] : cases) {
    try {
      dem::scene_sweep(write_temp("sw_ascii.toml", text));
      ADD_FAILURE() << "accepted: " << text;
    } catch (const dem::SceneError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  }
  // A comment may hold any bytes: the sweep is still read.
  const auto s = dem::scene_sweep(write_temp("sw_ascii_ok.toml", std::string(kScene) + "# \xc2\xb5 = 0.5\n" + sweep +
                                                                  "values = [[0.5], [0.25]]\n"));
  EXPECT_EQ(s.rows.size(), 2u);
}
