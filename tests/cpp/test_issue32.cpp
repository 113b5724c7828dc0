// Issue 32: nothing lost, nothing silently wrong (part three). Each test holds one class of
// fault with at least two spellings of it.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "dem/core/errors.hpp"
#include "dem/contact/contact_model.hpp"
#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"

namespace {

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// The SceneError text of loading `text` with `ov`; "" if it loaded. Anything else (or a crash)
// fails the test.
std::string scene_error(const std::string& text, const std::vector<std::string>& ov = {}) {
  try {
    dem::load_scene(text, ov, nullptr, "t.toml");
  } catch (const dem::SceneError& e) {
    return e.what();
  }
  return "";
}

const std::string kSmall = "[particles]\ncount = 100\n";

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// A state of `m` with one history record of `width` numbers (pair 0-1), as a run of another
// contact model would leave it.
dem::State state_with_history(const dem::Model& m, int width) {
  dem::State s = dem::random_packing(m, 0.3);
  s.history.width = width;
  s.history.ids = {0, 1};
  s.history.values.assign(width, 1e-9);
  return s;
}

}  // namespace

// ---- High 2: a key on one side of a physics record only is a difference.

TEST(Issue32, PhysicsDiffCountsAKeyPresentOnOneSideOnly) {
  const dem::Model frictionless = dem::load_scene(kSmall);
  const dem::Model frictional = dem::load_scene(kSmall + "[contact]\nfriction = 0.5\n");
  const dem::Model luding = dem::load_scene(kSmall + "[contact]\nnormal = \"luding\"\n");
  // Spelling 1: frictional checkpoint, frictionless scene (and the reverse).
  for (const auto& [a, b] : {std::pair{&frictional, &frictionless}, std::pair{&frictionless, &frictional}}) {
    const std::string d = dem::physics_diff(dem::shear_physics(*a), dem::shear_physics(*b), "checkpoint", "this scene");
    EXPECT_TRUE(has(d, "contact.tangential = ") && has(d, "cundall_strack") && has(d, "none")) << d;
    EXPECT_TRUE(has(d, "contact.friction = ") && has(d, "read as the default")) << d;
  }
  // Spelling 2: Luding against linear.
  const std::string d = dem::physics_diff(dem::shear_physics(luding), dem::shear_physics(frictionless), "kept curve",
                                          "this scene");
  EXPECT_TRUE(has(d, "contact.normal = luding (kept curve) vs linear (this scene: not in its record")) << d;
  EXPECT_TRUE(has(d, "contact.luding_kp_N_m") && has(d, "absent (this scene")) << d;
  // The same physics on both sides: no difference, whichever keys the records carry.
  for (const dem::Model* m : {&frictionless, &frictional, &luding})
    EXPECT_EQ(dem::physics_diff(dem::shear_physics(*m), dem::shear_physics(*m), "a", "b"), "");
}

TEST(Issue32, OldRecordsWithoutASubModelsKeysAreReadAsItsDefaults) {
  // A record written before SLLOD had no integration.kinematics: it was the plain scheme.
  const dem::Physics old_plain = dem::parse_physics_line("0123456789abcdef contact.stiffness_N_m=100000");
  const dem::Physics sllod = {{"contact.stiffness_N_m", "100000"}, {"integration.kinematics", "sllod"}};
  const dem::Physics plain = {{"contact.stiffness_N_m", "100000"}, {"integration.kinematics", "plain"}};
  const std::string d = dem::physics_diff(old_plain, sllod, "kept curve", "this scene");
  EXPECT_TRUE(has(d, "integration.kinematics = plain (kept curve: not in its record, read as the default")) << d;
  EXPECT_EQ(dem::physics_diff(old_plain, plain, "kept curve", "this scene"), "");
  // A frictional record without rolling keys has rolling off: equal to a record saying 0.
  const dem::Physics no_rolling = {{"contact.friction", "0.5"}};
  const dem::Physics rolling_zero = {{"contact.friction", "0.5"}, {"contact.rolling_friction", "0"}};
  const dem::Physics rolling_on = {{"contact.friction", "0.5"}, {"contact.rolling_friction", "0.10000000000000001"}};
  EXPECT_EQ(dem::physics_diff(no_rolling, rolling_zero, "a", "b"), "");
  EXPECT_TRUE(has(dem::physics_diff(rolling_on, no_rolling, "a", "b"), "contact.rolling_friction"));
  // Every default is a text a record could hold (no empty values).
  for (const auto& [k, v] : dem::record_defaults()) EXPECT_FALSE(k.empty() || v.empty()) << k;
}

// ---- High 3: malformed sections and override paths are a SceneError, never a crash.

TEST(Issue32, ASectionThatIsNotATableIsRefusedNamingIt) {
  for (const std::string& text :
       {std::string("particles = 5\n"), std::string("[[contact]]\nstiffness_N_m = 1e5\n"),
        std::string("contact = \"linear\"\n"), std::string("protocol = [1, 2]\n"), std::string("modes = 3\n"),
        std::string("paths = true\n"), std::string("sweep = 1\n"), std::string("[[particles]]\n[[particles]]\n"),
        std::string("output = { vtk = false }\n[[integration]]\n"), std::string("integration = 1979-05-27\n")}) {
    const std::string e = scene_error(text);
    EXPECT_TRUE(has(e, "must be a section")) << text << " -> " << e;
  }
  EXPECT_TRUE(has(scene_error("[[contact]]\n"), "not [[contact]]"));
  EXPECT_TRUE(has(scene_error("particles = 5\n"), "'particles' must be a section, [particles]"));
  // A table given inline is a table: accepted.
  EXPECT_EQ(scene_error("particles = { count = 100 }\n"), "");
}

TEST(Issue32, AnOverridePathWithABlankOrMissingNameIsRefused) {
  // Spaces around the names are TOML's own (accepted); blank names, empty segments, nested
  // keys, two keys and sections that are not tables are refused with the shape expected.
  EXPECT_EQ(scene_error(kSmall, {" contact.friction=0.5"}), "");
  EXPECT_EQ(scene_error(kSmall, {"contact . damping_kg_s = 0.5"}), "");
  for (const std::string& ov :
       {std::string("contact..friction=0.5"), std::string(".contact.friction=0.5"), std::string("contact.=0.5"),
        std::string("contact.\"\"=0.5"), std::string("\"\".friction=0.5"), std::string("\" \".friction=0.5"),
        std::string("contact.\" \"=0.5"), std::string("contact.a.b=1"), std::string("\"contact.friction\"=0.5"),
        std::string("contact.friction=0.5\nparticles.count=5"), std::string(" .friction=1"), std::string("=5"),
        std::string("nodot=5")}) {
    const std::string e = scene_error(kSmall, {ov});
    EXPECT_TRUE(has(e, "override") && (has(e, "section.key=value") || has(e, "name the section") ||
                                       has(e, "section")))
        << "'" << ov << "' -> " << e;
  }
  // An override into a section of the wrong shape: the section is named first.
  EXPECT_TRUE(has(scene_error("[[contact]]\n", {"contact.friction=0.5"}), "must be a section"));
  // A value TOML cannot read is taken as a bare string, and refused by the key's own type check.
  for (const std::string& ov : {std::string("contact.friction="), std::string("contact.friction=[1,")})
    EXPECT_TRUE(has(scene_error(kSmall, {ov}), "'contact.friction' must be a number")) << ov;
  // An inline table as a value is a value (refused by the key's own type check).
  EXPECT_TRUE(has(scene_error(kSmall, {"contact.friction={a=1}"}), "contact.friction"));
}

// ---- Medium: contact models, modes, measurements and targets.

TEST(Issue32, AStateCarryingAnotherModelsHistoryIsRefusedNotDropped) {
  const dem::Model frictionless = dem::load_scene(kSmall);
  const dem::Model frictional = dem::load_scene(kSmall + "[contact]\nfriction = 0.5\n");
  const dem::Model rolling = dem::load_scene(kSmall + "[contact]\nfriction = 0.5\nrolling_friction = 0.1\n");
  const int w_cs = dem::contact::history_width(frictional.contact), w_roll = dem::contact::history_width(rolling.contact);
  ASSERT_GT(w_cs, 0);
  ASSERT_NE(w_cs, w_roll);
  // Spelling 1: a frictional checkpoint under a frictionless scene; 2: under a rolling one.
  for (const auto& [model, width] : {std::pair{&frictionless, w_cs}, std::pair{&rolling, w_cs}, std::pair{&frictional, w_roll}}) {
    const std::string e = error_of([&, m = model, w = width] { dem::check_packing(*m, state_with_history(*m, w), "x.ckpt"); });
    EXPECT_TRUE(has(e, "x.ckpt") && has(e, "history of another contact model") && has(e, "contact.tangential = ")) << e;
  }
  EXPECT_EQ(error_of([&] { dem::check_packing(frictional, state_with_history(frictional, w_cs), "x.ckpt"); }), "");
  // Spelling 3: spins under a frictionless law.
  dem::State spinning = dem::random_packing(frictionless, 0.3);
  spinning.angular_velocity.assign(spinning.count(), dem::Vec3{0, 0, 0});
  spinning.angular_velocity[7] = dem::Vec3{0, 3, 0};
  const std::string e = error_of([&] { dem::check_packing(frictionless, spinning, "x.ckpt"); });
  EXPECT_TRUE(has(e, "spins") && has(e, "frictionless")) << e;
}

TEST(Issue32, ACheckpointWhoseHistoryWidthIsNotItsOwnModelsIsCorrupt) {
  const auto path = (std::filesystem::temp_directory_path() / "dem_i32_width.ckpt").string();
  for (const std::string& scene : {kSmall + "[contact]\nfriction = 0.5\n", kSmall}) {
    std::string toml;
    const dem::Model m = dem::load_scene(scene, {}, &toml);
    const int right = dem::contact::history_width(m.contact);
    for (int width : {right + 1, right + 3}) {
      dem::write_checkpoint(path, dem::Checkpoint{toml, "test", state_with_history(m, width)});
      const std::string e = error_of([&] { dem::read_checkpoint(path); });
      EXPECT_TRUE(has(e, "corrupt") && has(e, std::to_string(width) + " numbers per contact")) << e;
    }
    if (right > 0) {   // its own width reads back
      dem::write_checkpoint(path, dem::Checkpoint{toml, "test", state_with_history(m, right)});
      EXPECT_EQ(error_of([&] { dem::read_checkpoint(path); }), "");
    }
  }
  std::remove(path.c_str());
}

TEST(Issue32, AModesEntryCannotRedefineABuiltInMode) {
  for (const std::string& name : {"D2", "D3", "SS_xy", "iso_compress", "uniaxial_z"}) {
    const std::string e = scene_error("[modes]\n" + name + " = [1.0, -1.0, 0.0]\n");
    EXPECT_TRUE(has(e, "'" + name + "' is a built-in mode") && has(e, "rename it")) << e;
  }
  EXPECT_EQ(scene_error("[modes]\nmy_D2 = [1.0, 0.0, -1.0]\n[protocol]\nmodes = [\"my_D2\"]\n"), "");
}

TEST(Issue32, AStressTargetTheSpheresCannotCarryIsRefusedAtLoad) {
  const std::string head = "[protocol]\nmodes = [\"P\"]\n[paths]\nP = [";
  for (const std::string& stage : {std::string("{ rate = [0, 0, -1], sigma_Pa = { x = 1e308, y = 1e308 }, until = { eps_zz = -0.01 } }"),
                                   std::string("{ rate = \"D2\", pressure_Pa = 1e300, until = { eps_d = 0.01 } }"),
                                   std::string("{ rate = [0, 0, -1], sigma_Pa = { x = 1e12 }, until = { eps_zz = -0.01 } }")}) {
    const std::string e = scene_error(head + stage + "]\n");
    EXPECT_TRUE(has(e, "paths.P") && has(e, "beyond what these spheres carry") && has(e, "max_overlap_fraction")) << e;
  }
  // A target of the order of the example scenes' pressures stays accepted.
  const dem::Model m = dem::load_scene("");
  const double ok = 1e-3 * dem::stress_target_limit(m);
  EXPECT_EQ(scene_error(head + "{ rate = [0, 0, -1], sigma_Pa = { x = " + dem::physics_number(ok) +
                        " }, until = { eps_zz = -0.01 } }]\n"), "");
}
