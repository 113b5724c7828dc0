// Hertz-Mindlin (contact.normal = "hertz", contact.tangential = "mindlin" / "mindlin_force"),
// each against an independent truth: Hertz's closed forms for the force, the largest overlap
// and the contact time of a head-on impact; the restitution the damping was asked for; Mindlin's
// stiffness and the two rules for a changing k_t (displacement kept, force kept); oblique
// impacts against rigid-body sliding theory, and in the sticking limit against the impact's
// equations integrated here by RK4 for each rule. The kernels and the all-pairs oracle:
// test_history_kernels.cpp, test_friction.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>
#include <vector>

#include "dem/contact/contact_model.hpp"
#include "dem/contact/registry.hpp"
#include "dem/core/errors.hpp"
#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/stages/collision.hpp"
#include "test_support.hpp"

namespace {

constexpr double kPi = 3.14159265358979323846;
using dem::contact::PairLanes;
using dem::contact::V3;

// Glass-like but soft (E = 1e8 Pa) spheres of radii 1 and 1.5 mm: short runs.
dem::Model hertz_model(double e, const std::vector<std::string>& more = {}, double E = 1e8, double nu = 0.3,
                       double r_min = 1e-3, double r_max = 1.5e-3, double rho = 2500) {
  std::vector<std::string> o = {"contact.normal=\"hertz\"", "contact.background_damping_kg_s=0",
                                "contact.youngs_modulus_Pa=" + std::to_string(E),
                                "contact.poisson_ratio=" + std::to_string(nu),
                                "contact.restitution=" + std::to_string(e),
                                "particles.radius_min_m=" + std::to_string(r_min),
                                "particles.radius_max_m=" + std::to_string(r_max),
                                "particles.density_kg_m3=" + std::to_string(rho)};
  o.insert(o.end(), more.begin(), more.end());
  return dem_test::model_with(o);
}

struct Pair {
  double r_star, m_star, e_star;
};
Pair pair_of(const dem::Model& m, double r1, double r2) {
  const double E = m.contact.get("youngs_modulus_Pa"), nu = m.contact.get("poisson_ratio");
  const double m1 = 4.0 / 3.0 * kPi * r1 * r1 * r1 * m.density, m2 = 4.0 / 3.0 * kPi * r2 * r2 * r2 * m.density;
  // 1/E* = (1 - nu^2)/E + (1 - nu^2)/E (Johnson, Contact Mechanics, eq. 4.22)
  return {r1 * r2 / (r1 + r2), m1 * m2 / (m1 + m2), 1.0 / (2.0 * (1.0 - nu * nu) / E)};
}

// The sticking limit of an elastic oblique impact of equal spheres (no sliding, no spin at
// first), in units m* = 1, 4/3 E* sqrt(R*) = 1, v_n = 1: the normal motion x'' = -x^(3/2) and
// the contact point's tangential motion with mass m_t = 2/7 (m_t u'' = f_t) under
//   kept displacement:  f_t = -kappa S(x) u              (u: the tangential displacement)
//   incremental force:  f_t' = -kappa S(x) u'
// with S(x) = 3/2 x^(1/2) the Hertz tangent stiffness and kappa = k_t/S_n = 2(1 - nu)/(2 - nu).
// Returns v_t,after/v_t,before of the contact point (= psi2/psi1 in the sticking limit). RK4.
double sticking_ratio(double kappa, bool force_kept) {
  const double mt = 2.0 / 7.0, h = 1e-4;
  // y = {x, x', u, u' (kept) or f_t (incremental)}
  auto rhs = [&](const std::array<double, 5>& y) {
    const double x = std::max(y[0], 0.0), S = 1.5 * std::sqrt(x);
    std::array<double, 5> d{};
    d[0] = y[1];
    d[1] = -x * std::sqrt(x);
    d[2] = y[3];
    if (force_kept) { d[3] = y[4] / mt; d[4] = -kappa * S * y[3]; }
    else d[3] = -kappa * S * y[2] / mt;
    return d;
  };
  std::array<double, 5> y{0, 1, 0, 1, 0};
  for (int step = 0; step < 10000000; ++step) {
    auto add = [](const std::array<double, 5>& a, const std::array<double, 5>& b, double s) {
      std::array<double, 5> r;
      for (int k = 0; k < 5; ++k) r[k] = a[k] + s * b[k];
      return r;
    };
    const auto k1 = rhs(y), k2 = rhs(add(y, k1, h / 2)), k3 = rhs(add(y, k2, h / 2)), k4 = rhs(add(y, k3, h));
    std::array<double, 5> yn;
    for (int k = 0; k < 5; ++k) yn[k] = y[k] + h / 6 * (k1[k] + 2 * k2[k] + 2 * k3[k] + k4[k]);
    if (yn[0] < 0 && step > 10) return yn[3];
    y = yn;
  }
  return 0.0;
}

}  // namespace

TEST(Hertz, TheForceFollowsHertzsCurveAndTheDampingIsZeroAtUnitRestitution) {
  const dem::Model m = hertz_model(1.0);
  const Pair p = pair_of(m, 1e-3, 1.5e-3);
  dem::contact::with_contact_model(m.contact, [&](const auto& cm) {
    using CM = std::decay_t<decltype(cm)>;
    EXPECT_TRUE(CM::vectorised);     // every kernel runs it (test_history_kernels.cpp)
    EXPECT_TRUE(CM::history_loop);   // ... on the history loops, which pass the masses
    EXPECT_EQ(CM::history, 0);
    if constexpr (std::is_same_v<std::decay_t<decltype(cm.normal)>, dem::contact::HertzNormal>)
      for (double delta : {1e-7, 1e-6, 1e-5, 1e-4}) {
        for (double ddelta : {0.0, 1.0, -1.0}) {   // e = 1: no dashpot, the speed changes nothing
          const dem::contact::NormalGeometry<double> g{2.5e-3 - delta, 0, 0, 1, delta, ddelta, 0, 0, -ddelta};
          const double f = cm.normal_force(g, p.r_star, nullptr, false, p.m_star);
          EXPECT_NEAR(f, 4.0 / 3.0 * p.e_star * std::sqrt(p.r_star) * std::pow(delta, 1.5), 1e-12 * f) << delta;
        }
        // the tangent stiffness is the derivative of the force (the servo's), the energy its integral
        const double h = 1e-3 * delta;
        const double df = (cm.normal.elastic(delta + h, p.r_star) - cm.normal.elastic(delta - h, p.r_star)) / (2 * h);
        EXPECT_NEAR(cm.normal.tangent_stiffness(delta, p.r_star, nullptr), df, 1e-6 * df);
        const double dE =
            (cm.normal_energy(delta + h, p.r_star, nullptr) - cm.normal_energy(delta - h, p.r_star, nullptr)) / (2 * h);
        EXPECT_NEAR(cm.normal.elastic(delta, p.r_star), dE, 1e-6 * dE);
      }
    else ADD_FAILURE() << "contact.normal = hertz did not compose HertzNormal";
  });
}

// Hertz alone has no history but reads each pair's masses: the listed loop (every kernel) against
// the all-pairs oracle on a sheared random packing of unequal spheres, across list rebuilds.
TEST(Hertz, ListEqualsTheAllPairsOracleAcrossRebuilds) {
  const dem::Model m = dem_test::model_with({"contact.normal=hertz", "contact.restitution=0.5"});
  dem::State s = dem_test::random_state(400, 0.40, 0.5, 17);
  const dem::VelGrad rate{dem::Vec3{0, 0, 0}, dem::Vec3{0, 0.4 / (3000 * m.dt), 0}};
  dem::Engine e(m, s);
  for (int k = 1; k <= 3000; ++k) {
    e.step(rate);
    if (k % 1000 != 0) continue;
    dem::State b = s;
    dem::compute_forces_all_pairs(m, b, rate, nullptr);
    for (dem::PairKernel kernel : dem::supported_pair_kernels()) {
      dem::State a = s;
      dem::ForceScratch scratch;
      scratch.kernel = kernel;
      dem::compute_forces(m, a, e.neighbor_list(), rate, 1, 3, scratch);
      const double fscale = dem_test::max_force(a);
      ASSERT_GT(fscale, 0);
      EXPECT_LT(dem_test::max_force_difference(a, b), 1e-9 * fscale) << dem::pair_kernel_name(kernel) << " step " << k;
    }
  }
  EXPECT_GT(e.neighbor_list().builds, 2);
}

TEST(Hertz, HeadOnImpactMatchesHertzsContactTimeAndLargestOverlap) {
  const dem::Model m = hertz_model(1.0);
  const double r1 = 1e-3, r2 = 1.5e-3;
  const Pair p = pair_of(m, r1, r2);
  for (double v : {0.1, 1.0, 3.0}) {
    const dem::CollisionResult c = dem::simulate_collision(m, r1, r2, v);
    // Johnson, Contact Mechanics (1985), eqs. 11.23-11.24: delta_max = (15 m* v^2/(16 E* sqrt R*))^(2/5),
    // t_c = 2.868 (m*^2/(R* E*^2 v))^(1/5).
    const double delta_max = std::pow(15.0 * p.m_star * v * v / (16.0 * p.e_star * std::sqrt(p.r_star)), 0.4);
    const double tc = 2.868 * std::pow(p.m_star * p.m_star / (p.r_star * p.e_star * p.e_star * v), 0.2);
    std::printf("v = %g m/s: t_c = %.5g s (Hertz %.5g, %ld steps), delta_max = %.5g m (Hertz %.5g), e = %.6f\n", v,
                c.contact_time, tc, c.steps_in_contact, c.max_overlap * r1, delta_max, c.restitution);
    EXPECT_NEAR(c.contact_time, tc, 0.005 * tc) << v;
    EXPECT_NEAR(c.max_overlap * r1, delta_max, 0.005 * delta_max) << v;
    EXPECT_NEAR(c.restitution, 1.0, 1e-3) << v;
  }
}

TEST(Hertz, RestitutionIsTheRequestedOneAtEverySpeed) {
  for (double e : {0.3, 0.6, 0.9}) {
    const dem::Model m = hertz_model(e);
    EXPECT_NEAR(m.restitution, e, 1e-12);   // the Rayleigh-equivalent oscillator's, by construction
    using H = dem::contact::HertzNormal;
    std::printf("e = %.2f: alpha = %.5f solved; LAMMPS' polynomial alpha = %.5f gives e = %.4f\n", e, H::tsuji_alpha(e),
                H::lammps_tsuji_alpha(e), H::restitution_of_alpha(H::lammps_tsuji_alpha(e)));
    double e_slow = 0;
    for (double v : {0.05, 0.5, 3.0}) {
      const dem::CollisionResult c = dem::simulate_collision(m, 1e-3, 1.5e-3, v);
      std::printf("e = %.2f, v = %g m/s: measured e = %.5f\n", e, v, c.restitution);
      // Tsuji's damping with alpha solved for e: the engine's impact (velocity Verlet, real units)
      // gives e within 2 % of the request ...
      EXPECT_NEAR(c.restitution, e, 0.02 * e) << e << " at " << v;
      // ... and independent of the impact speed (the dashpot scales as the spring: Tsuji et al. 1992)
      if (e_slow == 0) e_slow = c.restitution;
      EXPECT_NEAR(c.restitution, e_slow, 2e-3) << e << " at " << v;
    }
  }
}

TEST(Hertz, TimeScaleIsTheRayleighTime) {
  const dem::Model m = hertz_model(0.8, {}, 7e10, 0.25, 1e-3, 1.5e-3, 2500);
  const double G = 7e10 / (2 * 1.25);
  const double tr = kPi * 1e-3 * std::sqrt(2500 / G) / (0.1631 * 0.25 + 0.8766);   // Li, Xu & Thornton 2005
  EXPECT_NEAR(m.t_contact, tr, 1e-9 * tr);
  EXPECT_NEAR(m.dt, m.dt_over_tc * tr, 1e-9 * tr);
  // p* = 2<r>p/k_ref with k_ref = 2 E* r_min
  EXPECT_NEAR(m.contact.reference_stiffness(), 2 * 7e10 / (2 * (1 - 0.0625)) * 1e-3, 1.0);
}

// Mindlin's k_t and the rule when it changes, on one contact (T = double, the lane body every
// kernel runs): a step at overlap d1, then a step without tangential motion at d2 < d1.
TEST(Mindlin, StiffnessCoulombLimitAndTheRuleWhenKtChanges) {
  for (const char* rule : {"mindlin", "mindlin_force"}) {
    const dem::Model m =
        hertz_model(1.0, {std::string("contact.tangential=\"") + rule + "\"", "contact.friction=0.3"});
    dem::contact::with_contact_model(m.contact, [&](const auto& cm) {
      using CM = std::decay_t<decltype(cm)>;
      EXPECT_EQ(CM::history, 5);
      EXPECT_TRUE(CM::rotations);
      EXPECT_TRUE(CM::vectorised);
      using Tn = std::decay_t<decltype(cm.tangential)>;
      if constexpr (std::is_same_v<Tn, dem::contact::MindlinTangential> ||
                    std::is_same_v<Tn, dem::contact::MindlinForceTangential>) {
        const bool force_kept = std::is_same_v<Tn, dem::contact::MindlinForceTangential>;
        const double E = 1e8, nu = 0.3, a12 = 6e-4, d1 = 1e-5, d2 = 4e-6, dt = 1e-6;
        const double g_star = E / (2 * (1 + nu)) / (2 * (2 - nu));   // 1/G* = 2(2 - nu)/G
        const V3<double> n{0, 0, 1}, still{0, 0, 0};
        double h[5] = {0, 0, 0, 0, 0}, diss = 0;
        const V3<double> f1 = cm.tangential.update(n, V3<double>{0.01, 0, 0}, 1.0, dt, h, diss, PairLanes<double>{d1, a12, 0});
        const double kt1 = 8 * g_star * std::sqrt(a12 * d1);
        EXPECT_NEAR(f1.x, -kt1 * 0.01 * dt, 1e-12 * kt1 * 0.01 * dt) << rule;   // sticking: f = -k_t v_t dt
        EXPECT_EQ(h[3], 0.0);
        EXPECT_NEAR(h[4], kt1, 1e-12 * kt1);
        // The overlap falls to d2, no tangential motion: kept displacement -> the force follows
        // k_t, f2/f1 = sqrt(d2/d1) (LAMMPS `mindlin`); kept force -> f2 = f1 (`mindlin/force`).
        double h2[5] = {h[0], h[1], h[2], h[3], h[4]};
        const V3<double> f2 = cm.tangential.update(n, still, 1.0, dt, h2, diss, PairLanes<double>{d2, a12, 0});
        EXPECT_NEAR(f2.x / f1.x, force_kept ? 1.0 : std::sqrt(d2 / d1), 1e-12) << rule;
        // the measurements' read-only force agrees with the step's
        const dem::contact::TangentialInput in2{dem::Vec3{0, 0, 1}, dem::Vec3{0, 0, 0}, 1.0, d2, a12};
        EXPECT_NEAR(cm.tangential.force(in2, h2).x / f2.x, 1.0, 1e-12) << rule;
        // Coulomb: a large slip is capped at mu f_n and the spring put on the cone
        const V3<double> f3 = cm.tangential.update(n, V3<double>{1e3, 0, 0}, 1e-3, dt, h, diss, PairLanes<double>{d1, a12, 0});
        EXPECT_NEAR(std::fabs(f3.x), 0.3 * 1e-3, 1e-15);
        EXPECT_EQ(h[3], 1.0);
        EXPECT_NEAR(h[0] * -kt1, f3.x, 1e-15);
        EXPECT_GT(diss, 0.0);
      } else {
        ADD_FAILURE() << rule << " did not compose a Mindlin law";
      }
    });
  }
}

TEST(Mindlin, NeedsHertzAndBadKeysAreRefused) {
  for (const char* rule : {"mindlin", "mindlin_force"})
    EXPECT_THROW(dem_test::model_with({std::string("contact.tangential=\"") + rule + "\"", "contact.friction=0.3"}),
                 dem::SceneError) << rule;
  EXPECT_THROW(hertz_model(0.9, {"contact.tangential=\"mindlin_rescale\""}), dem::SceneError);
  EXPECT_THROW(hertz_model(0.9, {"contact.stiffness_N_m=1e6"}), dem::SceneError);   // a linear key with Hertz
  EXPECT_THROW(hertz_model(0.9, {"contact.tangential=\"mindlin\"", "contact.friction=0.3",
                                 "contact.tangential_stiffness_ratio=0.5"}), dem::SceneError);   // Cundall-Strack's
  EXPECT_THROW(hertz_model(0.0), dem::SceneError);
  EXPECT_THROW(hertz_model(0.9, {}, 1e8, 0.6), dem::SceneError);
  EXPECT_EQ(dem::contact::history_width(hertz_model(0.9).contact), 0);
  EXPECT_EQ(dem::contact::history_width(hertz_model(0.9, {"contact.tangential=\"mindlin\"", "contact.friction=0.3"}).contact), 5);
  const std::string text = dem::contact::registry_text();   // dem info --contact-models
  for (const char* k : {"normal \"hertz\"", "contact.youngs_modulus_Pa [Pa]", "contact.poisson_ratio [1]",
                        "contact.restitution [1]", "tangential \"mindlin\"", "tangential \"mindlin_force\"",
                        "Law2_ScGeom_MindlinPhys_Mindlin", "damping tsuji", "mindlin/force"})
    EXPECT_NE(text.find(k), std::string::npos) << k;
}

// Oblique impacts of two elastic equal spheres, Chung & Ooi (2011) Test 4's material (E = 70 GPa,
// nu = 0.33, rho = 2700, mu = 0.092, |v| = 3.9 m/s), in Maw's normalised angles
// psi1 = 2 v_t/(mu (1 + e) v_n) (incidence) and psi2 the same of the contact point's tangential
// velocity after the impact. Rigid-body theory: gross sliding for psi1 > 7 with psi2 = psi1 - 7.
// In the sticking limit (psi1 -> 0) psi2/psi1 is the contact point's tangential restitution of
// the no-slip impact, integrated here for each rule (sticking_ratio). Between the regimes the
// contact point recoils (psi2 < 0) with a minimum of psi2 (Maw, Barber & Fawcett, Wear 38 (1976)
// 101; Di Renzo & Di Maio, Chem. Eng. Sci. 59 (2004) 525; Thornton, Cummins & Cleary, Powder
// Technol. 233 (2013) 30). J_t is taken from the spins (frame-free); J_n and e_n in the frame of
// the initial line of centres, which turns by about v_t t_c/(2r) during the contact (e_n = 0.985
// at 60 deg; J_t measured from the velocities in that frame was 40 % off at 0.05 deg and 5 % at
// 60 deg).
TEST(Mindlin, ObliqueImpactsFollowSlidingTheoryAndTheStickingLimitOfEachRule) {
  const double mu = 0.092, v = 3.9, r = 1e-3, nu = 0.33;
  const double kappa = 2 * (1 - nu) / (2 - nu);
  for (const char* rule : {"mindlin", "mindlin_force"}) {
    const bool force_kept = std::string(rule) == "mindlin_force";
    const dem::Model m = hertz_model(1.0, {std::string("contact.tangential=\"") + rule + "\"", "contact.friction=0.092"},
                                     7e10, nu, r, r, 2700);
    const double m1 = 4.0 / 3.0 * kPi * r * r * r * 2700, mr = 0.5 * m1;
    const double limit_ratio = sticking_ratio(kappa, force_kept);
    // Both rules have the same sticking limit (within 0.2 %): the small-angle rebound is not the rule's.
    EXPECT_NEAR(limit_ratio, sticking_ratio(kappa, !force_kept), 2e-3);
    std::printf("%s: sticking limit psi2/psi1 = %.4f (RK4 of the no-slip impact)\n", rule, limit_ratio);
    std::printf("theta_deg  psi1     psi2     e_n     Jt/(mu Jn)\n");
    double psi2_min = 1e9, psi1_at_min = 0;
    double last_gap = 0;   // |psi2/psi1 - limit| of the previous (smaller) sticking angle
    for (double deg : {0.005, 0.01, 0.05, 0.1, 0.5, 1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0, 20.0, 24.0, 30.0, 40.0, 50.0, 60.0}) {
      const double theta = deg * kPi / 180.0;
      const dem::ObliqueResult o = dem::simulate_oblique_collision(m, r, r, v, theta);
      const double vn = v * std::cos(theta), vt = v * std::sin(theta), en = o.normal_restitution;
      const double psi1 = 2 * vt / (mu * (1 + en) * vn);
      // The tangential impulse from the spin it left (I w / r, I = 2/5 m r^2): the torque is
      // a n x f_t at every step, so this is free of the turn of the line of centres that biases
      // the impulse measured in the initial frame (at 0.05 deg that bias is 40 % of J_t).
      const double j_t = 0.4 * m1 * r * o.omega[0].y;
      const double vct_after = vt - 3.5 * j_t / mr;   // the contact point
      const double psi2 = 2 * vct_after / (mu * (1 + en) * vn);
      const double ratio = j_t / (mu * o.normal_impulse);
      std::printf("%9.2f  %7.4f  %7.4f  %.5f  %.4f  psi2/psi1 = %.4f\n", deg, psi1, psi2, en, ratio, psi2 / psi1);
      EXPECT_LE(ratio, 1.0 + 1e-9) << rule << " " << deg;   // |f_t| <= mu f_n at every step
      if (deg <= 20) EXPECT_NEAR(en, 1.0, 2e-3) << rule << " " << deg;   // elastic normal (frame turn small)
      // Sticking: the rule's own no-slip impact (a 1 % error of k_t/m_t moves the ratio by 1.5 %).
      // The kept displacement meets it; the kept force slips at the end of the contact (its
      // force stays while mu f_n -> 0), less the smaller psi1: it tends to the limit from below.
      if (psi1 < 0.03) {
        const double gap = std::fabs(psi2 / psi1 - limit_ratio);
        if (!force_kept) EXPECT_LT(gap, 2e-3) << rule << " " << deg;
        else if (deg == 0.005) EXPECT_LT(gap, 6e-3) << rule << " " << deg;
        EXPECT_GE(gap, last_gap - 1e-4) << rule << " " << deg;
        last_gap = gap;
      }
      if (psi1 > 1.2 * 7) {   // gross sliding: psi2 = psi1 - 7
        EXPECT_NEAR(ratio, 1.0, 0.01) << rule << " " << deg;
        EXPECT_NEAR(psi2, psi1 - 7, 0.01 * psi1) << rule << " " << deg;
      } else if (psi1 > 3 && psi1 < 5) {   // between the regimes: the contact point recoils
        EXPECT_LT(psi2, 0.0) << rule << " " << deg;
        EXPECT_GT(psi2, -psi1) << rule << " " << deg;
      }
      if (psi2 < psi2_min) { psi2_min = psi2; psi1_at_min = psi1; }
    }
    EXPECT_GT(psi1_at_min, 1.5) << rule;   // the minimum lies between the regimes
    EXPECT_LT(psi1_at_min, 7.0) << rule;
    EXPECT_LT(psi2_min, 0.0) << rule;
  }
}
