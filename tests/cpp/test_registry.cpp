// The contact sub-model registry: every sub-model describes itself (keys, bounds, text,
// oscillators), the loader refuses keys of sub-models not in use and parameters the time step
// cannot integrate, and the composition generated from the slot lists matches each choice.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "dem/contact/contact_model.hpp"
#include "dem/contact/registry.hpp"
#include "dem/core/errors.hpp"
#include "dem/io/checks.hpp"
#include "test_support.hpp"

namespace {

std::string error_of(const std::vector<std::string>& overrides) {
  try {
    dem_test::model_with(overrides);
  } catch (const dem::SceneError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(Registry, EverySubModelDescribesItsKeysAndCounterparts) {
  std::set<std::string> seen;
  for (const dem::contact::SubModelInfo* m : dem::contact::submodels()) {
    EXPECT_FALSE(m->title.empty()) << m->name;
    EXPECT_FALSE(m->yade.empty()) << m->name;     // a counterpart or "none", said plainly
    EXPECT_FALSE(m->lammps.empty()) << m->name;
    EXPECT_TRUE(m->describe) << m->name;
    EXPECT_TRUE(seen.insert(dem::contact::slot_name(m->slot) + ":" + m->name).second) << "listed twice: " << m->name;
    for (const dem::contact::KeySpec& k : m->keys) {
      EXPECT_FALSE(k.unit.empty()) << k.name;
      EXPECT_FALSE(k.meaning.empty()) << k.name;
    }
  }
  // `dem info --contact-models` (registry_text) lists every key with its unit and default.
  const std::string text = dem::contact::registry_text();
  for (const dem::contact::SubModelInfo* m : dem::contact::submodels())
    for (const dem::contact::KeySpec& k : m->keys) EXPECT_NE(text.find("contact." + k.name + " [" + k.unit + "]"), std::string::npos);
}

TEST(Registry, TheGeneratedCompositionMatchesTheChoice) {
  auto check = [](const std::vector<std::string>& o, int history, bool rotations) {
    const dem::Model m = dem_test::model_with(o);
    EXPECT_EQ(dem::contact::history_width(m.contact), history);
    dem::contact::with_contact_model(m.contact, [&](const auto& cm) {
      using CM = std::decay_t<decltype(cm)>;
      EXPECT_EQ(CM::rotations, rotations);
    });
    // The cached composition (what the pair loops use) and a fresh one agree on the type.
    dem::ContactLaw copy = m.contact;
    copy.set("stiffness_N_m", copy.get("stiffness_N_m"));   // stales the cache: built anew
    EXPECT_EQ(dem::contact::history_width(copy), history);
  };
  check({}, 0, false);
  check({"contact.friction=0.5"}, 4, true);
  check({"contact.friction=0.5", "contact.rolling_friction=0.1"}, 7, true);
  check({"contact.friction=0.5", "contact.twisting_friction=0.1"}, 8, true);
  check({"contact.normal=luding"}, 1, false);
  check({"contact.normal=luding", "contact.friction=0.3", "contact.rolling_friction=0.1"}, 8, true);
}

TEST(Registry, AKeyOfASubModelNotInUseIsRefusedNamingIt) {
  // a Luding key with the linear law; a tangential key without friction; rolling without friction
  EXPECT_NE(error_of({"contact.luding_kc_N_m=1e7"}).find("\"luding\""), std::string::npos);
  EXPECT_NE(error_of({"contact.tangential_damping_kg_s=0.1"}).find("\"cundall_strack\""), std::string::npos);
  EXPECT_NE(error_of({"contact.rolling_friction=0.1"}).find("tangential model"), std::string::npos);
  // a rolling stiffness without rolling switched on names the switch
  EXPECT_NE(error_of({"contact.friction=0.5", "contact.rolling_stiffness_ratio=0.5"}).find("contact.rolling_friction > 0"),
            std::string::npos);
  // said outright, "off" takes the keys with it (sweeps over 0 keep their tables)
  EXPECT_EQ(error_of({"contact.friction=0.5", "contact.rolling_friction=0", "contact.rolling_stiffness_ratio=0.5"}), "");
  EXPECT_EQ(error_of({"contact.tangential=\"none\"", "contact.tangential_stiffness_ratio=0.5"}), "");
  // an unknown sub-model lists the registry's
  const std::string unknown = error_of({"contact.normal=\"hooke\""});
  EXPECT_NE(unknown.find("\"linear\""), std::string::npos);
  EXPECT_NE(unknown.find("\"luding\""), std::string::npos);
}

TEST(Registry, ParametersTheTimeStepCannotIntegrateAreRefusedWithTheLargestThatRuns) {
  // The spellings: gamma_t = 1000 kg/s at t_c/50; k_t/k = 5 and 10 at t_c/5.
  const std::string damped = error_of({"contact.friction=0.5", "contact.tangential_damping_kg_s=1000"});
  EXPECT_NE(damped.find("contact.tangential_damping_kg_s = 1000 -> at most"), std::string::npos) << damped;
  for (const char* ratio : {"5", "10"}) {
    const std::string stiff = error_of({"contact.friction=0.5", "integration.dt_over_tc=0.2",
                                        std::string("contact.tangential_stiffness_ratio=") + ratio});
    EXPECT_NE(stiff.find("contact.tangential_stiffness_ratio = " + std::string(ratio) + " -> at most"), std::string::npos)
        << stiff;
  }
  // rolling and twisting dashpots
  EXPECT_NE(error_of({"contact.friction=0.5", "contact.rolling_friction=0.1", "contact.rolling_damping_kg_s=1e4"})
                .find("contact.rolling_damping_kg_s"), std::string::npos);
  EXPECT_NE(error_of({"contact.friction=0.5", "contact.twisting_friction=0.1", "contact.twisting_damping_kg_s=1e4"})
                .find("contact.twisting_damping_kg_s"), std::string::npos);
}

TEST(Registry, TheLargestStableValueIsTheBoundOfTheClosedForm) {
  // The contact point's oscillator (m_eff = 2/7 m_r, k_t = ratio k): with no dashpot, stable
  // for omega dt < 2, i.e. ratio < (2/dt)^2 m_eff / k. The bisection must find that.
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "integration.dt_over_tc=0.2"});
  const dem::contact::PairScale s = dem::contact::pair_scale(m.contact, m.radius_min, m.density);
  const double m_eff = 2.0 / 7.0 * s.m_r, k = m.contact.get("stiffness_N_m");
  const double closed = (2.0 / m.dt) * (2.0 / m.dt) * m_eff / k;
  EXPECT_NEAR(dem::contact::largest_stable_value(m.contact, s, m.dt, "tangential_stiffness_ratio"), closed, 1e-9 * closed);
  // A scene just below the bound loads; one just above is refused.
  const double ratio = closed * 0.999;
  EXPECT_EQ(error_of({"contact.friction=0.5", "integration.dt_over_tc=0.2",
                      "contact.tangential_stiffness_ratio=" + dem::physics_number(ratio)}), "");
  EXPECT_NE(error_of({"contact.friction=0.5", "integration.dt_over_tc=0.2",
                      "contact.tangential_stiffness_ratio=" + dem::physics_number(closed * 1.001)}), "");
}

TEST(Registry, RecordsOfTheDefaultModelsKeepTheirKeysAndOrder) {
  // The frictionless linear record is the one runs before the registry wrote (same hash).
  std::vector<std::string> keys;
  for (const auto& kv : dem::material_physics(dem_test::model_with({}))) keys.push_back(kv.first);
  const std::vector<std::string> before = {"particles.radius_min_m", "particles.radius_max_m", "particles.density_kg_m3",
                                           "contact.stiffness_N_m", "contact.damping_kg_s", "contact.allow_attractive",
                                           "contact.background_damping_kg_s", "integration.integrator",
                                           "integration.dt_over_tc", "integration.kinematics"};
  EXPECT_EQ(keys, before);
  std::vector<std::string> rough;
  for (const auto& kv : dem::material_physics(dem_test::model_with({"contact.friction=0.5"}))) rough.push_back(kv.first);
  const std::vector<std::string> tail = {"contact.tangential", "contact.friction", "contact.tangential_stiffness_ratio",
                                         "contact.tangential_damping_kg_s"};
  EXPECT_EQ(std::vector<std::string>(rough.end() - 4, rough.end()), tail);
}

TEST(Registry, DemInfoSaysWhichTangentialLawFrictionAloneSelects) {
  // With the Hertz normal law, contact.friction > 0 alone selects Cundall-Strack's linear
  // spring, not Mindlin's: `dem info` (describe_contact) says so and names the laws the scene
  // could select instead; with the linear normal law there is no other to name.
  auto lines = [](const std::vector<std::string>& o) {
    const dem::Model m = dem_test::model_with(o);
    std::string all;
    for (const std::string& l : dem::contact::describe_contact(m.contact, dem::contact::pair_scale(m.contact, m.radius_min, m.density)))
      all += l + "\n";
    return all;
  };
  const std::string hertz = lines({"contact.normal=\"hertz\"", "contact.friction=0.5"});
  EXPECT_NE(hertz.find("tangential       cundall_strack:"), std::string::npos) << hertz;
  EXPECT_NE(hertz.find("contact.friction > 0 selects when contact.tangential is not given"), std::string::npos) << hertz;
  EXPECT_NE(hertz.find("\"mindlin\" or \"mindlin_force\""), std::string::npos) << hertz;
  const std::string linear = lines({"contact.friction=0.5"});
  EXPECT_EQ(linear.find("is not given"), std::string::npos) << linear;
  const std::string mindlin = lines({"contact.normal=\"hertz\"", "contact.tangential=\"mindlin\"", "contact.friction=0.5"});
  EXPECT_EQ(mindlin.find("is not given"), std::string::npos) << mindlin;
}
