// Conservation laws: energy without damping, momentum with contact damping.
#include <gtest/gtest.h>

#include <cmath>

#include "dem/engine/engine.hpp"
#include "dem/measure/measure.hpp"
#include "test_support.hpp"

using dem::Vec3;

namespace {
Vec3 momentum(const dem::State& s) {
  Vec3 p{0, 0, 0};
  for (int i = 0; i < s.count(); ++i) p += s.velocity[i] * s.mass[i];
  return p;
}
}  // namespace

TEST(Conservation, EnergyWithoutDampingVelocityVerlet) {
  // Dense gas with overlaps and motion; all damping off, box at rest.
  const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                                             "integration.dt_over_tc=0.02"});
  dem::State s = dem_test::random_state(300, 0.38, 0.5, 7);
  dem::Engine e(m, s);
  const Vec3 zero{0, 0, 0};
  auto total = [&]() {
    const auto meas = dem::measure(m, s, e.neighbor_list(), zero);
    return meas.E_kin + meas.E_pot;
  };
  const double e0 = total();
  double worst = 0;
  for (int k = 0; k < 20; ++k) {
    for (int j = 0; j < 1000; ++j) e.step(zero);
    worst = std::max(worst, std::fabs(total() - e0) / e0);
  }
  // Velocity Verlet: bounded O(dt^2) energy error, no drift. 1e-3 at dt = t_c/50.
  EXPECT_LT(worst, 1e-3);
  EXPECT_GT(e.neighbor_list().builds, 1);   // particles moved through the list
}

TEST(Conservation, EnergyErrorShrinksWithTimeStepSquared) {
  // Second order: halving dt divides the energy error by about 4.
  double err[2];
  for (int a = 0; a < 2; ++a) {
    const double dt = a == 0 ? 0.04 : 0.02;
    const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                                               "integration.dt_over_tc=" + std::to_string(dt)});
    dem::State s = dem_test::random_state(200, 0.38, 0.5, 11);
    dem::Engine e(m, s);
    const Vec3 zero{0, 0, 0};
    auto total = [&]() { auto q = dem::measure(m, s, e.neighbor_list(), zero); return q.E_kin + q.E_pot; };
    const double e0 = total();
    double worst = 0;
    const int steps = static_cast<int>(std::lround(200.0 / dt));
    for (int j = 0; j < steps; ++j) {
      e.step(zero);
      if (j % 50 == 0) worst = std::max(worst, std::fabs(total() - e0) / e0);
    }
    err[a] = worst;
  }
  EXPECT_GT(err[0] / err[1], 2.5);
  EXPECT_LT(err[0] / err[1], 6.0);
}

TEST(Conservation, MomentumWithContactDamping) {
  // Pair forces are equal and opposite, dashpot included: total momentum is conserved to
  // round-off when background damping is off, for both integrators and 1 or 2 threads.
  for (const char* integ : {"velocity_verlet", "symplectic_euler"})
    for (int threads : {1, 2}) {
      const dem::Model m = dem_test::model_with({"contact.background_damping_kg_s=0",
                                                 std::string("integration.integrator=") + integ,
                                                 "integration.threads=" + std::to_string(threads)});
      dem::State s = dem_test::random_state(300, 0.38, 0.5, 3);
      const Vec3 p0 = momentum(s);
      double scale = 0;
      for (int i = 0; i < s.count(); ++i) scale += s.mass[i] * norm(s.velocity[i]);
      dem::Engine e(m, s);
      for (int j = 0; j < 5000; ++j) e.step(Vec3(0, 0, 0));
      const Vec3 p1 = momentum(s);
      EXPECT_LT(norm(p1 - p0) / scale, 1e-12) << integ << " threads=" << threads;
    }
}

TEST(Conservation, BackgroundDampingDecaysFreeMotionExponentially) {
  // One free particle: m dv/dt = -gamma_b v  =>  v(t) = v0 exp(-gamma_b t / m).
  const dem::Model m = dem_test::model_with({"integration.dt_over_tc=0.02"});
  dem::State s = dem_test::make_state(Vec3(0.02, 0.02, 0.02), {Vec3(0.005, 0.01, 0.01), Vec3(0.015, 0.01, 0.01)},
                                      {1e-3, 1e-3});
  s.velocity[0] = Vec3(1e-3, 0, 0);
  dem::Engine e(m, s);
  const int steps = 20000;
  for (int j = 0; j < steps; ++j) e.step(Vec3(0, 0, 0));
  const int a = s.id[0] == 0 ? 0 : 1;
  const double expected = 1e-3 * std::exp(-m.background_damping * s.time / s.mass[a]);
  // Velocity Verlet evaluates the drag at the half-step velocity: a global relative error of
  // about n * 2 h^2 with h = gamma_b dt / (2 m) (first order in dt; 3e-5 here).
  const double h = m.background_damping * m.dt / (2 * s.mass[a]);
  EXPECT_NEAR(s.velocity[a].x / expected, 1.0, 1.5 * steps * 2 * h * h);
}
