// The incremental anisotropic model (demfit/model.hpp) against closed forms, and its joint
// calibration against synthetic ensembles made by the model with known parameters.
#include <gtest/gtest.h>

#include <ceres/jet.h>

#include <array>
#include <fstream>
#include <iomanip>
#include <memory>
#include <string>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "demfit/ensemble.hpp"
#include "demfit/fit.hpp"
#include "demfit/format.hpp"
#include "demfit/model.hpp"
#include "demfit/model_fit.hpp"
#include "demfit/jet_valued_cost.hpp"

using namespace demfit::model;

namespace {

// Isotropic laws close to the N = 9261 ensemble's (data/figure3_n9261/fit/isotropic.md).
Parameters truth() {
  Parameters P;
  P.p0 = 0.0412; P.nu_c = 0.6642; P.gamma_p = 0.0; P.C0 = 5.63; P.C1 = 8.30; P.nu_cC = 0.667; P.alpha = 0.514;
  const double sh[kNumShear] = {0.16, -0.5, std::log(50.0), -6.0, 0.11, -0.8, std::log(40.0), -4.0, 0.4, -10.0,
                                std::log(15.0), -7.0};
  std::copy(sh, sh + kNumShear, P.shear);
  P.nu_ref = 0.74;
  return P;
}

Segment shear_seg(double eps_d, int outputs, Control c = Control::Volume) {
  Segment s;
  s.eps_d = eps_d; s.outputs = outputs; s.control = c;
  return s;
}

}  // namespace

// The per-curve law x = x_max - (x_max - x0) exp(-beta eps) is the monotone constant-volume
// limit for s and F, whatever the pressure does (a_A, beta_p non-zero here).
TEST(Model, SaturatingLawIsTheMonotoneLimit) {
  const Parameters P = truth();
  const auto iso = P.iso();
  for (double nu : {0.68, 0.75, 0.81}) {
    const double p0 = isotropic_pressure(iso.data(), nu) * 1.1, s0 = 0.012, F0 = -0.004;
    const auto pts = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, s0, F0, {shear_seg(0.4, 80)});
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    for (const auto& q : pts) {
      EXPECT_NEAR(q.state.s, demfit::saturating(s0, L.s_max, L.beta_s, q.eps_d), 1e-9) << nu << " " << q.eps_d;
      EXPECT_NEAR(q.state.F, demfit::saturating(F0, L.F_max, L.beta_F, q.eps_d), 1e-9) << nu << " " << q.eps_d;
      EXPECT_NEAR(std::exp(q.state.ln_nu), nu, 1e-14);   // constant volume
    }
  }
}

// Isotropic compression and decompression integrate exactly to the packing's pressure law
// k p_iso(nu) (B = dp/dln nu is its derivative), from any start on or off the fitted law.
TEST(Model, IsotropicPathFollowsThePressureLaw) {
  const Parameters P = truth();
  const auto iso = P.iso();
  for (double k : {1.0, 0.8}) {
    const double nu0 = 0.70;
    Segment comp;
    comp.eps_d = 0; comp.eps_vol = -std::log(0.80 / nu0); comp.outputs = 40;
    Segment dec = comp;
    dec.eps_vol = std::log(0.80 / 0.68);
    const auto pts = integrate<double>(iso.data(), P.shear, P.nu_ref, nu0, k * isotropic_pressure(iso.data(), nu0), 0.0, 0.0,
                                       {comp, dec});
    for (const auto& q : pts) {
      const double nu = std::exp(q.state.ln_nu);
      EXPECT_NEAR(q.state.p, k * isotropic_pressure(iso.data(), nu), 1e-9 * isotropic_pressure(iso.data(), 0.8));
      EXPECT_NEAR(q.eps_vol, -std::log(nu / nu0), 1e-12);
    }
    EXPECT_NEAR(std::exp(pts.back().state.ln_nu), 0.68, 1e-12);
  }
}

// Constant volume, the pressure equation dp/de = a_A B F(e) - beta_p (p - p_ref) with the
// exponential F(e) is linear: closed form. With the rates -> 0 it is the linear-elastic case
// p = p0 + a_A B F0 e (the anisotropy modulus as a constant cross-modulus).
TEST(Model, PressureUnderShearMatchesClosedForm) {
  Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.72;
  const double p_ref = isotropic_pressure(iso.data(), nu), B = bulk_modulus(iso.data(), nu);
  const double p0 = 1.05 * p_ref, F0 = 0.01;
  const double k = p0 / p_ref;
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const auto pts = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, F0, {shear_seg(0.4, 40)});
  const double aB = L.a_A * k * B, bp = L.beta_p, bF = L.beta_F, Fm = L.F_max;
  for (const auto& q : pts) {
    const double e = q.eps_d;
    const double qex = (p0 - k * p_ref) * std::exp(-bp * e) + aB * Fm * (1 - std::exp(-bp * e)) / bp -
                       aB * (Fm - F0) * (std::exp(-bF * e) - std::exp(-bp * e)) / (bp - bF);
    EXPECT_NEAR(q.state.p, k * p_ref + qex, 1e-9 * p0) << e;
  }
  // Linear-elastic special case: no evolution of F, s, or the excess pressure.
  for (int i : {kLnBetaSA, kLnBetaFA, kLnBetaPA}) P.shear[i] = -60.0;   // beta = e^-60 ~ 1e-26
  for (int i : {kLnBetaSB, kLnBetaFB, kLnBetaPB}) P.shear[i] = 0.0;
  const auto lin = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.05, F0, {shear_seg(0.3, 30)});
  for (const auto& q : lin) {
    EXPECT_NEAR(q.state.p, p0 + L.a_A * k * B * F0 * q.eps_d, 1e-12 * p0);
    EXPECT_NEAR(q.state.s, 0.05, 1e-15);
    EXPECT_NEAR(q.state.F, F0, 1e-15);
  }
}

// Reversal: loading the other way from an isotropic state mirrors s and F and leaves p
// unchanged; after a reversal, s and F relax towards -x_max from the reversal value
// (closed form), and the accumulated strain keeps growing while eps_d comes back.
TEST(Model, ReversalSymmetryAndClosedForm) {
  const Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.70, p0 = isotropic_pressure(iso.data(), nu);
  const auto fwd = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, {shear_seg(0.2, 40)});
  const auto bwd = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, {shear_seg(-0.2, 40)});
  ASSERT_EQ(fwd.size(), bwd.size());
  for (std::size_t i = 0; i < fwd.size(); ++i) {
    EXPECT_NEAR(bwd[i].state.s, -fwd[i].state.s, 1e-14);
    EXPECT_NEAR(bwd[i].state.F, -fwd[i].state.F, 1e-14);
    EXPECT_NEAR(bwd[i].state.p, fwd[i].state.p, 1e-14);
    EXPECT_NEAR(bwd[i].eps_d, -fwd[i].eps_d, 1e-15);
  }
  const auto rev = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, {shear_seg(0.1, 20), shear_seg(-0.3, 60)});
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double s_r = rev[20].state.s, F_r = rev[20].state.F;
  EXPECT_NEAR(s_r, demfit::saturating(0.0, L.s_max, L.beta_s, 0.1), 1e-9);
  for (std::size_t i = 20; i < rev.size(); ++i) {
    const double de = rev[i].eps_d_acc - 0.1;
    // RK4 truncation: (beta h)^4 / 120 per unit approach, h = 5e-4, beta ~ 60
    EXPECT_NEAR(rev[i].state.s, demfit::saturating(s_r, -L.s_max, L.beta_s, de), 1e-8);
    EXPECT_NEAR(rev[i].state.F, demfit::saturating(F_r, -L.F_max, L.beta_F, de), 1e-8);
    EXPECT_NEAR(rev[i].eps_d, 0.1 - de, 1e-12);
  }
  EXPECT_NEAR(rev.back().eps_d_acc, 0.4, 1e-12);
}

// Mixed control: an isobaric segment holds p exactly; the volume change has the sign of the
// excess-pressure source a_A B F - beta_p (p - p_ref) (dilatancy where it is positive).
TEST(Model, IsobaricSegmentHoldsPressure) {
  const Parameters P = truth();
  const auto iso = P.iso();
  for (double nu : {0.70, 0.81}) {
    const double p0 = isotropic_pressure(iso.data(), nu);
    const auto pts = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, {shear_seg(0.3, 60, Control::Isobaric)});
    for (const auto& q : pts) EXPECT_NEAR(q.state.p, p0, 1e-12 * p0);
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    // Early on p = p_ref and F > 0: dilation (eps_vol > 0) iff a_A > 0.
    EXPECT_EQ(pts[5].eps_vol > 0, L.a_A > 0) << nu << " a_A=" << L.a_A;
  }
}

namespace {

// A synthetic ensemble: K members of the model's curves plus AR(1) noise (lag-1 rho) per
// member and quantity, on the grid of a DEM ensemble; mean, SE and 95 % half-width as `dem fit`
// writes them; members kept for the jackknife.
struct Synthetic {
  std::vector<CurveData> mean;
  std::vector<std::vector<CurveData>> members;   // [curve][member]
};

Synthetic synthetic(const Parameters& P, const std::vector<double>& nus, int K, double rho, std::uint64_t seed,
                    const std::string& mode = "D2") {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Synthetic S;
  const auto iso = P.iso();
  std::vector<double> eps;
  for (int i = 0; i <= 100; ++i) eps.push_back(0.004 * i);
  for (double nu : nus) {
    const double p0 = isotropic_pressure(iso.data(), nu);
    const Ext<double> ext{P.extended ? P.ext : nullptr, lode_b_of(mode), P.surface, P.fabric, P.extended && P.state_limit,
                          P.extended && P.state_lode};
    const auto st = monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.01, 0.01, eps, 1e-3, ext);
    std::vector<CurveData> mem;
    for (int k = 0; k < K; ++k) {
      CurveData c;
      c.mode = mode; c.nu = nu; c.packings = K; c.eps = eps; c.source = "synthetic";
      const double sd[3] = {0.01 * p0, 0.015, 0.008};   // p*, s_dev, F_dev noise per packing
      double z[3] = {g(rng), g(rng), g(rng)};
      for (std::size_t i = 0; i < eps.size(); ++i) {
        if (i > 0)
          for (double& v : z) v = rho * v + std::sqrt(1 - rho * rho) * g(rng);
        // the start state is common to the packings' mean (the model starts from it)
        const double f = i == 0 ? 0.0 : 1.0;
        c.p.push_back(st[i].p + f * sd[0] * z[0]);
        c.s.push_back(st[i].s + f * sd[1] * z[1]);
        c.F.push_back(st[i].F + f * sd[2] * z[2]);
      }
      mem.push_back(c);
    }
    CurveData m = mem[0];
    for (auto* v : {&m.se_p, &m.se_s, &m.se_F, &m.hw_p, &m.hw_s, &m.hw_F}) v->assign(eps.size(), 0.0);
    for (std::size_t i = 0; i < eps.size(); ++i) {
      std::vector<std::vector<double>> cols(3);
      for (const auto& c : mem) { cols[0].push_back(c.p[i]); cols[1].push_back(c.s[i]); cols[2].push_back(c.F[i]); }
      double* mv[3] = {&m.p[i], &m.s[i], &m.F[i]};
      double* sv[3] = {&m.se_p[i], &m.se_s[i], &m.se_F[i]};
      for (int q = 0; q < 3; ++q) {
        double mean = 0, ss = 0;
        for (double v : cols[q]) mean += v / K;
        for (double v : cols[q]) ss += (v - mean) * (v - mean);
        *mv[q] = mean;
        *sv[q] = i == 0 ? 0.0 : std::sqrt(ss / (K - 1) / K);
      }
    }
    // Start-state SE: what the DEM first row has (spread of the start states); a floor suffices.
    m.se_p[0] = m.se_p[1]; m.se_s[0] = m.se_s[1]; m.se_F[0] = m.se_F[1];
    S.mean.push_back(m);
    S.members.push_back(mem);
  }
  return S;
}

// The jackknife's leave-one-out calibrations: member k left out of every mean curve ((K mean - x_k)/(K - 1)),
// each fit from the options `o` (their start the full fit's); one estimate vector per left-out member.
// `others`: fitted means of other packings, held as they are (the two-set jackknife).
std::vector<std::vector<double>> leave_one_out_estimates(const std::vector<CurveData>& mean,
                                                         const std::vector<std::vector<CurveData>>& members, int K,
                                                         const CalibrationOptions& o,
                                                         const std::vector<CurveData>& others = {}) {
  std::vector<std::vector<double>> est;
  for (int k = 0; k < K; ++k) {
    std::vector<CurveData> loo = others;
    for (std::size_t j = 0; j < mean.size(); ++j) {
      CurveData c = mean[j];
      const CurveData& x = members[j][k];
      for (std::size_t i = 0; i < c.eps.size(); ++i) {
        c.p[i] = (K * c.p[i] - x.p[i]) / (K - 1);
        c.s[i] = (K * c.s[i] - x.s[i]) / (K - 1);
        c.F[i] = (K * c.F[i] - x.F[i]) / (K - 1);
      }
      loo.push_back(c);
    }
    est.push_back(calibrate(loo, {}, o).value);
  }
  return est;
}

}  // namespace

// The truth's shear block 10-20 % away (a start the fit must leave), and the options of a shear-only fit from START
// (the isotropic block held at it) on synthetic curves.
Parameters shear_start_away(const Parameters& P) {
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.8 : 1.1);
  return start;
}
CalibrationOptions shear_fit_options(const Parameters& P, const Parameters* start) {
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.nu_ref = P.nu_ref;
  o.max_step = 1e-3;
  o.start = start;
  return o;
}

// Calibration recovers the known shear laws from synthetic ensembles with strongly correlated
// noise (rho = 0.9, as DEM curves have; K = 8 packings, 4 volume fractions) within the
// jackknife-over-packings intervals the command states (estimate -/+ t_{K-1} se). Over 8
// seeded ensembles x 12 coefficients the 95 % intervals held the truth in 0.86 of the cases
// when this test was written (a slight under-coverage of the jackknife on a non-linear fit
// with K = 8, docs/model.md); the covariance of the weighted fit, which treats the correlated
// points as independent, covers far less.
TEST(ModelFit, RecoversKnownParametersWithinJackknifeErrors) {
  const Parameters P = truth();
  const int K = 8, seeds = 8;
  const double t95 = demfit::t_quantile(0.975, K - 1);
  int covered = 0, covered_cov = 0, total = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Synthetic S = synthetic(P, {0.69, 0.73, 0.77, 0.81}, K, 0.9, seed);
    const Parameters start = shear_start_away(P);   // start away from the truth: the fit must find it
    const CalibrationOptions o = shear_fit_options(P, &start);
    const Calibration cal = calibrate(S.mean, {}, o);
    ASSERT_TRUE(cal.ok) << cal.message;
    CalibrationOptions oj = o;
    oj.start = &cal.params;
    const auto est = leave_one_out_estimates(S.mean, S.members, K, oj);
    for (int i = 0; i < kNumShear; ++i) {
      const int a = kNumIso + i;
      double mean = 0, ss = 0;
      for (const auto& e : est) mean += e[a] / K;
      for (const auto& e : est) ss += (e[a] - mean) * (e[a] - mean);
      const double se = std::sqrt((K - 1.0) / K * ss), err = std::fabs(cal.value[a] - P.shear[i]);
      EXPECT_LT(err, 6 * se) << "seed " << seed << " " << shear_name(i) << ": estimate " << cal.value[a] << " truth "
                             << P.shear[i] << " jackknife se " << se;
      covered += err < t95 * se;
      covered_cov += err < 1.96 * cal.se_cov[a];
      ++total;
    }
  }
  const double coverage = static_cast<double>(covered) / total, coverage_cov = static_cast<double>(covered_cov) / total;
  std::printf("jackknife-t 95 %% coverage %.3f, covariance 95 %% coverage %.3f (%d intervals)\n", coverage, coverage_cov, total);
  EXPECT_GE(coverage, 0.80);
  EXPECT_LT(coverage_cov, coverage - 0.15) << "correlated noise: the covariance of independent points should under-cover";
}

// The jackknife over several sets of packings against its closed form: one set gives the usual (K-1)/K sum (x -
// mean)^2 and K - 1 degrees of freedom; two sets sum their parts, each about its own mean (a shift of one set's values
// changes nothing), and Welch-Satterthwaite's degrees of freedom lie between the smaller set's n - 1 and the sum.
TEST(ModelFit, JackknifeOverTwoSetsMatchesItsClosedForm) {
  const std::vector<double> a{1.0, 2.0, 4.0}, b{10.0, 10.5, 11.5, 12.0};
  std::vector<double> x = a, y;
  x.insert(x.end(), b.begin(), b.end());
  const std::vector<int> set{0, 0, 0, 1, 1, 1, 1};
  auto part = [](const std::vector<double>& v) {   // (n-1)/n sum (v - mean)^2 by hand
    double m = 0, ss = 0;
    for (double e : v) m += e;
    m /= v.size();
    for (double e : v) ss += (e - m) * (e - m);
    return (v.size() - 1.0) / v.size() * ss;
  };
  EXPECT_NEAR(jackknife_covariance(a, a), part(a), 1e-14);
  EXPECT_EQ(jackknife_dof(a), 2.0);
  const double va = part(a), vb = part(b);   // 14/9 x 2/3... by hand: a: mean 7/3, ss 14/3, x 2/3 = 28/9
  EXPECT_NEAR(va, 28.0 / 9.0, 1e-14);
  EXPECT_NEAR(jackknife_covariance(x, x, set), va + vb, 1e-13);
  EXPECT_NEAR(jackknife_dof(x, set), (va + vb) * (va + vb) / (va * va / 2 + vb * vb / 3), 1e-12);
  EXPECT_GT(jackknife_dof(x, set), 2.0);
  EXPECT_LT(jackknife_dof(x, set), 5.0);
  for (double& e : x) y.push_back(e);
  for (std::size_t k = 3; k < y.size(); ++k) y[k] += 100.0;   // one set shifted: no change
  EXPECT_NEAR(jackknife_covariance(y, y, set), va + vb, 1e-11);
  EXPECT_NEAR(jackknife_covariance(x, y, set), va + vb, 1e-11);
  // one set only: the pooled formula over all seven would include the sets' distance (much larger)
  EXPECT_GT(jackknife_covariance(x, x), 10 * (va + vb));
}

// A coefficient whose refits all end within round-off of one value has no jackknife error: the joint calibration at
// mu = 0 quoted n_dil (which does not act there) +- 2.3e-15 from refits an ulp apart (thirty-third round). A quoted
// coefficient held so is said (a bound); an undetermined one quotes nothing; a genuine spread is quoted as before.
TEST(ModelFit, ARoundOffSpreadIsNoJackknifeError) {
  Calibration cal;
  cal.names = {"spread", "undetermined", "held"};
  cal.value = {1.0, 5.752817178203651, 0.3};
  cal.se_cov = {0.1, std::nan(""), 0.01};
  cal.undetermined = {false, true, false};
  std::vector<std::vector<double>> est;
  const std::vector<int> sample{0, 0, 0, 1, 1};
  for (int k = 0; k < 5; ++k) {
    const double v = cal.value[1];
    est.push_back({1.0 + 0.01 * k * k, k % 2 ? std::nextafter(v, 10.0) : v, 0.3});
  }
  std::vector<std::string> said;
  std::vector<double> dof;
  const std::vector<double> se = jackknife_errors(est, cal, false, &said, sample, &dof);
  EXPECT_GT(se[0], 0.0);
  EXPECT_TRUE(std::isfinite(dof[0]));
  EXPECT_TRUE(std::isnan(se[1])) << "round-off is no spread: " << se[1];
  EXPECT_TRUE(std::isnan(se[2]));
  ASSERT_EQ(said.size(), 1u);
  EXPECT_NE(said[0].find("held: every jackknife refit ends on the same value"), std::string::npos) << said[0];
}

// Two sets of packings behind different fitted curves (D2 at nu = 0.69, 0.73 from 8 packings, at 0.77, 0.81 from 6
// others, as the joint calibration's D2 + D3 and TC_s3 come from the friction study's and the laboratory's): each
// packing left out of the means it holds, the errors summed over the sets (jackknife_errors with the sets), the 95 %
// intervals with Welch-Satterthwaite's t. Over 8 seeded ensembles x 12 coefficients they held the truth in 0.833 of
// the cases when written (one set's K = 8 test above: 0.86; with 4 packings in the second set, as the laboratory's,
// 0.81, and two estimates 6.2 and 8.3 errors from the truth: a fit 4 packings determine poorly).
TEST(ModelFit, RecoversKnownParametersWithinTwoSetJackknifeErrors) {
  const Parameters P = truth();
  const int KA = 8, KB = 6, seeds = 8;
  int covered = 0, total = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Synthetic A = synthetic(P, {0.69, 0.73}, KA, 0.9, seed), B = synthetic(P, {0.77, 0.81}, KB, 0.9, 100 + seed);
    std::vector<CurveData> mean = A.mean;
    mean.insert(mean.end(), B.mean.begin(), B.mean.end());
    const Parameters start = shear_start_away(P);
    const CalibrationOptions o = shear_fit_options(P, &start);
    const Calibration cal = calibrate(mean, {}, o);
    ASSERT_TRUE(cal.ok) << cal.message;
    CalibrationOptions oj = o;
    oj.start = &cal.params;
    std::vector<std::vector<double>> est;
    std::vector<int> set;
    for (const auto* S : {&A, &B}) {
      const std::vector<std::vector<double>> e = leave_one_out_estimates(S->mean, S->members, S == &A ? KA : KB, oj,
                                                                         S == &A ? B.mean : A.mean);
      est.insert(est.end(), e.begin(), e.end());
      set.insert(set.end(), e.size(), S == &A ? 0 : 1);
    }
    std::vector<double> dof;
    const std::vector<double> se = jackknife_errors(est, cal, false, nullptr, set, &dof);
    for (int i = 0; i < kNumShear; ++i) {
      const int a = kNumIso + i;
      ASSERT_TRUE(std::isfinite(se[a]) && std::isfinite(dof[a])) << shear_name(i);
      EXPECT_GE(dof[a], KB - 1 - 1e-9);
      EXPECT_LE(dof[a], KA + KB - 2 + 1e-9);
      const double err = std::fabs(cal.value[a] - P.shear[i]);
      EXPECT_LT(err, 6 * se[a]) << "seed " << seed << " " << shear_name(i) << ": estimate " << cal.value[a]
                                << " truth " << P.shear[i] << " two-set jackknife se " << se[a];
      covered += err < demfit::t_quantile(0.975, dof[a]) * se[a];
      ++total;
    }
  }
  const double coverage = static_cast<double>(covered) / total;
  std::printf("two-set jackknife-t 95 %% coverage %.3f (%d intervals)\n", coverage, total);
  EXPECT_GE(coverage, 0.80);
}

// Noise-free curves of the model: the joint fit (isotropic block included, branch points made
// by the laws) returns the truth from a start 10-20 % away.
TEST(ModelFit, RecoversExactParametersFromNoiseFreeCurves) {
  const Parameters P = truth();
  Synthetic S = synthetic(P, {0.69, 0.73, 0.77, 0.81}, 2, 0.0, 3);
  for (std::size_t j = 0; j < S.mean.size(); ++j) {   // replace the mean by the members' noise-free model curve
    const auto iso = P.iso();
    CurveData& c = S.mean[j];
    const auto st = monotone_shear<double>(iso.data(), P.shear, P.nu_ref, c.nu, c.p[0], c.s[0], c.F[0], c.eps, 1e-3);
    for (std::size_t i = 0; i < c.eps.size(); ++i) { c.p[i] = st[i].p; c.s[i] = st[i].s; c.F[i] = st[i].F; }
  }
  IsoData iso;
  const auto ib = P.iso();
  for (int i = 0; i < 40; ++i) {
    const double nu = 0.668 + 0.004 * i;
    iso.nu.push_back(nu); iso.p.push_back(isotropic_pressure(ib.data(), nu)); iso.C.push_back(coordination(ib.data(), nu));
  }
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.8 : 1.1);
  CalibrationOptions o;
  o.start = &start;
  o.nu_ref = P.nu_ref;
  o.max_step = 1e-3;
  const Calibration cal = calibrate(S.mean, iso, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  for (int i = 0; i < kNumShear; ++i)
    EXPECT_NEAR(cal.value[kNumIso + i], P.shear[i], 1e-5 * std::max(1.0, std::fabs(P.shear[i]))) << shear_name(i);
  EXPECT_NEAR(cal.params.p0, P.p0, 1e-6);
  EXPECT_NEAR(cal.params.alpha, P.alpha, 1e-4);
  EXPECT_EQ(cal.n_free, kNumIso + kNumShear);
  // One start volume fraction: the six nu-slopes are held at 0, so they are not free parameters of chi2/dof.
  const Calibration one = calibrate({S.mean[1]}, iso, o);
  EXPECT_EQ(one.n_free, kNumIso + kNumShear / 2);
  for (int i = 1; i < kNumShear; i += 2) EXPECT_EQ(one.value[kNumIso + i], 0.0) << shear_name(i);
}

// CalibrationOptions::evaluate_only (the jackknife's basin check, thirty-fifth round): chi2 at a start without a fit is
// the cost Ceres reports at the start of a fit from there (its BriefReport's "Initial cost", 7 digits), and at a
// converged fit's optimum the chi2 that fit ended with; no coefficient is fitted.
TEST(ModelFit, EvaluateOnlyGivesTheChi2AFitFromThatStartBeginsWith) {
  const Parameters P = truth();
  const Synthetic S = synthetic(P, {0.69, 0.73, 0.77, 0.81}, 4, 0.9, 7);
  const Parameters start = shear_start_away(P);
  const CalibrationOptions o = shear_fit_options(P, &start);
  const Calibration fit = calibrate(S.mean, {}, o);
  ASSERT_TRUE(fit.ok) << fit.message;
  CalibrationOptions e = o;
  e.evaluate_only = true;
  const Calibration at_start = calibrate(S.mean, {}, e);
  const auto at = fit.message.find("Initial cost: ");
  ASSERT_NE(at, std::string::npos) << fit.message;
  const double initial = 2 * std::stod(fit.message.substr(at + 14));
  EXPECT_NEAR(at_start.chi2, initial, 1e-6 * initial) << fit.message;
  EXPECT_GT(at_start.chi2, 1.5 * fit.chi2) << "the start is away from the optimum";
  EXPECT_EQ(at_start.n_residuals, fit.n_residuals);
  EXPECT_TRUE(at_start.value.empty()) << "nothing fitted";
  e.start = &fit.params;
  const Calibration at_optimum = calibrate(S.mean, {}, e);
  EXPECT_NEAR(at_optimum.chi2, fit.chi2, 1e-9 * fit.chi2);
}

// One jamming fraction (seventeenth round; docs/model.md, "One jamming fraction"): nu_cC <= 0 makes the coordination
// law read the pressure law's nu_c, the same law as nu_cC = nu_c written out; its stiffness B = dp*/d ln nu is then
// bounded as nu -> nu_c (x -> 0 cancels the coordination's (nu/nu_c - 1)^(alpha - 1)) and equals a central difference
// of p*(ln nu), where the separate law's B diverges at nu_cC. A calibration tied so (--jamming shared) recovers a shared
// truth from noise-free curves and branch points and a start with separate fractions, writes nu_cC = nu_c with nu_c's
// error and one free parameter fewer; holding nu_cC, or not fitting the isotropic block, is refused with the fix.
TEST(ModelFit, OneJammingFractionBoundsTheStiffnessAndIsRecovered) {
  Parameters P = truth();
  P.nu_cC = P.nu_c;
  std::vector<double> tied = P.iso(), written = P.iso();
  tied[kNuCC] = 0.0;
  for (double nu : {P.nu_c * (1 + 1e-12), 0.6643, 0.67, 0.75, 0.85}) {
    EXPECT_EQ(coordination(tied.data(), nu), coordination(written.data(), nu)) << nu;
    EXPECT_EQ(bulk_modulus(tied.data(), nu), bulk_modulus(written.data(), nu)) << nu;
    const double h = 1e-6, fd = (isotropic_pressure(tied.data(), nu * std::exp(h)) -
                                 isotropic_pressure(tied.data(), nu * std::exp(-h))) / (2 * h);
    if (nu > P.nu_c * 1.001) EXPECT_NEAR(bulk_modulus(tied.data(), nu), fd, 1e-6 * fd) << nu;
  }
  const double B0 = bulk_modulus(tied.data(), P.nu_c * (1 + 1e-12));
  EXPECT_NEAR(B0, P.p0 * P.C0, 1e-4 * P.p0 * P.C0) << "the limit at jamming: p0 C0";
  std::vector<double> sep = written;
  sep[kNuCC] = P.nu_c + 0.005;
  EXPECT_GT(bulk_modulus(sep.data(), sep[kNuCC] * (1 + 1e-12)), 1e3 * bulk_modulus(sep.data(), sep[kNuCC] * 1.01))
      << "separate fractions: the cusp";

  Synthetic S = synthetic(P, {0.69, 0.73, 0.77, 0.81}, 2, 0.0, 3);
  for (auto& c : S.mean) {   // the members' noise-free model curve
    const auto st = monotone_shear<double>(written.data(), P.shear, P.nu_ref, c.nu, c.p[0], c.s[0], c.F[0], c.eps, 1e-3);
    for (std::size_t i = 0; i < c.eps.size(); ++i) { c.p[i] = st[i].p; c.s[i] = st[i].s; c.F[i] = st[i].F; }
  }
  IsoData iso;
  for (int i = 0; i < 40; ++i) {
    const double nu = 0.666 + 0.004 * i;
    iso.nu.push_back(nu);
    iso.p.push_back(isotropic_pressure(written.data(), nu));
    iso.C.push_back(coordination(written.data(), nu));
  }
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.8 : 1.1);
  start.nu_cC = P.nu_c + 0.002;
  start.C0 = 5.0; start.alpha = 0.45;
  CalibrationOptions o;
  o.start = &start;
  o.nu_ref = P.nu_ref;
  o.max_step = 1e-3;
  o.shared_jamming = true;
  const Calibration cal = calibrate(S.mean, iso, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  EXPECT_TRUE(cal.shared_jamming);
  EXPECT_NEAR(cal.value[kNuC], P.nu_c, 1e-6);
  EXPECT_NEAR(cal.params.C0, P.C0, 1e-4);
  EXPECT_NEAR(cal.params.alpha, P.alpha, 1e-5);
  EXPECT_EQ(cal.value[kNuCC], cal.value[kNuC]);
  EXPECT_EQ(cal.params.nu_cC, cal.params.nu_c);
  EXPECT_EQ(std::isnan(cal.se_cov[kNuCC]), std::isnan(cal.se_cov[kNuC]));   // noise-free: both undetermined (null_directions)
  if (std::isfinite(cal.se_cov[kNuC])) EXPECT_EQ(cal.se_cov[kNuCC], cal.se_cov[kNuC]);
  EXPECT_EQ(cal.n_free, kNumIso - 1 + kNumShear);
  CalibrationOptions held = o;
  held.hold_iso = {kNuCC};
  CalibrationOptions fixed = o;
  fixed.fit_isotropic = false;
  for (const auto& bad : {held, fixed}) {
    try {
      calibrate(S.mean, iso, bad);
      FAIL() << "a tie that cannot act was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("leave nu_cC out of --hold-isotropic"), std::string::npos) << e.what();
    }
  }
}

TEST(ModelFit, BadInputIsRefusedWithTheFix) {
  const Parameters P = truth();
  Synthetic S = synthetic(P, {0.72}, 3, 0.5, 1);
  CurveData shifted = S.mean[0];
  for (double& e : shifted.eps) e += 0.01;
  CalibrationOptions no_iso;
  no_iso.fit_isotropic = false;
  no_iso.start = &P;
  try {
    calibrate({shifted}, {}, no_iso);
    FAIL() << "a curve not starting at eps_d = 0 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("does not start at eps_d = 0"), std::string::npos) << e.what();
  }
  CurveData one = S.mean[0];
  for (double& v : one.se_s) v = 0.0;
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.start = &P;
  try {
    calibrate({one}, {}, o);
    FAIL() << "a curve without between-packing errors was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(">= 2 packings"), std::string::npos) << e.what();
  }
  EXPECT_THROW(calibrate({}, {}, o), std::invalid_argument);
  EXPECT_THROW(calibrate(S.mean, {}, CalibrationOptions{}), std::invalid_argument);   // no isotropic branch
}

// ---- Paths given row by row (integrate_rows), as the DEM path ensembles are sampled ----

namespace {

struct Rows {
  std::vector<double> acc;
  std::vector<int> dir, isob;
};

// Constant-volume (or isobaric) D2 to `turn`, then reversed to `end` of accumulated strain
// (turn = end: monotone), rows every h, the turning point a row.
Rows rows_of(double turn, double end, double h, bool isobaric) {
  Rows r;
  const int n1 = static_cast<int>(std::lround(turn / h)), n2 = static_cast<int>(std::lround((end - turn) / h));
  for (int i = 0; i <= n1; ++i) { r.acc.push_back(turn * i / n1); r.dir.push_back(1); r.isob.push_back(isobaric); }
  for (int i = 1; i <= n2; ++i) { r.acc.push_back(turn + (end - turn) * i / n2); r.dir.push_back(-1); r.isob.push_back(isobaric); }
  return r;
}

// Excess pressure q(e) = p - k p_ref at constant volume for dq/de = sigma a B F(e) - beta_p q,
// F(e) = sigma F_max + (F0 - sigma F_max) e^{-beta_F e}: the linear ODE's closed form.
double excess(double q0, double F0, double sigma, double aB, double Fm, double bF, double bp, double e) {
  return q0 * std::exp(-bp * e) + aB * Fm * (1 - std::exp(-bp * e)) / bp +
         sigma * aB * (F0 - sigma * Fm) * (std::exp(-bF * e) - std::exp(-bp * e)) / (bp - bF);
}

}  // namespace

// Rows and segments are the same integration; after a reversal at constant volume the pressure
// follows the closed form with F relaxing from its reversal value towards -F_max: the
// anisotropy term first pushes p down (A = a_A B F > 0 against a negative strain increment)
// and up again once F has changed sign.
TEST(Model, RowPathReversalMatchesClosedForm) {
  const Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.70, p0 = 1.02 * isotropic_pressure(iso.data(), nu), F0 = 0.005;
  const Rows r = rows_of(0.15, 0.45, 0.003, false);
  const auto rows = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.01, F0, r.acc, r.dir, r.isob);
  const auto seg = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.01, F0, {shear_seg(0.15, 50), shear_seg(-0.3, 100)});
  ASSERT_EQ(rows.size(), seg.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    // the same integration; ceil(dl/max_step) may differ by one step where dl/max_step rounds: RK4 truncation
    EXPECT_NEAR(rows[i].state.p, seg[i].state.p, 1e-8 * p0);
    EXPECT_NEAR(rows[i].state.s, seg[i].state.s, 1e-8);
    EXPECT_NEAR(rows[i].state.F, seg[i].state.F, 1e-8);
  }
  const double p_ref = isotropic_pressure(iso.data(), nu), k = p0 / p_ref;
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double aB = L.a_A * k * bulk_modulus(iso.data(), nu);
  const std::size_t ir = 50;   // the reversal row
  const double q_r = rows[ir].state.p - k * p_ref, F_r = rows[ir].state.F;
  EXPECT_NEAR(q_r, excess(p0 - k * p_ref, F0, 1.0, aB, L.F_max, L.beta_F, L.beta_p, 0.15), 1e-9 * p0);
  double pmin = rows[ir].state.p;
  for (std::size_t i = ir; i < rows.size(); ++i) {
    const double e = r.acc[i] - 0.15;
    EXPECT_NEAR(rows[i].state.p, k * p_ref + excess(q_r, F_r, -1.0, aB, L.F_max, L.beta_F, L.beta_p, e), 1e-9 * p0) << e;
    pmin = std::min(pmin, rows[i].state.p);
  }
  if (L.a_A > 0) EXPECT_LT(pmin, rows[ir].state.p - 1e-3 * p0) << "a_A > 0: the pressure dips after the reversal";
}

// Isobaric rows hold p exactly and reach the critical state the pressure equation sets:
// a_A(nu) B(nu) F_max(nu) = beta_p(nu) (p0 - k p_iso(nu)) (no volume change), s -> s_max(nu).
TEST(Model, IsobaricRowsReachTheirCriticalState) {
  const Parameters P = truth();
  const auto iso = P.iso();
  for (double nu0 : {0.70, 0.80}) {
    const double p0 = isotropic_pressure(iso.data(), nu0);
    const double k = 1.0;
    const Rows r = rows_of(3.0, 3.0, 0.01, true);
    const auto rows = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, 0.0, 0.0, r.acc, r.dir, r.isob);
    for (const auto& q : rows) EXPECT_NEAR(q.state.p, p0, 1e-12 * p0);
    const double nu = std::exp(rows.back().state.ln_nu);
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    const double lhs = L.a_A * k * bulk_modulus(iso.data(), nu) * L.F_max;
    const double rhs = L.beta_p * (p0 - k * isotropic_pressure(iso.data(), nu));
    EXPECT_NEAR(lhs, rhs, 1e-6 * std::fabs(lhs) + 1e-12) << nu0;
    EXPECT_NEAR(rows.back().state.s, L.s_max, 1e-6);
    EXPECT_NEAR(rows.back().eps_vol, -std::log(nu / nu0), 1e-12);   // the full volumetric strain
    EXPECT_EQ(rows.back().eps_vol > 0, L.a_A > 0) << "dilatancy iff a_A > 0";
  }
}

// Constant side stress (triaxial, isob code 2): sigma_r = p (1 - s/3) is held at its start value
// on every row (the constraint solved for d eps_vol), s and p both change; the critical state is
// that of the isobaric path (s = s_max and sigma_r fixed: p fixed, so a_A B F_max = beta_p (p - k p_iso));
// the axial strain of an axisymmetric strain from (eps_vol, eps_d) inverts e_r - e_a = eps_d, 2 e_r + e_a = eps_vol.
TEST(Model, TriaxialRowsHoldTheSideStress) {
  const Parameters P = truth();
  const auto iso = P.iso();
  for (double nu0 : {0.70, 0.80}) {
    const double p0 = 1.02 * isotropic_pressure(iso.data(), nu0), s0 = 0.03, F0 = 0.01;
    const double k = p0 / isotropic_pressure(iso.data(), nu0);
    const double sr0 = p0 * (1.0 - s0 / 3.0);
    Rows r = rows_of(3.0, 3.0, 0.01, false);
    for (auto& c : r.isob) c = 2;
    const auto rows = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, s0, F0, r.acc, r.dir, r.isob);
    for (const auto& q : rows) EXPECT_NEAR(side_stress(q.state), sr0, 1e-10 * p0);
    // axial stress sigma_a = p + 2 s p / 3 rises: the mean stress rises by q/3
    EXPECT_GT(rows[20].state.p, p0 * 1.01);
    const double nu = std::exp(rows.back().state.ln_nu);
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    EXPECT_NEAR(rows.back().state.s, L.s_max, 1e-6);
    EXPECT_NEAR(rows.back().state.p, sr0 / (1.0 - L.s_max / 3.0), 1e-6 * p0);
    const double lhs = L.a_A * k * bulk_modulus(iso.data(), nu) * L.F_max;
    const double rhs = L.beta_p * (rows.back().state.p - k * isotropic_pressure(iso.data(), nu));
    EXPECT_NEAR(lhs, rhs, 1e-5 * std::fabs(lhs) + 1e-12) << nu0;
    EXPECT_NEAR(rows.back().eps_vol, -std::log(nu / nu0), 1e-12);
  }
  const double ea = axial_strain(0.01, 0.2), er = (0.01 - ea) / 2;
  EXPECT_NEAR(er - ea, 0.2, 1e-15);
  EXPECT_NEAR(std::sqrt(((er - er) * (er - er) + (er - ea) * (er - ea) + (ea - er) * (ea - er)) / 2), 0.2, 1e-15);
}

// Special case with a closed form: no anisotropy coupling (a_A = 0) and no pressure relaxation
// (beta_p -> 0). Then dp = -B d eps_vol integrates to the isotropic law, p = k p_iso(nu), and the
// constraint fixes p = sigma_r0 / (1 - s/3): the triaxial test is an isotropic compression driven
// by the mean stress the deviator adds, the volume at every row the one where k p_iso(nu) equals it.
// With s held at
// 0 (s_max = s0 = 0) the constraint is dp = 0 and the rows equal the isobaric ones.
TEST(Model, TriaxialReducesToIsotropicCompressionWithoutCoupling) {
  Parameters P = truth();
  P.shear[kAnisoA] = 0.0; P.shear[kAnisoB] = 0.0;
  P.shear[kLnBetaPA] = -40.0; P.shear[kLnBetaPB] = 0.0;
  const auto iso = P.iso();
  const double nu0 = 0.72, p0 = 1.03 * isotropic_pressure(iso.data(), nu0), s0 = 0.02, F0 = 0.015;
  const double k = p0 / isotropic_pressure(iso.data(), nu0), sr0 = p0 * (1.0 - s0 / 3.0);
  Rows r = rows_of(0.4, 0.4, 0.004, false);
  for (auto& c : r.isob) c = 2;
  const auto rows = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, s0, F0, r.acc, r.dir, r.isob);
  const Local<double> L0 = local(P.shear, nu0, P.nu_ref);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const double nu = std::exp(rows[i].state.ln_nu);
    EXPECT_NEAR(rows[i].state.p, k * isotropic_pressure(iso.data(), nu), 1e-9 * p0) << i;
    EXPECT_NEAR(rows[i].state.p, sr0 / (1.0 - rows[i].state.s / 3.0), 1e-10 * p0) << i;
    // F's law depends on the volume only through F_max(nu), beta_F(nu) (nu rises by 0.003 here)
    EXPECT_NEAR(rows[i].state.F, L0.F_max - (L0.F_max - F0) * std::exp(-L0.beta_F * r.acc[i]), 3e-3) << i;
  }
  EXPECT_LT(rows.back().eps_vol, -1e-4) << "the rising mean stress compacts";
  // s held at 0: the same rows as the isobaric path
  P.shear[kSmaxA] = 0.0; P.shear[kSmaxB] = 0.0;
  P.shear[kLnBetaPA] = std::log(15.0);
  Rows ri = r;
  for (auto& c : ri.isob) c = 1;
  const auto tri = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, 1.02 * p0, 0.0, F0, r.acc, r.dir, r.isob);
  const auto isb = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, 1.02 * p0, 0.0, F0, ri.acc, ri.dir, ri.isob);
  for (std::size_t i = 0; i < tri.size(); ++i) {
    EXPECT_EQ(tri[i].state.s, 0.0);
    EXPECT_NEAR(tri[i].state.p, isb[i].state.p, 1e-14);
    EXPECT_NEAR(tri[i].eps_vol, isb[i].eps_vol, 1e-14);
  }
}

namespace {

// A synthetic path ensemble: K members of the model along `r` plus AR(1) noise on p* (or eps_v
// on isobaric rows), s and F; means, SEs and 95 % half-widths as demkit.path_ensemble writes them.
PathData synthetic_path(const Parameters& P, const std::string& name, double nu, const Rows& r, int K, double rho,
                        std::mt19937_64& rng, double p_start = 0.0, const Ext<double>& ext = {}) {
  std::normal_distribution<double> g(0.0, 1.0);
  const auto iso = P.iso();
  const double p0 = p_start > 0 ? p_start : isotropic_pressure(iso.data(), nu);
  const auto st = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.01, 0.01, r.acc, r.dir, r.isob, 1e-3, ext);
  const std::size_t n = r.acc.size();
  PathData d;
  d.name = name; d.nu = nu; d.packings = K; d.source = "synthetic " + name;
  d.acc = r.acc; d.direction = r.dir; d.isobaric = r.isob;
  d.eps_signed.assign(n, 0.0);
  for (auto* v : {&d.nu_m, &d.ev, &d.p, &d.s, &d.F, &d.se_ev, &d.se_p, &d.se_s, &d.se_F, &d.hw_ev, &d.hw_p, &d.hw_s, &d.hw_F})
    v->assign(n, 0.0);
  const double sd[4] = {0.01 * p0, 2e-4, 0.015, 0.008};   // p*, eps_v, s, F per packing
  std::vector<std::vector<std::array<double, 4>>> mem(K, std::vector<std::array<double, 4>>(n));
  for (int k = 0; k < K; ++k) {
    double z[4] = {g(rng), g(rng), g(rng), g(rng)};
    for (std::size_t i = 0; i < n; ++i) {
      if (i > 0)
        for (double& v : z) v = rho * v + std::sqrt(1 - rho * rho) * g(rng);
      const double f = i == 0 ? 0.0 : 1.0;
      mem[k][i] = {st[i].state.p + f * sd[0] * z[0], st[i].eps_vol / 3 + f * sd[1] * z[1], st[i].state.s + f * sd[2] * z[2],
                   st[i].state.F + f * sd[3] * z[3]};
    }
  }
  const double t95 = demfit::t_quantile(0.975, K - 1);
  std::vector<double>* mv[4] = {&d.p, &d.ev, &d.s, &d.F};
  std::vector<double>* sv[4] = {&d.se_p, &d.se_ev, &d.se_s, &d.se_F};
  std::vector<double>* hv[4] = {&d.hw_p, &d.hw_ev, &d.hw_s, &d.hw_F};
  for (std::size_t i = 0; i < n; ++i) {
    d.nu_m[i] = std::exp(st[i].state.ln_nu);
    for (int q = 0; q < 4; ++q) {
      double m = 0, ss = 0;
      for (int k = 0; k < K; ++k) m += mem[k][i][q] / K;
      for (int k = 0; k < K; ++k) ss += (mem[k][i][q] - m) * (mem[k][i][q] - m);
      (*mv[q])[i] = m;
      (*sv[q])[i] = std::sqrt(ss / (K - 1) / K);
      (*hv[q])[i] = t95 * (*sv[q])[i];
    }
  }
  return d;
}

}  // namespace

// A leave-one-out refit enters the jackknife only when it converged to an optimum like the full fit's (twentieth
// round: the bounded mu = 1 dense jackknife had a refit at chi2/dof 659.5 against 5.85, the three-pressure mu = 0.1
// joint one two refits that failed at their start, nan; their values made a spread that was not the packings').
TEST(ModelFit, AJackknifeRefitThatFailedOrEndedFarAboveTheFullFitIsNotUsed) {
  auto fit = [](double chi2_dof, bool ok) {
    Calibration c;
    c.n_residuals = 1001;
    c.n_free = 1;
    c.chi2 = chi2_dof * 1000;
    c.ok = ok;
    return c;
  };
  const Calibration full = fit(5.85, true);
  EXPECT_TRUE(jackknife_refit_usable(fit(5.91, true), full));
  EXPECT_TRUE(jackknife_refit_usable(fit(16.97, true), full)) << "within 3 times";
  EXPECT_FALSE(jackknife_refit_usable(fit(659.5, true), full));
  EXPECT_FALSE(jackknife_refit_usable(fit(std::nan(""), true), full)) << "failed at its start";
  EXPECT_FALSE(jackknife_refit_usable(fit(5.9, false), full)) << "not converged";
  EXPECT_TRUE(jackknife_refit_usable(fit(2.9, true), fit(0.5, true))) << "a full fit below 1 counts as 1";
}

namespace {

struct Quotients {   // r_i = x_2i / x_2i+1: a jet divides by multiplying with the inverse, a double divides
  int n;
  template <class T>
  bool operator()(T const* const* x, T* r) const {
    for (int i = 0; i < n; ++i) r[i] = x[0][2 * i] / x[0][2 * i + 1];
    return true;
  }
};

ceres::DynamicAutoDiffCostFunction<Quotients, 4>* quotient_cost(Quotients* f) {
  auto* c = new ceres::DynamicAutoDiffCostFunction<Quotients, 4>(f);
  c->AddParameterBlock(2 * f->n);
  c->SetNumResiduals(f->n);
  return c;
}

}  // namespace

// JetValuedCost's cost-only residuals are the values of the residuals its Jacobian is evaluated with, bit for bit,
// where the double arithmetic of the plain autodiff cost differs in the last bits (twentieth round: the cost and the
// Jacobian at one point came from different numbers, and Ceres accepted a step whose Jacobian failed).
TEST(ModelFit, AJetValuedCostIsTheJacobiansOwnValueBitForBit) {
  const int n = 400;
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(0.1, 10.0);
  std::vector<double> x(2 * n);
  for (auto& v : x) v = u(rng);
  const double* blocks[] = {x.data()};
  auto* f_plain = new Quotients{n};
  std::unique_ptr<ceres::CostFunction> plain(quotient_cost(f_plain));
  auto* f_jet = new Quotients{n};
  demfit::JetValuedCost<Quotients, 4> jet_valued(f_jet, quotient_cost(f_jet));
  std::vector<double> r_jac(n), r_jet(n), r_double(n), jac(static_cast<std::size_t>(n) * 2 * n);
  double* jacobians[] = {jac.data()};
  ASSERT_TRUE(jet_valued.Evaluate(blocks, r_jac.data(), jacobians));
  ASSERT_TRUE(jet_valued.Evaluate(blocks, r_jet.data(), nullptr));
  ASSERT_TRUE(plain->Evaluate(blocks, r_double.data(), nullptr));
  int differ = 0;
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(r_jet[i], r_jac[i]) << "row " << i;
    EXPECT_EQ(r_double[i], x[2 * i] / x[2 * i + 1]);
    EXPECT_NEAR(r_double[i], r_jac[i], 4e-16 * std::abs(r_jac[i]));
    differ += r_double[i] != r_jac[i];
  }
  EXPECT_GT(differ, 0) << "the double and jet values never differ: the test would not see a cost made in double";
  EXPECT_EQ(jet_valued.num_residuals(), n);
  EXPECT_EQ(jet_valued.parameter_block_sizes(), std::vector<int32_t>{2 * n});
}

// The jackknife's errors from hand-made leave-one-out estimates (K = 4): sqrt((K-1)/K sum (e - mean)^2) for a free
// coefficient; a free one whose every refit ends on the same value (a bound) gets nan and a warning naming it; a held
// one nan; the critical-state line's terms held at the data's end states keep their spread (nu_cs always, lambda_cs
// with the logarithmic line, c_cs with the linear one); one the covariance left undetermined (fourteenth round: the
// mu = 1 joint optimum's pseudo-inverse is 0 in every direction) keeps the refits' spread where there is one.
TEST(ModelFit, JackknifeErrorsQuoteTheSpreadAndNotABound) {
  Calibration cal;
  const double nan = std::nan("");
  cal.names = {"s_max_a", "n_dil", "held", "nu_cs", "lambda_cs", "c_cs", "n_rate", "m_peak"};
  cal.value = {0.7, 150.0, 1.0, 0.6, 0.01, 1.8, 1.1, 0.2};
  cal.se_cov = {0.01, 3.0, nan, nan, nan, nan, nan, nan};
  cal.undetermined = {false, false, false, false, false, false, true, true};   // a degenerate pseudo-inverse
  const std::vector<std::vector<double>> est = {{0.69, 150.0, 1.0, 0.601, 0.011, 1.7, 1.0, 0.2},
                                                {0.71, 150.0, 2.0, 0.603, 0.012, 1.9, 1.2, 0.2},
                                                {0.70, 150.0, 3.0, 0.600, 0.010, 1.8, 1.1, 0.2},
                                                {0.72, 150.0, 4.0, 0.604, 0.013, 2.0, 1.3, 0.2}};
  auto spread = [&](std::size_t i) {   // written out: mean, then sqrt(3/4 sum of squares)
    const double mean = (est[0][i] + est[1][i] + est[2][i] + est[3][i]) / 4.0;
    double ss = 0;
    for (const auto& e : est) ss += (e[i] - mean) * (e[i] - mean);
    return std::sqrt(0.75 * ss);
  };
  for (bool linear : {true, false}) {
    SCOPED_TRACE(linear ? "--csl linear" : "--csl log");
    std::vector<std::string> warnings;
    const std::vector<double> se = jackknife_errors(est, cal, linear, &warnings);
    ASSERT_EQ(se.size(), cal.value.size());
    EXPECT_NEAR(se[0], spread(0), 1e-15);
    EXPECT_NEAR(se[0], std::sqrt(0.75 * 0.0005), 1e-12) << "0.69, 0.71, 0.70, 0.72 about 0.705";
    EXPECT_TRUE(std::isnan(se[1])) << "every refit on 150: no spread to quote";
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("n_dil: every jackknife refit ends on the same value 150"), std::string::npos) << warnings[0];
    EXPECT_TRUE(std::isnan(se[2])) << "held: no error, though its refits differ";
    EXPECT_NEAR(se[3], spread(3), 1e-15);
    EXPECT_GT(se[3], 0.0);
    if (linear) {
      EXPECT_TRUE(std::isnan(se[4]));
      EXPECT_NEAR(se[5], spread(5), 1e-15);
    } else {
      EXPECT_NEAR(se[4], spread(4), 1e-15);
      EXPECT_TRUE(std::isnan(se[5]));
    }
    EXPECT_NEAR(se[6], spread(6), 1e-15) << "undetermined by the covariance, its refits spread: the jackknife's error";
    EXPECT_TRUE(std::isnan(se[7])) << "undetermined and every refit on one value: nothing to quote (warned already)";
  }
  EXPECT_TRUE(std::isnan(jackknife_errors({}, cal, true)[0])) << "no refits: nothing quoted";
}

// A covariance error of 0 to rounding is "not determined" (nan, flagged, said), and the flag stays on its coefficient
// when the table drops entries before it (the volume form drops its unread ones: a first pass of the fourteenth
// round put the flags on the wrong rows); a covariance 0 in every direction is one warning, not one per coefficient.
TEST(ModelFit, UndeterminedCoefficientsKeepTheirFlagWhenEntriesAreDropped) {
  const double nan = std::nan("");
  Calibration cal;
  cal.names = {"a", "unread1", "unread2", "b", "c"};
  cal.value = {1.0, 0.0, 0.0, 2.0, 3.0};
  cal.se_cov = {0.1, nan, nan, 1e-12, 0.2};
  cal.corr.assign(5, std::vector<double>(5, 0.0));
  null_directions(cal);
  EXPECT_TRUE(std::isnan(cal.se_cov[3]));
  ASSERT_EQ(cal.warnings.size(), 1u);
  EXPECT_NE(cal.warnings[0].find("b is not determined"), std::string::npos) << cal.warnings[0];
  drop_entries(cal, 1, 2);
  ASSERT_EQ(cal.names.size(), 3u);
  ASSERT_EQ(cal.undetermined.size(), 3u);
  EXPECT_EQ(cal.names[1], "b");
  EXPECT_TRUE(cal.undetermined[1]) << "the flag on b's row";
  EXPECT_FALSE(cal.undetermined[0]);
  EXPECT_FALSE(cal.undetermined[2]);
  const std::vector<std::vector<double>> est = {{1.0, 2.1, 3.0}, {1.1, 1.9, 3.2}, {0.9, 2.0, 3.1}, {1.0, 2.0, 2.9}};
  const std::vector<double> se = jackknife_errors(est, cal, true);
  EXPECT_GT(se[1], 0.0) << "b's refits spread: the jackknife's error";
  Calibration all;
  all.names = {"x", "y", "z"};
  all.value = {1.0, 2.0, 3.0};
  all.se_cov = {1e-12, 0.0, nan};
  null_directions(all);
  ASSERT_EQ(all.warnings.size(), 1u) << "one warning for a covariance 0 in every quoted direction";
  EXPECT_NE(all.warnings[0].find("every direction"), std::string::npos) << all.warnings[0];
  EXPECT_TRUE(all.undetermined[0] && all.undetermined[1] && !all.undetermined[2]);
}

// Identifiability: from D2 alone, a_A and beta_p are pinned only through the pressure excess
// a_A B F_max / beta_p and its onset, so their estimates are strongly correlated. Does a strain
// reversal (A = a_A B F acting against the strain while F turns) or an isobaric test (the volume
// change instead of the pressure) separate them? Measured on a synthetic
// ensemble made by the model (K = 8, AR(1) noise, rho = 0.9): the correlation of the
// coefficients a_A_a, ln_beta_p_a and the standard error of a_A_a with and without the paths;
// the estimates recovered within the (covariance) errors.
TEST(ModelFit, PathsNarrowButDoNotSeparateAnisotropyModulusAndPressureRelaxation) {
  const Parameters P = truth();
  const std::vector<double> nus = {0.69, 0.73, 0.77, 0.81};
  const int K = 8;
  const Synthetic S = synthetic(P, nus, K, 0.9, 11);
  std::mt19937_64 rng(12);
  std::vector<PathData> rev, isob;
  for (double nu : nus) {
    rev.push_back(synthetic_path(P, "reversal", nu, rows_of(0.15, 0.45, 0.006, false), K, 0.9, rng));
    isob.push_back(synthetic_path(P, "isobaric", nu, rows_of(0.3, 0.3, 0.006, true), K, 0.9, rng));
  }
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.8 : 1.1);
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.nu_ref = P.nu_ref;
  o.max_step = 1e-3;
  o.start = &start;
  const int a = kNumIso + kAnisoA, b = kNumIso + kLnBetaPA;
  struct Case { const char* name; std::vector<PathData> paths; double corr = 0, se_a = 0, se_b = 0; };
  std::vector<Case> cases = {{"D2", {}}, {"D2+reversal", rev}, {"D2+isobaric", isob}};
  for (auto& c : cases) {
    const Calibration cal = calibrate(S.mean, {}, o, c.paths);
    ASSERT_TRUE(cal.ok) << c.name << ": " << cal.message;
    c.corr = cal.corr[a][b];
    c.se_a = cal.se_cov[a];
    c.se_b = cal.se_cov[b];
    std::printf("%-12s corr(a_A_a, ln_beta_p_a) = %+.3f  se(a_A_a) = %.4f  se(ln_beta_p_a) = %.4f  a_A_a = %.4f (truth %.4f)"
                "  ln_beta_p_a = %.4f (truth %.4f)  chi2/dof %.2f\n",
                c.name, c.corr, c.se_a, c.se_b, cal.value[a], P.shear[kAnisoA], cal.value[b], P.shear[kLnBetaPA], cal.chi2_dof());
    // correlated noise: the covariance under-covers (docs/model.md); a generous bound
    for (int i : {kAnisoA, kLnBetaPA})
      EXPECT_LT(std::fabs(cal.value[kNumIso + i] - P.shear[i]), 8 * cal.se_cov[kNumIso + i]) << c.name << " " << shear_name(i);
  }
  // What this measures (seeded, deterministic; numbers when written): D2 alone leaves a_A and
  // beta_p correlated (0.86); the reversal (its rows after the turn: the loading part is a D2
  // run, which the D2 curves carry) narrows both errors by about a fifth (se(a_A_a) 0.0064 ->
  // 0.0053) but leaves them as correlated (0.87); the isobaric path likewise (0.88). Neither
  // path separates them within this model: after a reversal, as under constant pressure, the
  // excess pressure (or the volume) follows an amplitude a_A B F_max / beta_p on the time scales
  // 1/beta_p and 1/beta_F, the same combination D2 pins (docs/model.md, Identifiability).
  EXPECT_GT(std::fabs(cases[0].corr), 0.8) << "D2 alone: a_A and beta_p strongly correlated";
  EXPECT_GT(std::fabs(cases[1].corr), 0.8) << "the reversal does not separate them (if this fails, update docs/model.md)";
  EXPECT_GT(std::fabs(cases[2].corr), 0.8) << "nor does the isobaric path";
  EXPECT_LT(cases[1].se_a, 0.9 * cases[0].se_a) << "the reversal adds information on a_A";
  EXPECT_LT(cases[1].se_b, 0.9 * cases[0].se_b) << "and on beta_p";
}

// ---- The frictional extension (docs/model.md, "The frictional extension") ----

namespace {

// A frictional material in the spirit of the mu = 0.5 ensembles: a stress ratio linear for longer
// (kappa_s > 0), a fabric gated by the mobilisation (n_F > 0), a dilatancy that changes sign.
Parameters frictional_truth() {
  Parameters P = truth();
  const double sh[kNumShear] = {0.85, -1.5, std::log(6.0), -5.0, 0.40, -1.0, std::log(12.0), -4.0, 0.3, -6.0,
                                std::log(10.0), -3.0};
  std::copy(sh, sh + kNumShear, P.shear);
  const double ex[kNumExt] = {3.0, 20.0, 0.8, -4.0, 0.05, -0.5, 0.6};
  std::copy(ex, ex + kNumExt, P.ext);
  P.extended = true;
  P.surface = Surface::LadeDuncan;
  P.fabric = FabricLode::Principal;
  return P;
}

// The strain grid of the rule tests: eps_d = 0 to 0.3 in 60 steps.
std::vector<double> shear_grid() {
  std::vector<double> eps;
  for (int i = 0; i <= 60; ++i) eps.push_back(0.005 * i);
  return eps;
}

// Constant-volume shear of P's material from nu = 0.78 at its isotropic pressure (s0 0.02, F0 0.01) along
// shear_grid(), under the extension block `ext` (null: the group model), the mode's Lode angle and `rule`.
std::vector<State<double>> frictional_shear(const Parameters& P, const double* ext, const char* mode, FabricLode rule) {
  const auto iso = P.iso();
  const double nu = 0.78;
  return monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, isotropic_pressure(iso.data(), nu), 0.02, 0.01,
                                shear_grid(), 2e-3, Ext<double>{ext, lode_b_of(mode), P.surface, rule});
}

std::vector<Segment> mixed_path() {
  return {shear_seg(0.1, 20), shear_seg(-0.15, 30), shear_seg(0.1, 20, Control::Isobaric),
          shear_seg(0.1, 20, Control::Triaxial)};
}

}  // namespace

// With every extension coefficient 0 and no Lode surface, the frictional family is the group
// model: the same numbers, bit for bit, on constant-volume, reversed, isobaric and triaxial
// segments (x * 1.0, pow(r, 0) = 1 and + B * 0 are exact in IEEE arithmetic). A surface at the
// calibration test's own b is also the identity.
TEST(ModelFriction, NeutralExtensionIsTheGroupModelBitForBit) {
  const Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.72, p0 = isotropic_pressure(iso.data(), nu);
  const double zeros[kNumExt] = {0, 0, 0, 0, 0, 0, 0};
  const auto group = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path());
  const auto neutral = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                         Ext<double>{zeros, kLodeBD2, Surface::None});
  const auto same_b = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                        Ext<double>{nullptr, kLodeBD2, Surface::LadeDuncan});
  ASSERT_EQ(group.size(), neutral.size());
  for (std::size_t i = 0; i < group.size(); ++i)
    for (const auto* o : {&neutral[i], &same_b[i]}) {
      EXPECT_EQ(group[i].state.p, o->state.p) << i;
      EXPECT_EQ(group[i].state.s, o->state.s) << i;
      EXPECT_EQ(group[i].state.F, o->state.F) << i;
      EXPECT_EQ(group[i].eps_vol, o->eps_vol) << i;
    }
  // The principal fabric rule is the identity at the calibration test's own b (D2), and the group
  // model (no extension block) ignores it at any b, D3 included: where the held-out test keeps the
  // group model (mu = 0) its numbers are today's, whatever --fabric-lode says.
  const Parameters Xp = frictional_truth();
  const auto norm_d2 = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                         Ext<double>{Xp.ext, kLodeBD2, Surface::LadeDuncan, FabricLode::Norm});
  const auto princ_d2 = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                          Ext<double>{Xp.ext, kLodeBD2, Surface::LadeDuncan, FabricLode::Principal});
  const auto group_d3 = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                          Ext<double>{nullptr, 0.0, Surface::None, FabricLode::Principal});
  for (std::size_t i = 0; i < group.size(); ++i) {
    EXPECT_EQ(norm_d2[i].state.F, princ_d2[i].state.F) << i;
    EXPECT_EQ(norm_d2[i].state.p, princ_d2[i].state.p) << i;
    EXPECT_EQ(group[i].state.F, group_d3[i].state.F) << i;
    EXPECT_EQ(group[i].state.p, group_d3[i].state.p) << i;
  }
  // ... and an active extension does change them (the comparison above could fail).
  const Parameters X = frictional_truth();
  const auto active = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                        Ext<double>{X.ext, kLodeBD2, Surface::None});
  double most = 0;
  for (std::size_t i = 0; i < group.size(); ++i) most = std::max(most, std::fabs(active[i].state.F - group[i].state.F));
  EXPECT_GT(most, 1e-3);
}

// The Lode-angle limit against closed forms. Matsuoka-Nakai passes through the Mohr-Coulomb
// corners in triaxial compression (b = 0) and extension (b = 1): q/p = 6 sin(phi)/(3 - sin(phi))
// and 6 sin(phi)/(3 + sin(phi)). Lade-Duncan (I1^3/I3 constant) at b = 1/2 and b = 0, with
// p = 1: principal stresses (1 + s/sqrt(3), 1, 1 - s/sqrt(3)) and (1 + 2x/3, 1 - x/3, 1 - x/3),
// so (1 + 2x/3)(1 - x/3)^2 = 1 - s^2/3.
TEST(ModelFriction, LodeLimitMatchesClosedForms) {
  for (double phi_deg : {10.0, 25.0, 35.0}) {
    const double sp = std::sin(phi_deg * M_PI / 180.0);
    const double Mc = 6 * sp / (3 - sp), Me = 6 * sp / (3 + sp);
    EXPECT_NEAR(lode_limit(Mc, 1.0, Surface::MatsuokaNakai, 0.0), Me, 1e-10) << phi_deg;
    EXPECT_NEAR(lode_limit(Me, 0.0, Surface::MatsuokaNakai, 1.0), Mc, 1e-10) << phi_deg;
  }
  for (double s : {0.16, 0.6, 1.0}) {
    const double x = lode_limit(s, 0.0, Surface::LadeDuncan, 0.5);
    EXPECT_NEAR((1 + 2 * x / 3) * (1 - x / 3) * (1 - x / 3), 1 - s * s / 3, 1e-12) << s;
    EXPECT_GT(x, s);   // compression holds a larger stress ratio than b = 1/2
  }
  EXPECT_EQ(lode_limit(0.7, 0.0, Surface::None), 0.7);
}

// The principal fabric rule against geometry built by hand: a deviator of magnitude F (sigma_dev
// convention, sqrt(((a-b)^2 + (b-c)^2 + (c-a)^2)/2)) with principal values along D2's Lode angle,
// (F/sqrt(3), 0, -F/sqrt(3)), or along axisymmetric compression, (2F/3, -F/3, -F/3). Holding the
// largest principal value fixed, D3's fabric limit is sqrt(3)/2 of D2's; and the model's fabric,
// integrated far along D2 and D3 at constant volume, reaches those two limits.
TEST(ModelFriction, FabricLimitHoldsTheLargestPrincipalComponent) {
  auto magnitude = [](double a, double b, double c) {
    return std::sqrt(((a - b) * (a - b) + (b - c) * (b - c) + (c - a) * (c - a)) / 2);
  };
  const double F = 0.3;
  const double d2[3] = {F / std::sqrt(3.0), 0.0, -F / std::sqrt(3.0)}, d3[3] = {2 * F / 3, -F / 3, -F / 3};
  EXPECT_NEAR(magnitude(d2[0], d2[1], d2[2]), F, 1e-15);
  EXPECT_NEAR(magnitude(d3[0], d3[1], d3[2]), F, 1e-15);
  EXPECT_NEAR(principal_fraction(0.5), d2[0] / F, 1e-15);
  EXPECT_NEAR(principal_fraction(0.0), d3[0] / F, 1e-15);
  EXPECT_NEAR(principal_fraction(1.0), 2.0 / 3.0, 1e-15);   // extension: the minor one, -2F/3, is largest in size
  const double factor = fabric_lode_factor(FabricLode::Principal, 0.0);
  EXPECT_NEAR(factor * F * d3[0] / F, d2[0], 1e-15);        // the same largest principal fabric
  EXPECT_NEAR(factor, std::sqrt(3.0) / 2, 1e-15);
  EXPECT_EQ(fabric_lode_factor(FabricLode::Norm, 0.0), 1.0);
  EXPECT_EQ(fabric_lode_factor(FabricLode::Principal, kLodeBD2), 1.0);

  const Parameters P = frictional_truth();
  const auto iso = P.iso();
  const double nu = 0.74, p0 = isotropic_pressure(iso.data(), nu);
  std::vector<double> eps;
  for (int i = 0; i <= 300; ++i) eps.push_back(0.01 * i);   // to eps_d = 3: every law saturated
  auto far = [&](const char* mode, FabricLode f) {
    return monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, eps, 2e-3,
                                  Ext<double>{P.ext, lode_b_of(mode), P.surface, f}).back().F;
  };
  const double F_max = local(P.shear, nu, P.nu_ref).F_max;
  EXPECT_NEAR(far("D2", FabricLode::Principal), F_max, 1e-6);
  EXPECT_NEAR(far("D3", FabricLode::Principal), std::sqrt(3.0) / 2 * F_max, 1e-6);
  EXPECT_NEAR(far("D3", FabricLode::Norm), F_max, 1e-6);
}

// The opening rule's gate: the minor principal component of a unit deviator (hand-built as in the
// test above: -F/sqrt(3) in D2, -F/3 in axisymmetric compression); at b_ref the rule is the
// principal rule bit for bit, in D3 the fabric grows later than under the principal rule but
// reaches the same limit, and the stress ratio and pressure paths are those of the principal
// rule until the fabric differs (the gate acts on the fabric only).
TEST(ModelFriction, OpeningRuleGatesTheFabricByTheMinorPrincipalStress) {
  EXPECT_NEAR(minor_fraction(0.5), 1 / std::sqrt(3.0), 1e-15);
  EXPECT_NEAR(minor_fraction(0.0), 1.0 / 3.0, 1e-15);
  EXPECT_NEAR(minor_fraction(1.0), 2.0 / 3.0, 1e-15);
  const Parameters P = frictional_truth();
  const auto iso = P.iso();
  const double nu = 0.74, p0 = isotropic_pressure(iso.data(), nu);
  std::vector<double> eps;
  for (int i = 0; i <= 300; ++i) eps.push_back(0.01 * i);
  auto run = [&](const char* mode, FabricLode f) {
    return monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, eps, 2e-3,
                                  Ext<double>{P.ext, lode_b_of(mode), P.surface, f});
  };
  const auto d2o = run("D2", FabricLode::Opening), d2p = run("D2", FabricLode::Principal);
  for (std::size_t i = 0; i < eps.size(); ++i) EXPECT_EQ(d2o[i].F, d2p[i].F) << i;
  const auto d3o = run("D3", FabricLode::Opening), d3p = run("D3", FabricLode::Principal);
  const double F_max = local(P.shear, nu, P.nu_ref).F_max;
  EXPECT_LT(d3o[20].F - d3o[0].F, 0.8 * (d3p[20].F - d3p[0].F));   // eps_d = 0.2: later
  EXPECT_NEAR(d3o.back().F, std::sqrt(3.0) / 2 * F_max, 1e-4);       // the same limit
  EXPECT_EQ(d3o[1].s, d3p[1].s);
}

// The overlap rule. (i) The mean overlap pi p*/(C nu) against a simple cubic lattice built by
// hand: spheres of diameter d at spacing a = d - delta (C = 6, nu = (pi d^3/6)/a^3), each
// contact f = k delta along a branch of length a, p = (1/V) sum f a / 3 = k delta / a^2, so
// p* = d p/k = d delta/a^2; the formula neglects the branch's shortening, a relative error
// delta/d. (ii) The gate in D2 at extension strain l/sqrt(3) equals D3's at 3 l/sqrt(3) (the same
// extension principal strain). (iii) The fabric's right-hand side against the closed form
// beta_F (F_lim - F) (1 - exp(-c3 l/delta))^n_F, built from the parts by hand. (iv) With n_F = 0
// the rule is the principal rule bit for bit (pow(x, 0) = 1), D2 and D3; with n_F > 0 it changes
// D2. (v) A reversal restarts the opening: l is the strain since the last reversal.
TEST(ModelFriction, OverlapRuleGatesTheFabricByTheOpenedFraction) {
  const double d = 1.0;
  for (double delta : {1e-4, 1e-3, 1e-2}) {
    const double a = d - delta, nu = (M_PI / 6) / (a * a * a), p_star = d * delta / (a * a);
    const double lattice[kNumIso] = {0.04, 0.6, 0.0, 6.0, 0.0, 0.6, 0.5};   // C(nu) = C0 = 6
    const double got = mean_overlap(lattice, nu, p_star);
    EXPECT_NEAR(got, delta / d, 1.01 * (delta / d) * (delta / d)) << delta;
  }
  const Parameters P = frictional_truth();
  const auto iso = P.iso();
  const double nu = 0.78, p = 0.1, l = 0.05;
  EXPECT_NEAR(opened_fraction(iso.data(), nu, p, l, 0.5), opened_fraction(iso.data(), nu, p, std::sqrt(3.0) * l, 0.0),
              1e-15);
  EXPECT_GT(opened_fraction(iso.data(), nu, p, l, 0.5), opened_fraction(iso.data(), nu, p, l, 0.0));

  for (double b : {0.5, 0.0}) {
    const Material<double> m{iso.data(), P.shear, P.nu_ref, 1.0,
                             Ext<double>{P.ext, b, Surface::LadeDuncan, FabricLode::Overlap}};
    State<double> y{std::log(nu), p, 0.3, 0.05};
    y.l = l;
    const State<double> dy = rhs(m, y, 1.0, Segment{});
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    const double n_F = P.ext[kNFA] + P.ext[kNFB] * (nu - P.nu_ref);
    const double C = iso[kC0] + iso[kC1] * std::pow(nu / iso[kNuCC] - 1, iso[kAlpha]);
    const double delta = M_PI * p / (C * nu), c3 = (1 + b) / (3 * std::sqrt(1 - b + b * b));
    const double F_lim = L.F_max * (b == 0.5 ? 1.0 : std::sqrt(3.0) / 2);
    const double want = L.beta_F * (F_lim - y.F) * std::pow(1 - std::exp(-c3 * l / delta), n_F);
    EXPECT_NEAR(dy.F, want, 1e-12 * std::fabs(want)) << b;
    EXPECT_EQ(dy.l, 1.0);
  }

  const double p0 = isotropic_pressure(iso.data(), nu);
  const std::vector<double> eps = shear_grid();
  auto run = [&](const double* ext, const char* mode, FabricLode f) { return frictional_shear(P, ext, mode, f); };
  double flat[kNumExt];
  std::copy(P.ext, P.ext + kNumExt, flat);
  flat[kNFA] = flat[kNFB] = 0.0;
  for (const char* mode : {"D2", "D3"}) {
    const auto o = run(flat, mode, FabricLode::Overlap), pr = run(flat, mode, FabricLode::Principal);
    for (std::size_t i = 0; i < eps.size(); ++i) {
      EXPECT_EQ(o[i].F, pr[i].F) << mode << " " << i;
      EXPECT_EQ(o[i].p, pr[i].p) << mode << " " << i;
    }
  }
  const auto o2 = run(P.ext, "D2", FabricLode::Overlap), p2 = run(P.ext, "D2", FabricLode::Principal);
  EXPECT_GT(std::fabs(o2[20].F - p2[20].F), 1e-4);   // the rule changes D2 (it is no identity there)

  const auto path = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01,
                                      {shear_seg(0.1, 20), shear_seg(-0.04, 8), shear_seg(-0.03, 6)},
                                      Ext<double>{P.ext, kLodeBD2, P.surface, FabricLode::Overlap});
  EXPECT_NEAR(path[20].state.l, 0.1, 1e-12);
  EXPECT_NEAR(path.back().state.l, 0.07, 1e-12);   // reset at the reversal, not at the next segment
}

// The extended family's calibration options of the synthetic recovery tests: the isotropic block held, P's nu_ref,
// Lade-Duncan, the fabric rule given.
static CalibrationOptions extended_options(const Parameters& P, FabricLode rule) {
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.nu_ref = P.nu_ref;
  o.max_step = 2e-3;
  o.extended = true;
  o.surface = Surface::LadeDuncan;
  o.fabric = rule;
  return o;
}

// A start 5-20 % off the truth: rates and limits up or down by turns, the extension block likewise.
static Parameters perturbed_start(const Parameters& P) {
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.9 : 1.05);
  for (int i = 0; i < kNumExt; ++i) start.ext[i] *= (i % 2 ? 0.8 : 1.2);
  return start;
}

// Synthetic D2 ensembles made by the frictional family with known parameters (K = 8, three
// volume fractions, AR(1) noise rho = 0.9): the calibration recovers the extension's
// coefficients within 3 jackknife standard errors, and the active terms (n_F, kappa_s) are
// resolved from zero. One seed, so that it runs in seconds; the coverage study of the group
// model (above) is the calibration of the jackknife itself.
static void recover_extension(FabricLode rule, bool state_limit = false) {
  Parameters P = frictional_truth();
  P.fabric = rule;
  if (state_limit) {   // a peak in the loose packings (n_psi 2.9 at 0.69), none at 0.80 (0.5)
    P.state_limit = true;
    P.ext[kNPsiA] = 1.8;
    P.ext[kNPsiB] = -20.0;
  }
  const int K = 8;
  const Synthetic S = synthetic(P, {0.69, 0.74, 0.80}, K, 0.9, 11);
  CalibrationOptions o = extended_options(P, rule);
  o.state_limit = state_limit;
  const Parameters start = perturbed_start(P);
  o.start = &start;
  const Calibration cal = calibrate(S.mean, {}, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  ASSERT_EQ(cal.value.size(), static_cast<std::size_t>(kNumIso + kNumShear + ext_size(state_limit)));
  CalibrationOptions oj = o;
  oj.start = &cal.params;
  const auto est = leave_one_out_estimates(S.mean, S.members, K, oj);
  // 3 SE; with the state limit t_{K-1,0.995} = 3.50: over seeds 11-21 its n_psi_a z-scores have an RMS
  // of 1.5 (the K = 8 jackknife SE is t-distributed and under-covers), and seed 11 puts n_psi_b at 3.15 SE
  // (docs/model.md, "The state-dependent limit").
  const double within = state_limit ? demfit::t_quantile(0.995, K - 1) : 3.0;
  for (int i = 0; i < ext_size(state_limit); ++i) {
    const int a = kNumIso + kNumShear + i;
    double mean = 0, ss = 0;
    for (const auto& e : est) mean += e[a] / K;
    for (const auto& e : est) ss += (e[a] - mean) * (e[a] - mean);
    const double se = std::sqrt((K - 1.0) / K * ss);
    EXPECT_LT(std::fabs(cal.value[a] - P.ext[i]), within * se + 1e-9)
        << ext_name(i) << ": estimate " << cal.value[a] << " truth " << P.ext[i] << " jackknife se " << se;
    if (i == kNFA || i == kKappaA || i == kNPsiA) {
      EXPECT_GT(std::fabs(cal.value[a]) / se, 3.0) << ext_name(i) << " not resolved from 0";
    }
  }
  // D3 from the same truth is predicted by the Lode surface without being fitted.
  const Synthetic S3 = synthetic(P, {0.74}, K, 0.9, 12, "D3");
  CurveData c3 = S3.mean[0];
  const double t95 = demfit::t_quantile(0.975, K - 1);
  for (std::size_t i = 0; i < c3.eps.size(); ++i) {
    c3.hw_p[i] = t95 * c3.se_p[i]; c3.hw_s[i] = t95 * c3.se_s[i]; c3.hw_F[i] = t95 * c3.se_F[i];
  }
  const ModelCurve m = predict_curve(cal.params, c3, 1e9, 2e-3);
  const auto errs = prediction_errors(m, c3);
  ASSERT_EQ(errs.size(), 3u);
  for (const auto& e : errs) EXPECT_LT(e.rms_over_band, 1.0) << e.quantity << " (rule " << fabric_lode_name(rule) << ")";
}

TEST(ModelFriction, RecoversExtensionWithinJackknifeErrors) { recover_extension(FabricLode::Principal); }

// The state exponent's Lode dependence (issue 31, eighth round; `--state-limit pressure-lode`): (i) the factor
// by hand, (p_ref/p)^(n_psi 3^(lambda/2)) in axisymmetric compression (c_3(1/2)/c_3(0) = (1/sqrt 3)/(1/3) = sqrt 3),
// n_psi itself at b = 1/2; (ii) D2 is the pressure limit's bit for bit whatever lambda_psi; (iii) lambda_psi = 0
// gives D3 the pressure limit's bit for bit; (iv) lambda_psi > 0 lowers D3's late stress ratio where the
// pressure has risen above its reference (a stronger softening), and leaves the start alone.
TEST(ModelFriction, LodeStateExponentScalesTheLimitAwayFromD2) {
  double ext[kNumExt] = {0};
  ext[kNPsiA] = 0.6;
  ext[kLambdaPsi] = 1.5;
  const double p = 0.05, p_ref = 0.04, nu = 0.74;
  const double want = std::pow(p_ref / p, 0.6 * std::pow(3.0, 0.75));
  EXPECT_NEAR(state_limit_factor<double>(ext, nu, nu, p, p_ref, 0.0, true), want, 1e-14);
  EXPECT_EQ(state_limit_factor<double>(ext, nu, nu, p, p_ref, 0.5, true), std::pow(p_ref / p, 0.6));
  EXPECT_EQ(state_limit_factor<double>(ext, nu, nu, p, p_ref, 0.0, false), std::pow(p_ref / p, 0.6));

  Parameters P = frictional_truth();
  P.ext[kNPsiA] = 1.8;
  const auto iso = P.iso();
  const double nu0 = 0.78, p0 = isotropic_pressure(iso.data(), nu0);
  auto run = [&](const char* mode, double lambda, bool lode) {
    double e[kNumExt];
    std::copy(P.ext, P.ext + kNumExt, e);
    e[kLambdaPsi] = lambda;
    return monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, 0.02, 0.01, shear_grid(), 2e-3,
                                  Ext<double>{e, lode_b_of(mode), P.surface, P.fabric, true, lode});
  };
  const auto d2 = run("D2", 0.0, false), d2l = run("D2", 2.0, true);
  const auto d3 = run("D3", 0.0, false), d30 = run("D3", 0.0, true), d3l = run("D3", 2.0, true);
  for (std::size_t i = 0; i < d2.size(); ++i) {
    EXPECT_EQ(d2[i].s, d2l[i].s) << i;
    EXPECT_EQ(d2[i].p, d2l[i].p) << i;
    EXPECT_EQ(d3[i].s, d30[i].s) << i;
    EXPECT_EQ(d3[i].F, d30[i].F) << i;
  }
  // (iv) at one state: above the reference pressure the D3 stress ratio is driven lower with lambda_psi > 0,
  // below it higher; D2's rate is the same
  for (double over : {1.2, 0.8}) {
    State<double> y{std::log(nu0), over * p0, 0.4, 0.05};
    auto ds = [&](double b, double lambda) {
      double e[kNumExt];
      std::copy(P.ext, P.ext + kNumExt, e);
      e[kLambdaPsi] = lambda;
      const Material<double> m{iso.data(), P.shear, P.nu_ref, 1.0, Ext<double>{e, b, P.surface, P.fabric, true, true}};
      return rhs(m, y, 1.0, Segment{}).s;
    };
    EXPECT_EQ(ds(0.5, 2.0), ds(0.5, 0.0));
    if (over > 1) EXPECT_LT(ds(0.0, 2.0), ds(0.0, 0.0));
    else EXPECT_GT(ds(0.0, 2.0), ds(0.0, 0.0));
  }
}

// Synthetic D2 and D3 ensembles (K = 8, three volume fractions each, AR(1) noise) from the weighted rule with the
// Lode-dependent state exponent (lambda_psi = 1.5): every extension coefficient, lambda_psi among them, is
// recovered within t_{K-1,0.995} jackknife SE and lambda_psi is resolved from 0; without a second Lode angle the
// option is refused.
TEST(ModelFriction, RecoversTheLodeStateExponentFromD2AndD3) {
  Parameters P = frictional_truth();
  P.fabric = FabricLode::Overlap;
  P.state_limit = P.state_lode = true;
  P.ext[kNPsiA] = 1.8;
  P.ext[kNPsiB] = -20.0;
  P.ext[kLambdaPsi] = 1.5;
  const int K = 8;
  Synthetic S = synthetic(P, {0.69, 0.74, 0.80}, K, 0.9, 31);
  const Synthetic S3 = synthetic(P, {0.69, 0.74, 0.80}, K, 0.9, 32, "D3");
  CalibrationOptions o = extended_options(P, FabricLode::Overlap);
  o.state_limit = o.state_lode = true;
  const Parameters start = perturbed_start(P);
  o.start = &start;
  EXPECT_THROW(calibrate(S.mean, {}, o), std::invalid_argument);   // D2 alone: lambda_psi cannot act
  S.mean.insert(S.mean.end(), S3.mean.begin(), S3.mean.end());
  S.members.insert(S.members.end(), S3.members.begin(), S3.members.end());
  const Calibration cal = calibrate(S.mean, {}, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  // the block without the `Weighted` pair (unread under the overlap rule): n_F .. n_psi_b, lambda_psi
  ASSERT_EQ(cal.value.size(), static_cast<std::size_t>(kNumIso + kNumShear + kNumExtBase + 3));
  EXPECT_EQ(cal.names.back(), "lambda_psi");
  CalibrationOptions oj = o;
  oj.start = &cal.params;
  const auto est = leave_one_out_estimates(S.mean, S.members, K, oj);
  const double within = demfit::t_quantile(0.995, K - 1);
  std::vector<int> idx;
  for (int i = 0; i < kNumExtBase + 2; ++i) idx.push_back(i);
  idx.push_back(kLambdaPsi);
  for (std::size_t j = 0; j < idx.size(); ++j) {
    const int a = kNumIso + kNumShear + static_cast<int>(j);
    double mean = 0, ss = 0;
    for (const auto& e : est) mean += e[a] / K;
    for (const auto& e : est) ss += (e[a] - mean) * (e[a] - mean);
    const double se = std::sqrt((K - 1.0) / K * ss);
    EXPECT_LT(std::fabs(cal.value[a] - P.ext[idx[j]]), within * se + 1e-9)
        << ext_name(idx[j]) << ": estimate " << cal.value[a] << " truth " << P.ext[idx[j]] << " jackknife se " << se;
    if (idx[j] == kLambdaPsi) EXPECT_GT(cal.value[a] / se, 3.0) << "lambda_psi not resolved from 0";
  }
}


// The same under the overlap rule, which changes D2 (its gate is the opened fraction, not the
// mobilisation): the coefficients, n_F among them, are recovered within 3 jackknife SE from D2 alone.
TEST(ModelFriction, RecoversExtensionUnderTheOverlapRule) { recover_extension(FabricLode::Overlap); }

// The extension rule (issue 31, fourth round): the overlap rule's gate and limit with the fabric's
// rate per unit extension (minor principal) strain. (i) The rate factor c3(b)/c3(1/2) against the
// deviators' minor components by hand: 1 in D2, (1/3)/(1/sqrt(3)) = 1/sqrt(3) in axisymmetric
// compression. (ii) D2 is the overlap rule's bit for bit (the factor is 1 at b = 1/2). (iii) D3's
// fabric right-hand side is the overlap rule's over sqrt(3) at the same state. (iv) With n_F = 0 (no
// gate) the D3 fabric at constant volume is the relaxation solved in closed form,
// F = F_lim + (F0 - F_lim) exp(-beta_F eps/sqrt(3)), F_lim = sqrt(3)/2 F_max (RK4 to 1e-9).
TEST(ModelFriction, ExtensionRuleRatesTheFabricPerUnitExtensionStrain) {
  EXPECT_EQ(fabric_rate_factor(FabricLode::Extension, 0.5), 1.0);
  EXPECT_NEAR(fabric_rate_factor(FabricLode::Extension, 0.0), 1.0 / std::sqrt(3.0), 1e-15);
  for (FabricLode f : {FabricLode::Norm, FabricLode::Principal, FabricLode::Opening, FabricLode::Overlap})
    EXPECT_EQ(fabric_rate_factor(f, 0.0), 1.0);
  const Parameters P = frictional_truth();
  const auto iso = P.iso();
  const double nu = 0.78;
  const std::vector<double> eps = shear_grid();
  auto run = [&](const double* ext, const char* mode, FabricLode f) { return frictional_shear(P, ext, mode, f); };
  const auto e2 = run(P.ext, "D2", FabricLode::Extension), o2 = run(P.ext, "D2", FabricLode::Overlap);
  for (std::size_t i = 0; i < eps.size(); ++i) {
    EXPECT_EQ(e2[i].F, o2[i].F) << i;
    EXPECT_EQ(e2[i].p, o2[i].p) << i;
    EXPECT_EQ(e2[i].s, o2[i].s) << i;
  }
  State<double> y{std::log(nu), 0.1, 0.3, 0.05};
  y.l = 0.05;
  auto rhs_at = [&](FabricLode f) {
    const Material<double> m{iso.data(), P.shear, P.nu_ref, 1.0, Ext<double>{P.ext, 0.0, Surface::LadeDuncan, f}};
    return rhs(m, y, 1.0, Segment{});
  };
  const State<double> de = rhs_at(FabricLode::Extension), dov = rhs_at(FabricLode::Overlap);
  EXPECT_NEAR(de.F, dov.F / std::sqrt(3.0), 1e-14 * std::fabs(dov.F));
  EXPECT_EQ(de.s, dov.s);
  EXPECT_EQ(de.p, dov.p);

  double flat[kNumExt];
  std::copy(P.ext, P.ext + kNumExt, flat);
  flat[kNFA] = flat[kNFB] = 0.0;
  // The group model (no extension block) ignores the rule, D3 included.
  const auto g3 = run(nullptr, "D3", FabricLode::Extension), gn = run(nullptr, "D3", FabricLode::Norm);
  for (std::size_t i = 0; i < eps.size(); ++i) EXPECT_EQ(g3[i].F, gn[i].F) << i;
  const auto e3 = run(flat, "D3", FabricLode::Extension);
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double F_lim = std::sqrt(3.0) / 2 * L.F_max;
  for (std::size_t i = 0; i < eps.size(); ++i) {
    const double want = F_lim + (0.01 - F_lim) * std::exp(-L.beta_F * eps[i] / std::sqrt(3.0));
    EXPECT_NEAR(e3[i].F, want, 1e-9) << i;
  }
}

// Synthetic D2 under the extension rule: D2 is the overlap rule's, so the same recovery; D3 from the
// same truth (rate per unit extension strain) predicted within a band.
TEST(ModelFriction, RecoversExtensionUnderTheExtensionRule) { recover_extension(FabricLode::Extension); }

// The state-dependent stress-ratio limit (issue 31, fifth round). (i) The factor is (p_ref/p)^n_psi
// with n_psi = a + b (nu - nu_ref), built by hand, and exactly 1 at p = p_ref. (ii) It moves the
// stress ratio's target only: at a state off the reference pressure the right-hand side differs from
// the plain limit's by beta_s (s_max/s_lim) s_lim (factor - 1)(1 + kappa_s r) in ds, and not at all in
// dp and dF (constant volume), in D2 and D3. (iii) Off, the n_psi entries are never read: a block with
// n_psi != 0 integrates, bit for bit, as one with n_psi = 0 switched on (exp(0 ln x) = 1, s_lim x 1),
// on constant-volume, reversed, isobaric and triaxial segments. (iv) Long constant-volume shear ends
// where the stress ratio equals the state-dependent limit at the end pressure, not s_lim: a
// critical state whose ratio is set by the state parameter (to 1e-3 of s).
TEST(ModelFriction, StateLimitIsAPressureFormStateParameter) {
  Parameters P = frictional_truth();
  P.fabric = FabricLode::Overlap;
  P.ext[kNPsiA] = 1.5;
  P.ext[kNPsiB] = -10.0;
  const auto iso = P.iso();
  const double nu = 0.71, p_ref = isotropic_pressure(iso.data(), nu);
  const double n = 1.5 - 10.0 * (nu - P.nu_ref);
  for (double p : {0.5 * p_ref, 1.2 * p_ref})
    EXPECT_NEAR(state_limit_factor(P.ext, nu, P.nu_ref, p, p_ref), std::pow(p_ref / p, n), 1e-14);
  EXPECT_EQ(state_limit_factor(P.ext, nu, P.nu_ref, p_ref, p_ref), 1.0);

  for (double b : {0.5, 0.0}) {
    const Material<double> on{iso.data(), P.shear, P.nu_ref, 1.0, Ext<double>{P.ext, b, Surface::LadeDuncan, P.fabric, true}};
    Material<double> off = on;
    off.ext.state_limit = false;
    State<double> y{std::log(nu), 1.2 * p_ref, 0.3, 0.05};
    y.l = 0.05;
    const State<double> d_on = rhs(on, y, 1.0, Segment{}), d_off = rhs(off, y, 1.0, Segment{});
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    const double s_lim = lode_limit(L.s_max, b, Surface::LadeDuncan);
    const double kappa = P.ext[kKappaA] + P.ext[kKappaB] * (nu - P.nu_ref);
    const double want = L.beta_s * (L.s_max / s_lim) * s_lim * (std::pow(1.0 / 1.2, n) - 1.0) * (1 + kappa * 0.3 / s_lim);
    EXPECT_NEAR(d_on.s - d_off.s, want, 1e-12 * std::fabs(want)) << b;
    EXPECT_LT(d_on.s, d_off.s) << "above the reference pressure the limit is lower";
    EXPECT_EQ(d_on.p, d_off.p) << b;
    EXPECT_EQ(d_on.F, d_off.F) << b;
  }

  const double p0 = isotropic_pressure(iso.data(), nu);
  double zero_psi[kNumExt];
  std::copy(P.ext, P.ext + kNumExt, zero_psi);
  zero_psi[kNPsiA] = zero_psi[kNPsiB] = 0.0;
  const auto off = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                     Ext<double>{P.ext, kLodeBD2, Surface::LadeDuncan, P.fabric, false});
  const auto on0 = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                     Ext<double>{zero_psi, kLodeBD2, Surface::LadeDuncan, P.fabric, true});
  const auto on = integrate<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, mixed_path(),
                                    Ext<double>{P.ext, kLodeBD2, Surface::LadeDuncan, P.fabric, true});
  ASSERT_EQ(off.size(), on0.size());
  for (std::size_t i = 0; i < off.size(); ++i) {
    EXPECT_EQ(off[i].state.p, on0[i].state.p) << i;
    EXPECT_EQ(off[i].state.s, on0[i].state.s) << i;
    EXPECT_EQ(off[i].state.F, on0[i].state.F) << i;
    EXPECT_EQ(off[i].eps_vol, on0[i].eps_vol) << i;
  }
  EXPECT_GT(std::fabs(on[20].state.s - off[20].state.s), 1e-4);   // and switched on it does act

  std::vector<double> eps;
  for (int i = 0; i <= 300; ++i) eps.push_back(0.01 * i);
  const auto st = monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.01, eps, 2e-3,
                                         Ext<double>{P.ext, kLodeBD2, Surface::LadeDuncan, P.fabric, true});
  const double s_max = local(P.shear, nu, P.nu_ref).s_max;
  const double p_end = st.back().p;
  ASSERT_GT(std::fabs(p_end / p0 - 1.0), 0.02) << "the test needs a pressure that moves";
  EXPECT_NEAR(st.back().s, s_max * std::pow(p0 / p_end, n), 1e-3);
  EXPECT_GT(std::fabs(st.back().s - s_max), 0.01);
}

// Synthetic D2 made with the state-dependent limit (overlap rule, K = 8, AR(1) rho = 0.9): the nine
// extension coefficients, n_psi's two among them, are recovered within t_{7,0.995} = 3.5 jackknife SE, n_psi at nu_ref
// resolved from 0, and D3 from the same truth predicted within a band.
TEST(ModelFriction, RecoversTheStateLimit) { recover_extension(FabricLode::Overlap, true); }

// The weighted rule (issue 31, sixth round): the Lode dependence of the fabric's onset and rate,
// (c3(b)/c3(1/2))^w, weighted by w = 1/(1 + exp(n_w (ln delta_w - ln delta))). (i) w against the
// formula by hand, 1/2 at delta_w, 0 where the overlap is not positive. (ii) D2 is the overlap rule's,
// bit for bit, whatever w's coefficients. (iii) With n_F = 0 (no gate) and n_w = 0 (w = 1/2 exactly)
// the D3 fabric at constant volume is the relaxation in closed form at the rate beta_F 3^(-1/4);
// with w -> 1 the extension rule's closed form (rate / sqrt(3)), with w -> 0 the rate beta_F itself.
// (iv) With the gate on and w -> 1 the D3 right-hand side is the extension rule's. (v) A calibration
// on D2 alone cannot see w and is refused by name.
TEST(ModelFriction, WeightedRuleSpansTheLodeBlindAndTheExtensionRules) {
  const double ex0[kNumExt] = {0, 0, 0, 0, 0, 0, 0, 0, 0, std::log(0.02), 6.0};
  EXPECT_DOUBLE_EQ(lode_weight(ex0, 0.02), 0.5);
  EXPECT_NEAR(lode_weight(ex0, 0.04), 1.0 / (1.0 + std::pow(0.02 / 0.04, 6.0)), 1e-15);
  EXPECT_EQ(lode_weight(ex0, 0.0), 0.0);
  const Parameters P = frictional_truth();
  const auto iso = P.iso();
  const double nu = 0.78;
  const std::vector<double> eps = shear_grid();
  auto run = [&](const double* ext, const char* mode, FabricLode f) { return frictional_shear(P, ext, mode, f); };
  double ext[kNumExt];
  std::copy(P.ext, P.ext + kNumExt, ext);
  ext[kLnDeltaW] = std::log(0.03);
  ext[kNW] = 5.0;
  const auto w2 = run(ext, "D2", FabricLode::Weighted), o2 = run(ext, "D2", FabricLode::Overlap);
  for (std::size_t i = 0; i < eps.size(); ++i) {
    EXPECT_EQ(w2[i].F, o2[i].F) << i;
    EXPECT_EQ(w2[i].p, o2[i].p) << i;
    EXPECT_EQ(w2[i].s, o2[i].s) << i;
  }
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double F_lim = std::sqrt(3.0) / 2 * L.F_max;
  const std::pair<double, double> cases[] = {{0.0, std::pow(3.0, -0.25)}, {30.0, 1.0 / std::sqrt(3.0)}, {-30.0, 1.0}};
  for (const auto& [n_w, rate] : cases) {   // n_w = +-30 about ln delta_w = -3.5 +- 6.5: w = 1 or 0 to 1e-80
    double flat[kNumExt];
    std::copy(ext, ext + kNumExt, flat);
    flat[kNFA] = flat[kNFB] = 0.0;
    flat[kNW] = n_w == 0.0 ? 0.0 : 30.0;
    flat[kLnDeltaW] = n_w > 0 ? -10.0 : n_w < 0 ? std::log(0.5) + 2.0 : -3.5;
    const auto w3 = run(flat, "D3", FabricLode::Weighted);
    for (std::size_t i = 0; i < eps.size(); ++i)
      EXPECT_NEAR(w3[i].F, F_lim + (0.01 - F_lim) * std::exp(-L.beta_F * rate * eps[i]), 1e-9) << n_w << " " << i;
  }
  double one[kNumExt];
  std::copy(ext, ext + kNumExt, one);
  one[kLnDeltaW] = -10.0;
  one[kNW] = 30.0;
  State<double> y{std::log(nu), 0.1, 0.3, 0.05};
  y.l = 0.05;
  auto rhs_at = [&](const double* e, FabricLode f) {
    const Material<double> m{iso.data(), P.shear, P.nu_ref, 1.0, Ext<double>{e, 0.0, Surface::LadeDuncan, f}};
    return rhs(m, y, 1.0, Segment{});
  };
  const State<double> dw = rhs_at(one, FabricLode::Weighted), de = rhs_at(one, FabricLode::Extension);
  EXPECT_NEAR(dw.F, de.F, 1e-13 * std::fabs(de.F));
  EXPECT_EQ(dw.s, de.s);
  EXPECT_EQ(dw.p, de.p);

  Parameters Pw = P;
  Pw.fabric = FabricLode::Weighted;
  std::copy(ext, ext + kNumExt, Pw.ext);
  const Synthetic S = synthetic(Pw, {0.74, 0.80}, 4, 0.9, 5);
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.extended = true;
  o.fabric = FabricLode::Weighted;
  o.start = &Pw;
  try {
    calibrate(S.mean, {}, o);
    ADD_FAILURE() << "a weighted calibration on D2 alone was not refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("second Lode angle"), std::string::npos) << e.what();
  }
}

// Synthetic D2 and D3 ensembles under the weighted rule, w switching from 0.1 at nu = 0.69 to 0.9 at
// 0.80 (the isotropic states' overlaps): the calibration on both Lode angles recovers every extension
// coefficient, ln delta_w and n_w among them, within 3 jackknife SE (K = 8, AR(1) noise), resolves n_w
// from 0, and reports no n_psi (the state limit is off).
TEST(ModelFriction, RecoversTheLodeWeightFromTwoLodeAngles) {
  Parameters P = frictional_truth();
  P.fabric = FabricLode::Weighted;
  const auto iso = P.iso();
  const double lo = std::log(mean_overlap(iso.data(), 0.69, isotropic_pressure(iso.data(), 0.69)));
  const double hi = std::log(mean_overlap(iso.data(), 0.80, isotropic_pressure(iso.data(), 0.80)));
  P.ext[kLnDeltaW] = 0.5 * (lo + hi);
  P.ext[kNW] = 2.0 * std::log(9.0) / (hi - lo);
  const int K = 8;
  const std::vector<double> nus = {0.69, 0.74, 0.80};
  const Synthetic S2 = synthetic(P, nus, K, 0.9, 21), S3 = synthetic(P, nus, K, 0.9, 22, "D3");
  std::vector<CurveData> all = S2.mean;
  all.insert(all.end(), S3.mean.begin(), S3.mean.end());
  std::vector<std::vector<CurveData>> members = S2.members;
  members.insert(members.end(), S3.members.begin(), S3.members.end());
  CalibrationOptions o = extended_options(P, FabricLode::Weighted);
  const Parameters start = perturbed_start(P);
  o.start = &start;
  const Calibration cal = calibrate(all, {}, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  ASSERT_EQ(cal.value.size(), static_cast<std::size_t>(kNumIso + kNumShear + kNumExtBase + 2));
  EXPECT_EQ(cal.names.back(), "n_w");
  CalibrationOptions oj = o;
  oj.start = &cal.params;
  const auto est = leave_one_out_estimates(all, members, K, oj);
  for (std::size_t a = kNumIso + kNumShear; a < cal.value.size(); ++a) {
    const int i = static_cast<int>(a) - kNumIso - kNumShear;
    const int idx = i < kNumExtBase ? i : i + 2;   // past the n_psi entries the report leaves out
    double mean = 0, ss = 0;
    for (const auto& e : est) mean += e[a] / K;
    for (const auto& e : est) ss += (e[a] - mean) * (e[a] - mean);
    const double se = std::sqrt((K - 1.0) / K * ss);
    EXPECT_EQ(cal.names[a], ext_name(idx));
    EXPECT_LT(std::fabs(cal.value[a] - P.ext[idx]), 3.0 * se + 1e-9)
        << ext_name(idx) << ": estimate " << cal.value[a] << " truth " << P.ext[idx] << " jackknife se " << se;
    if (idx == kNW) EXPECT_GT(cal.value[a] / se, 3.0) << "n_w not resolved from 0";
  }
}

// The Lode surface moves the limit, not the initial stiffness: from s = 0 the stress ratio rises
// at G/p = beta_s s_max in D2 (b = 1/2) and in D3 (b = 0) alike, and tends to s_max and to the
// surface's s_lim(b = 0) respectively (kappa_s = 0 here: the plain relaxation law, solved).
TEST(ModelFriction, LodeSurfaceMovesTheLimitNotTheInitialSlope) {
  Parameters P = frictional_truth();
  P.ext[kKappaA] = P.ext[kKappaB] = 0.0;
  const auto iso = P.iso();
  const double nu = 0.74, p0 = isotropic_pressure(iso.data(), nu);
  std::vector<double> eps;
  for (int i = 0; i <= 400; ++i) eps.push_back(0.005 * i);
  const auto d2 = monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.01, eps, 1e-3,
                                         Ext<double>{P.ext, lode_b_of("D2"), Surface::LadeDuncan});
  const auto d3 = monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.01, eps, 1e-3,
                                         Ext<double>{P.ext, lode_b_of("D3"), Surface::LadeDuncan});
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double slope = L.beta_s * L.s_max;
  EXPECT_NEAR(d2[1].s / eps[1], slope, 0.02 * slope);
  EXPECT_NEAR(d3[1].s / eps[1], d2[1].s / eps[1], 0.01 * slope);   // unscaled: 10 % apart, s_lim(0)/s_max
  EXPECT_NEAR(d2.back().s, L.s_max, 1e-4);
  EXPECT_NEAR(d3.back().s, lode_limit(L.s_max, 0.0, Surface::LadeDuncan), 1e-4);
  EXPECT_GT(d3.back().s, d2.back().s + 0.02);
}

// The plane-strain Lode parameter (thirteenth round): at the b it returns, the surface's gradient in principal
// stress, by central differences of I1 I2 / I3 (Matsuoka-Nakai) or I1^3 / I3 (Lade-Duncan) written out here, has no
// intermediate component in the deviatoric plane; 1/2 without a surface and as the surface shrinks to a circle;
// falling with the stress ratio, Lade-Duncan's nearer 1/2 than Matsuoka-Nakai's.
TEST(ModelFriction, PlaneStrainLodeParameterHasADeviatoricNormalWithoutIntermediateComponent) {
  const auto invariant = [](Surface f, const double* x) {
    const double i1 = x[0] + x[1] + x[2], i2 = x[0] * x[1] + x[1] * x[2] + x[2] * x[0], i3 = x[0] * x[1] * x[2];
    return f == Surface::LadeDuncan ? i1 * i1 * i1 / i3 : i1 * i2 / i3;
  };
  EXPECT_EQ(plane_strain_lode_b(Surface::None, 0.7), kLodeBD2);
  for (Surface f : {Surface::MatsuokaNakai, Surface::LadeDuncan}) {
    double last = 0.5;
    for (double s_ref : {0.01, 0.3, 0.6, 0.9}) {
      const double b = plane_strain_lode_b(f, s_ref);
      const double k = 1.0 / std::sqrt(1.0 - b + b * b), s = lode_limit(s_ref, b, f);
      const double sig[3] = {1 + s * (2 - b) / 3 * k, 1 + s * (2 * b - 1) / 3 * k, 1 - s * (1 + b) / 3 * k};
      double g[3];
      for (int i = 0; i < 3; ++i) {
        double up[3] = {sig[0], sig[1], sig[2]}, dn[3] = {sig[0], sig[1], sig[2]};
        up[i] += 1e-6; dn[i] -= 1e-6;
        g[i] = (invariant(f, up) - invariant(f, dn)) / 2e-6;
      }
      const double mean = (g[0] + g[1] + g[2]) / 3, dev1 = g[0] - mean;
      EXPECT_LT(std::fabs(g[1] - mean), 1e-5 * std::fabs(dev1)) << surface_name(f) << " " << s_ref << " b " << b;
      EXPECT_LT(b, last + 1e-12) << s_ref;
      last = b;
      if (s_ref == 0.01) EXPECT_NEAR(b, 0.5, 0.01);
    }
    EXPECT_LT(last, 0.4);
  }
  EXPECT_LT(plane_strain_lode_b(Surface::MatsuokaNakai, 0.7), plane_strain_lode_b(Surface::LadeDuncan, 0.7));
}

// Parameters::b_d2 is the stress's Lode parameter of D2 only: under the `Norm` fabric rule (the fabric blind to b)
// a D2 curve predicted with b_d2 = 0.25 is the same curve named TT_b025 with b_d2 = 1/2, to the last bit; D3's is
// untouched by b_d2; and b_d2 = 1/2 is the model of every earlier round.
TEST(ModelFriction, D2StressLodeParameterActsOnD2Only) {
  Parameters P = frictional_truth();
  P.extended = true;
  P.surface = Surface::LadeDuncan;
  P.fabric = FabricLode::Norm;
  const auto iso = P.iso();
  CurveData c;
  c.nu = 0.74;
  for (int i = 0; i <= 100; ++i) c.eps.push_back(0.003 * i);
  c.p.assign(c.eps.size(), isotropic_pressure(iso.data(), c.nu));
  c.s.assign(c.eps.size(), 0.0);
  c.F.assign(c.eps.size(), 0.01);
  Parameters Q = P;
  Q.b_d2 = 0.25;
  c.mode = "TT_b025";
  const ModelCurve tt = predict_curve(P, c, 1e9, 2e-3);
  c.mode = "D2";
  const ModelCurve d2q = predict_curve(Q, c, 1e9, 2e-3), d2p = predict_curve(P, c, 1e9, 2e-3);
  for (std::size_t i = 0; i < c.eps.size(); ++i) {
    EXPECT_EQ(d2q.s[i], tt.s[i]) << i;
    EXPECT_EQ(d2q.p[i], tt.p[i]) << i;
    EXPECT_EQ(d2q.F[i], tt.F[i]) << i;
  }
  EXPECT_GT(d2q.s.back(), d2p.s.back() + 0.01);   // b = 1/4 holds a larger stress ratio on Lade-Duncan than 1/2
  c.mode = "D3";
  const ModelCurve d3q = predict_curve(Q, c, 1e9, 2e-3), d3p = predict_curve(P, c, 1e9, 2e-3);
  for (std::size_t i = 0; i < c.eps.size(); ++i) EXPECT_EQ(d3q.s[i], d3p.s[i]) << i;
  EXPECT_EQ(lode_b_of("D2", 0.3), 0.3);
  EXPECT_EQ(lode_b_of("isobaric_D2", 0.3), 0.3);
  EXPECT_EQ(lode_b_of("TT_b050_dense", 0.3), 0.5);
  EXPECT_EQ(lode_b_of("TC_s3_loose", 0.3), 0.0);
}

// ---- Calibrated on the laboratory set (issue 31; docs/model.md, "Calibrated on drained triaxial tests") ----

namespace {
// The laboratory set of the tests below: synthetic triaxial ensembles at constant side stress from two volume
// fractions (K = 8, AR(1) noise rho = 0.5) and an isotropic branch of 8 states with 0.3 % scatter.
struct LabSet {
  std::vector<PathData> paths;
  IsoData branch;
};
LabSet lab_set(const Parameters& P) {
  const auto iso = P.iso();
  std::mt19937_64 rng(31);
  Rows r = rows_of(0.3, 0.3, 0.006, false);
  for (auto& c : r.isob) c = 2;
  LabSet L;
  for (double nu : {0.70, 0.78}) L.paths.push_back(synthetic_path(P, "TC_s3_synthetic", nu, r, 8, 0.5, rng));
  for (int i = 0; i < 8; ++i) {   // deterministic, alternating scatter
    const double nu = 0.68 + 0.018 * i, f = 1.0 + (i % 2 ? 0.003 : -0.003);
    L.branch.nu.push_back(nu);
    L.branch.p.push_back(f * isotropic_pressure(iso.data(), nu));
    L.branch.C.push_back(f * coordination(iso.data(), nu));
  }
  return L;
}
}  // namespace

// The path ensembles alone (constant side stress at two volume fractions) and an isotropic branch
// of a few states are the calibration when start values are given: synthetic triaxial ensembles
// made by the model with known parameters (K = 8, AR(1) noise rho = 0.5), a start 10-20 % off, the
// pressure law's curvature and the coordination law's onset and exponent held at their (true)
// start values. The held parameters stay exactly there; the others come back within their errors.
TEST(ModelFit, CalibratesOnTriaxialPathsAloneFromAStart) {
  const Parameters P = truth();
  const auto iso = P.iso();
  const LabSet L = lab_set(P);
  const std::vector<PathData>& paths = L.paths;
  const IsoData& br = L.branch;
  Parameters start = P;
  for (int i = 0; i < kNumShear; i += 2) start.shear[i] *= (i % 4 ? 0.9 : 1.1);
  start.p0 *= 1.15; start.C1 *= 0.9;
  CalibrationOptions o;
  o.max_step = 1e-3;
  o.nu_ref = P.nu_ref;
  EXPECT_THROW(calibrate({}, br, o, paths), std::invalid_argument) << "paths alone need start values";
  o.hold_iso = {kGammaP, kNuCC, kAlpha};
  EXPECT_THROW(calibrate({}, br, o, paths), std::invalid_argument) << "held parameters need start values";
  o.start = &start;
  IsoData few = br;
  few.nu.resize(5); few.p.resize(5); few.C.resize(5);
  EXPECT_THROW(calibrate({}, few, o, paths), std::invalid_argument) << "4 free isotropic parameters need >= 6 points";
  const Calibration cal = calibrate({}, br, o, paths);
  ASSERT_TRUE(cal.ok) << cal.message;
  for (int i : {kGammaP, kNuCC, kAlpha}) {
    EXPECT_EQ(cal.value[i], start.iso()[i]) << iso_name(i) << " held";
    EXPECT_TRUE(std::isnan(cal.se_cov[i])) << iso_name(i) << " held: no error";
  }
  EXPECT_EQ(cal.n_free, kNumIso - 3 + kNumShear);
  for (int i : {kP0, kNuC, kC0, kC1})
    EXPECT_LT(std::fabs(cal.value[i] - iso[i]), 5 * cal.se_cov[i] + 1e-9) << iso_name(i);
  for (int i : {kSmaxA, kLnBetaSA, kFmaxA, kLnBetaFA})
    EXPECT_LT(std::fabs(cal.value[kNumIso + i] - P.shear[i]), 5 * cal.se_cov[kNumIso + i]) << shear_name(i);
  EXPECT_LT(std::fabs(cal.value[kP0] - iso[kP0]), 0.03 * iso[kP0]) << "p0 from 15 % off";
  EXPECT_LT(cal.chi2_dof(), 3.0);
  // A held jamming fraction above the data's lowest nu (a start from denser packings) is moved 0.005
  // below it, not onto it, where the coordination law's cusp would sit on the start state.
  Parameters high = start;
  high.nu_cC = 0.75;
  o.start = &high;
  o.max_iterations = 5;
  const Calibration c2 = calibrate({}, br, o, paths);
  double numin = 1e9;
  for (const auto& d : paths) for (double v : d.nu_m) numin = std::min(numin, v);
  EXPECT_NEAR(c2.value[kNuCC], numin - 0.005, 1e-12);
}

// `--start` from a stored optimum starts there: no iteration from the optimum's own parameters gives its chi2 (the
// isotropic block was once replaced by the branch's own fit, which the paths pull away from: a restart began up to
// 3.8 times the stored cost, docs/model.md). A start from laws that miss this branch (p0 three times too large, as
// another material's) starts from them too, or, with start_iso_from_file false (`--start-isotropic branch`), from the
// branch's own fit.
TEST(ModelFit, ARestartFromAnOptimumStartsThere) {
  const Parameters P = truth();
  const LabSet L = lab_set(P);
  CalibrationOptions o;
  o.max_step = 1e-3;
  o.nu_ref = P.nu_ref;
  Parameters start = P;
  for (int i = 0; i < kNumShear; i += 2) start.shear[i] *= (i % 4 ? 0.9 : 1.1);
  start.p0 *= 1.15; start.C1 *= 0.9;
  o.start = &start;
  const Calibration cal = calibrate({}, L.branch, o, L.paths);
  ASSERT_TRUE(cal.ok) << cal.message;
  CalibrationOptions again = o;
  again.start = &cal.params;
  again.max_iterations = 0;
  const Calibration re = calibrate({}, L.branch, again, L.paths);
  // (the weights come from the branch's own fit, converged from another start: equal to about 1e-7)
  EXPECT_NEAR(re.chi2_dof(), cal.chi2_dof(), 1e-5 * cal.chi2_dof());
  for (int i = 0; i < kNumIso; ++i) EXPECT_EQ(re.value[i], cal.value[i]) << iso_name(i);
  Parameters foreign = cal.params;
  foreign.p0 *= 3;
  again.start = &foreign;
  EXPECT_EQ(calibrate({}, L.branch, again, L.paths).value[kP0], foreign.p0);
  again.start_iso_from_file = false;
  const Calibration fr = calibrate({}, L.branch, again, L.paths);
  EXPECT_LT(std::fabs(fr.value[kP0] - P.p0), 0.03 * P.p0) << "the branch's own fit, not the start's p0";
  EXPECT_LT(fr.chi2_dof(), 2 * cal.chi2_dof()) << "from the branch's own isotropic fit and the optimum's shear laws";
}

// A parameters.csv as `dem model` writes it (quoted laws with commas) read back; re-centring the
// nu-laws leaves every law the same at any nu; the laboratory tests' Lode parameter b from their
// names; a start state below the isotropic law's jamming fraction is refused, not integrated.
TEST(ModelFit, StartValuesLodeNamesAndLowStartStates) {
  const std::string path = ::testing::TempDir() + "/model_parameters_read.csv";
  Parameters P = truth();
  P.extended = true;
  const double ex[kNumExt] = {2.0, 15.0, 1.5, -2.0, -0.1, 0.3, 0.05};
  std::copy(ex, ex + kNumExt, P.ext);
  {
    std::ofstream f(path);
    f << "parameter,law,value,se\n";
    const auto iso = P.iso();
    for (int i = 0; i < kNumIso; ++i) f << iso_name(i) << ",\"p*(nu) = p0 (nu C(nu)/nu_c) x (1 + gamma_p x), x = ln\"," << iso[i] << ",1\n";
    for (int i = 0; i < kNumShear; ++i) f << shear_name(i) << ",\"q(nu) = a, b\"," << std::setprecision(17) << P.shear[i] << ",1\n";
    for (int i = 0; i < kNumExt; ++i) f << ext_name(i) << ",law," << std::setprecision(17) << P.ext[i] << ",1\n";
    f << "nu_ref,centre," << P.nu_ref << ",nan\n";
  }
  const Parameters Q = read_parameters(path);
  EXPECT_TRUE(Q.extended);
  EXPECT_DOUBLE_EQ(Q.nu_c, P.nu_c);
  EXPECT_DOUBLE_EQ(Q.shear[kLnBetaPB], P.shear[kLnBetaPB]);
  EXPECT_DOUBLE_EQ(Q.ext[kChiD], P.ext[kChiD]);
  EXPECT_DOUBLE_EQ(Q.nu_ref, P.nu_ref);
  const Parameters R = recentred(Q, 0.66);
  EXPECT_EQ(R.nu_ref, 0.66);
  for (double nu : {0.6, 0.7, 0.8}) {
    const Local<double> a = local(Q.shear, nu, Q.nu_ref), b = local(R.shear, nu, R.nu_ref);
    EXPECT_NEAR(a.s_max, b.s_max, 1e-12); EXPECT_NEAR(a.beta_F, b.beta_F, 1e-9 * a.beta_F); EXPECT_NEAR(a.a_A, b.a_A, 1e-12);
    const LocalExt<double> x = local_ext(Q.ext, nu, Q.nu_ref), y = local_ext(R.ext, nu, R.nu_ref);
    EXPECT_NEAR(x.n_F, y.n_F, 1e-12); EXPECT_NEAR(x.kappa_s, y.kappa_s, 1e-12); EXPECT_NEAR(x.d_D, y.d_D, 1e-12);
  }
  {
    std::ofstream f(path);
    f << "parameter,law,value\np0,law,0.04\n";
  }
  EXPECT_THROW(read_parameters(path), std::runtime_error);
  EXPECT_THROW(read_parameters(path + ".missing"), std::runtime_error);

  EXPECT_EQ(lode_b_of("TC_s3_dense"), 0.0);
  EXPECT_EQ(lode_b_of("TC_p_loose"), 0.0);
  EXPECT_EQ(lode_b_of("TE_s3_dense"), 1.0);
  EXPECT_EQ(lode_b_of("TE_p_loose"), 1.0);
  EXPECT_EQ(lode_b_of("TT_b025_dense"), 0.25);
  EXPECT_EQ(lode_b_of("TT_b075_loose"), 0.75);
  EXPECT_EQ(lode_b_of("D2"), kLodeBD2);
  EXPECT_EQ(lode_b_of("triaxial"), 0.0);

  const auto iso = P.iso();
  EXPECT_THROW(check_start_scale(iso, P.nu_c - 0.005, "test"), std::invalid_argument);
  EXPECT_THROW(check_start_scale(iso, P.nu_c, "test"), std::invalid_argument);
  EXPECT_NO_THROW(check_start_scale(iso, P.nu_c + 0.005, "test"));
  PathData d;
  d.name = "TC_s3_low"; d.nu = P.nu_c - 0.01; d.source = "low";
  d.acc = {0.0, 0.01}; d.direction = {1, 1}; d.isobaric = {2, 2};
  d.p = {1e-3, 1e-3}; d.s = {0.0, 0.0}; d.F = {0.0, 0.0};
  EXPECT_THROW(predict_path(P, d), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// The volume-form state parameter psi = nu - nu_cs(p) (issue 31, tenth round; docs/model.md, "The volume-form state
// parameter").

namespace {

// A critical-state material: the laws of psi (the a's the critical state's), a_A = 0 so that the critical state is
// psi = 0 exactly, the line nu_cs(p) = 0.60 + 0.008 ln(p*/1e-3), a peak e^{8 psi}, a phase transformation e^{-40 psi}.
Parameters volume_truth() {
  Parameters P = truth();
  const double sh[kNumShear] = {0.70, 0.0, std::log(80.0), -10.0, 0.35, 5.0, std::log(40.0), -20.0, 0.0, 0.0,
                                std::log(5.0), 0.0};
  std::copy(sh, sh + kNumShear, P.shear);
  std::fill(P.ext, P.ext + kNumExt, 0.0);
  P.ext[kNFA] = 1.0; P.ext[kKappaA] = 0.5; P.ext[kDilA] = 0.3; P.ext[kChiD] = 1.0;
  P.ext[kNuCs] = 0.60; P.ext[kLambdaCs] = 0.008; P.ext[kNB] = 8.0; P.ext[kND] = 40.0;
  P.ext[kNRate] = 0.7;   // the rates slow with the pressure, less than the stiffness falls (twelfth round)
  P.extended = true;
  P.state_volume = true;
  P.surface = Surface::LadeDuncan;
  P.fabric = FabricLode::Overlap;
  return P;
}

Ext<double> volume_ext(const Parameters& P, double b) {
  Ext<double> e{P.ext, b, P.surface, P.fabric, false, false, true};
  e.excess_relaxes = P.excess_relaxes;
  e.excess_bounded = P.excess_relaxes && P.excess_bounded;
  return e;
}

// Drained triaxial compression at constant side stress to eps_d = 1.2 (rows every 0.006).
Rows triaxial_rows(double end = 1.2) {
  Rows r = rows_of(end, end, 0.006, false);
  for (auto& c : r.isob) c = 2;
  return r;
}

}  // namespace

// Dense (psi0 = +0.06) and loose (psi0 = -0.01) packings at the same side stress end on the same critical state: psi
// = 0 and s = the limit on the Lode surface (a_A = 0 makes it exact), whatever the preparation; the dense one peaks
// above it by 5 % or more, the loose one by less than 1 %; and the elastic volume fraction nu e^{e_pl} stays on the isotropic law at p
// (d ln nu_el = dp/B), so that the relaxation towards k p_iso(nu_el) never acts.
TEST(ModelVolumeState, DenseAndLooseEndOnTheCriticalStateLine) {
  const Parameters P = volume_truth();
  const auto iso = P.iso();
  const Rows r = triaxial_rows(2.4);   // the rates scale with B/p: at 1e-2 the critical state is reached later
  const double s_cs = lode_limit(P.shear[kSmaxA], 0.0, Surface::LadeDuncan);
  for (double p0 : {1e-3, 1e-2}) {
    const double nu_line = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef);
    double nu_end[2], s_end[2];
    int k = 0;
    for (double psi0 : {0.06, -0.01}) {
      const auto st = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu_line + psi0, p0, 0.0, 0.0, r.acc, r.dir,
                                             r.isob, 1e-3, volume_ext(P, 0.0));
      double s_peak = 0;
      for (const auto& x : st) {
        s_peak = std::max(s_peak, x.state.s);
        const double nu_el = std::exp(x.state.ln_nu + x.state.e_pl);
        EXPECT_NEAR(isotropic_pressure(iso.data(), nu_el), x.state.p, 1e-5 * x.state.p) << "nu_el on the isotropic law (RK4: 2e-6 at p* = 1e-3)";
      }
      const State<double>& e = st.back().state;
      nu_end[k] = std::exp(e.ln_nu);
      s_end[k] = e.s;
      EXPECT_NEAR(state_psi(P.ext, nu_end[k], e.p), 0.0, 2e-5) << "p0 " << p0 << " psi0 " << psi0;
      EXPECT_NEAR(e.s, s_cs, 1e-4) << "the critical stress ratio on the Lode surface";
      if (psi0 > 0) EXPECT_GT(s_peak, 1.05 * s_cs) << "the dense packing peaks";
      else EXPECT_LT(s_peak, 1.01 * s_cs) << "the loose one does not (within 1 %: at 1e-2 its plastic contraction, whose "
                                              "rate B/p does not scale, carries it to psi = +0.007 before s saturates)";
      ++k;
    }
    EXPECT_NEAR(nu_end[0], nu_end[1], 5e-5) << "one critical state from both preparations";
    EXPECT_NEAR(s_end[0], s_end[1], 1e-4);
  }
}

// The entries of the volume-form state parameter are never read without it: the right-hand side with them set and
// the flag off equals the extended model without them, bit for bit (so the fifth to ninth rounds' models are
// unchanged), and the flag on changes it.
TEST(ModelVolumeState, EntriesAreUnreadWithoutTheFlag) {
  Parameters P = frictional_truth();
  const auto iso = P.iso();
  double with[kNumExt];
  std::copy(P.ext, P.ext + kNumExt, with);
  with[kNuCs] = 0.6; with[kLambdaCs] = 0.01; with[kNB] = 5.0; with[kND] = 20.0;
  const State<double> y{std::log(0.70), 0.02, 0.3, 0.05};
  for (double b : {0.5, 0.0}) {
    const Material<double> a{iso.data(), P.shear, P.nu_ref, 1.1, Ext<double>{P.ext, b, P.surface, P.fabric}};
    const Material<double> c{iso.data(), P.shear, P.nu_ref, 1.1, Ext<double>{with, b, P.surface, P.fabric}};
    Material<double> on = c;
    on.ext.state_volume = true;
    for (const Segment& seg : {Segment{}, shear_seg(0.1, 1, Control::Triaxial)}) {
      const State<double> da = rhs(a, y, 1.0, seg), dc = rhs(c, y, 1.0, seg), don = rhs(on, y, 1.0, seg);
      EXPECT_EQ(da.p, dc.p); EXPECT_EQ(da.s, dc.s); EXPECT_EQ(da.F, dc.F); EXPECT_EQ(da.ln_nu, dc.ln_nu);
      EXPECT_EQ(dc.e_pl, 0.0);
      EXPECT_NE(don.s, dc.s);
    }
  }
}

namespace {
// Synthetic drained triaxial ensembles of the material P (its line logarithmic or linear in p*), calibrated with the
// same form of the line; the checks of RecoversTheStateParametersFromDrainedTriaxialTests. The material's isotropic law
// has one jamming fraction (nu_cC = nu_c): volume_truth's nu_cC above nu_c puts the law's cusp at p* = 9.8e-4, which
// the relaxing excess's elastic state (at p - q, below the start pressure 1e-3) crosses; there the cost is rough
// (docs/model.md, "The isotropic law's cusp"), and the fit stalled 2.9 % low in a_A (nineteenth round).
void recover_volume_state(const Parameters& material, bool linear, const std::vector<double>& pressures = {1e-3, 1e-2}) {
  Parameters P = material;
  P.nu_cC = P.nu_c;
  ASSERT_TRUE(std::isnan(cusp_pressure(P.iso().data())));
  const Rows r = triaxial_rows(2.4);
  std::mt19937_64 rng(41);
  std::vector<PathData> paths;
  for (double p0 : pressures)
    for (double psi0 : {0.06, -0.01}) {
      const double nu0 = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) + P.ext[kCCs] * (p0 - kPCsRef) + psi0;
      paths.push_back(synthetic_path(P, "TC_s3_synthetic", nu0, r, 8, 0.0, rng, p0, volume_ext(P, 0.0)));
    }
  CalibrationOptions o = extended_options(P, FabricLode::Overlap);
  o.state_volume = true;
  o.csl_linear = linear;
  o.excess_relaxes = P.excess_relaxes;
  o.excess_bounded = P.excess_bounded;
  for (const auto& d : paths)   // the material inside its law's domain: q < p, the elastic state jammed
    EXPECT_LT(largest_excess_ratio(predict_path(P, d, 1e-3)), 1.0);
  Parameters start = perturbed_start(P);
  start.state_volume = false;   // a start without the line: it comes from the end states
  o.start = &start;
  const Calibration cal = calibrate({}, {}, o, paths);
  ASSERT_TRUE(cal.ok) << cal.message;
  for (const auto& w : cal.warnings) EXPECT_EQ(w.find("unbounded"), std::string::npos) << w;
  auto at = [&](const std::string& n) {
    for (std::size_t i = 0; i < cal.names.size(); ++i) if (cal.names[i] == n) return static_cast<int>(i);
    ADD_FAILURE() << n << " not reported";
    return 0;
  };
  EXPECT_NEAR(cal.value[at("nu_cs")], P.ext[kNuCs], 2e-4) << "the line of the end states";
  EXPECT_NEAR(cal.value[at("lambda_cs")], P.ext[kLambdaCs], 2e-4);
  EXPECT_NEAR(cal.value[at("c_cs")], P.ext[kCCs], 0.02) << "the linear term (0.02 moves nu_cs(1e-2) by 2e-4)";
  EXPECT_EQ(cal.value[at("chi_D")], 1.0);
  EXPECT_EQ(cal.value[at("s_max_b")], 0.0);
  for (const char* n : {"n_psi_a", "lambda_psi", "ln_delta_w"})
    for (const auto& name : cal.names) EXPECT_NE(name, n) << "not in this law";
  std::vector<std::pair<std::string, double>> want = {
      {"s_max_a", P.shear[kSmaxA]}, {"F_max_a", P.shear[kFmaxA]}, {"F_max_b", P.shear[kFmaxB]},
      {"ln_beta_s_a", P.shear[kLnBetaSA]}, {"ln_beta_F_a", P.shear[kLnBetaFA]}, {"d_D_a", P.ext[kDilA]},
      {"n_peak", P.ext[kNB]}, {"n_dil", P.ext[kND]}, {"kappa_s_a", P.ext[kKappaA]}, {"n_rate", P.ext[kNRate]}};
  if (P.excess_relaxes) {   // a_A and beta_p within 4 covariance errors too (seed 41: 0.4 and 0.0 errors off)
    want.push_back({"a_A_a", P.shear[kAnisoA]});
    want.push_back({"ln_beta_p_a", P.shear[kLnBetaPA]});
  } else {
    EXPECT_TRUE(std::isnan(cal.se_cov[at("ln_beta_p_a")])) << "beta_p held: it does not act";
  }
  EXPECT_EQ(cal.value[at("ln_beta_p_b")], 0.0);
  EXPECT_EQ(cal.params.excess_relaxes, P.excess_relaxes);
  EXPECT_EQ(cal.params.excess_bounded, P.excess_bounded);
  if (pressures.size() >= 3) {
    const int i = at("m_peak");
    EXPECT_LT(std::fabs(cal.value[i] - P.ext[kMPeak]), 4 * cal.se_cov[i]) << "m_peak = " << cal.value[i] << " +- " << cal.se_cov[i];
    EXPECT_GT(std::fabs(cal.value[i]), 4 * cal.se_cov[i]) << "m_peak resolved";
  } else {
    EXPECT_EQ(cal.value[at("m_peak")], 0.0) << "held at its start from two pressures";
    EXPECT_TRUE(std::isnan(cal.se_cov[at("m_peak")]));
  }
  // From three pressures s_max_a's covariance error falls to 1e-4 of the value, and the recovered value sits 1e-3 off
  // (10 such errors; chi2/dof below 3): the errors of the three-pressure fit are quoted with a floor of 0.2 % of the truth
  const double floor_rel = pressures.size() >= 3 ? 2e-3 : 0.0;
  for (const auto& [n, v] : want) {
    const int i = at(n);
    ASSERT_TRUE(std::isfinite(cal.se_cov[i])) << n;
    EXPECT_LT(std::fabs(cal.value[i] - v), std::max(4 * cal.se_cov[i], floor_rel * std::fabs(v)))
        << n << " = " << cal.value[i] << " +- " << cal.se_cov[i];
  }
  for (const char* n : {"n_peak", "n_dil"}) EXPECT_GT(cal.value[at(n)], 4 * cal.se_cov[at(n)]) << n << " resolved";
  EXPECT_LT(cal.chi2_dof(), 3.0);
}
}  // namespace

// Synthetic drained triaxial ensembles (dense and loose, p* = 1e-3 and 1e-2, K = 8, independent noise, so that the
// covariance errors hold: with AR(1) rho = 0.9 they are 4 times too small, as the jackknife tests above show) made by the
// critical-state material: `--state-limit volume` takes the line from their end states and recovers the material's
// coefficients within 4 covariance standard errors from a start 5-20 % off; the state exponents are resolved from 0.
// Both forms of the line: logarithmic (lambda_cs) and linear in the pressure (c_cs, `--csl linear`).
TEST(ModelVolumeState, RecoversTheStateParametersFromDrainedTriaxialTests) {
  for (bool linear : {false, true}) {
    SCOPED_TRACE(linear ? "linear line" : "logarithmic line");
    Parameters P = volume_truth();
    if (linear) { P.ext[kLambdaCs] = 0.0; P.ext[kCCs] = 1.6; }   // 0.60 + 1.6 (p* - 1e-3): 0.6144 at 1e-2
    recover_volume_state(P, linear);
  }
}

// The relaxing anisotropic pressure's coefficients from the same synthetic tests (a_A = 0.05, beta_p = 5: an excess up
// to 59 % of p at 1e-3, 8 % at 1e-2; the eighteenth round's a_A = 0.3 took it to 3 times p, an elastic state below
// jamming, which recover_volume_state now refuses): a_A and beta_p (the excess's size a_A B F/beta_p and its rate)
// within 4 covariance standard errors, as the rest.
TEST(ModelVolumeState, RecoversTheRelaxingExcessFromDrainedTriaxialTests) {
  Parameters P = volume_truth();
  P.ext[kLambdaCs] = 0.0; P.ext[kCCs] = 1.6;
  P.shear[kAnisoA] = 0.05;
  P.shear[kLnBetaPA] = std::log(5.0);
  P.excess_relaxes = true;
  recover_volume_state(P, true);
}

// The bounded excess's coefficients (nineteenth round, `--anisotropy-pressure bounded`) from the same synthetic tests,
// with an excess that the gate 1 - (q/p)^2 shapes (a_A = 0.1, beta_p = 5: q up to 0.69 of p at 1e-3, 0.16 at 1e-2):
// every coefficient within 4 covariance standard errors. (At a_A = 0.3, q up to 0.9 of p, the fit from the same start
// ends in a local minimum, chi2/dof 88 against the truth's 1.39: docs/model.md, "A bounded excess".)
TEST(ModelVolumeState, RecoversTheBoundedExcessFromDrainedTriaxialTests) {
  Parameters P = volume_truth();
  P.ext[kLambdaCs] = 0.0; P.ext[kCCs] = 1.6;
  P.shear[kAnisoA] = 0.1;
  P.shear[kLnBetaPA] = std::log(5.0);
  P.excess_relaxes = true;
  P.excess_bounded = true;
  recover_volume_state(P, true);
}

// The twelfth round's peak exponent at pressure, n_peak (p*/1e-3)^m_peak: from three start pressures (1e-3, 1e-2,
// 5e-2, as data/geotech's) it is resolved and recovered with the rest; from two it is held at its start (above).
TEST(ModelVolumeState, RecoversThePeakExponentsPressureDependenceFromThreePressures) {
  Parameters P = volume_truth();
  P.ext[kLambdaCs] = 0.0; P.ext[kCCs] = 1.6;
  P.ext[kMPeak] = 0.2;   // the peak's exponent 2.2 times larger at 5e-2 than at 1e-3
  EXPECT_NEAR(peak_exponent(P.ext, 5e-2), P.ext[kNB] * std::pow(50.0, 0.2), 1e-12);
  EXPECT_EQ(peak_exponent(P.ext, kPCsRef), P.ext[kNB]);
  recover_volume_state(P, true, {1e-3, 1e-2, 5e-2});
}

// The eighteenth round's relaxing anisotropic pressure (`--anisotropy-pressure relaxing`): with a_A F large against the
// dilatancy, constant-p compression (b = 0) and the same at b = 1/2 (the fabric at D2's limit) end on the
// critical-state line (psi = 0, s on the Lode surface) from dense and loose starts, with the excess q = p - p_iso(nu_el)
// at its steady value a_A B F / beta_p (the fixed point of dq = A sigma - beta_p q, B and F at the end state). Along the
// path q, read from p and nu_el through the isotropic law, follows dq/d eps = A - beta_p q (central differences).
// With the permanent pressure of the tenth to seventeenth rounds the same material does not reach psi = 0: a constant-p
// path is steady only where the dilatancy cancels a_A F (docs/model.md, "Why a constant-p path can run away").
TEST(ModelVolumeState, ARelaxingAnisotropicPressureEndsOnTheCriticalStateLine) {
  Parameters P = volume_truth();
  P.shear[kAnisoA] = 0.3;
  P.shear[kLnBetaPA] = std::log(5.0);
  const auto iso = P.iso();
  const double p0 = 1e-3, h = 0.002;
  Rows r = rows_of(3.0, 3.0, h, true);
  const double nu_line = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef);
  for (double b : {0.0, 0.5}) {
    const double s_cs = lode_limit(P.shear[kSmaxA], b, Surface::LadeDuncan);
    for (bool relaxes : {true, false}) {
      P.excess_relaxes = relaxes;
      for (double psi0 : {0.06, -0.01}) {
        SCOPED_TRACE("b " + std::to_string(b) + (relaxes ? " relaxing" : " permanent") + " psi0 " + std::to_string(psi0));
        const auto st = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu_line + psi0, p0, 0.0, 0.0, r.acc, r.dir,
                                               r.isob, 1e-3, volume_ext(P, b));
        const State<double>& e = st.back().state;
        const double psi_end = state_psi(P.ext, std::exp(e.ln_nu), e.p);
        if (!relaxes) {
          EXPECT_LT(psi_end, -0.005) << "the permanent pressure: steady loose of the line, where the contracting "
                                        "dilatancy d_D (r - e^{-n_d psi}) cancels a_A F";
          continue;
        }
        EXPECT_NEAR(psi_end, 0.0, 1e-4);
        EXPECT_NEAR(e.s, s_cs, 1e-3 * s_cs);
        EXPECT_NEAR(e.p, p0, 1e-12) << "p held";
        auto excess_at = [&](const State<double>& y) { return y.p - isotropic_pressure(iso.data(), std::exp(y.ln_nu + y.e_pl)); };
        auto A_at = [&](const State<double>& y) {
          const double nu_el = std::exp(y.ln_nu + y.e_pl);
          const double psi = state_psi(P.ext, std::exp(y.ln_nu), y.p);
          return (P.shear[kAnisoA] + P.shear[kAnisoB] * psi) * bulk_modulus(iso.data(), nu_el) * y.F;
        };
        EXPECT_NEAR(excess_at(e), A_at(e) / 5.0, 1e-3 * A_at(e) / 5.0) << "q = a_A B F / beta_p";
        EXPECT_GT(excess_at(e), 0.02 * p0) << "an excess that acts";
        for (std::size_t i : {10, 50, 200}) {
          const double dq = (excess_at(st[i + 1].state) - excess_at(st[i - 1].state)) / (2 * h);
          EXPECT_NEAR(dq, A_at(st[i].state) - 5.0 * excess_at(st[i].state), 2e-3 * std::fabs(A_at(st[i].state))) << "row " << i;
        }
      }
    }
  }
}

// The relaxing excess moves the elastic state to p - q, below the path's own pressure (nineteenth round): a drained
// compression from p* = 1e-3 whose pressure stays above the isotropic law's cusp (volume_truth's nu_cC above nu_c:
// p*(nu_cC) = 9.8e-4) crosses it in its elastic state, and cusp_crossed names it, where the permanent law's elastic
// state (at p itself) does not. predict_path's p_el is p - q: on the isotropic law at p with the permanent law; with the
// relaxing one q = p - p_el ends at its steady value a_A B F/beta_p. Near jamming B/p is large (here ~200), so a_A =
// 0.05 already makes q 53 % of p, and a_A = 0.1 more than p (largest_excess_ratio > 1): the elastic state below the
// jamming fraction, p_iso(nu_el) < 0, which dem model names.
TEST(ModelVolumeState, TheRelaxingExcessMeetsACuspBelowThePathsPressureAndCanExceedIt) {
  Parameters P = volume_truth();
  P.shear[kAnisoA] = 0.05;   // q ends at 53 % of p (at a_A = 0.1 above p: the elastic state below jamming)
  P.shear[kLnBetaPA] = std::log(5.0);
  const auto iso = P.iso();
  const double p_cusp = cusp_pressure(iso.data());
  ASSERT_NEAR(p_cusp, 9.8e-4, 1e-5);
  ASSERT_NEAR(isotropic_pressure(iso.data(), P.nu_cC), p_cusp, 1e-12) << "the law's pressure at nu_cC";
  const Rows r = triaxial_rows(2.4);
  const double p0 = 1e-3, nu0 = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) - 0.01;
  std::mt19937_64 rng(3);
  for (bool relaxes : {false, true}) {
    SCOPED_TRACE(relaxes ? "relaxing" : "permanent");
    P.excess_relaxes = relaxes;
    const PathData d = synthetic_path(P, "TC_s3_synthetic", nu0, r, 4, 0.0, rng, p0, volume_ext(P, 0.0));
    const PathPrediction m = predict_path(P, d, 1e-3);
    ASSERT_EQ(m.p_el.size(), m.p.size());
    EXPECT_EQ(m.excess_relaxes, relaxes);
    EXPECT_GT(*std::min_element(m.p.begin(), m.p.end()), p_cusp) << "the path's own pressure stays above the cusp";
    const double p_el_min = *std::min_element(m.p_el.begin(), m.p_el.end());
    if (!relaxes) {
      for (std::size_t i = 0; i < m.p.size(); ++i)   // to the steps near the cusp (3.5e-6 from row 1 on)
        EXPECT_NEAR(m.p_el[i], m.p[i], 1e-5 * m.p[i]) << "row " << i;
      EXPECT_TRUE(std::isnan(cusp_crossed(P, m)));
      continue;
    }
    EXPECT_LT(p_el_min, p_cusp) << "the elastic state at p - q goes below it";
    EXPECT_GT(p_el_min, 0.0) << "and stays jammed";
    EXPECT_EQ(cusp_crossed(P, m), p_cusp);
    const std::size_t e = m.p.size() - 1;
    const double nu_el = isotropic_volume<double>(iso.data(), m.p_el[e]);
    const double A = P.shear[kAnisoA] * bulk_modulus(iso.data(), nu_el) * m.F[e];
    EXPECT_NEAR(m.p[e] - m.p_el[e], A / 5.0, 1e-2 * A / 5.0) << "q = a_A B F / beta_p at the end";
    Parameters Q = P;
    Q.nu_cC = Q.nu_c;   // one jamming fraction: no cusp to meet
    EXPECT_TRUE(std::isnan(cusp_crossed(Q, predict_path(Q, d, 1e-3))));
    double at = -1;
    EXPECT_NEAR(largest_excess_ratio(m, &at), 1 - p_el_min / m.p[e], 0.02) << "q/p largest at the end, 53 %";
    EXPECT_LT(largest_excess_ratio(m), 1.0);
    EXPECT_EQ(at, m.acc[e]);
    Q = P;
    Q.shear[kAnisoA] = 0.1;   // twice the anisotropy: q above p, the elastic state below jamming
    const PathPrediction big = predict_path(Q, d, 1e-3);
    EXPECT_GT(largest_excess_ratio(big), 1.0);
    EXPECT_LT(*std::min_element(big.p_el.begin(), big.p_el.end()), 0.0) << "p_iso(nu_el) < 0: below jamming";
  }
  P.excess_relaxes = false;
  EXPECT_EQ(largest_excess_ratio(predict_path(P, synthetic_path(P, "TC_s3_synthetic", nu0, r, 4, 0.0, rng, p0, volume_ext(P, 0.0)), 1e-3)), 0.0)
      << "none with the permanent law";
}

// The bounded excess (nineteenth round, `--anisotropy-pressure bounded`): dq = A sigma (1 - (q/p)^2) - beta_p q. At
// constant p from dense and loose starts, where the relaxing excess ends above p (a_A = 0.3, beta_p = 5: the elastic
// state below jamming), the bounded one stays below p on every row, the path still ends on the critical-state line
// (psi = 0, s on the Lode surface), and q ends at the root of A (1 - (q/p)^2) = beta_p q (B and F at the end state).
// With an excess small against p (a_A = 0.002) the two laws end within 1e-4 of each other in s and 1e-6 in nu.
TEST(ModelVolumeState, ABoundedExcessStaysBelowThePressureAndEndsOnTheLine) {
  Parameters P = volume_truth();
  P.shear[kLnBetaPA] = std::log(5.0);
  P.excess_relaxes = true;
  const auto iso = P.iso();
  const double p0 = 1e-3;
  const Rows r = rows_of(3.0, 3.0, 0.004, true);
  const double nu_line = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef);
  const double s_cs = lode_limit(P.shear[kSmaxA], 0.0, Surface::LadeDuncan);
  auto run = [&](const Parameters& Q, double psi0) {
    return integrate_rows<double>(iso.data(), Q.shear, Q.nu_ref, nu_line + psi0, p0, 0.0, 0.0, r.acc, r.dir, r.isob,
                                  1e-3, volume_ext(Q, 0.0));
  };
  auto q_of = [&](const State<double>& y) { return y.p - isotropic_pressure(iso.data(), std::exp(y.ln_nu + y.e_pl)); };
  for (double psi0 : {0.06, -0.01}) {
    SCOPED_TRACE("psi0 " + std::to_string(psi0));
    P.shear[kAnisoA] = 0.3;
    P.excess_bounded = false;
    const State<double> relaxed = run(P, psi0).back().state;
    EXPECT_GT(q_of(relaxed), relaxed.p) << "the relaxing excess above p";
    P.excess_bounded = true;
    const auto st = run(P, psi0);
    for (std::size_t i = 0; i < st.size(); ++i) {
      EXPECT_LT(q_of(st[i].state), st[i].state.p) << "row " << i;
      EXPECT_GT(q_of(st[i].state), -st[i].state.p) << "row " << i;
    }
    const State<double>& e = st.back().state;
    EXPECT_NEAR(state_psi(P.ext, std::exp(e.ln_nu), e.p), 0.0, 1e-4);
    EXPECT_NEAR(e.s, s_cs, 1e-3 * s_cs);
    const double nu_el = std::exp(e.ln_nu + e.e_pl), q = q_of(e), x = q / e.p;
    const double A = P.shear[kAnisoA] * bulk_modulus(iso.data(), nu_el) * e.F;
    EXPECT_GT(x, 0.3) << "an excess that acts";
    EXPECT_NEAR(A * (1 - x * x), 5.0 * q, 1e-3 * 5.0 * q) << "the steady root";
    P.shear[kAnisoA] = 0.002;   // q small against p: the gate is 1 to (q/p)^2
    const State<double> small_b = run(P, psi0).back().state;
    P.excess_bounded = false;
    const State<double> small_r = run(P, psi0).back().state;
    EXPECT_LT(std::fabs(q_of(small_r)), 0.05 * small_r.p);
    EXPECT_NEAR(small_b.s, small_r.s, 1e-4);
    EXPECT_NEAR(std::exp(small_b.ln_nu), std::exp(small_r.ln_nu), 1e-6);
  }
}


namespace {
// Every coefficient a path's residuals read, as Ceres sees them: the iso block, the shear block, the extension block.
struct Coefficient {
  int block, index;
};

// p, s, F and the volumetric strain on every row of `r` from (nu0, p0), and their derivatives by each coefficient
// through Ceres' jets (one at a time).
template <class T>
std::vector<RowState<T>> rows_with(const Parameters& P, const T* iso, const T* shear, const T* ext, double nu0,
                                   double p0, const Rows& r) {
  Ext<T> e{ext, 0.0, P.surface, P.fabric, false, false, true};
  e.excess_relaxes = P.excess_relaxes;
  e.excess_bounded = P.excess_relaxes && P.excess_bounded;
  return integrate_rows<T>(iso, shear, P.nu_ref, nu0, p0, 0.0, 0.0, r.acc, r.dir, r.isob, 1e-3, e);
}

// A drained triaxial compression (constant side stress), reversed, then sheared at constant pressure and at constant
// volume: every control the laboratory paths use, a reversal included.
Rows mixed_rows() {
  Rows r;
  r.acc = {0.0}; r.dir = {1}; r.isob = {2};
  auto add = [&](int n, double h, int dir, int isob) {
    for (int i = 0; i < n; ++i) { r.acc.push_back(r.acc.back() + h); r.dir.push_back(dir); r.isob.push_back(isob); }
  };
  add(40, 0.01, 1, 2);
  add(20, 0.01, -1, 2);
  add(20, 0.01, 1, 1);
  add(20, 0.01, -1, 0);
  return r;
}
}  // namespace

// The fit's Jacobian is what Ceres' jets give through integrate_rows (isotropic_volume's bisection in double, then
// Newton steps in jets). On a path through every control and a reversal, each coefficient's jet derivative of p, s, F
// and eps_v on every row equals a central difference (step 1e-6 relative), for the permanent, the relaxing and the
// bounded excess, from a dense and a loose start. A derivative lost through a double (a value taken out of a jet) would
// show as a zero or a wrong column here.
TEST(ModelVolumeState, TheFitsDerivativesEqualCentralDifferences) {
  using J = ceres::Jet<double, 1>;
  Parameters P = volume_truth();
  P.shear[kLnBetaPA] = std::log(5.0);
  P.shear[kAnisoA] = 0.05;
  P.nu_cC = P.nu_c;
  const Rows r = mixed_rows();
  const double p0 = 2e-3, nu_line = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef);
  std::vector<Coefficient> cs;
  for (int i : {kP0, kNuC, kGammaP, kC0, kC1, kAlpha}) cs.push_back({0, i});
  for (int i : {kSmaxA, kLnBetaSA, kFmaxA, kLnBetaFA, kAnisoA, kLnBetaPA}) cs.push_back({1, i});
  for (int i : {kNFA, kKappaA, kDilA, kNuCs, kLambdaCs, kNB, kND, kNRate}) cs.push_back({2, i});
  for (int law = 0; law < 3; ++law)
    for (double psi0 : {0.05, -0.01}) {
      P.excess_relaxes = law > 0;
      P.excess_bounded = law == 2;
      for (const Coefficient& c : cs) {
        if (law == 0 && c.block == 1 && c.index == kLnBetaPA) continue;   // not read by the permanent law (held)
        SCOPED_TRACE("law " + std::to_string(law) + ", psi0 " + std::to_string(psi0) + ", block " +
                     std::to_string(c.block) + " entry " + std::to_string(c.index));
        std::vector<double> v[3] = {P.iso(), std::vector<double>(P.shear, P.shear + kNumShear),
                                    std::vector<double>(P.ext, P.ext + kNumExt)};
        std::vector<J> j[3];
        for (int b = 0; b < 3; ++b) for (double x : v[b]) j[b].push_back(J(x));
        j[c.block][c.index].v[0] = 1.0;
        const auto jet = rows_with<J>(P, j[0].data(), j[1].data(), j[2].data(), nu_line + psi0, p0, r);
        const double x = v[c.block][c.index];
        auto moved = [&](double by) {
          v[c.block][c.index] = x + by;
          return rows_with<double>(P, v[0].data(), v[1].data(), v[2].data(), nu_line + psi0, p0, r);
        };
        auto values = [](const RowState<double>& y) {
          return std::array<double, 4>{y.state.p, y.state.s, y.state.F, y.eps_vol};
        };
        auto slopes = [](const RowState<J>& y) {
          return std::array<double, 4>{y.state.p.v[0], y.state.s.v[0], y.state.F.v[0], y.eps_vol.v[0]};
        };
        // Each quantity's scale: its largest derivative on the path, at least what moves it by 1e-7 of its size per
        // unit relative change of the coefficient (below that a difference is rounding).
        const auto at = moved(0.0);
        double scale[4] = {0, 0, 0, 0};
        for (std::size_t i = 0; i < r.acc.size(); ++i)
          for (int k = 0; k < 4; ++k)
            scale[k] = std::max({scale[k], std::fabs(slopes(jet[i])[k]),
                                 1e-7 * std::fabs(values(at[i])[k]) / std::max(std::fabs(x), 1e-2)});
        // The error on each row and quantity: the central difference's at the step that agrees best. The laws have
        // kinks (the floors of the mobilisation and of the opened fraction): a step across one differences two
        // branches, a smaller one does not; a rounding-dominated small step is backed by a larger one.
        std::vector<std::array<double, 4>> err(r.acc.size(), {1e300, 1e300, 1e300, 1e300});
        for (double rel : {1e-5, 1e-6, 1e-7}) {
          const double h = rel * std::max(std::fabs(x), 1e-2);
          const auto up = moved(h), dn = moved(-h);
          for (std::size_t i = 0; i < r.acc.size(); ++i)
            for (int k = 0; k < 4; ++k) {
              const double fd = (values(up[i])[k] - values(dn[i])[k]) / (2 * h);
              err[i][k] = std::min(err[i][k], std::fabs(slopes(jet[i])[k] - fd) / scale[k]);
            }
        }
        v[c.block][c.index] = x;
        double worst = 0;
        for (const auto& e : err) worst = std::max({worst, e[0], e[1], e[2], e[3]});
        EXPECT_LT(worst, 1e-3);
      }
    }
}

namespace {
// A state of the volume-form material at pressure p, psi above the critical-state line, its elastic volume fraction on
// the isotropic law at p (start_state's e_pl).
State<double> volume_state(const Parameters& P, double p, double psi, double s, double F) {
  const auto iso = P.iso();
  const double nu = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p / kPCsRef) + P.ext[kCCs] * (p - kPCsRef) + psi;
  State<double> y{std::log(nu), p, s, F};
  y.e_pl = std::log(isotropic_volume<double>(iso.data(), p) / nu);
  return y;
}
}  // namespace

// The drained triaxial control solves (B - A/3) (d eps_vol - dil) = ... for the volume change (rhs): where the
// anisotropy modulus A = a_A B F reaches 3B the volume change per unit shear has a pole and no constant side stress can
// be held (the nineteenth round's failed mu = 0.1 three-pressure bounded refit stepped into it: Ceres' "Residual and
// Jacobian evaluation failed"). At one state, varied in a_A alone: the volume rate is dil + (n0 + n1 a_A)/(B (1 - a_A
// F/3)) (three values fix dil, n0, n1; a fourth at 1 - a_A F/3 = 0.11 follows to 1e-9); the state is lost (NaN,
// State::lost) from 1 - a_A F/3 = kTriaxialMargin on and not before, never at constant volume. A drained compression
// whose fabric grows towards the pole is lost there (its rows before finite, the last one past a_A F/3 = 0.8), and
// predict_path names the row; the same data predicted with a small a_A are not lost.
TEST(ModelVolumeState, TheDrainedTriaxialControlIsLostAtThePoleWhereAEqualsThreeB) {
  Parameters P = volume_truth();
  P.nu_cC = P.nu_c;
  const auto iso = P.iso();
  const double p0 = 1e-3, F = 0.2;
  const State<double> y = volume_state(P, p0, 0.02, 0.3, F);
  Segment tri;
  tri.control = Control::Triaxial;
  auto rate = [&](double x, const Segment& seg) {   // x = a_A F/3
    Parameters Q = P;
    Q.shear[kAnisoA] = 3 * x / F;
    const Material<double> m = start_material(iso.data(), Q.shear, Q.nu_ref, std::exp(y.ln_nu), p0, volume_ext(Q, 0.0));
    return rhs(m, y, 1.0, seg);
  };
  const double x[4] = {0.2, 0.4, 0.6, 0.89};
  double dvol[4];
  for (int i = 0; i < 4; ++i) {
    const State<double> d = rate(x[i], tri);
    ASSERT_FALSE(d.lost);
    dvol[i] = -d.ln_nu;
  }
  // dvol = dil + (n0 + n1 a)/(B (1 - x)), a = 3x/F: (dvol - dil)(1 - x) linear in x; solve from the first three
  const double B = bulk_modulus(iso.data(), std::exp(y.ln_nu + y.e_pl));
  auto g = [&](int i, double dil) { return (dvol[i] - dil) * (1 - x[i]) * B; };
  // linear in x through points 0, 1 and 2: the dil that makes the three collinear (g is affine in dil)
  auto bend = [&](double dil) {
    return (g(2, dil) - g(0, dil)) / (x[2] - x[0]) - (g(1, dil) - g(0, dil)) / (x[1] - x[0]);
  };
  const double dil = -bend(0.0) / (bend(1.0) - bend(0.0));
  const double slope = (g(1, dil) - g(0, dil)) / (x[1] - x[0]);
  const double predicted = dil + (g(0, dil) + slope * (x[3] - x[0])) / (B * (1 - x[3]));
  EXPECT_NEAR(dvol[3], predicted, 1e-9 * std::fabs(dvol[3])) << "the pole at a_A F = 3";
  EXPECT_FALSE(rate(1 - 1.01 * kTriaxialMargin, tri).lost);
  for (double at : {1 - 0.99 * kTriaxialMargin, 1.0, 1.5}) {
    const State<double> d = rate(at, tri);
    EXPECT_TRUE(d.lost) << at;
    EXPECT_TRUE(std::isnan(d.p) && std::isnan(d.ln_nu) && std::isnan(d.s)) << at;
    EXPECT_FALSE(rate(at, Segment{}).lost) << "constant volume: no control to lose";
  }

  // A path: drained compression with the bounded excess at beta_p = 300 (q near its steady value, so that the volume
  // rate's numerator stays small and the pole is approached, not jumped at), a_A F/3 = 1 at F = 0.2 < F_max.
  P.excess_relaxes = P.excess_bounded = true;
  P.shear[kLnBetaPA] = std::log(300.0);
  P.shear[kAnisoA] = 3 / F;
  const Rows tc = triaxial_rows(0.3);
  const double nu0 = std::exp(y.ln_nu);
  const auto st = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, 0.0, 0.02, tc.acc, tc.dir, tc.isob,
                                         1e-3, volume_ext(P, 0.0));
  std::size_t lost = 0;
  while (lost < st.size() && !st[lost].state.lost) ++lost;
  ASSERT_LT(lost, st.size()) << "the path reaches the pole";
  ASSERT_GT(lost, 2u);
  for (std::size_t i = 0; i < lost; ++i) {
    EXPECT_TRUE(std::isfinite(st[i].state.p) && std::isfinite(st[i].eps_vol)) << "row " << i;
    EXPECT_LT(P.shear[kAnisoA] * st[i].state.F / 3, 1 - kTriaxialMargin) << "row " << i;
  }
  for (std::size_t i = lost; i < st.size(); ++i) EXPECT_TRUE(st[i].state.lost && std::isnan(st[i].state.p)) << i;
  EXPECT_GT(P.shear[kAnisoA] * st[lost - 1].state.F / 3, 0.8) << "lost next to the pole, not elsewhere";
  std::mt19937_64 rng(5);
  Parameters Q = P;
  Q.shear[kAnisoA] = 1.0;   // data the pole never reaches, predicted with the material that reaches it
  const PathData d = synthetic_path(Q, "TC_s3_synthetic", nu0, tc, 4, 0.0, rng, p0, volume_ext(Q, 0.0));
  const PathPrediction far = predict_path(Q, d, 1e-3), near = predict_path(P, d, 1e-3);
  EXPECT_EQ(far.lost_row, -1);
  EXPECT_EQ(near.lost_row, static_cast<int>(lost));
  EXPECT_TRUE(std::isnan(near.p.back()));
}

// The elastic split (eleventh round): with the volume-form state parameter the plastic dilatancy moves the volume and
// not the stress. Under drained control (isobaric, constant side stress) the stress increments are those of the
// material without dilatancy (d_D = 0) and only the volume differs, by the plastic rate d_D (r - e^{-n_d psi}); the
// side stress stays held. Before this, -(A - sB)/p dvol fed the dilatancy back into s (the runaway of TE_s3).
TEST(ModelVolumeState, PlasticDilatancyMovesTheVolumeNotTheStress) {
  Parameters P = volume_truth();
  P.shear[kAnisoA] = 0.3;   // an anisotropy modulus that acts
  Parameters Q = P;
  Q.ext[kDilA] = 0.0;
  const auto iso = P.iso();
  for (double b : {0.0, 1.0}) {
    const double sigma = b == 0.0 ? 1.0 : -1.0;   // compression, extension
    const Material<double> m = start_material<double>(iso.data(), P.shear, P.nu_ref, 0.64, 2e-3, volume_ext(P, b));
    const Material<double> m0 = start_material<double>(iso.data(), Q.shear, Q.nu_ref, 0.64, 2e-3, volume_ext(Q, b));
    const State<double> y = volume_state(P, 2e-3, 0.03, 0.6 * sigma, 0.1 * sigma);
    const double s_lim = lode_limit(P.shear[kSmaxA], b, Surface::LadeDuncan);
    const double psi = state_psi(P.ext, std::exp(y.ln_nu), y.p);
    const double dil = P.ext[kDilA] * (0.6 / s_lim - std::exp(-P.ext[kND] * psi));
    for (Control c : {Control::Isobaric, Control::Triaxial}) {
      const Segment seg = shear_seg(0.1, 1, c);
      const State<double> d = rhs(m, y, sigma, seg), d0 = rhs(m0, y, sigma, seg);
      EXPECT_NEAR(d.s, d0.s, 1e-12 * std::fabs(d0.s)) << "b " << b;
      EXPECT_NEAR(d.p, d0.p, 1e-12 * std::fabs(d0.p) + 1e-15) << "b " << b;
      EXPECT_NEAR(d0.ln_nu - d.ln_nu, dil, 1e-12) << "the plastic rate, b " << b;
      if (c == Control::Triaxial)   // (1 - s/3) dp - (p/3) ds = 0: the side stress held
        EXPECT_NEAR((1 - y.s / 3) * d.p - y.p / 3 * d.s, 0.0, 1e-12 * std::fabs(y.p * d.s)) << "b " << b;
      else
        EXPECT_NEAR(d.p, 0.0, 1e-15) << "p held";
    }
  }
}

// The rates of the stress ratio and the fabric scale with the elastic stiffness B/p of the isotropic law at the
// pressure to the power n_rate (1: a shear modulus in a fixed ratio to the bulk modulus; 0: unscaled), 1 at p* =
// kPCsRef: on the critical-state line (the psi-laws the same) from s = F = 0 at constant volume, ds and dF at p and at
// kPCsRef stand in the ratio ((B/p)/(B/p)_ref)^n_rate.
TEST(ModelVolumeState, RatesScaleWithTheElasticStiffness) {
  Parameters P = volume_truth();
  P.ext[kNFA] = 0.0;   // the fabric's gate r_F^0 = 1 at every overlap
  const auto iso = P.iso();
  auto rates = [&](double p, double n_rate) {
    Parameters Q = P;
    Q.ext[kNRate] = n_rate;
    const Material<double> m = start_material<double>(iso.data(), Q.shear, Q.nu_ref, 0.64, p, volume_ext(Q, kLodeBD2));
    return rhs(m, volume_state(Q, p, 0.0, 0.0, 0.0), 1.0, Segment{});
  };
  auto stiffness = [&](double p) { return bulk_modulus(iso.data(), isotropic_volume<double>(iso.data(), p)) / p; };
  const double shape = 1 + P.ext[kKappaA] * 1e-6;   // r at its floor
  for (double n_rate : {1.0, 0.7, 0.0}) {
    SCOPED_TRACE(n_rate);
    const State<double> ref = rates(kPCsRef, n_rate);
    EXPECT_NEAR(ref.s, std::exp(P.shear[kLnBetaSA]) * P.shear[kSmaxA] * shape, 1e-9) << "unscaled at kPCsRef";
    for (double p : {1e-4, 1e-2, 5e-2}) {
      const State<double> d = rates(p, n_rate);
      const double want = std::pow(stiffness(p) / stiffness(kPCsRef), n_rate);
      EXPECT_NEAR(d.s / ref.s, want, 1e-9 * want) << "p " << p;
      EXPECT_NEAR(d.F / ref.F, want, 1e-9 * want) << "p " << p;
    }
  }
  EXPECT_LT(stiffness(5e-2), 0.5 * stiffness(kPCsRef)) << "a test that could fail: the stiffness ratio moves";
  EXPECT_EQ(Parameters{}.ext[kNRate], 1.0) << "files and starts without n_rate: the eleventh round's scaling";
}

// The stress ratio's shape 1 + kappa_s r is floored at kShapeFloor with the volume-form state parameter: a kappa_s
// below -1/r (a psi-law extrapolated) gives the rates of the shape at the floor, not a negative shape that drives s
// away from its target (the loose calibration's constant-p runaway of the eleventh round, docs/model.md).
TEST(ModelVolumeState, TheStressRatioShapeStaysPositive) {
  Parameters P = volume_truth();
  P.ext[kKappaB] = 0.0;   // kappa_s = kappa_s_a at every state
  const auto iso = P.iso();
  const double s = 0.6, r = s / lode_limit(P.shear[kSmaxA], 0.0, Surface::LadeDuncan);
  auto rates = [&](double kappa, Control c) {
    Parameters Q = P;
    Q.ext[kKappaA] = kappa;
    const Material<double> m = start_material<double>(iso.data(), Q.shear, Q.nu_ref, 0.64, 2e-3, volume_ext(Q, 0.0));
    return rhs(m, volume_state(Q, 2e-3, -0.002, s, 0.1), 1.0, shear_seg(0.1, 1, c));
  };
  const double at_floor = (kShapeFloor - 1.0) / r, below = -3.0;
  ASSERT_LT(1.0 + below * r, 0.0) << "a shape that would be negative";
  for (Control c : {Control::Isobaric, Control::Triaxial}) {
    const State<double> d = rates(below, c), f = rates(at_floor, c), up = rates(0.5 * at_floor, c);
    EXPECT_NEAR(d.s, f.s, 1e-12 * std::fabs(f.s)) << "the shape at its floor";
    EXPECT_NEAR(d.ln_nu, f.ln_nu, 1e-12 * std::fabs(f.ln_nu) + 1e-15);
    EXPECT_GT(std::fabs(up.s - f.s), 1e-6 * std::fabs(f.s)) << "a test that could fail: kappa_s acts above the floor";
  }
}

// Above its target a stress ratio relaxes at least as fast as at the target (fourteenth round): with the volume-form
// state parameter the shape 1 + kappa_s r is read at most at the target's mobilisation r_t when kappa_s < 0, then
// floored. On the critical-state line at kPCsRef (the laws at their a values, the rate scale 1, b = b_ref so s_lim =
// s_max) with the peak's exponent off (r_t = 1), ds(kappa) - ds(0) = beta_s (s_max - s) (shape - 1) exactly at
// constant volume (the volumetric term does not read kappa_s): written out here for r = 1.3 and r = 0.6.
TEST(ModelVolumeState, AStressRatioAboveItsTargetRelaxesAtLeastAsFastAsAtIt) {
  Parameters P = volume_truth();
  P.ext[kNB] = 0.0;   // s_target = s_lim: r_t = 1
  const auto iso = P.iso();
  const double s_max = P.shear[kSmaxA], beta = std::exp(P.shear[kLnBetaSA]);
  auto ds = [&](double kappa, double r) {
    Parameters Q = P;
    Q.ext[kKappaA] = kappa;
    const Material<double> m =
        start_material<double>(iso.data(), Q.shear, Q.nu_ref, 0.64, kPCsRef, volume_ext(Q, kLodeBD2));
    return rhs(m, volume_state(Q, kPCsRef, 0.0, r * s_max, 0.05), 1.0, Segment{}).s;
  };
  struct Case { double kappa, r, shape; const char* what; };
  const Case cases[] = {
      {-0.5, 1.3, 0.5, "above the target: the shape at r_t (unbounded 0.35)"},
      {-0.9, 1.3, 1.0 - 0.9, "above: at r_t (unbounded -0.17, the floor's 0.05 before this round)"},
      {-1.2, 1.3, kShapeFloor, "above: the shape at r_t negative, floored"},
      {0.5, 1.3, 1.0 + 0.5 * 1.3, "kappa_s > 0: faster above the target already, unchanged"},
      {-0.5, 0.6, 1.0 - 0.5 * 0.6, "below the target: 1 + kappa_s r"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const double want = beta * (s_max - c.r * s_max) * (c.shape - 1.0);
    EXPECT_NEAR(ds(c.kappa, c.r) - ds(0.0, c.r), want, 1e-9 * std::fabs(want));
  }
  EXPECT_LT(ds(-0.9, 1.3), 0.0) << "above the target s falls";
  EXPECT_EQ(stress_shape(-0.9, 1.3, 1.0, false), 1.0 - 0.9 * 1.3) << "without the volume form: unbounded";
}

// The range of psi the laws are read in (thirteenth round): psi_range is [-R, R], R the largest |psi| of the model's
// own states along the calibration paths (at least that of the rows, computed here from predict_path and state_psi;
// RK4's stages between them reach 1e-4 further at most); those paths predicted with the range are the unclamped ones
// to the last bit; and a state beyond R reads every law of psi at R: a dense path
// (psi >= R throughout) predicted with the range equals, to rounding, the unclamped prediction of a model whose laws
// are constants equal to their values at psi = R (the peak's exponent off in both; the dilatancy reads psi itself).
TEST(ModelVolumeState, PsiRangeHoldsTheLawsAtTheCalibrationsReach) {
  Parameters P = volume_truth();
  P.shear[kSmaxB] = 2.0;
  P.ext[kNFB] = -10.0;   // n_F > -1 on every path here (-30, before the graded start, made it -2.6 at psi = 0.12)
  P.ext[kKappaB] = 5.0; P.ext[kDilB] = -2.0;
  P.ext[kNB] = 0.0;
  const auto iso = P.iso();
  const Rows r = triaxial_rows(0.6);
  std::mt19937_64 rng(7);
  std::vector<PathData> cal;
  for (double p0 : {1e-3, 1e-2}) {
    const double nu = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) + 0.03;
    cal.push_back(synthetic_path(P, "TC_s3_dense", nu, r, 4, 0.5, rng, p0, volume_ext(P, 0.0)));
  }
  double R = 0;
  for (const auto& d : cal) {
    const PathPrediction m = predict_path(P, d);
    for (std::size_t i = 0; i < m.nu.size(); ++i) R = std::max(R, std::fabs(state_psi(P.ext, m.nu[i], m.p[i])));
  }
  const auto range = psi_range(P, {}, cal);
  EXPECT_EQ(range.first, -range.second);
  EXPECT_GE(range.second, R);
  EXPECT_LT(range.second, R + 1e-4);
  EXPECT_GT(R, 0.02);
  R = range.second;
  Parameters C = P;
  C.psi_lo = range.first;
  C.psi_hi = range.second;
  for (const auto& d : cal) {
    const PathPrediction a = predict_path(P, d), b = predict_path(C, d);
    for (std::size_t i = 0; i < a.s.size(); ++i) {
      EXPECT_EQ(a.s[i], b.s[i]) << i;
      EXPECT_EQ(a.p[i], b.p[i]) << i;
      EXPECT_EQ(a.F[i], b.F[i]) << i;
      EXPECT_EQ(a.ev[i], b.ev[i]) << i;
    }
  }
  // beyond the reach: a start 0.12 denser than the line, 0.02 of strain
  const Rows shortr = triaxial_rows(0.02);
  PathData dense = synthetic_path(P, "TC_s3_dense", P.ext[kNuCs] + 0.12, shortr, 4, 0.5, rng, 1e-3, volume_ext(P, 0.0));
  Parameters Q = P;   // every law of psi a constant at psi = R
  for (int i = 0; i + 1 < kNumShear; i += 2) { Q.shear[i] = P.shear[i] + P.shear[i + 1] * R; Q.shear[i + 1] = 0.0; }
  for (int i : {kNFA, kKappaA, kDilA}) { Q.ext[i] = P.ext[i] + P.ext[i + 1] * R; Q.ext[i + 1] = 0.0; }
  const PathPrediction clamped = predict_path(C, dense), constant = predict_path(Q, dense), free = predict_path(P, dense);
  for (std::size_t i = 0; i < clamped.nu.size(); ++i)
    ASSERT_GT(state_psi(P.ext, clamped.nu[i], clamped.p[i]), R) << "the path stays beyond the reach, row " << i;
  for (std::size_t i = 1; i < clamped.s.size(); ++i) {
    EXPECT_NEAR(clamped.s[i], constant.s[i], 1e-9 * std::fabs(constant.s[i]) + 1e-12) << i;
    EXPECT_NEAR(clamped.p[i], constant.p[i], 1e-9 * constant.p[i]) << i;
    EXPECT_NEAR(clamped.F[i], constant.F[i], 1e-9 * std::fabs(constant.F[i]) + 1e-12) << i;
  }
  EXPECT_GT(std::fabs(free.s.back() - clamped.s.back()), 1e-3) << "unclamped, the laws at psi = 0.1 differ";
}

// The isotropic law's cusp (sixteenth round; docs/model.md, "The isotropic law's cusp"): where the coordination law's
// jamming fraction nu_cC lies above the pressure's nu_c, the stiffness B = dp*/d ln nu is unbounded at p*(nu_cC) (the
// coordination's slope (nu/nu_cC - 1)^(alpha - 1) times a pressure factor that is not zero there), and the volume-form
// state parameter takes the elastic state along the law with p*. A dense drained path that falls back through that
// pressure after its peak (an anisotropy modulus a_A = 0.3 couples the stress ratio to B) then ends where the steps
// put it: the same path with rows every 1e-3 and every 1e-5 ends 0.01 or more apart in s. With nu_c moved up to nu_cC
// (no cusp) the two agree to 1e-7.
TEST(ModelVolumeState, APathThroughTheIsotropicCuspEndsWhereItsStepsPutIt) {
  Parameters P = volume_truth();
  P.shear[kAnisoA] = 0.3;
  ASSERT_GT(P.nu_cC, P.nu_c);
  const double p0 = 6e-4, nu0 = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) + 0.06;
  auto end_s = [&](const Parameters& Q, double h) {
    const auto iso = Q.iso();
    const Rows r = rows_of(0.3, 0.3, h, false);
    std::vector<int> isob(r.acc.size(), 2);
    const auto st = integrate_rows<double>(iso.data(), Q.shear, Q.nu_ref, nu0, p0, 0.0, 0.0, r.acc, r.dir, isob, 5e-4,
                                           volume_ext(Q, 0.0));
    double p_max = 0;
    for (const auto& x : st) p_max = std::max(p_max, x.state.p);
    EXPECT_GT(p_max, isotropic_pressure(Q.iso().data(), P.nu_cC)) << "the path rises through the cusp's pressure";
    return st.back().state.s;
  };
  EXPECT_GT(std::fabs(end_s(P, 1e-3) - end_s(P, 1e-5)), 0.01) << "with the cusp";
  Parameters Q = P;
  Q.nu_c = P.nu_cC;
  EXPECT_NEAR(end_s(Q, 1e-3), end_s(Q, 1e-5), 1e-7) << "without it";
}

namespace {
// Two drained triaxial compressions of P from psi = 0.04 at p* = 1e-3 and 1e-2 (K = 8, seed 5), and 8 points of its
// isotropic branch at nu = 0.68-0.806 scattered by +-0.3 %, alternating.
void drained_pair_and_branch(const Parameters& P, std::vector<PathData>& paths, IsoData& branch) {
  const auto iso = P.iso();
  const Rows r = triaxial_rows(0.6);
  std::mt19937_64 rng(5);
  for (double p0 : {1e-3, 1e-2})
    paths.push_back(synthetic_path(P, "TC_s3_synthetic", P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) + 0.04,
                                   r, 8, 0.0, rng, p0, volume_ext(P, 0.0)));
  for (int i = 0; i < 8; ++i) {
    const double nu = 0.68 + 0.018 * i, f = 1.0 + (i % 2 ? 0.003 : -0.003);
    branch.nu.push_back(nu);
    branch.p.push_back(f * isotropic_pressure(iso.data(), nu));
    branch.C.push_back(f * coordination(iso.data(), nu));
  }
}
}  // namespace

// The calibration keeps the paths off the cusp: with the volume-form state parameter and nu_cC held, nu_c is bounded
// below by it (a start below it is moved onto it, and the truth here, 0.6642 < 0.667, would take it below), and the
// table says that it sits on that bound; with the whole isotropic block held at a law with the cusp, the calibration
// warns, naming the pressure and the fix.
TEST(ModelVolumeState, TheCalibrationKeepsNuCAtOrAboveAHeldNuCC) {
  const Parameters P = volume_truth();
  std::vector<PathData> paths;
  IsoData branch;
  drained_pair_and_branch(P, paths, branch);
  CalibrationOptions o = extended_options(P, FabricLode::Overlap);
  o.state_volume = true;
  o.max_iterations = 20;
  Parameters start = P;
  start.nu_c = 0.660;
  o.start = &start;
  o.fit_isotropic = true;
  o.hold_iso = {kGammaP, kNuCC, kAlpha};
  const Calibration cal = calibrate({}, branch, o, paths);
  EXPECT_EQ(cal.value[kNuCC], P.nu_cC) << "held";
  EXPECT_EQ(cal.value[kNuC], P.nu_cC) << "on it: the data would take it below";
  auto said = [](const Calibration& c, const std::string& what) {
    for (const auto& w : c.warnings) if (w.find(what) != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(said(cal, "nu_c sits on its bound, the held nu_cC")) << "said";
  EXPECT_TRUE(std::isnan(cal.se_cov[kNuC])) << "no error on a bound";
  EXPECT_FALSE(said(cal, "is unbounded at p*"));
  o.fit_isotropic = false;
  o.hold_iso.clear();
  o.max_iterations = 2;
  const Calibration held = calibrate({}, {}, o, paths);
  EXPECT_EQ(held.value[kNuC], start.nu_c);
  EXPECT_TRUE(said(held, "is unbounded at p* = 0.002473")) << "the cusp of the start's law named (p*(0.667) at nu_c 0.660)";
  EXPECT_TRUE(said(held, "--hold-isotropic nu_cC")) << "and the fix";
}

// A coordination law that falls above nu_cC (C1 < 0, as four stored bounded calibrations fitted) makes p_iso rise
// from nu_c to a maximum and fall again before nu = 1. A pressure just above the law's value at 1 was bracketed on
// [nu_c, 1], found p_iso(1) < p and returned 1: a last digit of a coefficient moved a path's elastic start from the
// rising branch to nu = 1 (the stored bounded mu = 1 dense calibration). Now both sides find the rising branch, and a
// pressure above the law's maximum is not a number.
TEST(ModelVolumeState, TheIsotropicVolumeStaysOnTheRisingBranchOfALawThatFallsAgain) {
  const double iso[kNumIso] = {0.04, 0.65, -0.2, 8.4, -10.5, 0.62, 0.56};   // p0 nu_c gamma_p C0 C1 nu_cC alpha
  const double p1 = isotropic_pressure(iso, 1.0);
  double p_max = 0, nu_max = 0;
  for (int i = 1; i <= 100000; ++i) {
    const double nu = 0.65 + 0.35 * i / 100000;
    if (isotropic_pressure(iso, nu) > p_max) { p_max = isotropic_pressure(iso, nu); nu_max = nu; }
  }
  ASSERT_GT(p1, 0.0);
  ASSERT_GT(p_max, 1.5 * p1) << "the law falls again: its maximum inside (nu_c, 1)";
  ASSERT_LT(nu_max, 0.95);
  const double below = isotropic_volume<double>(iso, p1 * (1 - 1e-9));
  const double above = isotropic_volume<double>(iso, p1 * (1 + 1e-9));
  for (double nu : {below, above}) {
    EXPECT_LT(nu, nu_max) << "the rising branch";
    EXPECT_GT(bulk_modulus(iso, nu), 0.0);
  }
  EXPECT_NEAR(isotropic_pressure(iso, above), p1 * (1 + 1e-9), 1e-12 * p1);
  EXPECT_NEAR(above, below, 1e-8) << "no jump across p_iso(1)";
  EXPECT_TRUE(std::isnan(isotropic_volume<double>(iso, 1.01 * p_max))) << "beyond the law's reach";
  const double mono[kNumIso] = {0.04, 0.65, -0.2, 8.4, 10.5, 0.62, 0.56};   // C1 > 0: one root, the plain bisection's
  const double nu = isotropic_volume<double>(mono, 0.01);
  EXPECT_NEAR(isotropic_pressure(mono, nu), 0.01, 1e-15);
}

// isotropic_reach is the pressure up to which isotropic_volume is a number: on the rising law, p_iso(1); on a law that
// falls again, its maximum (found here on a grid 400 times finer than the reach's own).
TEST(ModelVolumeState, TheIsotropicReachIsWhereTheElasticVolumeFractionStops) {
  const double falls[kNumIso] = {0.04, 0.65, -0.2, 8.4, -10.5, 0.62, 0.56};
  const double rises[kNumIso] = {0.04, 0.65, -0.2, 8.4, 10.5, 0.62, 0.56};
  double p_max = 0;
  for (int i = 1; i <= 100000; ++i) p_max = std::max(p_max, isotropic_pressure(falls, 0.65 + 0.35 * i / 100000));
  EXPECT_NEAR(isotropic_reach(falls), p_max, 1e-4 * p_max) << "the maximum inside (nu_c, 1)";
  EXPECT_EQ(isotropic_reach(rises), isotropic_pressure(rises, 1.0)) << "the law's value at nu = 1";
  for (const double* iso : {falls, rises}) {
    const double reach = isotropic_reach(iso);
    EXPECT_TRUE(std::isfinite(isotropic_volume<double>(iso, reach * (1 - 1e-9))));
    EXPECT_TRUE(std::isnan(isotropic_volume<double>(iso, reach * (1 + 1e-6))));
  }
}

// A start whose isotropic law does not reach a path's start pressure (a jackknife refit from an optimum on the reach,
// whose left-out mean starts higher: the joint bounded variant's refits without m001, m002, m004, thirty-third round)
// has no elastic volume fraction there, and Ceres stopped before its first step. With p0 free the calibration raises
// p0 until the law reaches every start pressure, says so, and fits; with the isotropic block held it says why the
// start cannot be evaluated.
TEST(ModelVolumeState, AStartBeyondTheIsotropicLawsReachIsMovedWithinIt) {
  const Parameters P = volume_truth();
  std::vector<PathData> paths;
  IsoData branch;
  drained_pair_and_branch(P, paths, branch);
  const double top = std::max(paths[0].p.front(), paths[1].p.front());
  const auto iso = P.iso();
  Parameters start = P;
  start.p0 = P.p0 * 0.9 * top / isotropic_reach(iso.data());   // its law ends 10 % below the higher start pressure
  ASSERT_LT(isotropic_reach(start.iso().data()), top);
  CalibrationOptions o = extended_options(P, FabricLode::Overlap);
  o.state_volume = true;
  o.max_iterations = 20;
  o.start = &start;
  o.fit_isotropic = true;
  o.hold_iso = {kGammaP, kNuCC, kAlpha};
  auto said = [](const Calibration& c, const std::string& what) {
    for (const auto& w : c.warnings) if (w.find(what) != std::string::npos) return true;
    return false;
  };
  const Calibration cal = calibrate({}, branch, o, paths);
  EXPECT_TRUE(std::isfinite(cal.chi2)) << cal.message;
  EXPECT_GT(cal.message.find("Iterations"), 0u);
  EXPECT_EQ(cal.message.find("FAILURE"), std::string::npos) << cal.message;
  EXPECT_TRUE(said(cal, "p0 raised from")) << "said";
  EXPECT_EQ(cal.start_moved.rfind("p0 raised from ", 0), 0u) << "recorded for jackknife.md: " << cal.start_moved;
  EXPECT_GE(isotropic_reach(cal.params.iso().data()), top) << "the fitted law reaches every start pressure";
  EXPECT_NEAR(cal.value[kP0], P.p0, 0.1 * P.p0) << "the branch takes p0 back towards the truth's";
  o.fit_isotropic = false;
  o.hold_iso.clear();
  o.max_iterations = 2;
  const Calibration held = calibrate({}, {}, o, paths);
  EXPECT_TRUE(std::isnan(held.chi2)) << "the held law cannot be evaluated at the higher start";
  EXPECT_TRUE(said(held, "cannot be evaluated")) << "the cause named";
  EXPECT_EQ(held.value[kP0], start.p0) << "a held p0 is not moved";
  EXPECT_TRUE(held.start_moved.empty());
}

// A jamming fraction's start above the data's lowest volume fraction is moved inside its bound: the pressure law's nu_c
// just inside (a refit from an optimum on the bound restarts where it ended), the coordination law's nu_cC (and a nu_c
// tied to it) 0.005 below, off the cusp; a start already inside is not moved.
TEST(ModelFit, AJammingFractionStartIsMovedJustInsideItsBound) {
  const double numin = 0.603453;   // lab_dense's lowest mean volume fraction without m2 (thirty-fourth round)
  const double full = 0.6035662;   // the full fit's nu_c, on its own bound 0.603567
  EXPECT_EQ(jamming_start_inside(0.59, numin, false), 0.59);
  EXPECT_EQ(jamming_start_inside(0.59, numin, true), 0.59);
  const double moved = jamming_start_inside(full, numin, false);
  EXPECT_LT(moved, numin * (1 - 1e-6)) << "feasible for the bound numin (1 - 1e-6)";
  EXPECT_GT(moved, numin * (1 - 2e-5)) << "just inside, not 0.005 away";
  EXPECT_DOUBLE_EQ(jamming_start_inside(full, numin, true), numin - 0.005);
  EXPECT_EQ(jamming_start_inside(numin * (1 - 1e-6), numin, false), numin * (1 - 1e-6)) << "on the bound: inside";
}

// A start Ceres cannot evaluate names its cause in the message (starts.md's and jackknife.md's column; thirty-fourth
// round: a stored multi-start listed only Ceres' "Residual and Jacobian evaluation failed"). Here a start whose
// anisotropy modulus a_A (30, the truth's 0) blows the first drained path up at every RK4 step down to 1/64 of the
// fixed one: the named path fails where and as predict_path says it does (path_not_a_number's wording; until the
// thirty-sixth round's step control the fixed step's blow-up crossed the pole's margin in an RK4 stage, and the path
// was called lost there), and the truth's own start is not called failed.
TEST(ModelVolumeState, AStartThatCannotBeEvaluatedNamesThePathAndTheCause) {
  const Parameters P = volume_truth();
  std::vector<PathData> paths;
  IsoData branch;
  drained_pair_and_branch(P, paths, branch);
  Parameters start = P;
  start.shear[kAnisoA] = 30.0;   // a_A F/3 reaches 0.9 at F = 0.03, which the first path's fabric passes early
  const PathPrediction lost = predict_path(start, paths[0]);
  const std::string cause = path_not_a_number(lost);
  ASSERT_FALSE(cause.empty()) << "the start does not follow the first path";
  for (double step : {5e-5, 1e-5})   // not the step's failure: finer fixed steps fail there too
    EXPECT_FALSE(path_not_a_number(predict_path(start, paths[0], step)).empty()) << step;
  const std::string where = paths[0].name + " nu=" + demfit::fmt(paths[0].nu, 4);
  EXPECT_EQ(start_failure(start, {}, paths).rfind(where + cause, 0), 0u) << start_failure(start, {}, paths);
  EXPECT_EQ(start_failure(P, {}, paths), "") << "the truth is a number on every path";
  Parameters high = P;   // a law that ends below the paths' start pressures: the reach named instead
  high.p0 = P.p0 * 0.5 * std::min(paths[0].p.front(), paths[1].p.front()) / isotropic_reach(P.iso().data());
  EXPECT_NE(start_failure(high, {}, paths).find(where + " starts at p* = "), std::string::npos);
  EXPECT_NE(start_failure(high, {}, paths).find("above the isotropic law's reach"), std::string::npos);
  CalibrationOptions o = extended_options(P, FabricLode::Overlap);   // the calibration from that start (the critical
  o.state_volume = true;                                             // state moved to the paths' ends: its own cause)
  o.max_iterations = 2;
  o.start = &start;
  const Calibration cal = calibrate({}, {}, o, paths);
  ASSERT_TRUE(std::isnan(cal.chi2)) << cal.message;
  const std::string why = start_failure(cal.params, {}, paths);
  ASSERT_EQ(why.rfind(where, 0), 0u) << why;
  EXPECT_NE(cal.message.find("FAILURE"), std::string::npos);
  EXPECT_EQ(cal.message.substr(cal.message.size() - why.size() - 15), "; at its start " + why) << cal.message;
  bool warned = false;
  for (const auto& w : cal.warnings) warned = warned || w == "the start cannot be evaluated: " + why;
  EXPECT_TRUE(warned);
}

// path_not_a_number (thirty-fifth round: a failed start's message and a held-out path a refit does not follow), on
// predictions built by hand: every row a number says nothing; a row the drained control did not reach names the last
// strain reached and the pole; a row not a number without the control lost names its own strain.
TEST(ModelVolumeState, APathNotANumberIsWordedOnceForBothUses) {
  PathPrediction m;
  m.acc = {0.0, 0.1, 0.2, 0.3};
  m.p = {1, 1, 1, 1};
  m.s = {0, 0.1, 0.2, 0.3};
  m.F = {0, 0.01, 0.02, 0.03};
  EXPECT_EQ(path_not_a_number(m), "");
  m.s[2] = std::nan("");
  EXPECT_EQ(path_not_a_number(m), " is not a number from eps_d_accumulated = 0.2");
  m.lost_row = 2;
  const std::string lost = path_not_a_number(m);
  EXPECT_EQ(lost.rfind(" loses its drained control after eps_d_accumulated = 0.1 (a_A F/3 within ", 0), 0u) << lost;
  EXPECT_NE(lost.find("the pole"), std::string::npos) << lost;
}

// The residual functors keep one Ext<double> of options and bind their Jet block to it (with_block, twenty-ninth
// round): every option, each set away from its default, arrives on the Jet Ext unchanged, and the block is the one
// given (a member with_block forgot would keep its default here; a new member stops the build at its static_assert).
TEST(ModelOptions, WithBlockCarriesEveryOptionOntoAnotherScalar) {
  Ext<double> o{nullptr, 0.25, Surface::MatsuokaNakai, FabricLode::Weighted, true, true, true, 0.4, -0.03, 0.05};
  o.excess_relaxes = o.excess_bounded = o.start_unaligned = o.dilatancy_gated = o.fabric_state = true;
  o.deviator_reference = true;
  double psi[2] = {0, 0};
  o.psi_seen = psi;
  using J = ceres::Jet<double, 2>;
  const J block[3] = {J(1.0, 0), J(2.0, 1), J(3.0)};
  const Ext<J> e = with_block(o, block);
  EXPECT_EQ(e.p, block);
  EXPECT_EQ(e.b, 0.25);
  EXPECT_EQ(e.surface, Surface::MatsuokaNakai);
  EXPECT_EQ(e.fabric, FabricLode::Weighted);
  EXPECT_TRUE(e.state_limit && e.state_lode && e.state_volume);
  EXPECT_EQ(e.b_stress, 0.4);
  EXPECT_EQ(e.psi_lo, -0.03);
  EXPECT_EQ(e.psi_hi, 0.05);
  EXPECT_TRUE(e.excess_relaxes && e.excess_bounded && e.start_unaligned && e.dilatancy_gated && e.fabric_state &&
              e.deviator_reference);
  EXPECT_EQ(e.psi_seen, nullptr);   // a Jet run records no psi range (plain double runs only)
  const Ext<double> none = with_block(Ext<double>{}, static_cast<const double*>(nullptr));
  EXPECT_FALSE(none.state_limit || none.excess_relaxes || none.start_unaligned || none.dilatancy_gated ||
               none.fabric_state || none.deviator_reference);
  EXPECT_EQ(none.surface, Surface::None);
}

// An unaligned start (twenty-eighth round, Ext::start_unaligned): the DEM's s_dev and F_dev are magnitudes of tensors
// whose start part (the random deviator of a finite isotropic packing) is orthogonal to the aligned part the model
// integrates, so a packing shows sqrt(x^2 + x0^2). Closed forms: the sum, its sign, its derivative (a Jet), and x
// itself with no start part.
TEST(ModelUnaligned, ObservedMagnitudeIsTheOrthogonalSum) {
  EXPECT_DOUBLE_EQ(observed(0.4, 0.3, true), 0.5);
  EXPECT_DOUBLE_EQ(observed(-0.4, 0.3, true), -0.5);
  EXPECT_DOUBLE_EQ(observed(0.0, 0.03, true), 0.03);   // the first row: the measured start value
  EXPECT_DOUBLE_EQ(observed(0.4, 0.3, false), 0.4);
  EXPECT_DOUBLE_EQ(observed(-0.4, 0.0, true), -0.4);
  using J = ceres::Jet<double, 1>;
  const J y = observed(J(0.4, 0), 0.3, true);
  EXPECT_DOUBLE_EQ(y.a, 0.5);
  EXPECT_NEAR(y.v[0], 0.4 / 0.5, 1e-15);
}

// Under constant pressure the coupling a_A B F moves the volume at a rate a_A F per unit eps_d: an aligned start
// F0 moves it from the first step, an unaligned one (F from 0) only as the aligned fabric grows, so over the first
// 1e-3 of strain the volume moves less by at least the ratio of F0 to the fabric grown there. The first row shows the
// measured start values either way; with no start part the two starts are the same path bit for bit.
TEST(ModelUnaligned, AnUnalignedStartDoesNotCoupleTheRandomFabricToTheVolume) {
  Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.74, p0 = isotropic_pressure(iso.data(), nu);
  std::vector<double> acc{0.0, 1e-3, 2e-3, 0.05};
  const std::vector<int> dir(acc.size(), 1), isob(acc.size(), 1);
  Ext<double> aligned, unaligned;
  unaligned.start_unaligned = true;
  const auto a = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.03, acc, dir, isob, 1e-4, aligned);
  const auto u = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.03, acc, dir, isob, 1e-4, unaligned);
  EXPECT_DOUBLE_EQ(a[0].state.F, 0.03);
  EXPECT_DOUBLE_EQ(u[0].state.F, 0.0);
  EXPECT_DOUBLE_EQ(observed(u[0].state.F, 0.03, true), 0.03);
  EXPECT_DOUBLE_EQ(observed(u[0].state.s, 0.02, true), 0.02);
  const double a_A = P.shear[kAnisoA] + P.shear[kAnisoB] * (nu - P.nu_ref);
  // the aligned start's rate a_A F0 (a_A > 0 here: the anisotropic pressure A dilates a packing held at constant p)
  EXPECT_NEAR(a[1].eps_vol, a_A * 0.03 * 1e-3, 0.1 * a_A * 0.03 * 1e-3);
  EXPECT_LT(std::fabs(u[1].eps_vol), 0.1 * std::fabs(a[1].eps_vol));
  EXPECT_GT(u[1].state.F, 0.0);   // the aligned part grows from 0
  const auto a0 = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, acc, dir, isob, 1e-4, aligned);
  const auto u0 = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.0, acc, dir, isob, 1e-4, unaligned);
  for (std::size_t i = 0; i < acc.size(); ++i) {
    EXPECT_EQ(a0[i].eps_vol, u0[i].eps_vol);
    EXPECT_EQ(a0[i].state.F, u0[i].state.F);
  }
}

// Noise-free curves of the model with an unaligned start (s0 = 0.02, F0 = 0.03 observed on the first row): the
// calibration with --start-anisotropy unaligned returns the truth from a start 10-20 % away and writes the flag into its
// parameters; the aligned model cannot reach those curves (its chi2 stays far above the unaligned fit's).
TEST(ModelUnaligned, RecoversTheTruthFromCurvesWithAnUnalignedStart) {
  Parameters P = truth();
  P.start_unaligned = true;
  std::vector<CurveData> curves;
  const auto iso = P.iso();
  for (double nu : {0.69, 0.73, 0.77, 0.81}) {
    CurveData c;
    c.mode = "D2"; c.nu = nu; c.packings = 8; c.source = "synthetic";
    for (int i = 0; i <= 100; ++i) c.eps.push_back(0.004 * i);
    c.p.assign(c.eps.size(), isotropic_pressure(iso.data(), nu));
    c.s.assign(c.eps.size(), 0.02);
    c.F.assign(c.eps.size(), 0.03);
    const ModelCurve m = predict_curve(P, c, 1e9, 1e-3);
    c.p = m.p; c.s = m.s; c.F = m.F;
    EXPECT_DOUBLE_EQ(c.s[0], 0.02);
    EXPECT_DOUBLE_EQ(c.F[0], 0.03);
    c.se_p.assign(c.eps.size(), 0.01 * c.p[0]);
    c.se_s.assign(c.eps.size(), 0.01);
    c.se_F.assign(c.eps.size(), 0.005);
    c.hw_p = c.se_p; c.hw_s = c.se_s; c.hw_F = c.se_F;
    curves.push_back(c);
  }
  Parameters start = P;
  for (int i = 0; i < kNumShear; ++i) start.shear[i] *= (i % 2 ? 0.8 : 1.1);
  CalibrationOptions o;
  o.fit_isotropic = false;
  o.start = &start;
  o.nu_ref = P.nu_ref;
  o.max_step = 1e-3;
  o.start_unaligned = true;
  const Calibration cal = calibrate(curves, {}, o);
  ASSERT_TRUE(cal.ok) << cal.message;
  EXPECT_TRUE(cal.params.start_unaligned);
  for (int i = 0; i < kNumShear; ++i)
    EXPECT_NEAR(cal.value[kNumIso + i], P.shear[i], 1e-4 * std::max(1.0, std::fabs(P.shear[i]))) << shear_name(i);
  o.start_unaligned = false;
  const Calibration al = calibrate(curves, {}, o);
  EXPECT_FALSE(al.params.start_unaligned);
  EXPECT_GT(al.chi2, 100 * std::max(cal.chi2, 1e-6)) << "aligned chi2 " << al.chi2 << ", unaligned " << cal.chi2;
}

// The plastic dilatancy gated by the mobilisation (twenty-eighth round, Ext::dilatancy_gated): at a state on the
// isotropic law (no relaxation) with a_A = 0, the volume rate under constant pressure is the dilatancy itself, d_D (r -
// chi_D)(1 - F/F_max) ungated and d_D r (r - chi_D)(1 - F/F_max) gated (r = s/s_max): closed forms from rhs. Along an
// isobaric path from an unaligned start the gated volume starts flat (r from 0), the ungated one at its largest
// contraction d_D chi_D per unit eps_d.
TEST(ModelUnaligned, AGatedDilatancyStartsAtZeroWithTheMobilisation) {
  Parameters P = truth();
  P.shear[kAnisoA] = 0.0; P.shear[kAnisoB] = 0.0;
  double ext[kNumExt] = {};
  ext[kDilA] = 0.01; ext[kChiD] = 2.0;
  const auto iso = P.iso();
  const double nu = 0.74, p0 = isotropic_pressure(iso.data(), nu);
  Ext<double> plain{ext, kLodeBD2, Surface::None, FabricLode::Norm}, gated = plain;
  gated.dilatancy_gated = true;
  gated.start_unaligned = plain.start_unaligned = true;
  Segment seg;
  seg.control = Control::Isobaric;
  const double s = 0.08, F = 0.05, s_max = P.shear[kSmaxA], F_max = P.shear[kFmaxA], r = s / s_max;
  State<double> y{std::log(nu), p0, s, F};
  for (const auto* e : {&plain, &gated}) {
    const Material<double> m = start_material<double>(iso.data(), P.shear, P.nu_ref, nu, p0, *e);
    const double dvol = -rhs(m, y, 1.0, seg).ln_nu;
    const double expect = 0.01 * (r - 2.0) * (1 - F / F_max) * (e->dilatancy_gated ? r : 1.0);
    EXPECT_NEAR(dvol, expect, 1e-12 * std::fabs(expect)) << (e->dilatancy_gated ? "gated" : "ungated");
  }
  const std::vector<double> acc{0.0, 1e-3};
  const std::vector<int> dir(2, 1), isob(2, 1);
  const auto u = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.03, acc, dir, isob, 1e-4, plain);
  const auto g = integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.02, 0.03, acc, dir, isob, 1e-4, gated);
  EXPECT_NEAR(u[1].eps_vol, -0.01 * 2.0 * 1e-3, 0.1 * 0.01 * 2.0 * 1e-3);
  EXPECT_LT(std::fabs(g[1].eps_vol), 0.1 * std::fabs(u[1].eps_vol));
}

// The fabric's state limit (thirtieth round, Ext::fabric_state): the fabric is driven to F_max (p_ref/p)^n_psi, the
// stress ratio's state factor, instead of F_max. At a state on the isotropic law (p = p_ref) the two rates agree to the
// last bit; at p = 2 p_ref (n_psi = 1.5 at nu_ref) the fabric rate's ratio is the closed form (F_max 2^-1.5 - F)/(F_max
// - F), every other factor of the rate (beta_F, the rate scaling, the gate) cancelling, and the stress ratio's rate
// and the volume's do not move (the option acts on the fabric alone). Without the state limit it does nothing.
TEST(ModelFabricState, TheFabricIsDrivenToTheStressRatiosStateLimit) {
  Parameters P = truth();
  double ext[kNumExt] = {};
  ext[kNPsiA] = 1.5;
  ext[kDilA] = 0.01; ext[kChiD] = 2.0;
  const auto iso = P.iso();
  const double nu = P.nu_ref, p0 = isotropic_pressure(iso.data(), nu);
  Ext<double> plain{ext, kLodeBD2, Surface::None, FabricLode::Norm, true}, state = plain;
  state.fabric_state = true;
  Segment seg;
  seg.control = Control::Volume;
  const double F = 0.05, F_max = P.shear[kFmaxA];   // F_max 0.11: F between F_max 2^-1.5 and F_max
  auto rates = [&](const Ext<double>& e, double p) {
    const Material<double> m = start_material<double>(iso.data(), P.shear, P.nu_ref, nu, p0, e);
    return rhs(m, State<double>{std::log(nu), p, 0.05, F}, 1.0, seg);
  };
  const auto a0 = rates(plain, p0), b0 = rates(state, p0);
  EXPECT_EQ(a0.F, b0.F) << "on the isotropic law the state factor is 1";
  const auto a = rates(plain, 2 * p0), b = rates(state, 2 * p0);
  const double factor = std::pow(0.5, 1.5);
  EXPECT_NEAR(b.F / a.F, (F_max * factor - F) / (F_max - F), 1e-12);
  EXPECT_LT(b.F, 0.0) << "above its limit F_max 2^-1.5 = " << F_max * factor << " the fabric softens";
  EXPECT_EQ(a.s, b.s);
  EXPECT_EQ(a.p, b.p);
  Ext<double> no_limit = state;
  no_limit.state_limit = false;
  plain.state_limit = false;
  EXPECT_EQ(rates(no_limit, 2 * p0).F, rates(plain, 2 * p0).F) << "the option needs the state limit";
}

// The deviatoric stress under a volume change (thirtieth round, Ext::deviator_reference): sigma_dev scales with the
// isotropic reference pressure p_ref(nu). Closed forms from rhs, with a_A = 0 (no anisotropy modulus):
// - a pure volumetric segment: d ln sigma_dev = d ln p_ref = -B/p_ref per unit eps_vol with the option, 0 without;
// - isobaric: the same volume rate, and d s lower by s B/p_ref d eps_vol (the elastic pressure drop no longer raises s);
// - constant volume: every rate the same to the last bit (a D2/D3 calibration does not see the option);
// - drained triaxial: the side stress p (1 - s/3) held, (1 - s/3) dp - (p/3) ds = 0, with and without it (the
//   volume rate's denominator B - (A + E_dev)/3 derived again).
TEST(ModelDeviatorVolume, SigmaDevScalesWithTheReferencePressure) {
  Parameters P = truth();
  P.shear[kAnisoA] = 0.0; P.shear[kAnisoB] = 0.0;
  double ext[kNumExt] = {};
  ext[kNPsiA] = 0.7;
  ext[kDilA] = 0.01; ext[kChiD] = 0.5;
  const auto iso = P.iso();
  const double nu = 0.72, p0 = isotropic_pressure(iso.data(), nu), B = bulk_modulus(iso.data(), nu);
  Ext<double> plain{ext, kLodeBD2, Surface::None, FabricLode::Norm, true}, ref = plain;
  ref.deviator_reference = true;
  const double s = 0.3, p = 1.2 * p0;   // above the reference pressure (p_ref = p0: k = 1 at this start)
  auto rates = [&](const Ext<double>& e, Control c, double eps_vol = 0.0) {
    const Material<double> m = start_material<double>(iso.data(), P.shear, P.nu_ref, nu, p0, e);
    Segment seg;
    seg.control = c;
    seg.eps_vol = eps_vol;
    return rhs(m, State<double>{std::log(nu), p, s, 0.05}, eps_vol != 0.0 ? 0.0 : 1.0, seg);
  };
  for (const auto* e : {&plain, &ref}) {
    const auto d = rates(*e, Control::Volume, 1e-3);   // a volumetric segment (sigma = 0), extension
    const double dvol = -d.ln_nu;
    const double dln_sdev = d.s / s + d.p / p;
    const double expect = e->deviator_reference ? -B / p0 * dvol : 0.0;
    EXPECT_NEAR(dln_sdev, expect, 1e-9 * B / p0) << (e->deviator_reference ? "reference" : "fixed");
  }
  const auto ia = rates(plain, Control::Isobaric), ib = rates(ref, Control::Isobaric);
  EXPECT_EQ(ia.ln_nu, ib.ln_nu);
  EXPECT_NEAR(ib.s - ia.s, -s * B / p0 * (-ib.ln_nu), 1e-12);
  EXPECT_NE(ib.s, ia.s);
  const auto ca = rates(plain, Control::Volume), cb = rates(ref, Control::Volume);
  EXPECT_EQ(ca.s, cb.s);
  EXPECT_EQ(ca.p, cb.p);
  EXPECT_EQ(ca.F, cb.F);
  for (const auto* e : {&plain, &ref}) {
    const auto t = rates(*e, Control::Triaxial);
    EXPECT_NEAR((1 - s / 3) * t.p - p / 3 * t.s, 0.0, 1e-12 * B) << (e->deviator_reference ? "reference" : "fixed");
  }
}

namespace {
// Drained triaxial extension at constant side stress (b = 1) from a dense start at p* = 1e-3 to eps_d = 0.3 (rows every
// 0.006), with the stress ratio's rate beta_s at nu_ref set to BETA_S.
struct StiffExtension {
  Parameters P = volume_truth();
  Rows r = rows_of(0.3, 0.3, 0.006, false);
  double p0 = 1e-3, nu0 = 0;
  explicit StiffExtension(double beta_s) {
    P.shear[kLnBetaSA] = std::log(beta_s);
    for (auto& c : r.isob) c = 2;
    for (auto& d : r.dir) d = -1;
    nu0 = P.ext[kNuCs] + P.ext[kLambdaCs] * std::log(p0 / kPCsRef) + 0.03;
  }
  std::vector<RowState<double>> rows(double max_step) const {
    const auto iso = P.iso();
    return integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, 0.0, 0.0, r.acc, r.dir, r.isob, max_step,
                                  volume_ext(P, 1.0));
  }
  // The first row by fixed RK4 steps of 5e-4 (12 of them), without the step control.
  State<double> fixed_first_row() const {
    const auto iso = P.iso();
    const Material<double> m = start_material(iso.data(), P.shear, P.nu_ref, nu0, p0, volume_ext(P, 1.0));
    State<double> y = start_state(m, nu0, p0, 0.0, 0.0);
    Segment seg;
    seg.control = Control::Triaxial;
    for (int k = 0; k < 12; ++k) y = rk4_step(m, y, -1.0, seg, 5e-4);
    return y;
  }
};
}  // namespace

// RK4's step control (model::advance; thirty-sixth round: the mu = 1 joint calibration's TE_s3_dense at p* = 1e-3 was
// not a number from its second row). With the stress ratio's rate at 4000 (the fit's bounds reach 3300) the fixed step
// of 5e-4 lies outside RK4's stability region on a drained extension: without the control the first row is already not
// a number. With it the step is halved where an interval moves the side stress p (1 - s/3) by more than kHeldDrift,
// every row holds it to kHeldDrift of the row before, and the rows agree with fixed steps of 1e-6 (which need no
// halving) to 1e-3. At the rate 300 nothing is halved, and the first row is the fixed steps' bit for bit.
TEST(ModelVolumeState, RK4HalvesItsStepWhereTheFixedStepDoesNotHoldTheSideStress) {
  const StiffExtension stiff(4000.0);
  EXPECT_FALSE(std::isfinite(stiff.fixed_first_row().s)) << "the fixed step is unstable here";
  const auto rows = stiff.rows(5e-4), fine = stiff.rows(1e-6);
  int halved = 0;
  for (std::size_t i = 1; i < rows.size(); ++i) {
    ASSERT_GE(rows[i].halvings, 0) << "row " << i << ": some step held the side stress";
    EXPECT_EQ(fine[i].halvings, 0) << "row " << i;
    halved = std::max(halved, rows[i].halvings);
    EXPECT_LE(std::fabs(side_stress(rows[i].state) / side_stress(rows[i - 1].state) - 1), kHeldDrift) << "row " << i;
    EXPECT_NEAR(rows[i].state.p, fine[i].state.p, 1e-3 * fine[i].state.p) << "row " << i;
    EXPECT_NEAR(rows[i].state.s, fine[i].state.s, 1e-3) << "row " << i;
    EXPECT_NEAR(rows[i].state.F, fine[i].state.F, 1e-3) << "row " << i;
    EXPECT_NEAR(rows[i].eps_vol, fine[i].eps_vol, 1e-5) << "row " << i;
  }
  EXPECT_GE(halved, 1);
  EXPECT_LE(halved, kMaxHalvings);
  EXPECT_LT(rows.back().state.s, -0.5) << "an extension that reached its limit";

  const StiffExtension mild(300.0);
  const auto plain = mild.rows(5e-4);
  for (const auto& q : plain) EXPECT_EQ(q.halvings, 0);
  const State<double> y = mild.fixed_first_row();
  EXPECT_EQ(plain[1].state.p, y.p);
  EXPECT_EQ(plain[1].state.s, y.s);
  EXPECT_EQ(plain[1].state.F, y.F);
  EXPECT_EQ(plain[1].state.ln_nu, y.ln_nu);
}

namespace {
// int_0^l phi^n dl', phi = 1 - e^{-c l'/delta}: (delta/c) sum_k U^{n+k+1}/(n+k+1), U = phi(l) (u = phi: dl' = delta
// du/(c (1 - u)), 1/(1 - u) a geometric series).
double opened_gate_integral(double l, double n, double c, double delta) {
  const double U = 1.0 - std::exp(-c * l / delta);
  double sum = 0, term = std::pow(U, n + 1);
  for (int k = 0; k < 10000000 && term > 1e-18 * sum; ++k, term *= U) sum += term / (n + k + 1);
  return delta / c * sum;
}

// The two gate tests' start: the volume truth without the state parameter or dilatancy, at constant volume on the
// isotropic law at nu_ref (p, and so the overlap delta, constant), F0 = 0.01, the overlap rule at n_F; l_f the gate
// floor's stretch (phi = 1e-6 up to it, opened_fraction_at).
struct GateStart {
  Parameters P = volume_truth();
  std::vector<double> iso;
  double nu0 = 0, p0 = 0, F0 = 0.01, delta = 0, c = minor_fraction(kLodeBD2), Fm = 0, bF = 0, l_f = 0;
  explicit GateStart(double n_F) {
    P.state_volume = false;
    P.ext[kDilA] = 0.0;
    iso = P.iso();
    nu0 = P.nu_ref;
    p0 = isotropic_pressure(iso.data(), nu0);
    delta = mean_overlap(iso.data(), nu0, p0);
    Fm = P.shear[kFmaxA];
    bF = std::exp(P.shear[kLnBetaFA]);
    l_f = -delta / c * std::log1p(-1e-6);
    set_gate(n_F);
  }
  void set_gate(double n_F) { P.ext[kNFA] = n_F; }
  Ext<double> ext() const { return {P.ext, kLodeBD2, Surface::LadeDuncan, FabricLode::Overlap, false, false, false}; }
  Material<double> material() const { return start_material(iso.data(), P.shear, P.nu_ref, nu0, p0, ext()); }
  State<double> start(const Material<double>& m) const { return start_state(m, nu0, p0, 0.0, F0); }
  std::vector<State<double>> shear(const std::vector<double>& eps) const {
    return monotone_shear<double>(iso.data(), P.shear, P.nu_ref, nu0, p0, 0.0, F0, eps, 5e-4, ext());
  }
};
}  // namespace

// A negative gate exponent (thirty-sixth round: the stored lab_dense calibration's n_F = -0.53 at its dense start) makes
// the fabric's rate beta_F (F_max - F) phi^n_F unbounded where nothing has opened (phi -> 0, floored at 1e-6), an
// integrable singularity. At constant volume with a_A = 0, no dilatancy and the start on the isotropic law, p and so the
// overlap delta stay constant, and the fabric has a closed form: F = F_max - (F_max - F0) exp(-beta_F int_0^l phi^n).
// From a singular start the first interval is integrated on graded pieces (model::advance): every row agrees with the
// closed form (the floor's stretch included) to 1e-6, where the fixed step's first row (its first stage reads the
// floor, 1e6^0.5 = 1000 times the rate) is off by more than 0.05. With n_F = +0.5 there is nothing singular and nothing graded.
TEST(Model, ANegativeGateExponentIsIntegratedFromItsSingularStart) {
  GateStart g(-0.5);
  std::vector<double> eps;
  for (int i = 1; i <= 10; ++i) eps.push_back(0.002 * i);
  const auto st = g.shear(eps);
  // The gate's floor: the gate 1e6^0.5 up to l_f (3.6e-5 of 0.017 at eps_d 0.002).
  auto floored_gate_integral = [&](double l) {
    return g.l_f * 1e3 + opened_gate_integral(l, -0.5, g.c, g.delta) - opened_gate_integral(g.l_f, -0.5, g.c, g.delta);
  };
  for (std::size_t i = 0; i < eps.size(); ++i) {
    EXPECT_NEAR(st[i].p, g.p0, 1e-12 * g.p0) << "the overlap stays constant";
    const double exact = g.Fm - (g.Fm - g.F0) * std::exp(-g.bF * floored_gate_integral(eps[i]));
    EXPECT_NEAR(st[i].F, exact, 1e-6) << "eps_d " << eps[i];
  }
  const Material<double> m = g.material();
  State<double> y = g.start(m);
  EXPECT_TRUE(singular_start(m, y, 1.0));
  for (int k = 0; k < 4; ++k) y = rk4_step(m, y, 1.0, Segment{}, 5e-4);
  const double exact = g.Fm - (g.Fm - g.F0) * std::exp(-g.bF * floored_gate_integral(eps[0]));
  EXPECT_GT(std::fabs(y.F - exact), 0.05) << "the fixed step reads the gate's floor";

  g.set_gate(0.5);
  const Material<double> m2 = g.material();
  EXPECT_FALSE(singular_start(m2, g.start(m2), 1.0));
}

// Below n_F = -1 the gate is not integrable (thirty-seventh round: the mu = 0 joint calibration's leave-one-out refits,
// n_F about -2.9 at D3 nu = 0.8, were not a number at their start): beta_F int_0^l phi^n_F is infinite in the law and
// beta_F l_f 1e6^|n_F| on the gate's floor, so in the closed form above F reaches F_max at once and stays there. No RK4
// step down to 1/64 of the smallest graded piece holds it, and model::advance integrates such a start's graded pieces
// with the fabric's relaxation taken exactly (split_step): every row is F_max to 1e-12 and p stays put. With RK4 on
// the graded pieces (the finest finite try kept) the rows at n_F = -3 and -5 are not F_max; at -1.5 and -2 the finest
// try happens to land on it.
TEST(Model, AGateThatIsNotIntegrableTakesTheFabricToItsLimitAtOnce) {
  GateStart g(-3.0);
  ASSERT_GT(g.bF * g.l_f * 1e12, 100.0) << "the floor's stretch alone relaxes the fabric completely";
  std::vector<double> eps;
  for (int i = 1; i <= 10; ++i) eps.push_back(0.002 * i);
  const auto st = g.shear(eps);
  for (std::size_t i = 0; i < eps.size(); ++i) {
    EXPECT_NEAR(st[i].p, g.p0, 1e-12 * g.p0) << "the overlap stays constant";
    EXPECT_NEAR(st[i].F, g.Fm, 1e-12) << "eps_d " << eps[i];
  }
  const Material<double> m = g.material();
  const State<double> y0 = g.start(m);
  ASSERT_TRUE(singular_start(m, y0, 1.0));
  State<double> y = y0;
  for (int k = 0; k < 4; ++k) y = rk4_step(m, y, 1.0, Segment{}, 5e-4);
  EXPECT_FALSE(std::isfinite(y.F) && std::fabs(y.F - g.Fm) < 1e-3) << "the fixed step: " << y.F;
  StepReport r;
  r.halvings = 7;
  double ev = 0;
  advance(m, y0, 1.0, Segment{}, 0.002, 5e-4, ev, &r);
  EXPECT_TRUE(r.graded && r.split);
  EXPECT_EQ(r.halvings, 0) << "split_step holds at the graded pieces' own steps";
  g.set_gate(-0.9);   // integrable: RK4 on the graded pieces, as before
  const Material<double> m9 = g.material();
  advance(m9, g.start(m9), 1.0, Segment{}, 0.002, 5e-4, ev, &r);
  EXPECT_TRUE(r.graded);
  EXPECT_FALSE(r.split);
}

namespace {
// The group truth with the excess pressure's rate beta_p = BETA_P at every nu, the others' as truth(): from nu = 0.72 at
// p0 = 1.05 p_ref, F0 = 0.01, rows every 0.004 to eps_d = 0.2 under CONTROL (0 constant volume, 1 isobaric, 2 the
// drained triaxial control), at steps of at most MAX_STEP.
std::vector<RowState<double>> stiff_excess_rows(double beta_p, int control, double max_step) {
  Parameters P = truth();
  P.shear[kLnBetaPA] = std::log(beta_p);
  P.shear[kLnBetaPB] = 0.0;
  const auto iso = P.iso();
  const double nu = 0.72, p0 = 1.05 * isotropic_pressure(iso.data(), nu);
  Rows r = rows_of(0.2, 0.2, 0.004, false);
  for (auto& c : r.isob) c = control;
  return integrate_rows<double>(iso.data(), P.shear, P.nu_ref, nu, p0, 0.0, 0.01, r.acc, r.dir, r.isob, max_step);
}
}  // namespace

// The excess pressure's relaxation taken exactly (relax_pressure, split_step; thirty-eighth round). The group fits at
// mu >= 0.3 relax their excess at beta_p up to 4e5, h beta_p = 200 at the fixed step: RK4 held there only at 1/64 of
// the step, which made those fits 10 times slower. At beta_p = 2e5 every row is reached with the relaxation split off
// at the fixed step (no halving), and agrees with the closed form of PressureUnderShearMatchesClosedForm at constant
// volume and with fixed RK4 steps of 1e-6 (h beta_p = 0.2, nothing split) under the isobaric and the drained triaxial
// controls: p and the volume to 1e-6 of p0 and 1e-7, s and F to 1e-6. At beta_p = 50 (h beta_p = 0.025) nothing is
// split and nothing halved.
TEST(Model, AStiffExcessPressureIsRelaxedExactlyAtTheFixedStep) {
  const Parameters P = truth();
  const auto iso = P.iso();
  const double nu = 0.72, p_ref = isotropic_pressure(iso.data(), nu), B = bulk_modulus(iso.data(), nu);
  const double p0 = 1.05 * p_ref, k = 1.05, bp = 2e5;
  const Local<double> L = local(P.shear, nu, P.nu_ref);
  const double aB = L.a_A * k * B, bF = L.beta_F, Fm = L.F_max, F0 = 0.01;
  const auto cv = stiff_excess_rows(bp, 0, 5e-4);
  for (std::size_t i = 1; i < cv.size(); ++i) {
    EXPECT_TRUE(cv[i].relaxed) << "row " << i;
    EXPECT_EQ(cv[i].halvings, 0) << "row " << i;
    const double e = 0.004 * i;
    const double qex = (p0 - k * p_ref) * std::exp(-bp * e) + aB * Fm * (1 - std::exp(-bp * e)) / bp -
                       aB * (Fm - F0) * (std::exp(-bF * e) - std::exp(-bp * e)) / (bp - bF);
    EXPECT_NEAR(cv[i].state.p, k * p_ref + qex, 1e-6 * p0) << "row " << i;
  }
  for (int control : {1, 2}) {
    const auto rows = stiff_excess_rows(bp, control, 5e-4), fine = stiff_excess_rows(bp, control, 1e-6);
    for (std::size_t i = 1; i < rows.size(); ++i) {
      EXPECT_TRUE(rows[i].relaxed && !fine[i].relaxed) << "control " << control << " row " << i;
      EXPECT_EQ(rows[i].halvings, 0) << "control " << control << " row " << i;
      EXPECT_NEAR(rows[i].state.p, fine[i].state.p, 1e-6 * p0) << "control " << control << " row " << i;
      EXPECT_NEAR(rows[i].eps_vol, fine[i].eps_vol, 1e-7) << "control " << control << " row " << i;
      EXPECT_NEAR(rows[i].state.s, fine[i].state.s, 1e-6) << "control " << control << " row " << i;
      EXPECT_NEAR(rows[i].state.F, fine[i].state.F, 1e-6) << "control " << control << " row " << i;
    }
  }
  for (int control : {0, 1, 2})
    for (const auto& q : stiff_excess_rows(50.0, control, 5e-4)) EXPECT_TRUE(!q.relaxed && q.halvings == 0);
}
