// Two-sphere collisions against the closed-form linear spring-dashpot solution.
#include <gtest/gtest.h>

#include <cmath>

#include "dem/engine.hpp"
#include "test_support.hpp"

using dem::Vec3;

namespace {

struct CollisionOutcome { double contact_time, restitution; };

// Head-on collision along x of spheres r1, r2 approaching at speed v0; contact time from the
// interpolated zero crossings of the overlap, restitution from the separation speed.
CollisionOutcome collide(const dem::Model& m, double r1, double r2, double v0, bool across_boundary) {
  const double L = 20e-3, gap = 2e-7;   // [m]: contact within ~2e-6 s at 0.1 m/s
  double x1 = across_boundary ? L - r1 - gap / 2 : 5e-3;
  double x2 = across_boundary ? r2 + gap / 2 : x1 + r1 + r2 + gap;
  dem::State s = dem_test::make_state(Vec3(L, L, L), {Vec3(x1, 10e-3, 10e-3), Vec3(x2, 10e-3, 10e-3)}, {r1, r2});
  s.velocity[0] = Vec3(0.5 * v0, 0, 0);
  s.velocity[1] = Vec3(-0.5 * v0, 0, 0);
  dem::Engine e(m, s);
  auto overlap = [&]() {
    double d = s.position[1].x - s.position[0].x;
    d -= L * std::round(d / L);
    return s.radius[0] + s.radius[1] - std::fabs(d);
  };
  auto rel_speed = [&]() {
    const int a = s.id[0] == 0 ? 0 : 1, b = 1 - a;   // list rebuilds may reorder particles
    return s.velocity[b].x - s.velocity[a].x;
  };
  double t_in = -1, t_out = -1, prev = overlap(), prev_t = s.time;
  for (int k = 0; k < 1000000 && t_out < 0; ++k) {
    e.step(Vec3(0, 0, 0));
    const double now = overlap();
    if (prev <= 0 && now > 0) t_in = prev_t + (s.time - prev_t) * (-prev) / (now - prev);
    if (prev > 0 && now <= 0 && t_in >= 0) t_out = prev_t + (s.time - prev_t) * prev / (prev - now);
    prev = now;
    prev_t = s.time;
  }
  // Separation speed: free flight after contact, no background damping.
  for (int k = 0; k < 10; ++k) e.step(Vec3(0, 0, 0));
  const double v_out = std::fabs(rel_speed());
  return {t_out - t_in, v_out / v0};
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
