// Simple shear in a sheared (triclinic) periodic cell: the neighbour list against the oracle
// across cell flips, bit-exact restart across a flip, hand-built pairs across the tilted
// boundary, the energy balance under shear, the deformation gradient and log strain, and the
// eigenvalue-based (objective) measures against the diagonal ones and under rotation.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "dem/io/checks.hpp"
#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/protocol.hpp"
#include "dem/io/scene.hpp"
#include "test_support.hpp"

using dem::Sym3;
using dem::Vec3;
using dem::VelGrad;

namespace {

int contacts_all_pairs(const dem::State& s) {
  int c = 0;
  for (int i = 0; i < s.count(); ++i)
    for (int j = i + 1; j < s.count(); ++j)
      c += norm(dem::minimum_image(s.box, s.position[i], s.position[j])) < s.radius[i] + s.radius[j];
  return c;
}

VelGrad mode_gradient(const char* name, double rate) {
  dem::DeformationMode dm;
  EXPECT_TRUE(dem::builtin_mode(name, &dm)) << name;
  return dm.shape * rate;
}

// The list's forces against the oracle's for the state's current positions and velocities.
double list_vs_oracle(const dem::Model& m, dem::State& s, const dem::NeighborList& list, const VelGrad& g) {
  dem::ForceScratch scratch;
  dem::compute_forces(m, s, list, g, 1, 1, scratch);
  dem::State oracle = s;
  dem::compute_forces_all_pairs(m, oracle, g);
  const double scale = dem_test::max_force(oracle);
  EXPECT_GT(scale, 0);
  return dem_test::max_force_difference(s, oracle) / scale;
}

}  // namespace

TEST(Shear, BuiltinSimpleShearHasTheStretchingOfD2) {
  dem::DeformationMode ss, d2;
  ASSERT_TRUE(dem::builtin_mode("SS_xz", &ss));
  ASSERT_TRUE(dem::builtin_mode("D2", &d2));
  EXPECT_TRUE(ss.sheared());
  EXPECT_EQ(ss.shape.shear.y, 2.0);
  double a[3], b[3];
  Vec3 va[3], vb[3];
  dem::principal(Sym3{0, 0, 0, 0, 0.5 * ss.shape.shear.y, 0}, a, va);
  dem::principal(Sym3{d2.shape.diag.x, d2.shape.diag.y, d2.shape.diag.z, 0, 0, 0}, b, vb);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], 1e-15);
  // the compressive direction of simple shear v_x = g z is (1, 0, -1)/sqrt 2
  EXPECT_NEAR(dem::axis_angle_deg(va[0], Vec3(1, 0, -1)), 0.0, 1e-6);
}

TEST(Shear, ListEqualsOracleUnderLargeShearAcrossFlips) {
  // gamma = 2 r t up to 3.2: three flips of the cell for each simple shear; and a general
  // upper-triangular gradient with stretching, tilting every face.
  struct Case { const char* name; VelGrad shape; };
  const Case cases[] = {{"SS_xz", VelGrad(Vec3(0, 0, 0), Vec3(0, 2, 0))},
                        {"SS_xy", VelGrad(Vec3(0, 0, 0), Vec3(2, 0, 0))},
                        {"SS_yz", VelGrad(Vec3(0, 0, 0), Vec3(0, 0, 2))},
                        {"general", VelGrad(Vec3(0.2, -0.1, -0.1), Vec3(1.3, -1.1, 1.7))}};
  for (const Case& c : cases) {
    dem::Model m = dem_test::model_with();
    dem::State s = dem_test::random_state(400, 0.36, 2.0, 3);
    const VelGrad g = c.shape * (4e-3 / m.t_contact);
    dem::Engine e(m, s);
    int checked = 0;
    long flips_seen = 0;
    for (int k = 0; k < 20000; ++k) {
      e.step(g);
      if (e.flips() != flips_seen || k % 2500 == 0) {   // right after every flip, and in between
        flips_seen = e.flips();
        dem::State t = s;
        EXPECT_LT(list_vs_oracle(m, t, e.neighbor_list(), g), 1e-12) << c.name << " step " << k;
        const auto q = dem::measure(m, s, e.neighbor_list(), g);
        ASSERT_EQ(q.contacts, contacts_all_pairs(s)) << c.name << " step " << k;
        ++checked;
      }
    }
    EXPECT_GE(e.flips(), 3) << c.name;
    EXPECT_GT(checked, 8) << c.name;
    const auto q = dem::measure(m, s, e.neighbor_list(), g);
    EXPECT_GT(q.contacts, 20) << c.name;
    // |tilt| never beyond half the edge it leans along
    EXPECT_LE(std::fabs(s.box.tilt.x), 0.5 * s.box.length.x * (1 + 1e-12));
    EXPECT_LE(std::fabs(s.box.tilt.y), 0.5 * s.box.length.x * (1 + 1e-12));
    EXPECT_LE(std::fabs(s.box.tilt.z), 0.5 * s.box.length.y * (1 + 1e-12));
  }
}

TEST(Shear, ListNeverMissesAContactUnderFastShear) {
  dem::Model m = dem_test::model_with({"integration.skin_over_rmin=0.1"});
  dem::State s = dem_test::random_state(300, 0.38, 5.0, 9);
  const VelGrad g = mode_gradient("SS_xz", 5e-3 / m.t_contact);
  dem::Engine e(m, s);
  for (int k = 0; k < 12000; ++k) {
    e.step(g);
    if (k % 150 == 0) ASSERT_EQ(dem::measure(m, s, e.neighbor_list(), g).contacts, contacts_all_pairs(s)) << k;
  }
  EXPECT_GE(e.flips(), 1);
}

TEST(Shear, DeformationGradientAndLogStrainAcrossFlips) {
  // Dilute spheres at rest in the fluctuation frame follow x(t) = F x(0) up to a lattice vector of
  // the current cell; F = [[1, 0, gamma], [0, 1, 0], [0, 0, 1]] exactly through flips, and the
  // log strain of simple shear has the eigenvalues +-asinh(gamma/2), 0.
  const dem::Model m = dem_test::model_with();
  const double L = 20e-3;
  dem::State s = dem_test::make_state(Vec3(L, L, L),
                                      {Vec3(3e-3, 4e-3, 5e-3), Vec3(13e-3, 14e-3, 15e-3), Vec3(7e-3, 17e-3, 11e-3)},
                                      {0.5e-3, 1e-3, 1.5e-3});
  std::vector<Vec3> x0(3);
  for (int i = 0; i < 3; ++i) x0[s.id[i]] = s.position[i];
  const double rate = 1e-2 / m.t_contact;
  const VelGrad g = mode_gradient("SS_xz", rate);
  dem::Engine e(m, s);
  for (int k = 0; k < 12000; ++k) e.step(g);
  const double gamma = 2 * rate * s.time;
  ASSERT_GT(gamma, 4.0);
  EXPECT_GE(e.flips(), 4);
  double F[3][3];
  s.box.deformation_gradient(F);
  EXPECT_NEAR(F[0][2], gamma, 1e-9 * gamma);
  EXPECT_NEAR(F[0][0], 1, 1e-15);
  EXPECT_NEAR(F[2][2], 1, 1e-15);
  EXPECT_NEAR(F[0][1], 0, 1e-15);
  EXPECT_NEAR(F[1][2], 0, 1e-15);
  for (int i = 0; i < 3; ++i) {
    const Vec3& a = x0[s.id[i]];
    const Vec3 affine{a.x + F[0][2] * a.z, a.y, a.z};
    const Vec3 frac = s.box.fractional(s.position[i] - affine);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(frac[k], std::round(frac[k]), 1e-9) << "particle " << i << " axis " << k;
  }
  const auto q = dem::measure(m, s, e.neighbor_list(), g);
  EXPECT_NEAR(q.eps_d_eig, std::sqrt(3.0) * std::asinh(gamma / 2), 1e-9);
  EXPECT_NEAR(q.eps_v, 0.0, 1e-12);
  EXPECT_NEAR(q.strain_tensor.trace(), 0.0, 1e-12);
  EXPECT_GT(q.strain_tensor.xz, 0.3);   // the log strain's shear component
  EXPECT_NEAR(s.box.volume() / (L * L * L), 1.0, 1e-15);
}

TEST(Shear, SplitRunEqualsStraightRunBitForBitAcrossAFlip) {
  for (int threads : {1, 2}) {
    const dem::Model m = dem_test::model_with({"integration.threads=" + std::to_string(threads)});
    const VelGrad g = mode_gradient("SS_xz", 8e-3 / m.t_contact);   // gamma 0.32 per 1000 steps: flips at 0.5, 1.5
    dem::State straight = dem_test::random_state(300, 0.38, 1.0, 21);
    dem::State split = straight;
    long flips_straight = 0;
    {
      dem::Engine e(m, straight);
      for (int k = 0; k < 6000; ++k) e.step(g);
      flips_straight = e.flips();
    }
    const std::string path = (std::filesystem::temp_directory_path() / "dem_shear_split.ckpt").string();
    long flips_first = 0;
    {
      dem::Engine e(m, split);
      for (int k = 0; k < 3000; ++k) e.step(g);
      flips_first = e.flips();
      dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split});
    }
    {
      std::ifstream in(path, std::ios::binary);
      char magic[8];
      in.read(magic, 8);
      EXPECT_EQ(std::string(magic, 8), "DEMCKPT4") << "a sheared state is written as version 4";
    }
    dem::Checkpoint c = dem::read_checkpoint(path);
    std::remove(path.c_str());
    EXPECT_EQ(0, std::memcmp(&c.state.box.tilt, &split.box.tilt, sizeof(Vec3)));
    dem::Engine e2(m, c.state, /*forces_are_current=*/true);
    for (int k = 0; k < 3000; ++k) e2.step(g);
    EXPECT_GE(flips_first, 1) << "the first half must flip";
    EXPECT_GE(e2.flips(), 1) << "the second half must flip";
    EXPECT_EQ(flips_first + e2.flips(), flips_straight);
    EXPECT_TRUE(dem_test::same_bits(c.state.position, straight.position)) << "threads " << threads;
    EXPECT_TRUE(dem_test::same_bits(c.state.velocity, straight.velocity)) << "threads " << threads;
    EXPECT_EQ(0, std::memcmp(&c.state.box.tilt, &straight.box.tilt, sizeof(Vec3)));
    EXPECT_EQ(0, std::memcmp(c.state.box.flips, straight.box.flips, sizeof straight.box.flips));
  }
}

TEST(Shear, DiagonalStatesStillWriteVersion3Checkpoints) {
  const std::string path = (std::filesystem::temp_directory_path() / "dem_diag_v3.ckpt").string();
  dem::State s = dem_test::random_state(50, 0.3, 0.0, 2);
  dem::write_checkpoint(path, dem::Checkpoint{"", "x", s});
  std::ifstream in(path, std::ios::binary);
  char magic[8];
  in.read(magic, 8);
  in.close();
  std::remove(path.c_str());
  EXPECT_EQ(std::string(magic, 8), "DEMCKPT3");
}

TEST(Shear, PairAcrossTheTiltedBoundaryGivesStressAndFabric) {
  // A cell tilted by xz = 0.3 L_x. Sphere j sits near the bottom face, sphere i near the top: they
  // touch through the image j + c, c = (xz, 0, L_z): branch d along a hand-chosen direction n.
  const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0"});
  const double r = 1e-3, delta = 2e-5, l = 2 * r - delta;
  const Vec3 L(10e-3, 12e-3, 15e-3);
  const double xz = 0.3 * L.x;
  const Vec3 n = Vec3(0.3, -0.2, 1.0) * (1 / std::sqrt(0.09 + 0.04 + 1.0));
  const Vec3 xi(4e-3, 6e-3, L.z - 0.4e-3);
  const Vec3 xj_image = xi + n * l;              // above the top face
  const Vec3 xj = xj_image - Vec3(xz, 0, L.z);   // its copy in the cell
  dem::State s = dem_test::make_state(L, {xi, xj}, {r, r});
  s.box.tilt = Vec3(0, xz, 0);
  ASSERT_GT(xj.z, 0);
  ASSERT_LT(xj.z, L.z);
  dem::Engine e(m, s);
  const auto q = dem::measure(m, s, e.neighbor_list(), VelGrad());
  const double V = L.x * L.y * L.z, f = 1e8 * delta;
  ASSERT_EQ(q.contacts, 1);
  EXPECT_EQ(contacts_all_pairs(s), 1);
  const double a = f * l / V;   // sigma = f l n n / V
  EXPECT_NEAR(q.stress.xx, a * n.x * n.x, 1e-9 * a);
  EXPECT_NEAR(q.stress.zz, a * n.z * n.z, 1e-9 * a);
  EXPECT_NEAR(q.stress.xz, a * n.x * n.z, 1e-9 * a);
  EXPECT_NEAR(q.stress.yz, a * n.y * n.z, 1e-9 * a);
  EXPECT_NEAR(q.stress.xy, a * n.x * n.y, 1e-9 * a);
  const double vp = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_NEAR(q.fabric.xz, 2 * vp / V * n.x * n.z, 1e-12);
  EXPECT_NEAR(q.fabric.zz, 2 * vp / V * n.z * n.z, 1e-12);
  // one contact: a uniaxial tensor f l n n / V; its eigen deviator is f l / V (as diag (a, 0, 0)),
  // whatever n; and its major direction is n
  EXPECT_NEAR(q.sigma_dev_eig, a, 1e-9 * a);
  EXPECT_NEAR(q.angle_sigma_F, 0.0, 1e-6);
  // and the force is the oracle's
  dem::State t = s;
  EXPECT_LT(list_vs_oracle(m, t, e.neighbor_list(), VelGrad()), 1e-12);
  EXPECT_NEAR(norm(t.force[0]), f, 1e-9 * f);
}

namespace {
struct ShearBalance { double de, work, kinetic_work; };
ShearBalance shear_balance(double dt_over_tc, int steps, double rate) {
  const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0", "contact.background_damping_kg_s=0",
                                             "integration.dt_over_tc=" + std::to_string(dt_over_tc)});
  dem::State s = dem_test::random_state(400, 0.3, 0.5, 5);
  const VelGrad g = mode_gradient("SS_xz", rate);
  dem::Engine e(m, s);
  auto energy = [&]() {
    const auto q = dem::measure(m, s, e.neighbor_list(), g);
    return q.E_kin + q.E_pot;
  };
  auto power = [&](double* kinetic) {
    const auto q = dem::measure(m, s, e.neighbor_list(), g);
    const double V = s.box.volume();
    *kinetic = -V * q.stress_kinetic.xz * g.shear.y;
    return -V * q.stress.xz * g.shear.y;   // sigma:L with L = g e_x e_z
  };
  double work = 0, kinetic_work = 0;
  const double e0 = energy();
  for (int k = 0; k < steps; ++k) {
    double k0 = 0, k1 = 0;
    const double p0 = power(&k0);
    e.step(g);
    const double p1 = power(&k1);
    work += 0.5 * (p0 + p1) * m.dt;
    kinetic_work += 0.5 * (k0 + k1) * m.dt;
  }
  return {energy() - e0, work, kinetic_work};
}
}  // namespace

TEST(Shear, EnergyBalanceUnderSimpleShearWithDampingOff) {
  // gamma = 0.08 (gamma_dot = 4e3/s, D2's eps_d rate in test_control.cpp). Measured relative
  // errors: 8.6e-3 (dt = t_c/50), 1.9e-3 (t_c/100), 5.0e-4 (t_c/200): the splitting's second-order
  // truncation, not a missing term (which would not shrink with dt); the kinetic stress does 23 %
  // of the work.
  const ShearBalance coarse = shear_balance(0.01, 8000, 4e3 / 2);
  const ShearBalance fine = shear_balance(0.005, 16000, 4e3 / 2);
  const double err_coarse = std::fabs(coarse.de - coarse.work) / std::fabs(coarse.work);
  const double err_fine = std::fabs(fine.de - fine.work) / std::fabs(fine.work);
  ASSERT_GT(std::fabs(fine.kinetic_work), 0.02 * std::fabs(fine.work)) << "the kinetic stress must do work";
  EXPECT_LT(err_fine, 1e-3) << fine.de << " vs " << fine.work;
  EXPECT_GT(err_coarse / err_fine, 2.5) << "second order in dt";
  EXPECT_LT(err_coarse / err_fine, 6.5) << "second order in dt";
  std::printf("[ simple shear energy balance: dE = %.6e J, work = %.6e J (kinetic %.3f), rel. error %.2e (2 dt: %.2e) ]\n",
              fine.de, fine.work, fine.kinetic_work / fine.work, err_fine, err_coarse);
}

TEST(Shear, EigenMeasuresEqualTheDiagonalOnesForD2AndD3) {
  for (const char* name : {"D2", "D3"}) {
    const dem::Model m = dem_test::model_with();
    dem::State s = dem_test::random_state(300, 0.38, 0.0, 5);
    const VelGrad g = mode_gradient(name, 1e-3 / m.t_contact);
    dem::Engine e(m, s);
    for (int k = 0; k < 8000; ++k) e.step(g);
    const auto q = dem::measure(m, s, e.neighbor_list(), g);
    EXPECT_FALSE(s.box.tilted());
    // strain: exactly diagonal, the same values
    EXPECT_EQ(q.strain_tensor.xz, 0.0);
    EXPECT_NEAR(q.eps_d_eig, q.eps_d, 1e-14 * q.eps_d) << name;
    EXPECT_GT(q.eps_d, 0.1);
    // stress and fabric: the eigen form adds the off-diagonal parts (sqrt(3 J2)):
    // sigma_dev_eig^2 = sigma_dev^2 + 3 (xy^2 + xz^2 + yz^2)
    auto with_shear = [](double diag, const Sym3& t) {
      return std::sqrt(diag * diag + 3 * (t.xy * t.xy + t.xz * t.xz + t.yz * t.yz));
    };
    EXPECT_NEAR(q.sigma_dev_eig, with_shear(q.sigma_dev, q.stress), 1e-10 * q.sigma_dev) << name;
    EXPECT_NEAR(q.F_dev_eig, with_shear(q.F_dev, q.fabric), 1e-10 * q.F_dev) << name;
    EXPECT_GE(q.sigma_dev_eig, q.sigma_dev * (1 - 1e-12));
    EXPECT_TRUE(std::isfinite(q.angle_sigma_D)) << name;
  }
  // A hand-built diagonal stress (contacts along the axes only): the forms are equal.
  const dem::Model m = dem_test::model_with();
  const int n = 5;
  const double r = 1e-3, delta = 1e-5, a = 2 * r - delta, az = 2.5 * r;
  std::vector<Vec3> x;
  std::vector<double> rad;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) { x.emplace_back((i + 0.5) * a, (j + 0.5) * a, (k + 0.5) * az); rad.push_back(r); }
  dem::State s = dem_test::make_state(Vec3(n * a, n * a, n * az), x, rad);
  dem::Engine e(m, s);
  const auto q = dem::measure(m, s, e.neighbor_list(), VelGrad());
  EXPECT_NEAR(q.sigma_dev_eig, q.sigma_dev, 1e-12 * q.sigma_dev);
  EXPECT_NEAR(q.s_dev_eig, 1.5, 1e-9);
  EXPECT_NEAR(q.F_dev_eig, q.F_dev, 1e-12 * q.F_dev);
  EXPECT_TRUE(std::isnan(q.angle_sigma_D)) << "no rate: no strain-rate direction";
}

TEST(Shear, EigenMeasuresAreInvariantUnderARotationOfAHandBuiltCluster) {
  // A central sphere touching 7 others in arbitrary directions (with different overlaps), far
  // from the cell's faces; rotated about the cell centre by an arbitrary rotation. The stress and
  // fabric tensors rotate (sigma' = R sigma R^T); the eigen measures and the angle between the
  // principal directions of stress and fabric do not change; the diagonal forms do.
  const dem::Model m = dem_test::model_with({"contact.damping_kg_s=0"});
  const double L = 30e-3;
  const Vec3 c(15e-3, 15e-3, 15e-3);
  const Vec3 dirs[7] = {{1, 0.2, 0.1}, {-0.3, 1, 0.4}, {0.1, -0.5, 1}, {-1, -0.4, 0.3},
                        {0.2, -1, -0.6}, {0.5, 0.4, -1}, {-0.6, 0.7, -0.7}};
  const double r0 = 1.2e-3;
  std::vector<Vec3> x = {c};
  std::vector<double> rad = {r0};
  for (int k = 0; k < 7; ++k) {
    const double rk = 0.6e-3 + 0.1e-3 * k, overlap = (1 + k) * 4e-6;
    x.push_back(c + dirs[k] * ((r0 + rk - overlap) / norm(dirs[k])));
    rad.push_back(rk);
  }
  // a rotation: axis (1, 2, 3)/|.|, angle 0.7
  const Vec3 u = Vec3(1, 2, 3) * (1 / std::sqrt(14.0));
  const double th = 0.7, cs = std::cos(th), sn = std::sin(th);
  auto rotate = [&](const Vec3& v) {
    const Vec3 uxv{u.y * v.z - u.z * v.y, u.z * v.x - u.x * v.z, u.x * v.y - u.y * v.x};
    return v * cs + uxv * sn + u * (dot(u, v) * (1 - cs));
  };
  std::vector<Vec3> xr;
  for (const Vec3& p : x) xr.push_back(c + rotate(p - c));
  dem::State s1 = dem_test::make_state(Vec3(L, L, L), x, rad);
  dem::State s2 = dem_test::make_state(Vec3(L, L, L), xr, rad);
  dem::Engine e1(m, s1), e2(m, s2);
  const auto q1 = dem::measure(m, s1, e1.neighbor_list(), VelGrad());
  const auto q2 = dem::measure(m, s2, e2.neighbor_list(), VelGrad());
  ASSERT_EQ(q1.contacts, 7);
  ASSERT_EQ(q2.contacts, 7);
  EXPECT_NEAR(q2.p, q1.p, 1e-12 * q1.p);
  EXPECT_NEAR(q2.sigma_dev_eig, q1.sigma_dev_eig, 1e-11 * q1.sigma_dev_eig);
  EXPECT_NEAR(q2.s_dev_eig, q1.s_dev_eig, 1e-11);
  EXPECT_NEAR(q2.F_dev_eig, q1.F_dev_eig, 1e-11 * q1.F_dev_eig);
  EXPECT_NEAR(q2.angle_sigma_F, q1.angle_sigma_F, 1e-6);
  EXPECT_GT(q1.angle_sigma_F, 1.0) << "stress and fabric must not be coaxial for the test to mean something";
  // the diagonal forms are not objective: they change under the rotation
  EXPECT_GT(std::fabs(q2.s_dev - q1.s_dev), 1e-3 * q1.s_dev);
  // and the eigenvalues of the stress rotate with it
  double v1[3], v2[3];
  Vec3 w1[3], w2[3];
  dem::principal(q1.stress, v1, w1);
  dem::principal(q2.stress, v2, w2);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(v2[k], v1[k], 1e-11 * v1[2]);
  EXPECT_NEAR(dem::axis_angle_deg(w2[2], rotate(w1[2])), 0.0, 1e-5);
}

TEST(Shear, ScenesTakeAVelocityGradientAndRefuseEntriesBelowTheDiagonal) {
  const dem::Model m = dem::load_scene("[modes]\nmyshear = [[0, 0, 1.5], [0, 0, 0], [0, 0, 0]]\n"
                                       "[protocol]\nmodes = [\"SS_xz\", \"myshear\", \"D2\"]\n",
                                       {}, nullptr, "test");
  ASSERT_EQ(m.protocol.modes.size(), 3u);
  EXPECT_EQ(m.protocol.modes[0].shape.shear.y, 2.0);
  EXPECT_EQ(m.protocol.modes[1].shape.shear.y, 1.5);
  EXPECT_FALSE(m.protocol.modes[2].sheared());
  EXPECT_NE(dem::mode_definition(m, m.protocol.modes[1]).find("shear_shape=[0,1.5,0]"), std::string::npos);
  EXPECT_EQ(dem::mode_definition(m, m.protocol.modes[2]).find("shear_shape"), std::string::npos)
      << "diagonal modes keep their definition line";
  try {
    dem::load_scene("[modes]\nbad = [[0, 0, 0], [0, 0, 0], [1, 0, 0]]\n[protocol]\nmodes = [\"bad\"]\n", {}, nullptr,
                    "test");
    FAIL() << "a gradient below the diagonal must be refused";
  } catch (const dem::SceneError& err) {
    EXPECT_NE(std::string(err.what()).find("below the diagonal"), std::string::npos) << err.what();
  }
  // A path stage takes a shear since simple shear at constant normal stress (docs/simple_shear.md):
  // its definition line names it; a diagonal path's line is unchanged.
  const dem::Model p = dem::load_scene("[paths]\np = [{ rate = \"SS_xz\", until = { eps_d = 0.1 } }]\n"
                                       "q = [{ rate = \"D2\", until = { eps_d = 0.1 } }]\n[protocol]\nmodes = [\"p\", \"q\"]\n",
                                       {}, nullptr, "test");
  EXPECT_EQ(p.protocol.modes[0].path.at(0).shape.shear.y, 2);
  EXPECT_NE(dem::mode_definition(p, p.protocol.modes[0]).find(":shear_shape=[0,2,0]"), std::string::npos);
  EXPECT_EQ(dem::mode_definition(p, p.protocol.modes[1]).find("shear_shape"), std::string::npos);
}

TEST(Shear, ModeStageRunsSimpleShearToItsStrainAcrossAFlip) {
  // run_stage with SS_xz (the path of `dem mode` and `dem run`): lands on eps_d_max of the log
  // strain, constant volume, the sheared preamble line, a flip on the way (gamma ~ 0.74).
  const dem::Model m = dem_test::model_with({"output.sample_strain=0.02"});
  dem::State s = dem_test::random_state(300, 0.38, 0.0, 7);
  dem::DeformationMode dm;
  ASSERT_TRUE(dem::builtin_mode("SS_xz", &dm));
  const double rate = 5e-3 / m.t_contact;
  dem::StageSpec spec = dem::mode_stage(m, dm);
  spec.gradient = dm.shape * rate;
  spec.target = 0.6;
  const std::string path = (std::filesystem::temp_directory_path() / "dem_ss_stage.csv").string();
  dem::run_stage(m, s, spec, dem::StageOutput{path});
  std::ifstream in(path);
  std::string line, header, last;
  bool sheared_note = false;
  int rows = 0;
  while (std::getline(in, line)) {
    if (line.rfind("# sheared cell", 0) == 0) sheared_note = true;
    if (line.empty() || line[0] == '#') continue;
    if (header.empty()) { header = line; continue; }
    last = line;
    ++rows;
  }
  std::remove(path.c_str());
  EXPECT_TRUE(sheared_note);
  EXPECT_GT(rows, 25);
  auto column = [&](const std::string& row, const std::string& name) {
    std::vector<std::string> h, v;
    std::stringstream hs(header), vs(row);
    for (std::string t; std::getline(hs, t, ',');) h.push_back(t);
    for (std::string t; std::getline(vs, t, ',');) v.push_back(t);
    for (std::size_t k = 0; k < h.size(); ++k)
      if (h[k] == name) return std::stod(v[k]);
    ADD_FAILURE() << "no column " << name;
    return 0.0;
  };
  EXPECT_NEAR(column(last, "eps_d"), 0.6, 1e-6);
  EXPECT_EQ(column(last, "eps_d"), column(last, "eps_d_eig"));
  EXPECT_NEAR(column(last, "eps_v"), 0.0, 1e-12);
  const double gamma = 2 * std::sinh(0.6 / std::sqrt(3.0));
  EXPECT_NEAR(column(last, "eps_xz"), std::asinh(gamma / 2) / std::sqrt(1 + 0.25 * gamma * gamma), 1e-8)
      << "the log strain's shear component (for simple shear: asinh(g/2) / sqrt(1 + g^2/4))";
  EXPECT_NE(s.box.flips[1], 0) << "the stage must flip the cell";
}
