// Box deformation: affine motion, exact volume conservation of D2/D3, eps_d formulas.
#include <gtest/gtest.h>

#include <cmath>

#include "dem/engine/engine.hpp"
#include "dem/measure/measure.hpp"
#include "test_support.hpp"

using dem::Vec3;

TEST(Box, DilutePariclesFollowTheAffineFlowExactly) {
  // Particles far apart, at rest in the fluctuation frame: their box-scaled coordinates x/L
  // stay constant while the box deforms (affine motion), for any diagonal rate.
  const dem::Model m = dem_test::model_with();
  dem::State s = dem_test::make_state(Vec3(20e-3, 20e-3, 20e-3),
                                      {Vec3(3e-3, 4e-3, 5e-3), Vec3(13e-3, 14e-3, 15e-3), Vec3(7e-3, 17e-3, 11e-3)},
                                      {0.5e-3, 1e-3, 1.5e-3});
  std::vector<Vec3> reduced(3);
  for (int i = 0; i < 3; ++i) reduced[s.id[i]] = Vec3(s.position[i].x / 20e-3, s.position[i].y / 20e-3, s.position[i].z / 20e-3);
  const Vec3 rate = Vec3(0.3, -0.7, 0.2) * (1e-3 / m.t_contact);
  dem::Engine e(m, s);
  for (int k = 0; k < 5000; ++k) e.step(rate);
  for (int i = 0; i < 3; ++i)
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(s.position[i][a] / s.box.length[a], reduced[s.id[i]][a], 1e-12);
  // True strain equals rate * time exactly (up to round-off).
  const Vec3 eps = s.box.true_strain();
  EXPECT_NEAR(eps.x, rate.x * s.time, 1e-12);
  EXPECT_NEAR(eps.y, rate.y * s.time, 1e-12);
}

TEST(Box, D2AndD3ConserveVolumeAndGiveTheirEpsD) {
  for (const char* name : {"D2", "D3"}) {
    const dem::Model m = dem_test::model_with();
    dem::State s = dem_test::random_state(300, 0.38, 0.0, 5);
    const double v0 = s.box.volume();
    dem::DeformationMode dm;
    ASSERT_TRUE(dem::builtin_mode(name, &dm));
    const double rate = 1e-3 / m.t_contact;
    dem::Engine e(m, s);
    for (int k = 0; k < 20000; ++k) e.step(dm.shape.diag * rate);
    EXPECT_NEAR(s.box.volume() / v0, 1.0, 1e-12) << name;
    const auto q = dem::measure(m, s, e.neighbor_list(), dm.shape.diag * rate);
    const double eps = rate * s.time;   // magnitude of the rate-1 axis strain
    // eps_d = sqrt(((a-b)^2+(b-c)^2+(c-a)^2)/2): D2 (1,0,-1) -> sqrt(3) eps, D3 (1/2,1/2,-1) -> 3/2 eps
    const double expected = std::string(name) == "D2" ? std::sqrt(3.0) * eps : 1.5 * eps;
    EXPECT_NEAR(q.eps_d / expected, 1.0, 1e-10) << name;
    EXPECT_NEAR(q.eps_v, 0.0, 1e-13) << name;
    EXPECT_GT(q.eps_d, 0.3);
  }
}

TEST(Box, IsotropicCompressionReachesVolumeFraction) {
  const dem::Model m = dem_test::model_with();
  dem::State s = dem_test::random_state(200, 0.3, 0.0, 6);
  const double phi0 = s.volume_fraction();
  const double rate = 1e-3 / m.t_contact;
  dem::Engine e(m, s);
  for (int k = 0; k < 1000; ++k) e.step(Vec3(-rate, -rate, -rate));
  // phi = phi0 exp(3 rate t)
  EXPECT_NEAR(s.volume_fraction() / (phi0 * std::exp(3 * rate * s.time)), 1.0, 1e-12);
}
