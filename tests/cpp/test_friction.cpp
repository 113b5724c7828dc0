// Friction (Cundall-Strack on the contact-model wing), each against an independent truth:
// rigid-body impact theory, energy conservation, the all-pairs oracle, the frictionless law.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/control.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/collision.hpp"
#include "dem/contact/normal_luding.hpp"
#include "test_support.hpp"

using dem::Vec3;
using dem::VelGrad;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Chung & Ooi (2011) Test 4 adapted to two spheres: mu = 0.092, |v| = 3.9 m/s.
dem::Model impact_model(double mu, double r_min, double r_max, const std::vector<std::string>& more = {}) {
  std::vector<std::string> o = {"contact.friction=" + std::to_string(mu), "contact.background_damping_kg_s=0",
                                "particles.radius_min_m=" + std::to_string(r_min),
                                "particles.radius_max_m=" + std::to_string(r_max)};
  o.insert(o.end(), more.begin(), more.end());
  return dem_test::model_with(o);
}

// Rigid-body theory with I = 2/5 m R^2 for two spheres (relative velocities): the tangential
// compliance of the contact point is 7/2 that of the centres for any size ratio.
struct Theory {
  bool sliding;
  double e_t;         // v_t after / before, centres
  double omega[2];    // |w| of each sphere after [rad/s]
};
Theory theory(double mu, double e_n, double theta, double v, double r1, double r2, double m1, double m2) {
  const double mr = m1 * m2 / (m1 + m2), vn = v * std::cos(theta), vt = v * std::sin(theta);
  Theory t;
  t.sliding = std::tan(theta) > 3.5 * mu * (1 + e_n);
  const double Jt = t.sliding ? mu * (1 + e_n) * mr * vn : (2.0 / 7.0) * mr * vt;   // rolling: v_c -> 0
  t.e_t = 1.0 - Jt / (mr * vt);
  t.omega[0] = 2.5 * Jt / (m1 * r1);
  t.omega[1] = 2.5 * Jt / (m2 * r2);
  return t;
}

void expect_impacts_follow_rigid_body_theory(double r1, double r2, bool print) {
  const double mu = 0.092, v = 3.9;
  const dem::Model m = impact_model(mu, std::min(r1, r2), std::max(r1, r2));
  const double m1 = dem::sphere_mass(r1, m.density), m2 = dem::sphere_mass(r2, m.density);
  if (print) std::printf("theta_deg  e_n     e_t     e_t_theory  w0_rad_s  w0_theory  w1_rad_s  w1_theory  regime\n");
  for (int deg = 5; deg <= 85; deg += 5) {
    const double theta = deg * kPi / 180.0;
    const dem::ObliqueResult r = dem::simulate_oblique_collision(m, r1, r2, v, theta);
    const Theory t = theory(mu, r.normal_restitution, theta, v, r1, r2, m1, m2);
    const double w0 = r.omega[0].y, w1 = r.omega[1].y;   // spin about y (normal z, slip along x)
    if (print)
      std::printf("%9d  %.4f  %.4f  %.4f      %8.1f  %8.1f   %8.1f  %8.1f   %s\n", deg, r.normal_restitution,
                  r.tangential_restitution, t.e_t, w0, t.omega[0], w1, t.omega[1], t.sliding ? "sliding" : "sticking");
    // Both spheres spin the same way (the friction on each opposes its own slip).
    EXPECT_GT(w0 * w1, 0.0) << deg;
    if (std::tan(theta) > 1.3 * 3.5 * mu * (1 + r.normal_restitution)) {   // well inside gross sliding
      EXPECT_NEAR(r.tangential_restitution, t.e_t, 0.01) << deg << " deg";
      EXPECT_NEAR(std::fabs(w0), t.omega[0], 0.01 * t.omega[0]) << deg << " deg";
      EXPECT_NEAR(std::fabs(w1), t.omega[1], 0.01 * t.omega[1]) << deg << " deg";
    } else if (deg <= 10) {
      // Maw's regime without slip: with k_t/k = 2/7 the tangential oscillation of the contact
      // point (stiffness k_t, effective mass 2/7 m_r) has the normal one's period, so over the
      // contact it turns once: v_c reverses fully, twice the rigid (rolling) impulse. Then
      // e_t = 1 - 2 (2/7) = 3/7 and each spin is twice the rolling one.
      EXPECT_NEAR(r.tangential_restitution, 3.0 / 7.0, 0.01) << deg;
      EXPECT_NEAR(std::fabs(w0), 2 * t.omega[0], 0.02 * t.omega[0]) << deg;
      EXPECT_NEAR(std::fabs(w1), 2 * t.omega[1], 0.02 * t.omega[1]) << deg;
    }
  }
}

}  // namespace

TEST(Friction, ObliqueImpactsOfEqualSpheresFollowRigidBodyTheory) {
  expect_impacts_follow_rigid_body_theory(1e-3, 1e-3, true);
}

// Size ratio w = 3 (LAMMPS PR #4244 reports unphysical sticking of the project-and-rescale
// spring at large size ratios): the same closed forms hold in relative velocities.
TEST(Friction, ObliqueImpactsAtSizeRatioThreeFollowRigidBodyTheory) {
  expect_impacts_follow_rigid_body_theory(0.5e-3, 1.5e-3, true);
}

// The same impact with one sphere an image across the boundary of a sheared cell gives the same
// impulses once the image's affine velocity is part of the relative velocity.
TEST(Friction, ImpactAcrossASheredBoundaryGivesTheSameImpulses) {
  const dem::Model m = impact_model(0.3, 1e-3, 1e-3);
  for (double deg : {20.0, 60.0}) {
    const double theta = deg * kPi / 180.0;
    const dem::ObliqueResult plain = dem::simulate_oblique_collision(m, 1e-3, 1e-3, 3.9, theta);
    const dem::ObliqueResult across = dem::simulate_oblique_collision(m, 1e-3, 1e-3, 3.9, theta, true, 200.0);
    EXPECT_NEAR(across.normal_impulse, plain.normal_impulse, 2e-3 * plain.normal_impulse) << deg;
    EXPECT_NEAR(across.tangential_impulse, plain.tangential_impulse, 2e-3 * std::fabs(plain.tangential_impulse)) << deg;
    EXPECT_NEAR(across.omega[0].y, plain.omega[0].y, 2e-3 * std::fabs(plain.omega[0].y)) << deg;
  }
}

// mu = 0 with the frictional model: zero tangential force, so the trajectory is the frictionless
// law's, bit for bit (the frictional loop adds the same normal forces in the same order).
TEST(Friction, ZeroFrictionCoefficientGivesTheFrictionlessBits) {
  const dem::Model smooth = dem_test::model_with({"integration.threads=1"});
  const dem::Model rough = dem_test::model_with({"integration.threads=1", "contact.tangential=cundall_strack",
                                                 "contact.friction=0"});
  dem::State a = dem_test::random_state(300, 0.38, 1.0, 3), b = a;
  const VelGrad rate = Vec3(1, 0, -1) * (2e-3 / smooth.t_contact);
  dem::Engine ea(smooth, a), eb(rough, b);
  ea.set_pair_kernel(dem::PairKernel::reference);
  for (int k = 0; k < 2000; ++k) { ea.step(rate); eb.step(rate); }
  EXPECT_GT(eb.neighbor_list().builds, 2);
  EXPECT_TRUE(b.rotations());
  EXPECT_FALSE(a.rotations());
  EXPECT_TRUE(dem_test::same_bits(a.position, b.position));
  EXPECT_TRUE(dem_test::same_bits(a.velocity, b.velocity));
}

namespace {

// Energy balance with friction and damping off: the change of E_kin + E_rot + E_springs plus the
// energy the Coulomb limit dissipated equals the work of the stress, -int V sigma^T : L dt.
struct FrictionBalance {
  double error = 0, work = 0, dissipated = 0, scale = 0;
};

FrictionBalance friction_balance(double dt_over_tc, double time, const VelGrad& shape, bool objective = true,
                                 double mu = 0.5, double rate_tc = 1e-2) {
  dem::Model m = dem_test::model_with({"contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                                       "contact.tangential=cundall_strack", "contact.friction=" + std::to_string(mu),
                                       "integration.threads=1",
                                       "integration.dt_over_tc=" + std::to_string(dt_over_tc)});
  m.contact.set("objective_spring", objective ? 1.0 : 0.0);
  dem::State s = dem_test::random_state(300, 0.36, 2.0, 11);
  const VelGrad rate = shape * (rate_tc / m.t_contact);   // fast: contacts rotate and slide
  dem::Engine e(m, s);
  auto energy = [&]() {
    const auto q = dem::measure(m, s, e.neighbor_list(), rate);
    return q.E_kin + q.E_rot + q.E_pot + s.friction_dissipated;
  };
  // -V sigma^T : L for an upper-triangular L (contact + kinetic stress; the antisymmetric part
  // of d (x) f_t enters with the transpose).
  auto power = [&]() {
    const auto q = dem::measure(m, s, e.neighbor_list(), rate);
    const dem::Sym3& t = q.stress;
    const Vec3& a = q.stress_antisym;
    return -s.box.volume() * (t.xx * rate.diag.x + t.yy * rate.diag.y + t.zz * rate.diag.z +
                              (t.xy - a.x) * rate.shear.x + (t.xz - a.y) * rate.shear.y + (t.yz - a.z) * rate.shear.z);
  };
  FrictionBalance b;
  const double e0 = energy();
  const long steps = std::lround(time / m.dt);
  double p0 = power();
  for (long k = 0; k < steps; ++k) {
    e.step(rate);
    const double p1 = power();
    b.work += 0.5 * (p0 + p1) * m.dt;
    p0 = p1;
  }
  b.dissipated = s.friction_dissipated;
  b.error = energy() - e0 - b.work;
  b.scale = std::fabs(b.work) + b.dissipated;
  return b;
}

}  // namespace

TEST(Friction, EnergyBalanceIsSecondOrderInD2AndSimpleShear) {
  // Measured (300 spheres, mu = 0.5, rate 1e-3/t_c, 16 t_c): the error falls 2.9-3.7 times per
  // halving of dt from t_c/25 to t_c/200 (frictionless, the same harness: 2.7-4.5).
  for (const VelGrad& shape : {VelGrad{Vec3{1, 0, -1}, Vec3{0, 0, 0}}, VelGrad{Vec3{0, 0, 0}, Vec3{0, 1, 0}}}) {
    const double T = 400 * 0.04 * dem_test::model_with({}).t_contact;
    const FrictionBalance coarse = friction_balance(0.02, T, shape, true, 0.5, 1e-3);
    const FrictionBalance fine = friction_balance(0.01, T, shape, true, 0.5, 1e-3);
    std::printf("shear %g: work %.4g J, friction %.4g J, error %.3g J (t_c/50) %.3g J (t_c/100)\n", shape.shear.y,
                coarse.work, coarse.dissipated, coarse.error, fine.error);
    EXPECT_GT(coarse.dissipated, 0.3 * coarse.scale);   // friction did real work
    EXPECT_LT(std::fabs(fine.error), 2e-3 * fine.scale);
    EXPECT_GT(std::fabs(coarse.error) / std::fabs(fine.error), 2.5);   // second order: about 4
  }
}

// Mutation check: a spring that is not rotated with the contact (not objective) keeps a
// normal component that does work; the balance must see it (fast shear: contacts turn).
TEST(Friction, EnergyBalanceCatchesANonObjectiveSpringRotation) {
  const VelGrad shape{Vec3{0, 0, 0}, Vec3{0, 1, 0}};
  const double T = 400 * 0.04 * dem_test::model_with({}).t_contact;
  const FrictionBalance good = friction_balance(0.01, T, shape, true);
  const FrictionBalance bad = friction_balance(0.01, T, shape, false);
  std::printf("objective %.3g J, not objective %.3g J (scale %.3g J)\n", good.error, bad.error, good.scale);
  EXPECT_GT(std::fabs(bad.error), 10 * std::fabs(good.error));
}

// The list with its history against the all-pairs oracle, on states along a sheared run
// (rebuilds, re-sorts and cell flips): the same forces, torques and updated springs.
// With rolling and twisting on as well, every history entry is compared: the odd/even rule of
// place_history and history_by_ids (tangential spring odd, rolling and twisting springs even
// under i <-> j) is what makes the list (rows in cell order) and the oracle (pairs oriented by
// id) agree on the pairs whose two orientations differ.
// wrong_bits: a mutation check, history entries wrongly declared odd in the conversion to the
// oracle's orientation, which must make the torques disagree.
static void expect_list_with_history_equals_oracle(const std::vector<std::string>& keys, unsigned wrong_bits = 0) {
  const dem::Model m = dem_test::model_with(keys);
  dem::State s = dem_test::random_state(400, 0.38, 0.5, 17);
  const VelGrad rate{Vec3{0, 0, 0}, Vec3{0, 0.4 / (3000 * m.dt), 0}};   // gamma = 0.4 per 3000 steps
  dem::Engine e(m, s);
  int checked = 0;
  double wrong_tdiff = 0;
  for (int k = 1; k <= 6000; ++k) {
    e.step(rate);
    if (k % 1000 != 0) continue;
    dem::State a = s, b = s;
    dem::ForceScratch scratch;
    dem::compute_forces(m, a, e.neighbor_list(), rate, 1, 1, scratch);
    dem::PairHistoryMap oracle = dem::history_by_ids(s);
    dem::compute_forces_all_pairs(m, b, rate, &oracle);
    const double fscale = dem_test::max_force(a);
    ASSERT_GT(fscale, 0);
    EXPECT_LT(dem_test::max_force_difference(a, b), 1e-9 * fscale) << "step " << k;
    double tscale = 0, tdiff = 0;
    for (int i = 0; i < s.count(); ++i) {
      tscale = std::max(tscale, norm(a.torque[i]));
      tdiff = std::max(tdiff, norm(a.torque[i] - b.torque[i]));
    }
    EXPECT_LT(tdiff, 1e-9 * tscale) << "step " << k;
    if (wrong_bits != 0) {
      dem::State w = s, c = s;
      w.history.odd |= wrong_bits;
      dem::PairHistoryMap wrong = dem::history_by_ids(w);
      dem::compute_forces_all_pairs(m, c, rate, &wrong);
      for (int i = 0; i < s.count(); ++i) wrong_tdiff = std::max(wrong_tdiff, norm(a.torque[i] - c.torque[i]) / tscale);
    }
    const dem::PairHistoryMap listed = dem::history_by_ids(a);
    ASSERT_EQ(listed.size(), oracle.size()) << "step " << k;
    ASSERT_GT(listed.size(), 8u);
    double xscale = 0, xdiff = 0;
    for (const auto& [key, h] : listed) {
      const auto it = oracle.find(key);
      ASSERT_NE(it, oracle.end());
      for (int c = 0; c < static_cast<int>(h.size()); ++c) {
        if (c == 3) continue;
        xscale = std::max(xscale, std::fabs(h[c]));
        xdiff = std::max(xdiff, std::fabs(h[c] - it->second[c]));
      }
      EXPECT_EQ(h[3], it->second[3]);   // slip flags
    }
    EXPECT_LT(xdiff, 1e-9 * xscale) << "step " << k;
    ++checked;
  }
  EXPECT_EQ(checked, 6);
  EXPECT_GE(e.flips(), 1);
  EXPECT_GT(e.neighbor_list().builds, 10);
  if (wrong_bits != 0) EXPECT_GT(wrong_tdiff, 1e-3) << "a wrong odd mask should change the oracle's torques";
}

TEST(Friction, ListWithHistoryEqualsTheAllPairsOracleAcrossRebuildsAndFlips) {
  expect_list_with_history_equals_oracle({"contact.friction=0.5", "integration.threads=1"});
}

// Hertz-Mindlin (test_hertz.cpp): the per-pair normal (a12 and m* from the masses) and Mindlin's
// history (xi, slip, k_t) against the oracle, for both rules of a changing k_t.
TEST(Mindlin, ListWithHertzMindlinHistoryEqualsTheAllPairsOracle) {
  for (const char* rule : {"mindlin", "mindlin_force"})
    expect_list_with_history_equals_oracle({"contact.normal=\"hertz\"", std::string("contact.tangential=\"") + rule + "\"",
                                            "contact.friction=0.5", "contact.restitution=0.5", "integration.threads=1"});
}

TEST(Twisting, ListWithRollingAndTwistingHistoryEqualsTheAllPairsOracle) {
  // The twist spring is entry 7 (after xi_t, slip, xi_r): declaring it odd must be caught.
  expect_list_with_history_equals_oracle({"contact.friction=0.5", "contact.rolling_friction=0.1",
                                          "contact.twisting_friction=0.1", "integration.threads=1"}, 1u << 7);
}

// The springs are carried by the pair's ids: a run rebuilding its list every few steps (thin
// skin) and one rebuilding rarely (thick skin) hold the same springs after the same steps.
TEST(Friction, SpringsDoNotDependOnHowOftenTheListIsRebuilt) {
  const VelGrad shape{Vec3{0, 0, 0}, Vec3{0, 1, 0}};
  auto run = [&](double skin, long* builds) {
    const dem::Model m = dem_test::model_with({"contact.friction=0.5", "integration.threads=1",
                                               "integration.skin_over_rmin=" + std::to_string(skin)});
    dem::State s = dem_test::random_state(300, 0.36, 2.0, 23);
    dem::Engine e(m, s);
    for (int k = 0; k < 1500; ++k) e.step(shape * (0.3 / (1500 * m.dt)));
    *builds = e.neighbor_list().builds;
    return dem::history_by_ids(s);
  };
  long thin_builds = 0, thick_builds = 0;
  const dem::PairHistoryMap thin = run(0.05, &thin_builds), thick = run(1.5, &thick_builds);
  EXPECT_GT(thin_builds, 5 * thick_builds);
  ASSERT_GT(thin.size(), 8u);
  EXPECT_EQ(thin.size(), thick.size());
  double scale = 0, diff = 0;
  for (const auto& [key, h] : thin) {
    const auto it = thick.find(key);
    ASSERT_NE(it, thick.end());
    for (int c = 0; c < 3; ++c) { scale = std::max(scale, std::fabs(h[c])); diff = std::max(diff, std::fabs(h[c] - it->second[c])); }
  }
  EXPECT_LT(diff, 1e-6 * scale);   // other summation orders only (chaos grows from 1e-16)
}

TEST(Friction, SplitRunEqualsStraightRunBitForBit) {
  for (int threads : {1, 2}) {
    const dem::Model m = dem_test::model_with({"contact.friction=0.5", "integration.threads=" + std::to_string(threads)});
    const VelGrad rate{Vec3{0, 0, 0}, Vec3{0, 0.3 / (3000 * m.dt), 0}};
    dem::State straight = dem_test::random_state(300, 0.38, 1.0, 29);
    dem::State split = straight;
    {
      dem::Engine e(m, straight);
      for (int k = 0; k < 3000; ++k) e.step(rate);
    }
    const std::string path = (std::filesystem::temp_directory_path() / "dem_friction_split.ckpt").string();
    {
      dem::Engine e(m, split);
      for (int k = 0; k < 1500; ++k) e.step(rate);
      dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split});
    }
    dem::Checkpoint c = dem::read_checkpoint(path);
    std::remove(path.c_str());
    EXPECT_EQ(c.state.history.width, 4);
    dem::Engine e2(m, c.state, /*forces_are_current=*/true);
    for (int k = 0; k < 1500; ++k) e2.step(rate);
    EXPECT_TRUE(dem_test::same_bits(c.state.position, straight.position)) << threads;
    EXPECT_TRUE(dem_test::same_bits(c.state.angular_velocity, straight.angular_velocity)) << threads;
    EXPECT_EQ(c.state.history.values.size(), straight.history.values.size());
    EXPECT_EQ(0, std::memcmp(c.state.history.values.data(), straight.history.values.data(),
                             straight.history.values.size() * sizeof(double)));
    EXPECT_EQ(c.state.friction_dissipated, straight.friction_dissipated);
  }
}

TEST(Friction, ThreadsGiveTheSameBits) {
  std::vector<Vec3> ref;
  for (int threads : {1, 2, 3}) {
    const dem::Model m = dem_test::model_with({"contact.friction=0.5", "integration.threads=" + std::to_string(threads)});
    dem::State s = dem_test::random_state(300, 0.38, 1.0, 31);
    dem::Engine e(m, s);
    for (int k = 0; k < 1500; ++k) e.step(VelGrad{Vec3{1, 0, -1} * (2e-3 / m.t_contact), Vec3{0, 0, 0}});
    if (ref.empty()) ref = s.angular_velocity;
    else EXPECT_TRUE(dem_test::same_bits(ref, s.angular_velocity)) << threads;
  }
}

TEST(Friction, SceneKeysComposeAndBadValuesAreRefused) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5"});
  EXPECT_EQ(m.contact.model(dem::ContactSlot::Tangential), "cundall_strack");
  EXPECT_NEAR(m.contact.get("tangential_stiffness_ratio"), 2.0 / 7.0, 1e-15);
  EXPECT_FALSE(dem_test::model_with({}).contact.frictional());
  std::string resolved;   // a frictionless scene's resolved text (stored with every result) is unchanged
  dem::load_scene("[particles]\ncount = 100\n", {}, &resolved);
  EXPECT_EQ(resolved.find("friction"), std::string::npos);
  EXPECT_EQ(resolved.find("tangential"), std::string::npos);
  EXPECT_THROW(dem_test::model_with({"contact.friction=-0.1"}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.friction=0.5", "contact.tangential=\"none\""}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.tangential=\"mindlin_deresiewicz\""}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.tangential_stiffness_ratio=0.5"}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.friction=0.5", "contact.tangential_stiffness_ratio=0"}), dem::SceneError);
}

// The servo's affine stiffness with friction: a sticking spring adds k_t l^2 (delta_ab n_a^2 -
// n_a^2 n_b^2) / V to M. Checked against the stress change that one engine step of a tiny strain
// causes beyond the same step without strain (the free motion cancels).
TEST(Friction, AffineStiffnessOfAStickingContactMatchesTheStressChange) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.damping_kg_s=0",
                                             "contact.background_damping_kg_s=0"});
  const Vec3 n{0.6, 0.8, 0.0};
  const double l = 1.99e-3;
  dem::State s = dem_test::make_state(Vec3{10e-3, 10e-3, 10e-3}, {Vec3{4e-3, 4e-3, 5e-3}, Vec3{4e-3, 4e-3, 5e-3} + n * l},
                                      {1e-3, 1e-3});
  dem::State still = s;
  dem::Engine e(m, s), e0(m, still);
  const double strain = 1e-9, rate = strain / m.dt;   // extension along x in one step
  const dem::AxisResponse r0 = dem::axis_response(m, s, e.neighbor_list(), Vec3{0, 0, 0});
  e.step(Vec3{rate, 0, 0});
  e0.step(Vec3{0, 0, 0});
  const dem::AxisResponse r1 = dem::axis_response(m, s, e.neighbor_list(), Vec3{0, 0, 0});
  const dem::AxisResponse rs = dem::axis_response(m, still, e0.neighbor_list(), Vec3{0, 0, 0});
  const double V = s.box.volume(), k = m.contact.get("stiffness_N_m"), kt = k * m.contact.get("tangential_stiffness_ratio");
  const double n2[3] = {n.x * n.x, n.y * n.y, n.z * n.z};
  // sigma V changes by -M V strain; the volume change itself divides the stress by (1 + strain)
  const double sv[3] = {r1.stress.xx * V - rs.stress.xx * still.box.volume(), r1.stress.yy * V - rs.stress.yy * still.box.volume(),
                        r1.stress.zz * V - rs.stress.zz * still.box.volume()};
  for (int a = 0; a < 3; ++a) {
    const double closed = l * l * (k * n2[a] * n2[0] + kt * ((a == 0 ? n2[a] : 0.0) - n2[a] * n2[0])) / V;
    EXPECT_NEAR(r0.M[a][0], closed, 1e-9 * std::fabs(closed) + 1e-6) << a;
    // per unit compressive strain, less the pre-stress term f_a delta(d_a) that M leaves out
    const double geometric = a == 0 ? r0.stress.xx * V * strain : 0.0;
    const double fd = -(sv[a] - geometric) / (V * strain);
    EXPECT_NEAR(fd, closed, 1e-2 * std::fabs(r0.M[0][0])) << a;
  }
  EXPECT_GT(std::fabs(r0.M[1][0] - l * l * k * n2[1] * n2[0] / V), 0.1 * std::fabs(r0.M[1][0]));   // friction matters
}

namespace {

// Four equal spheres in a ring along x (each pressed by both neighbours: no net force), spins
// alternating +-w0 about z: every contact rolls (the contact points do not slip: a_i w_i + a_j w_j
// = 0) with relative spin 2 w0. Returns the state after `steps` steps and records w_0(t).
struct Ring {
  dem::Model m;
  dem::State s;
  double a_red, fn, I;
};
Ring make_ring(double w0, double mu_r) {
  Ring g{dem_test::model_with({"contact.friction=0.5", "contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                               "contact.rolling_friction=" + std::to_string(mu_r)}), {}, 0, 0, 0};
  const double r = 1e-3, delta = 1e-5, pitch = 2 * r - delta;
  std::vector<Vec3> x;
  for (int k = 0; k < 4; ++k) x.push_back(Vec3{(k + 0.5) * pitch, 5e-3, 5e-3});
  g.s = dem_test::make_state(Vec3{4 * pitch, 10e-3, 10e-3}, x, {r, r, r, r});
  g.s.angular_velocity.assign(4, Vec3{0, 0, 0});
  g.s.torque.assign(4, Vec3{0, 0, 0});
  for (int k = 0; k < 4; ++k) g.s.angular_velocity[k] = Vec3{0, 0, (k % 2 ? -1.0 : 1.0) * w0};
  const double a = r - delta / 2;
  g.a_red = a * a / (2 * a);
  g.fn = g.m.contact.get("stiffness_N_m") * delta;
  g.I = 0.4 * g.s.mass[0] * r * r;
  return g;
}
double spin_of_id0(const dem::State& s) {
  for (int i = 0; i < s.count(); ++i) if (s.id[i] == 0) return s.angular_velocity[i].z;
  return NAN;
}

}  // namespace

// Elastic rolling: per contact the spring k_r acts on a' times the relative rotation 2 phi, so
// I phi'' = -2 k_r a'^2 (2 phi): w_0 = w0 cos(Omega t), Omega^2 = 4 k_r a'^2 / I; energy kept.
TEST(Rolling, ElasticRollingOscillatesAtTheSpringsFrequencyAndKeepsEnergy) {
  Ring g = make_ring(1e4, 1.0);
  dem::Engine e(g.m, g.s);
  const double kr = g.m.contact.get("rolling_stiffness_ratio") * g.m.contact.get("stiffness_N_m");
  const double omega = std::sqrt(4 * kr * g.a_red * g.a_red / g.I);
  auto energy = [&] {
    const auto q = dem::measure(g.m, g.s, e.neighbor_list(), Vec3{0, 0, 0});
    return q.E_rot + q.E_pot + q.E_kin;
  };
  const double e0 = energy();
  double prev = spin_of_id0(g.s), t_zero = -1, worst = 0;
  for (int k = 0; k < 2000 && t_zero < 0; ++k) {
    const double t0 = g.s.time;
    e.step(Vec3{0, 0, 0});
    const double now = spin_of_id0(g.s);
    if (prev > 0 && now <= 0) t_zero = t0 + (g.s.time - t0) * prev / (prev - now);
    prev = now;
    worst = std::max(worst, std::fabs(energy() - e0));
  }
  ASSERT_GT(t_zero, 0);
  EXPECT_NEAR(t_zero, 0.5 * kPi / omega, 5e-3 * 0.5 * kPi / omega);   // a quarter period
  EXPECT_LT(worst, 2e-3 * e0);
}

// At the limit the rolling torque is mu_r a' f_n per contact: the spin decays at the constant
// rate 2 mu_r a' f_n / I (rolling friction) until the spring can hold it.
TEST(Rolling, TheRollingTorqueLimitDeceleratesTheSpinAtTheClosedFormRate) {
  const double w0 = 1e6, mu_r = 0.1;
  Ring g = make_ring(w0, mu_r);
  dem::Engine e(g.m, g.s);
  const double rate = 2 * mu_r * g.a_red * g.fn / g.I;   // [rad/s^2]
  const double t_stop = w0 / rate;
  double w_a = NAN, w_b = NAN, t_a = 0.25 * t_stop, t_b = 0.75 * t_stop;
  while (g.s.time < t_b) {
    e.step(Vec3{0, 0, 0});
    if (std::isnan(w_a) && g.s.time >= t_a) { w_a = spin_of_id0(g.s); t_a = g.s.time; }
  }
  w_b = spin_of_id0(g.s);
  t_b = g.s.time;
  EXPECT_NEAR((w_a - w_b) / (t_b - t_a), rate, 1e-2 * rate);
  // The spin energy lost is what the limit dissipated (no damping anywhere else).
  const auto q = dem::measure(g.m, g.s, e.neighbor_list(), Vec3{0, 0, 0});
  const double e_rot0 = 4 * 0.5 * g.I * w0 * w0;
  EXPECT_NEAR(q.W_friction, e_rot0 - q.E_rot - q.E_t - q.E_kin, 1e-3 * e_rot0);
  EXPECT_GT(q.W_friction, 0.5 * e_rot0);
}

// Constructing an engine evaluates the forces of the state as it is: the springs are not
// advanced (no time passes) and nothing is dissipated.
TEST(Friction, ConstructingAnEngineDoesNotAdvanceTheSprings) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=0.1"});
  dem::State s = dem_test::random_state(300, 0.38, 1.0, 41);
  { dem::Engine e(m, s); for (int k = 0; k < 500; ++k) e.step(Vec3{1, 0, -1} * (1e-3 / m.t_contact)); }
  const std::vector<double> springs = s.history.values;
  const double w = s.friction_dissipated;
  ASSERT_GT(std::count_if(springs.begin(), springs.end(), [](double v) { return v != 0.0; }), 10);
  dem::Engine again(m, s);
  EXPECT_EQ(s.history.values, springs);
  EXPECT_EQ(s.friction_dissipated, w);
}

TEST(Rolling, KeysNeedFrictionAndAreRecorded) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=0.1"});
  EXPECT_TRUE(m.contact.rolling());
  EXPECT_EQ(dem::contact::history_width(m.contact), 7);
  EXPECT_THROW(dem_test::model_with({"contact.rolling_friction=0.1"}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=-1"}), dem::SceneError);
}

// Rolling springs are history too: a split run equals the straight one bit for bit.
TEST(Rolling, SplitRunWithRollingEqualsStraightRunBitForBit) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=0.1", "integration.threads=2"});
  const VelGrad rate{Vec3{0, 0, 0}, Vec3{0, 0.3 / (3000 * m.dt), 0}};
  dem::State straight = dem_test::random_state(300, 0.38, 1.0, 37), split = straight;
  { dem::Engine e(m, straight); for (int k = 0; k < 2000; ++k) e.step(rate); }
  const std::string path = (std::filesystem::temp_directory_path() / "dem_rolling_split.ckpt").string();
  { dem::Engine e(m, split); for (int k = 0; k < 1000; ++k) e.step(rate); dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split}); }
  dem::Checkpoint c = dem::read_checkpoint(path);
  std::remove(path.c_str());
  dem::Engine e2(m, c.state, true);
  for (int k = 0; k < 1000; ++k) e2.step(rate);
  EXPECT_TRUE(dem_test::same_bits(c.state.angular_velocity, straight.angular_velocity));
  EXPECT_EQ(0, std::memcmp(c.state.history.values.data(), straight.history.values.data(),
                           straight.history.values.size() * sizeof(double)));
}

namespace {

// The ring of four spheres along x again, now spinning about x (the contact normals) with
// alternating signs: every contact twists at relative spin 2 w0 about its normal; neither the
// tangential spring (the contact points do not move: the spins are along n) nor the rolling
// spring ((w_i - w_j) x n = 0) is loaded.
Ring make_twist_ring(double w0, double mu_o, double gamma_o) {
  Ring g = make_ring(0.0, 0.0);
  g.m = dem_test::model_with({"contact.friction=0.5", "contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                              "contact.twisting_friction=" + std::to_string(mu_o),
                              "contact.twisting_damping_kg_s=" + std::to_string(gamma_o)});
  for (int k = 0; k < 4; ++k) g.s.angular_velocity[k] = Vec3{(k % 2 ? -1.0 : 1.0) * w0, 0, 0};
  return g;
}
double twist_of_id0(const dem::State& s) {
  for (int i = 0; i < s.count(); ++i) if (s.id[i] == 0) return s.angular_velocity[i].x;
  return NAN;
}

}  // namespace

// Elastic twisting: per contact the spring k_o acts on a' times the relative twist 2 phi, two
// contacts per sphere: I phi'' = -4 k_o a'^2 phi, w_0 = w0 cos(Omega t), Omega^2 = 4 k_o a'^2/I;
// the energy E_rot + E_pot (the twist springs are in E_t, part of E_pot) is kept.
TEST(Twisting, ElasticTwistOscillatesAtTheSpringsFrequencyAndKeepsEnergy) {
  Ring g = make_twist_ring(1e4, 1.0, 0.0);
  dem::Engine e(g.m, g.s);
  const double ko = g.m.contact.get("twisting_stiffness_ratio") * g.m.contact.get("stiffness_N_m");
  const double omega = std::sqrt(4 * ko * g.a_red * g.a_red / g.I);
  auto energy = [&] {
    const auto q = dem::measure(g.m, g.s, e.neighbor_list(), Vec3{0, 0, 0});
    return q.E_rot + q.E_pot + q.E_kin;
  };
  const double e0 = energy();
  double prev = twist_of_id0(g.s), t_zero = -1, worst = 0, e_t_max = 0;
  for (int k = 0; k < 2000 && t_zero < 0; ++k) {
    const double t0 = g.s.time;
    e.step(Vec3{0, 0, 0});
    const double now = twist_of_id0(g.s);
    if (prev > 0 && now <= 0) t_zero = t0 + (g.s.time - t0) * prev / (prev - now);
    prev = now;
    worst = std::max(worst, std::fabs(energy() - e0));
    e_t_max = std::max(e_t_max, dem::measure(g.m, g.s, e.neighbor_list(), Vec3{0, 0, 0}).E_t);
  }
  ASSERT_GT(t_zero, 0);
  EXPECT_NEAR(t_zero, 0.5 * kPi / omega, 5e-3 * 0.5 * kPi / omega);   // a quarter period
  EXPECT_LT(worst, 2e-3 * e0);
  EXPECT_GT(e_t_max, 0.9 * 4 * 0.5 * g.I * 1e4 * 1e4);   // at the quarter period the springs hold the spin energy
  for (const Vec3& w : g.s.angular_velocity) {   // only twist
    EXPECT_EQ(w.y, 0.0);
    EXPECT_EQ(w.z, 0.0);
  }
}

// With the twisting dashpot: phi'' + 2 eta phi' + Omega^2 phi = 0, eta = 2 gamma_o a'^2/I, so
// w_0(t) = w0 exp(-eta t) (cos(w_d t) - eta/w_d sin(w_d t)), w_d^2 = Omega^2 - eta^2.
TEST(Twisting, DampedTwistFollowsTheSpringDashpotClosedForm) {
  Ring probe = make_twist_ring(1e4, 1.0, 0.0);
  const double ko = probe.m.contact.get("twisting_stiffness_ratio") * probe.m.contact.get("stiffness_N_m");
  const double omega = std::sqrt(4 * ko * probe.a_red * probe.a_red / probe.I);
  const double eta = 0.2 * omega, gamma_o = eta * probe.I / (2 * probe.a_red * probe.a_red);
  Ring g = make_twist_ring(1e4, 1.0, gamma_o);
  dem::Engine e(g.m, g.s);
  const double wd = std::sqrt(omega * omega - eta * eta), w0 = 1e4;
  double worst = 0;
  while (g.s.time < 3 * kPi / wd) {
    e.step(Vec3{0, 0, 0});
    const double t = g.s.time;
    const double closed = w0 * std::exp(-eta * t) * (std::cos(wd * t) - eta / wd * std::sin(wd * t));
    worst = std::max(worst, std::fabs(twist_of_id0(g.s) - closed));
  }
  EXPECT_LT(worst, 1e-2 * w0);
  // 1.5 periods at zeta = 0.2: |w| = w0 exp(-3 pi eta/w_d) = 0.146 w0 (without the dashpot: w0)
  EXPECT_LT(std::fabs(twist_of_id0(g.s)), 0.2 * w0);
}

// At the limit the twisting torque is mu_o a' f_n per contact: the spin decays at the constant
// rate 2 mu_o a' f_n / I, and the spin energy lost is W_friction.
TEST(Twisting, TheTwistingTorqueLimitDeceleratesTheSpinAtTheClosedFormRate) {
  const double w0 = 1e6, mu_o = 0.1;
  Ring g = make_twist_ring(w0, mu_o, 0.0);
  dem::Engine e(g.m, g.s);
  const double rate = 2 * mu_o * g.a_red * g.fn / g.I;
  const double t_stop = w0 / rate;
  double w_a = NAN, t_a = 0.25 * t_stop, t_b = 0.75 * t_stop;
  while (g.s.time < t_b) {
    e.step(Vec3{0, 0, 0});
    if (std::isnan(w_a) && g.s.time >= t_a) { w_a = twist_of_id0(g.s); t_a = g.s.time; }
  }
  const double w_b = twist_of_id0(g.s);
  t_b = g.s.time;
  EXPECT_NEAR((w_a - w_b) / (t_b - t_a), rate, 1e-2 * rate);
  const auto q = dem::measure(g.m, g.s, e.neighbor_list(), Vec3{0, 0, 0});
  const double e_rot0 = 4 * 0.5 * g.I * w0 * w0;
  EXPECT_NEAR(q.W_friction, e_rot0 - q.E_rot - q.E_t - q.E_kin, 1e-3 * e_rot0);
  EXPECT_GT(q.W_friction, 0.5 * e_rot0);
}

TEST(Twisting, KeysNeedFrictionAreRecordedAndOffByDefault) {
  EXPECT_FALSE(dem_test::model_with({"contact.friction=0.5"}).contact.twisting());
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.twisting_friction=0.1"});
  EXPECT_TRUE(m.contact.twisting());
  EXPECT_EQ(dem::contact::history_width(m.contact), 8);   // xi_t, slip, xi_r, xi_o
  EXPECT_EQ(dem::contact::history_odd_mask(m.contact), 0x7u);   // only the tangential spring is odd
  const dem::Model both = dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=0.1",
                                                "contact.twisting_friction=0.1", "contact.normal=luding"});
  EXPECT_EQ(dem::contact::history_width(both.contact), 9);   // + delta_max first
  EXPECT_EQ(dem::contact::history_odd_mask(both.contact), 0x7u << 1);
  bool recorded = false;
  for (const auto& kv : dem::material_physics(m)) recorded |= kv.first == "contact.twisting_friction";
  EXPECT_TRUE(recorded);
  EXPECT_THROW(dem_test::model_with({"contact.twisting_friction=0.1"}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.friction=0.5", "contact.twisting_friction=-1"}), dem::SceneError);
  EXPECT_THROW(dem_test::model_with({"contact.friction=0.5", "contact.twisting_friction=0.1",
                                     "contact.twisting_stiffness_ratio=0"}), dem::SceneError);
}

// Twisting springs are history: a split run equals the straight one bit for bit.
TEST(Twisting, SplitRunWithRollingAndTwistingEqualsStraightRunBitForBit) {
  const dem::Model m = dem_test::model_with({"contact.friction=0.5", "contact.rolling_friction=0.1",
                                             "contact.twisting_friction=0.1", "integration.threads=2"});
  const VelGrad rate{Vec3{0, 0, 0}, Vec3{0, 0.3 / (3000 * m.dt), 0}};
  dem::State straight = dem_test::random_state(300, 0.38, 1.0, 43), split = straight;
  { dem::Engine e(m, straight); for (int k = 0; k < 2000; ++k) e.step(rate); }
  const std::string path = (std::filesystem::temp_directory_path() / "dem_twisting_split.ckpt").string();
  { dem::Engine e(m, split); for (int k = 0; k < 1000; ++k) e.step(rate); dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split}); }
  dem::Checkpoint c = dem::read_checkpoint(path);
  std::remove(path.c_str());
  EXPECT_EQ(c.state.history.width, 8);
  dem::Engine e2(m, c.state, true);
  for (int k = 0; k < 1000; ++k) e2.step(rate);
  EXPECT_TRUE(dem_test::same_bits(c.state.angular_velocity, straight.angular_velocity));
  ASSERT_EQ(c.state.history.values.size(), straight.history.values.size());
  EXPECT_EQ(0, std::memcmp(c.state.history.values.data(), straight.history.values.data(),
                           straight.history.values.size() * sizeof(double)));
  long twisted = 0;
  for (std::size_t r = 7; r < straight.history.values.size(); r += 8) twisted += straight.history.values[r] != 0.0;
  EXPECT_GT(twisted, 10);   // the twist springs were loaded
  EXPECT_EQ(c.state.friction_dissipated, straight.friction_dissipated);
}

namespace {

// Luding's law without damping, integrated by hand over an impact (written from the law's
// definition, not from normal_luding.hpp): loading along k1 to delta_max, beyond
// delta* = kp/(kp - k1) phi_f 2 a12 along the elastic limit branch kp (delta - phi_f 2 a12);
// delta_max from the kinetic energy m_r v^2/2; unloading along k2 (delta - delta0) to the
// adhesive limit at delta_c = k2 delta0 / (k2 + kc), then along -kc delta to zero.
// e^2 = energy out / energy in; 0 when the adhesive well holds the pair.
double luding_restitution(double k1, double kp, double kc, double phi_f, double a12, double m_r, double v) {
  const double d0s = phi_f * 2 * a12, ds = kp / (kp - k1) * d0s, in = 0.5 * m_r * v * v;
  double dmax, k2, d0;
  if (in <= 0.5 * k1 * ds * ds) {
    dmax = std::sqrt(2 * in / k1);
    k2 = k1 + (kp - k1) * dmax / ds;
    d0 = (1 - k1 / k2) * dmax;
  } else {
    dmax = d0s + std::sqrt((ds - d0s) * (ds - d0s) + (2 * in - k1 * ds * ds) / kp);
    k2 = kp;
    d0 = d0s;
  }
  const double dc = k2 * d0 / (k2 + kc);
  const double out = 0.5 * k2 * ((dmax - d0) * (dmax - d0) - (dc - d0) * (dc - d0)) - 0.5 * kc * dc * dc;
  return out > 0 ? std::sqrt(out / in) : 0.0;
}

}  // namespace

// The sub-model against its piecewise definition: virgin loading, unloading to the plastic
// overlap, reloading on the same line, the adhesive limit, k2 saturating at kp.
TEST(Luding, ForceOverlapLoopFollowsThePiecewiseLaw) {
  const double k1 = 1e8, kp = 5e8, kc = 0.5e8, phi = 0.001, a12 = 2.5e-4;
  const dem::contact::LudingNormal law{k1, kp, kc, phi};
  const double dstar = kp / (kp - k1) * phi * 2 * a12;
  double h = 0;
  const double d1 = 0.4 * dstar;
  EXPECT_DOUBLE_EQ(law.update(d1, a12, &h), k1 * d1);            // loading
  EXPECT_DOUBLE_EQ(h, d1);
  const double k2 = k1 + (kp - k1) * 0.4, d0 = (1 - k1 / k2) * d1;
  EXPECT_NEAR(law.update(0.5 * (d0 + d1), a12, &h), k2 * 0.5 * (d1 - d0), 1e-9 * k1 * d1);   // unloading line
  EXPECT_NEAR(law.update(d0, a12, &h), 0.0, 1e-9 * k1 * d1);     // zero force at the plastic overlap
  EXPECT_NEAR(law.update(0.9 * d1, a12, &h), k2 * (0.9 * d1 - d0), 1e-9 * k1 * d1);   // reloading: the same line
  EXPECT_DOUBLE_EQ(h, d1);                                       // delta_max unchanged off the virgin branch
  EXPECT_DOUBLE_EQ(law.update(1.2 * d1, a12, &h), k1 * 1.2 * d1);   // back on k1 beyond delta_max
  // Deep unloading hits the adhesive limit -kc delta, and delta_max moves so that the k2-line
  // passes through the point reached.
  double hh = d1;
  const double small = 0.1 * d0;
  EXPECT_DOUBLE_EQ(law.update(small, a12, &hh), -kc * small);
  const double k2h = k1 + (kp - k1) * hh / dstar;   // the new delta_max's own k2-line through the point
  EXPECT_NEAR(k2h * (small - (1 - k1 / k2h) * hh), -kc * small, 1e-9 * kc * small);
  EXPECT_LT(hh, d1);
  EXPECT_NEAR(law.force(small, a12, &hh), -kc * small, 1e-9 * kc * small);   // a consumer sees the same force
  EXPECT_NEAR(law.update(0.8 * small, a12, &hh), -kc * 0.8 * small, 1e-9 * kc * small);   // further: still -kc delta
  const double k2r = k1 + (kp - k1) * hh / dstar;   // reloading from there: along that line
  EXPECT_NEAR(law.update(2 * small, a12, &hh), k2r * (2 * small - (1 - k1 / k2r) * hh), 1e-9 * k1 * d1);
  // Beyond delta* the unloading stiffness is kp, and the contact is elastic on the limit branch
  // kp (delta - phi_f 2 a12): above the k1-line, the same force on loading and unloading, the
  // plastic overlap held at phi_f 2 a12 (MercuryDPM and YADE: the "fluid" branch).
  EXPECT_DOUBLE_EQ(law.k2_of(2 * dstar, a12), kp);
  double hl = 0;
  const double dp = phi * 2 * a12, up = kp * (1.5 * dstar - dp);
  EXPECT_NEAR(law.update(1.5 * dstar, a12, &hl), up, 1e-12 * up);
  EXPECT_GT(up, 1.1 * k1 * 1.5 * dstar);
  EXPECT_NEAR(hl, dstar, 1e-15);
  EXPECT_NEAR(law.update(1.2 * dstar, a12, &hl), kp * (1.2 * dstar - dp), 1e-12 * up);
  EXPECT_NEAR(law.update(1.5 * dstar, a12, &hl), up, 1e-12 * up);
  EXPECT_NEAR(law.update(0.5 * (dstar + dp), a12, &hl), kp * 0.5 * (dstar - dp), 1e-12 * up);   // below delta*: the same line
  EXPECT_NEAR(law.force(3 * dstar, a12, &hl), kp * (3 * dstar - dp), 1e-12 * up);   // read-only: the same value
  EXPECT_NEAR(hl, dstar, 1e-15);
}

// Two-sphere impacts through the engine against the hand-integrated law: e = sqrt(k1/k2) without
// adhesion below delta*, rising again beyond it (the elastic limit branch), lower with adhesion,
// sticking when adhesion wins.
TEST(Luding, RestitutionOfImpactsMatchesTheClosedFormAndAdhesionSticks) {
  const double r = 0.5e-3, k1 = 1e8, kp = 5e8, phi = 0.001;
  auto model = [&](double kc) {
    return dem_test::model_with({"contact.normal=luding", "contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                                 "contact.luding_kp_N_m=5e8", "contact.luding_kc_N_m=" + std::to_string(kc),
                                 "contact.luding_plasticity_depth=0.001", "contact.allow_attractive=true"});
  };
  const double m_r = 0.5 * dem::sphere_mass(r, 2000.0), a12 = r / 2;
  std::printf("kc/k1   v_m_s   e       e_theory\n");
  for (double kc : {0.0, 0.1 * k1})
    for (double v : {1.0, 4.0, 10.0, 30.0}) {
      const dem::Model m = model(kc);
      const double e = dem::simulate_collision(m, r, r, v).restitution;
      const double theory = luding_restitution(k1, kp, kc, phi, a12, m_r, v);
      std::printf("%5.2f  %6.1f  %.4f  %.4f\n", kc / k1, v, e, theory);
      ASSERT_GT(theory, 0.2);
      EXPECT_NEAR(e, theory, 5e-3 * theory) << kc << " " << v;
    }
  // kc = 5 k1 at 4 m/s: the adhesive branch takes more than the elastic return (the pair
  // sticks), while at 30 m/s the elastic limit branch beyond delta* throws it apart again.
  ASSERT_EQ(luding_restitution(k1, kp, 5 * k1, phi, a12, m_r, 4.0), 0.0);
  ASSERT_GT(luding_restitution(k1, kp, 5 * k1, phi, a12, m_r, 30.0), 0.5);
  EXPECT_NEAR(dem::simulate_collision(model(5 * k1), r, r, 30.0).restitution,
              luding_restitution(k1, kp, 5 * k1, phi, a12, m_r, 30.0), 5e-3);
  const dem::Model m = model(5 * k1);
  dem::State s = dem_test::make_state(Vec3{20e-3, 20e-3, 20e-3}, {Vec3{5e-3, 10e-3, 10e-3}, Vec3{5e-3 + 2 * r + 1e-7, 10e-3, 10e-3}},
                                      {r, r});
  s.velocity[0] = Vec3{2.0, 0, 0};
  s.velocity[1] = Vec3{-2.0, 0, 0};
  dem::Engine e(m, s);
  for (int k = 0; k < 20000; ++k) e.step(Vec3{0, 0, 0});   // ~100 contact times
  const double gap = norm(dem::minimum_image(s.box, s.position[0], s.position[1])) - 2 * r;
  EXPECT_LT(gap, 0.0) << "the pair should stick";
}

// Zero adhesion gives the non-adhesive bits (issue 35). Luding's law is f = k1 delta on virgin
// loading, k2 (delta - delta0) with delta0 = (1 - k1/k2) delta_max on unloading, -kc delta at
// the adhesive limit, plus the same dashpot, and (a history law) no no-tension clamp. With
// kc = 0 and k2 = k1 it is f = k1 delta + gamma d(delta)/dt on every branch: the linear
// spring-dashpot with contact.allow_attractive = true (the linear law's default clamps the sum
// at zero; Luding's kc = 0 does not: the dashpot may pull). The law needs kp > k1: at kp =
// nextafter(k1) the increment (kp - k1) delta_max / delta* is below k1's last bit for every
// overlap (delta* ~ 7e15 phi_f 2 a12 at k1 = 1e8 N/m), so k2 rounds to k1, delta0 to 0 and the force to the
// bits of k1 delta. The curves are then the same bits; dt is taken from the linear model (t_c
// of kp and of k1 may differ in the last bit).
namespace {

struct Witness {
  dem::State s;
  std::vector<std::vector<Vec3>> positions, forces;
};

Witness run_witness(const dem::Model& m, const dem::State& start, int steps, const VelGrad& rate) {
  Witness w{start, {}, {}};
  dem::Engine e(m, w.s);
  for (int k = 0; k < steps; ++k) {
    e.step(rate);
    if (k % 100 == 99) { w.positions.push_back(w.s.position); w.forces.push_back(w.s.force); }
  }
  return w;
}

bool same_curves(const Witness& a, const Witness& b) {
  if (a.positions.size() != b.positions.size()) return false;
  for (std::size_t k = 0; k < a.positions.size(); ++k)
    if (!dem_test::same_bits(a.positions[k], b.positions[k]) || !dem_test::same_bits(a.forces[k], b.forces[k]))
      return false;
  return dem_test::same_bits(a.s.velocity, b.s.velocity) && a.s.box.length.x == b.s.box.length.x;
}

// Luding with kc = 0 and kp = nextafter(k1) (k2 = k1 in floating point), dt of the linear model.
dem::Model luding_as_linear(const std::vector<std::string>& more) {
  std::vector<std::string> o = {"contact.normal=luding", "contact.luding_kc_N_m=0"};
  o.insert(o.end(), more.begin(), more.end());
  dem::Model m = dem_test::model_with(o);
  const double k1 = m.contact.get("stiffness_N_m");
  m.contact.set("luding_kp_N_m", std::nextafter(k1, 2 * k1));
  return m;
}

}  // namespace

TEST(Luding, ZeroAdhesionAndNoPlasticityGiveTheLinearLawsBits) {
  // 300 spheres at 0.38 with small overlaps and random velocities, compressed and sheared: contacts
  // load, unload (the dashpot pulling on some) and open.
  const dem::State start = dem_test::random_state(300, 0.38, 1.0, 7);
  for (const std::string mu : {"0", "0.5"}) {
    const std::vector<std::string> common = {"contact.friction=" + mu, "contact.damping_kg_s=1"};
    std::vector<std::string> lin = common, clamped = common;
    lin.push_back("contact.allow_attractive=true");
    const dem::Model linear = dem_test::model_with(lin), linear_clamped = dem_test::model_with(clamped);
    dem::Model luding = luding_as_linear(common);
    ASSERT_NE(luding.contact.get("luding_kp_N_m"), luding.contact.get("stiffness_N_m"));
    luding.dt = linear.dt;
    const VelGrad rate{Vec3{-0.05, -0.05, -0.05} * (1.0 / (2000 * linear.dt)), Vec3{0, 0.1 / (2000 * linear.dt), 0}};
    const Witness a = run_witness(linear, start, 2000, rate);
    const Witness b = run_witness(luding, start, 2000, rate);
    EXPECT_TRUE(same_curves(a, b)) << "mu = " << mu;
    EXPECT_GT(dem_test::max_force(a.s), 0.0);
    // The witnesses discriminate: the clamped linear law differs where a dashpot pulls, and the
    // runs' plasticity (kp = 5 k1) where a contact unloads.
    EXPECT_FALSE(same_curves(a, run_witness(linear_clamped, start, 2000, rate))) << "mu = " << mu;
    dem::Model plastic = luding;
    plastic.contact.set("luding_kp_N_m", 5 * plastic.contact.get("stiffness_N_m"));
    EXPECT_FALSE(same_curves(a, run_witness(plastic, start, 2000, rate))) << "mu = " << mu;
  }
}

// With the runs' plasticity (kp = 5 k1, kc = 0) the law is still k1 delta on virgin loading: a
// head-on impact gives the linear law's forces bit for bit while the overlap grows, and less
// (k2 (delta - delta0) < k1 delta) from the first step it shrinks.
TEST(Luding, ZeroAdhesionGivesTheLinearForcesBitForBitWhileEveryContactLoads) {
  const double r = 0.5e-3;
  const std::vector<std::string> common = {"contact.damping_kg_s=0.5", "contact.background_damping_kg_s=0",
                                           "contact.allow_attractive=true"};
  std::vector<std::string> lud = common;
  lud.insert(lud.end(), {"contact.normal=luding", "contact.luding_kc_N_m=0", "contact.luding_kp_N_m=5e8",
                         "contact.luding_plasticity_depth=0.05"});
  const dem::Model linear = dem_test::model_with(common);
  dem::Model luding = dem_test::model_with(lud);
  luding.dt = linear.dt;
  dem::State s = dem_test::make_state(Vec3{20e-3, 20e-3, 20e-3},
                                      {Vec3{5e-3, 10e-3, 10e-3}, Vec3{5e-3 + 2 * r - 1e-9, 10e-3, 10e-3}}, {r, r});
  s.velocity[0] = Vec3{1.0, 0, 0};
  s.velocity[1] = Vec3{-1.0, 0, 0};
  dem::State sa = s, sb = s;
  dem::Engine ea(linear, sa), eb(luding, sb);
  double deepest = 0;
  int loading = 0, unloading = 0;
  for (int k = 0; k < 400 && unloading == 0; ++k) {
    ea.step(Vec3{0, 0, 0});
    eb.step(Vec3{0, 0, 0});
    // the forces of this step are those of the positions it reached
    ASSERT_TRUE(dem_test::same_bits(sa.position, sb.position)) << "step " << k;
    const double overlap = 2 * r - norm(dem::minimum_image(sa.box, sa.position[0], sa.position[1]));
    if (overlap >= deepest) {   // virgin loading: delta = delta_max
      ++loading;
      deepest = overlap;
      ASSERT_EQ(sa.force[1].x, sb.force[1].x) << "step " << k;
      ASSERT_GT(sa.force[1].x, 0.0);   // particle 1 (right) is pushed along +x
    } else {   // the first unloading step: k2 (delta - delta0) < k1 delta at the same overlap
      ++unloading;
      EXPECT_LT(sb.force[1].x, sa.force[1].x) << "step " << k;
      const double k1 = 1e8, kp = 5e8, dstar = kp / (kp - k1) * 0.05 * 2 * (r / 2);
      const double k2 = k1 + (kp - k1) * deepest / dstar, fb = k2 * (overlap - (1 - k1 / k2) * deepest);
      const double dashpot = sa.force[1].x - k1 * overlap;   // the same dashpot in both
      EXPECT_NEAR(sb.force[1].x, fb + dashpot, 1e-9 * k1 * deepest);
    }
  }
  EXPECT_GT(loading, 10);
  EXPECT_EQ(unloading, 1);
}

TEST(Friction, TheVectorAngularKickGivesTheScalarBits) {
  // kick_angular four particles at a time (AVX2) against one at a time, on random masses, radii,
  // torques and spins, for ranges that start and end off a multiple of four.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0), pos(0.2, 3.0);
  const int n = 103;
  std::vector<dem::Vec3> t(n), w0(n);
  std::vector<double> m(n), r(n);
  for (int i = 0; i < n; ++i) {
    t[i] = {u(rng) * 1e-6, u(rng) * 1e-6, u(rng) * 1e-6};
    w0[i] = {u(rng) * 1e3, u(rng) * 1e3, u(rng) * 1e3};
    m[i] = pos(rng) * 1e-6;
    r[i] = pos(rng) * 1e-3;
  }
  for (int begin : {0, 1, 3}) {
    for (int end : {n, n - 2, begin + 5}) {
      std::vector<dem::Vec3> a = w0, b = w0;
      dem::kick_angular(a.data(), t.data(), m.data(), r.data(), begin, end, 0.37e-7, true);
      dem::kick_angular(b.data(), t.data(), m.data(), r.data(), begin, end, 0.37e-7, false);
      EXPECT_EQ(std::memcmp(a.data(), b.data(), n * sizeof(dem::Vec3)), 0) << begin << " " << end;
      EXPECT_NE(std::memcmp(a.data(), w0.data(), n * sizeof(dem::Vec3)), 0);   // it kicked
      // untouched outside [begin, end)
      for (int i = 0; i < n; ++i)
        if (i < begin || i >= end) EXPECT_EQ(std::memcmp(&a[i], &w0[i], sizeof(dem::Vec3)), 0) << i;
    }
  }
}
