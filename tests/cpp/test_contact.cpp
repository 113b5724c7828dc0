// Two-sphere collisions against the closed-form linear spring-dashpot solution.
#include <gtest/gtest.h>

#include <cmath>

#include "dem/stages/collision.hpp"
#include "test_support.hpp"

using dem::Vec3;

namespace {
dem::CollisionResult collide(const dem::Model& m, double r1, double r2, double v0, bool across) {
  return dem::simulate_collision(m, r1, r2, v0, across);
}
}  // namespace

TEST(TwoSphereCollision, SmallestPairMatchesPaperNumbers) {
  // Analytic: t_c = 0.22787 us, e = 0.8044 for two r = 0.5 mm spheres (k = 1e8, gamma = 1).
  const dem::Model m = dem_test::model_with({"contact.background_damping_kg_s=0"});
  EXPECT_NEAR(m.t_contact, 0.22787e-6, 0.00001e-6);
  EXPECT_NEAR(m.restitution, 0.8044, 0.0001);
}

TEST(TwoSphereCollision, ContactTimeAndRestitutionBothIntegrators) {
  for (const char* integ : {"velocity_verlet", "symplectic_euler"}) {
    // The analytic solution is that of the unclamped law (force may turn attractive).
    const dem::Model m = dem_test::model_with({"contact.background_damping_kg_s=0", "contact.allow_attractive=true",
                                               "integration.dt_over_tc=0.0005",
                                               std::string("integration.integrator=") + integ});
    for (bool across : {false, true}) {
      for (auto radii : {std::pair{0.5e-3, 0.5e-3}, std::pair{0.5e-3, 1.5e-3}}) {
        const double m1 = dem::sphere_mass(radii.first, 2000), m2 = dem::sphere_mass(radii.second, 2000);
        const auto truth = dem::pair_collision(1e8, 1.0, m1 * m2 / (m1 + m2));
        const auto got = collide(m, radii.first, radii.second, 0.1, across);
        SCOPED_TRACE(std::string(integ) + (across ? " across boundary" : "") + " r2=" + std::to_string(radii.second));
        EXPECT_NEAR(got.contact_time / truth.t_contact, 1.0, 1e-3);
        EXPECT_NEAR(got.restitution / truth.restitution, 1.0, 1e-3);
      }
    }
  }
}

TEST(TwoSphereCollision, ClampedForceNeverPullsAndRestitutionIsHigher) {
  // With the force clamped at zero the dashpot cannot pull during separation: less energy
  // is lost than in the unclamped law, so e exceeds the analytic value, but stays below 1.
  const dem::Model m = dem_test::model_with({"contact.background_damping_kg_s=0", "integration.dt_over_tc=0.0005"});
  const auto got = collide(m, 0.5e-3, 0.5e-3, 0.1, false);
  EXPECT_GT(got.restitution, m.restitution + 1e-3);
  EXPECT_LT(got.restitution, 1.0);
}

TEST(TwoSphereCollision, OverdampedPairIsRejected) {
  EXPECT_THROW(dem_test::model_with({"contact.damping_kg_s=1000"}), dem::SceneError);
}
