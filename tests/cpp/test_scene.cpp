// Bad input gets a clear error naming the key or line and the fix.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "dem/io/io.hpp"
#include "dem/core/model.hpp"
#include "dem/io/scene.hpp"
#include "dem/stages/plan.hpp"

#include <unistd.h>

namespace {
std::string error_of(const std::string& text, const std::vector<std::string>& ov = {}) {
  try {
    dem::load_scene(text, ov, nullptr, "t.toml");
  } catch (const dem::SceneError& e) {
    return e.what();
  }
  return "";
}
bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string write_temp(const std::string& name, const std::string& content) {
  const std::string p = (std::filesystem::temp_directory_path() / name).string();
  std::ofstream(p) << content;
  return p;
}
std::string packing_error(const std::string& content) {
  const std::string p = write_temp("dem_bad_packing.txt", content);
  try {
    dem::read_packing(p, 2000);
  } catch (const std::runtime_error& e) {
    std::remove(p.c_str());
    return e.what();
  }
  std::remove(p.c_str());
  return "";
}
}  // namespace

TEST(Scene, DefaultsReproduceThePaper) {
  const dem::Model m = dem::load_scene("");
  EXPECT_EQ(m.count, 9261);
  EXPECT_NEAR(m.t_contact, 0.22787e-6, 1e-11);
  EXPECT_NEAR(m.dt, m.t_contact / 50, 1e-20);
  EXPECT_EQ(m.protocol.modes.size(), 2u);
}

TEST(Scene, UnknownKeyIsNamedWithTheKnownOnes) {
  const auto e = error_of("[contact]\nstifness_N_m = 1e8\n");
  EXPECT_TRUE(has(e, "contact.stifness_N_m")) << e;
  EXPECT_TRUE(has(e, "stiffness_N_m")) << e;
  EXPECT_TRUE(has(error_of("[contakt]\n"), "unknown section [contakt]"));
}

TEST(Scene, WrongTypesAndImpossibleValues) {
  EXPECT_TRUE(has(error_of("[particles]\ncount = \"many\"\n"), "particles.count' must be an integer"));
  EXPECT_TRUE(has(error_of("[particles]\nradius_min_m = -1e-3\n"), "radius_min_m must be positive"));
  EXPECT_TRUE(has(error_of("[particles]\nradius_max_m = 0.1e-3\n"), "radius_max_m must be at least"));
  EXPECT_TRUE(has(error_of("[protocol]\ncycle_phi_max = 0.95\n"), "beyond what these soft"));
  EXPECT_TRUE(has(error_of("[protocol]\ninitial_phi = 0.6\n"), "initial_phi must be in"));
  EXPECT_TRUE(has(error_of("[protocol]\ncheckpoints_unloading = [0.5]\n"), "outside [target_phi, cycle_phi_max]"));
  EXPECT_TRUE(has(error_of("[protocol]\nmodes = [\"D7\"]\n"), "'D7'"));
  EXPECT_TRUE(has(error_of("[protocol]\ndeviatoric_rate_tc = 0.5\n"), "far from quasi-static"));
  EXPECT_TRUE(has(error_of("[integration]\nintegrator = \"rk4\"\n"), "velocity_verlet"));
  EXPECT_TRUE(has(error_of("[contact]\nk = \n"), "TOML syntax error"));
}

TEST(Scene, TimeStepBeyondStabilityLimitIsRefused) {
  const auto e = error_of("[integration]\ndt_over_tc = 0.7\n");
  EXPECT_TRUE(has(e, "stability limit")) << e;
  EXPECT_TRUE(has(e, "0.637")) << e;
  EXPECT_EQ(error_of("[integration]\ndt_over_tc = 0.5\n"), "");
}

TEST(Scene, OverridesReachEveryKeyAndTheResolvedSceneReloads) {
  std::string resolved;
  const dem::Model m = dem::load_scene("[particles]\ncount = 100\n",
                                       {"particles.count=500", "contact.damping_kg_s=0", "integration.integrator=symplectic_euler",
                                        "protocol.modes=[\"D3\"]", "protocol.checkpoints_unloading=[0.7]"},
                                       &resolved);
  EXPECT_EQ(m.count, 500);
  EXPECT_EQ(m.contact.get("damping_kg_s"), 0.0);
  EXPECT_EQ(m.integrator, dem::Integrator::SymplecticEuler);
  ASSERT_EQ(m.protocol.modes.size(), 1u);
  EXPECT_EQ(m.protocol.modes[0].name, "D3");
  const dem::Model again = dem::load_scene(resolved);
  EXPECT_EQ(again.count, 500);
  EXPECT_EQ(again.dt, m.dt);
  EXPECT_EQ(again.protocol.deviatoric_rate, m.protocol.deviatoric_rate);
  EXPECT_TRUE(has(error_of("", {"count=5"}), "name the section"));
  EXPECT_TRUE(has(error_of("", {"particles.cuont=5"}), "particles.cuont"));
}

TEST(Scene, CustomModesAreDiagonalRateTensors) {
  const dem::Model m = dem::load_scene("[modes]\nshear_xy = [1.0, -1.0, 0.0]\n[protocol]\nmodes = [\"shear_xy\", \"D2\"]\n");
  ASSERT_EQ(m.protocol.modes.size(), 2u);
  EXPECT_EQ(m.protocol.modes[0].shape.diag.y, -1.0);
  EXPECT_TRUE(has(error_of("[modes]\nbad = [1.0, 2.0]\n"), "modes.bad must be"));
}

TEST(Packing, BadFilesNameTheProblem) {
  EXPECT_TRUE(has(packing_error("1 2 3 0.001\n"), "no '##PERIODIC::"));
  EXPECT_TRUE(has(packing_error("##PERIODIC:: 0.01 0.01\n"), "expected '##PERIODIC:: Lx Ly Lz'"));
  EXPECT_TRUE(has(packing_error("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003\n"), ":2: expected 'x y z r'"));
  EXPECT_TRUE(has(packing_error("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003 -0.001\n0.005 0.005 0.005 0.001\n"),
                  "radius must be positive"));
  EXPECT_TRUE(has(packing_error("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.03 0.001\n0.005 0.005 0.005 0.001\n"),
                  "outside the periodic cell"));
  EXPECT_EQ(packing_error("##PERIODIC:: 0.01 0.01 0.01\n0.001 0.002 0.003 0.001\n0.005 0.005 0.005 0.001\n"), "");
}

TEST(Packing, SharedBenchmarkPackingHasTheAdvertisedVolumeFraction) {
  const dem::State s = dem::read_packing(std::string(DEM_SOURCE_DIR) + "/data/packings/n9261_phi0.70.txt", 2000);
  EXPECT_EQ(s.count(), 9261);
  EXPECT_NEAR(s.volume_fraction(), 0.700, 5e-4);
}

// The skin: "auto" (the default) follows the time step by its rule, a number overrides it, and the
// resolved scene keeps "auto", so a resolved scene run at another dt gets that dt's skin.
TEST(Scene, SkinIsAutoByDefaultANumberOverridesIt) {
  std::string resolved;
  const dem::Model t50 = dem::load_scene("", {}, &resolved);
  EXPECT_TRUE(t50.skin_auto);
  EXPECT_EQ(t50.skin_over_rmin, 0.4);   // the default time step keeps the old skin (and bits)
  EXPECT_TRUE(has(resolved, "skin_over_rmin = 'auto'")) << resolved;
  const dem::Model t5 = dem::load_scene(resolved, {"integration.dt_over_tc=0.2"});
  EXPECT_NEAR(t5.skin_over_rmin, 0.4 * std::pow(10.0, 0.4), 1e-12);
  const dem::Model t10 = dem::load_scene("[integration]\ndt_over_tc = 0.1\nskin_over_rmin = \"auto\"\n");
  EXPECT_TRUE(t10.skin_auto);
  EXPECT_GT(t10.skin_over_rmin, t50.skin_over_rmin);
  EXPECT_LT(t10.skin_over_rmin, t5.skin_over_rmin);
  // A box of few particles caps it (at least the old 0.4 r_min): 120 spheres at t_c/2.5 hold 0.4 only.
  const dem::Model few = dem::load_scene("[particles]\ncount = 120\n[integration]\ndt_over_tc = 0.4\n");
  EXPECT_TRUE(few.skin_auto);
  EXPECT_EQ(few.skin_over_rmin, 0.4);
  const dem::Model some = dem::load_scene("[particles]\ncount = 200\n[integration]\ndt_over_tc = 0.4\n");
  EXPECT_GT(some.skin_over_rmin, 0.4);
  EXPECT_LT(some.skin_over_rmin, dem::auto_skin_over_rmin(0.4));
  const dem::Model set = dem::load_scene("[integration]\ndt_over_tc = 0.2\nskin_over_rmin = 0.3\n");
  EXPECT_FALSE(set.skin_auto);
  EXPECT_EQ(set.skin_over_rmin, 0.3);
  EXPECT_TRUE(has(error_of("[integration]\nskin_over_rmin = \"thick\"\n"), "must be a number or \"auto\""));
  EXPECT_TRUE(has(error_of("[integration]\nskin_over_rmin = 0\n"), "skin_over_rmin must be in (0, 4]"));
}

// An ensemble folder of a version before "auto" stores the skin as a number: it continues when
// "auto" gives the same skin (t_c/50), and is another scene when it does not (t_c/5).
TEST(Scene, AnEnsembleFolderWithTheSkinAsANumberContinuesWhenTheSkinIsTheSame) {
  namespace fs = std::filesystem;
  for (const char* dt : {"0.02", "0.2"}) {
    std::string resolved;
    dem::load_scene(std::string("[integration]\ndt_over_tc = ") + dt + "\n", {}, &resolved);
    ASSERT_NE(resolved.find("skin_over_rmin = 'auto'"), std::string::npos);
    std::string stored = resolved;
    stored.replace(stored.find("skin_over_rmin = 'auto'"), 23, "skin_over_rmin = 0.40000000000000002");
    const fs::path dir = fs::temp_directory_path() / (std::string("dem_old_skin_") + dt);
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::ofstream(dir / "scene.toml") << stored;
    if (std::string(dt) == "0.02") {
      const int lock = dem::prepare_ensemble_folder(dir.string(), resolved, false);
      EXPECT_GE(lock, 0);
      ::close(lock);
    } else {
      try {
        dem::prepare_ensemble_folder(dir.string(), resolved, false);
        ADD_FAILURE() << "a folder run at another skin must be refused";
      } catch (const std::runtime_error& e) {
        EXPECT_TRUE(has(e.what(), "another scene")) << e.what();
      }
    }
    fs::remove_all(dir);
  }
}
