#include "demfit/format.hpp"
#include "demfit/jet_valued_cost.hpp"
#include "demfit/model_fit.hpp"
#include "demfit/jacobian_check.hpp"
#include "demfit/settle.hpp"

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <memory>
#include <fstream>
#include <set>
#include <limits>
#include <mutex>
#include <numeric>
#include <stdexcept>

#include "demfit/fit.hpp"
#include "demfit/table.hpp"

namespace demfit::model {

namespace {

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !(x > 0) || !std::isfinite(x); }), v.end());
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Point weights 1/sigma: sigma = max(se, floor x median se) (a point whose packings happen to
// agree must not pin the fit; the first row, where every packing starts from the same state,
// has se of the start-state spread).
std::vector<double> weights(const std::vector<double>& se, double floor_rel, const std::string& what) {
  const double med = median(se);
  if (!(med > 0))
    throw std::invalid_argument("model calibration: " + what +
                                " has no positive standard errors (one packing?): the joint fit weights every point "
                                "by the spread between packings; run an ensemble with >= 2 packings");
  std::vector<double> w(se.size());
  for (std::size_t i = 0; i < se.size(); ++i)
    w[i] = 1.0 / std::max(std::isfinite(se[i]) ? se[i] : 0.0, floor_rel * med);
  return w;
}

// The frictional family's options for one calibration curve or path of MODE (its block bound at each evaluation,
// with_block): the Lode parameters of MODE, and what CalibrationOptions asks for (X: the frictional family).
Ext<double> calibration_ext(const CalibrationOptions& o, const std::string& mode, bool X) {
  Ext<double> e{nullptr, lode_b_of(mode), X ? o.surface : Surface::None, o.fabric, X && o.state_limit,
                X && o.state_lode, X && o.state_volume, lode_b_of(mode, o.b_d2)};
  e.excess_relaxes = o.state_volume && o.excess_relaxes;
  e.excess_bounded = e.excess_relaxes && o.excess_bounded;
  e.start_unaligned = o.start_unaligned;
  e.dilatancy_gated = o.dilatancy_gated && !o.state_volume;
  e.fabric_state = X && o.state_limit && o.fabric_state;
  e.deviator_reference = X && o.deviator_reference && !o.state_volume;
  return e;
}

// One D2 curve: residuals (model - mean)/sigma for p*, s_dev, F_dev at every strain.
// par[2]: the extension block of the frictional family (when `extended`).
struct CurveResidual {
  std::vector<double> eps, p, s, F, wp, ws, wF;
  double nu0, p0, s0, F0, nu_ref, max_step;
  bool extended = false;   ///< par[2]: the frictional family's block
  Ext<double> opt = Ext<double>{};   ///< the frictional family's options (calibration_ext), par[2] bound to them (with_block)
  template <class T>
  bool operator()(T const* const* par, T* r) const {
    const Ext<T> ext = with_block(opt, extended ? par[2] : static_cast<const T*>(nullptr));
    const auto st = monotone_shear<T>(par[0], par[1], nu_ref, nu0, p0, s0, F0, eps, max_step, ext);
    const std::size_t n = eps.size();
    for (std::size_t i = 0; i < n; ++i) {
      r[i] = (st[i].p - T(p[i])) * T(wp[i]);
      r[n + i] = (observed(st[i].s, s0, opt.start_unaligned) - T(s[i])) * T(ws[i]);
      r[2 * n + i] = (observed(st[i].F, F0, opt.start_unaligned) - T(F[i])) * T(wF[i]);
    }
    return true;
  }
};

// One point of the isotropic branch: (p_iso(nu) - p)/sigma_p, (C(nu) - C)/sigma_C.
struct IsoResidual {
  double nu, p, C, wp, wC;
  template <class T>
  bool operator()(const T* iso, T* r) const {
    r[0] = (isotropic_pressure(iso, T(nu)) - T(p)) * T(wp);
    r[1] = (coordination(iso, T(nu)) - T(C)) * T(wC);
    return true;
  }
};

// One path ensemble: per row, (p* or eps_v, s, F) residuals; p* on rows at prescribed volume,
// eps_v (= tr E / 3) on rows where p was held; row 0 is the start state (residual 0).
struct PathResidual {
  std::vector<double> acc, p, ev, s, F, w1, ws, wF;
  std::vector<int> direction, isobaric;
  double nu0, p0, s0, F0, nu_ref, max_step;
  bool extended = false;   ///< par[2]: the frictional family's block
  Ext<double> opt = Ext<double>{};   ///< the frictional family's options (calibration_ext), par[2] bound to them (with_block)
  template <class T>
  bool operator()(T const* const* par, T* r) const {
    const Ext<T> ext = with_block(opt, extended ? par[2] : static_cast<const T*>(nullptr));
    const auto st = integrate_rows<T>(par[0], par[1], nu_ref, nu0, p0, s0, F0, acc, direction, isobaric, max_step, ext);
    const std::size_t n = acc.size();
    for (std::size_t i = 0; i < n; ++i) {
      r[i] = isobaric[i] ? (st[i].eps_vol / T(3.0) - T(ev[i])) * T(w1[i]) : (st[i].state.p - T(p[i])) * T(w1[i]);
      r[n + i] = (observed(st[i].state.s, s0, opt.start_unaligned) - T(s[i])) * T(ws[i]);
      r[2 * n + i] = (observed(st[i].state.F, F0, opt.start_unaligned) - T(F[i])) * T(wF[i]);
    }
    return true;
  }
};

// Every value the model integrates from or is fitted to must be a number: a NaN row (a hand-edited
// or truncated ensemble curve) is refused by name, never integrated.
void check_finite(const std::string& source, const std::vector<std::pair<const char*, const std::vector<double>*>>& cols) {
  for (const auto& [name, v] : cols)
    for (std::size_t i = 0; i < v->size(); ++i)
      if (!std::isfinite((*v)[i]))
        throw std::invalid_argument("model calibration: " + source + ": " + name + " is not a finite number at data row " +
                                    std::to_string(i + 1) + ": rewrite the ensemble curves with `dem fit DIR --force`");
}

void check_path(const PathData& d) {
  check_finite(d.source, {{"eps_d_accumulated", &d.acc}, {"p_star", &d.p}, {"eps_v", &d.ev}, {"s_dev_signed", &d.s},
                          {"F_dev_signed", &d.F}});
  if (d.acc.size() < 6)
    throw std::invalid_argument("model calibration: " + d.source + " has " + std::to_string(d.acc.size()) +
                                " rows; need at least 6");
  if (std::fabs(d.acc.front()) > 1e-12)
    throw std::invalid_argument("model calibration: " + d.source + " does not start at eps_d_accumulated = 0");
  const std::size_t n = d.acc.size();
  for (const auto* v : {&d.p, &d.ev, &d.s, &d.F, &d.se_p, &d.se_ev, &d.se_s, &d.se_F})
    if (v->size() != n)
      throw std::invalid_argument("model calibration: " + d.source + ": a column has " + std::to_string(v->size()) +
                                  " rows, eps_d_accumulated " + std::to_string(n));
  if (d.direction.size() != n || d.isobaric.size() != n || d.nu_m.size() != n)
    throw std::invalid_argument("model calibration: " + d.source + ": direction/isobaric/nu_mean columns do not match the rows");
  if (!(d.p.front() > 0) || !(d.nu > 0))
    throw std::invalid_argument("model calibration: " + d.source + " starts with p* <= 0 or nu <= 0");
  for (std::size_t i = 1; i < d.acc.size(); ++i)
    if (d.acc[i] < d.acc[i - 1])
      throw std::invalid_argument("model calibration: " + d.source + ": eps_d_accumulated decreases at row " + std::to_string(i));
}

CurveData truncated(const CurveData& c, double eps_max) {
  CurveData t = c;
  std::size_t n = 0;
  while (n < c.eps.size() && c.eps[n] <= eps_max + 1e-12) ++n;
  for (auto* v : {&t.eps, &t.p, &t.s, &t.F, &t.se_p, &t.se_s, &t.se_F, &t.hw_p, &t.hw_s, &t.hw_F}) v->resize(n);
  return t;
}

void check_curve(const CurveData& c) {
  check_finite(c.source, {{"eps_d", &c.eps}, {"p_star_mean", &c.p}, {"s_dev_mean", &c.s}, {"F_dev_mean", &c.F}});
  if (c.eps.size() < 6)
    throw std::invalid_argument("model calibration: " + c.source + " has " + std::to_string(c.eps.size()) +
                                " rows in the fitted range; need at least 6 (widen --eps-max or sample the runs more finely)");
  if (std::fabs(c.eps.front()) > 1e-12)
    throw std::invalid_argument("model calibration: " + c.source + " does not start at eps_d = 0 (its first row is the "
                                "start state the model integrates from): give the ensemble curve from `dem fit`");
  if (!(c.p.front() > 0) || !(c.nu > 0))
    throw std::invalid_argument("model calibration: " + c.source + " starts with p* <= 0 or nu <= 0: the model needs a "
                                "jammed start state (nu above jamming)");
  for (std::size_t i = 1; i < c.eps.size(); ++i)
    if (!(c.eps[i] > c.eps[i - 1]))
      throw std::invalid_argument("model calibration: " + c.source + ": eps_d is not increasing at row " + std::to_string(i));
}

// Start values: the isotropic laws fitted alone (fit_law), the shear laws from a saturating
// fit per curve regressed on nu.
Parameters start_values(const std::vector<CurveData>& curves, const IsoData& iso, double nu_ref) {
  Parameters s;
  s.nu_ref = nu_ref;
  const double numin = *std::min_element(iso.nu.begin(), iso.nu.end());
  try {
    const CurveFit cf = fit_law("power", iso.nu, iso.C, {6.0, 5.0, numin * 0.98, 0.5});
    if (cf.ok) { s.C0 = cf.params[0]; s.C1 = cf.params[1]; s.nu_cC = cf.params[2]; s.alpha = cf.params[3]; }
  } catch (const std::exception&) {}
  s.nu_cC = std::min(s.nu_cC, numin * (1 - 1e-6));
  s.nu_c = std::min(s.nu_cC, numin) * (1 - 1e-3);
  // p0 by linear least squares at gamma_p = 0.
  double num = 0, den = 0;
  for (std::size_t i = 0; i < iso.nu.size(); ++i) {
    double par[kNumIso] = {1.0, s.nu_c, 0.0, s.C0, s.C1, s.nu_cC, s.alpha};
    const double g = isotropic_pressure(par, iso.nu[i]);
    num += g * iso.p[i]; den += g * g;
  }
  if (den > 0 && num > 0) s.p0 = num / den;
  // Shear laws: saturating fits of each curve, then a weighted line through them.
  std::vector<double> nus, smax, lbs, fmax, lbf;
  for (const auto& c : curves) {
    try {
      FitOptions fo;
      fo.residual_diagnostics = false;
      const FitResult fs = fit_saturating(c.eps, c.s, fo), ff = fit_saturating(c.eps, c.F, fo);
      nus.push_back(c.nu); smax.push_back(fs.x_max); lbs.push_back(std::log(fs.beta));
      fmax.push_back(ff.x_max); lbf.push_back(std::log(ff.beta));
    } catch (const std::exception&) {}
  }
  auto line = [&](const std::vector<double>& y, double* a, double* b) {
    const std::size_t n = y.size();
    if (n == 0) return;
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < n; ++i) { mx += nus[i] - nu_ref; my += y[i]; }
    mx /= n; my /= n;
    double sxy = 0, sxx = 0;
    for (std::size_t i = 0; i < n; ++i) { sxy += (nus[i] - nu_ref - mx) * (y[i] - my); sxx += (nus[i] - nu_ref - mx) * (nus[i] - nu_ref - mx); }
    *b = sxx > 0 ? sxy / sxx : 0.0;
    *a = my - *b * mx;
  };
  line(smax, &s.shear[kSmaxA], &s.shear[kSmaxB]);
  line(lbs, &s.shear[kLnBetaSA], &s.shear[kLnBetaSB]);
  line(fmax, &s.shear[kFmaxA], &s.shear[kFmaxB]);
  line(lbf, &s.shear[kLnBetaFA], &s.shear[kLnBetaFB]);
  s.shear[kAnisoA] = 0.2; s.shear[kAnisoB] = 0.0;
  s.shear[kLnBetaPA] = std::log(20.0); s.shear[kLnBetaPB] = 0.0;
  return s;
}

// Per-curve start of the frictional family: at constant volume s and F do not depend on p, so
// each curve's (s_max, ln beta_s, kappa_s, F_max, ln beta_F, n_F) is fitted to its s and F alone.
struct StressFabricResidual {
  std::vector<double> eps, s, F, ws, wF;
  double nu, p0, s0, F0, max_step;
  std::vector<double> iso;
  Ext<double> opt = Ext<double>{};   ///< the curve's Lode parameter, surface, fabric rule and options (the block: x below)
  template <class T>
  bool operator()(T const* const* par, T* r) const {
    const T* x = par[0];
    T sh[kNumShear], ex[kNumExt], isoT[kNumIso];
    for (int i = 0; i < kNumShear; ++i) sh[i] = T(0.0);
    for (int i = 0; i < kNumExt; ++i) ex[i] = T(0.0);
    for (int i = 0; i < kNumIso; ++i) isoT[i] = T(iso[i]);
    sh[kSmaxA] = x[0]; sh[kLnBetaSA] = x[1]; ex[kKappaA] = x[2]; sh[kFmaxA] = x[3]; sh[kLnBetaFA] = x[4]; ex[kNFA] = x[5];
    const Ext<T> ext = with_block(opt, static_cast<const T*>(ex));
    const auto st = monotone_shear<T>(isoT, sh, nu, nu, p0, s0, F0, eps, max_step, ext);
    const std::size_t n = eps.size();
    for (std::size_t i = 0; i < n; ++i) {
      r[i] = (observed(st[i].s, s0, opt.start_unaligned) - T(s[i])) * T(ws[i]);
      r[n + i] = (observed(st[i].F, F0, opt.start_unaligned) - T(F[i])) * T(wF[i]);
    }
    return true;
  }
};

// Weighted least-squares line y = a + b (nu - nu_ref) through per-curve values.
void line_through(const std::vector<double>& nus, const std::vector<double>& y, double nu_ref, double* a, double* b) {
  const std::size_t n = y.size();
  if (n == 0) return;
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < n; ++i) { mx += nus[i] - nu_ref; my += y[i]; }
  mx /= n; my /= n;
  double sxy = 0, sxx = 0;
  for (std::size_t i = 0; i < n; ++i) { sxy += (nus[i] - nu_ref - mx) * (y[i] - my); sxx += (nus[i] - nu_ref - mx) * (nus[i] - nu_ref - mx); }
  *b = sxx > 0 ? sxy / sxx : 0.0;
  *a = my - *b * mx;
}

// The frictional family's start: per-curve fits of the stress-ratio and fabric laws (three
// starts in n_F, the best kept), lines through them in nu; the pressure terms from `base` (the
// group model's calibration), the dilatancy off (d_D = 0, chi_D = 0.5).
Parameters extended_start(const std::vector<CurveData>& curves, const Parameters& base, const CalibrationOptions& o) {
  Parameters P = base;
  std::vector<double> nus, v[6];
  const std::vector<double> iso = base.iso();
  for (const auto& c : curves) {
    std::vector<double> best;
    double best_cost = 1e300;
    for (double n0 : {0.5, 3.0, 8.0}) {
      double x[6] = {*std::max_element(c.s.begin(), c.s.end()), std::log(6.0), 0.5,
                     1.1 * *std::max_element(c.F.begin(), c.F.end()), std::log(10.0), n0};
      auto* f = new StressFabricResidual{c.eps, c.s, c.F, weights(c.se_s, o.se_floor, c.source + " s_dev"),
                                         weights(c.se_F, o.se_floor, c.source + " F_dev"), c.nu, c.p.front(), c.s.front(),
                                         c.F.front(), 2e-3, iso};
      f->opt = Ext<double>{nullptr, lode_b_of(c.mode), o.surface, o.fabric};
      f->opt.start_unaligned = o.start_unaligned;
      f->opt.dilatancy_gated = o.dilatancy_gated && !o.state_volume;
      auto* cost = new ceres::DynamicAutoDiffCostFunction<StressFabricResidual, 6>(f);
      cost->AddParameterBlock(6);
      cost->SetNumResiduals(2 * static_cast<int>(c.eps.size()));
      ceres::Problem pr;
      pr.AddResidualBlock(cost, nullptr, x);
      const double lo[6] = {0.01, std::log(0.1), -0.9, 0.005, std::log(0.1), -1.0};
      const double hi[6] = {5.0, std::log(2e3), 30.0, 5.0, std::log(2e3), 30.0};
      for (int i = 0; i < 6; ++i) { pr.SetParameterLowerBound(x, i, lo[i]); pr.SetParameterUpperBound(x, i, hi[i]); }
      ceres::Solver::Options so;
      so.linear_solver_type = ceres::DENSE_QR;
      so.max_num_iterations = 200;
      ceres::Solver::Summary sum;
      ceres::Solve(so, &pr, &sum);
      if (sum.IsSolutionUsable() && sum.final_cost < best_cost) { best_cost = sum.final_cost; best.assign(x, x + 6); }
    }
    if (best.empty()) continue;
    nus.push_back(c.nu);
    for (int i = 0; i < 6; ++i) v[i].push_back(best[i]);
  }
  line_through(nus, v[0], P.nu_ref, &P.shear[kSmaxA], &P.shear[kSmaxB]);
  line_through(nus, v[1], P.nu_ref, &P.shear[kLnBetaSA], &P.shear[kLnBetaSB]);
  line_through(nus, v[2], P.nu_ref, &P.ext[kKappaA], &P.ext[kKappaB]);
  line_through(nus, v[3], P.nu_ref, &P.shear[kFmaxA], &P.shear[kFmaxB]);
  line_through(nus, v[4], P.nu_ref, &P.shear[kLnBetaFA], &P.shear[kLnBetaFB]);
  line_through(nus, v[5], P.nu_ref, &P.ext[kNFA], &P.ext[kNFB]);
  P.ext[kDilA] = 0.0; P.ext[kDilB] = 0.0; P.ext[kChiD] = 0.5;
  return P;
}

}  // namespace

int iso_index(const std::string& name) {
  for (int i = 0; i < kNumIso; ++i)
    if (name == iso_name(i)) return i;
  return -1;
}

int ext_index(const std::string& name) {
  for (int i = 0; i < kNumExt; ++i)
    if (name == ext_name(i)) return i;
  return -1;
}

namespace {
// One CSV line split into fields, "..." quoting with commas inside (as write_table_all writes).
std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (c == '"') {
      if (quoted && i + 1 < line.size() && line[i + 1] == '"') { out.back() += '"'; ++i; }
      else quoted = !quoted;
    } else if (c == ',' && !quoted) {
      out.emplace_back();
    } else if (c != '\r') {
      out.back() += c;
    }
  }
  return out;
}
}  // namespace

Parameters read_parameters(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + " cannot be read: give the parameters.csv of a `dem model` run");
  std::string line;
  std::map<std::string, double> v;
  int col = -1;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto f = csv_fields(line);
    if (col < 0) {
      for (std::size_t i = 0; i < f.size(); ++i) if (f[i] == "value") col = static_cast<int>(i);
      if (col < 0 || f.front() != "parameter")
        throw std::runtime_error(path + " has no header 'parameter,...,value': give the parameters.csv of a `dem model` run");
      continue;
    }
    if (static_cast<int>(f.size()) > col) v[f.front()] = std::strtod(f[col].c_str(), nullptr);
  }
  auto get = [&](const std::string& n) {
    const auto it = v.find(n);
    if (it == v.end() || !std::isfinite(it->second))
      throw std::runtime_error(path + " has no value for " + n + ": give the parameters.csv of a `dem model` run");
    return it->second;
  };
  Parameters P;
  double isov[kNumIso];
  for (int i = 0; i < kNumIso; ++i) isov[i] = get(iso_name(i));
  P.set_iso(isov);
  for (int i = 0; i < kNumShear; ++i) P.shear[i] = get(shear_name(i));
  P.nu_ref = get("nu_ref");
  if (v.count("b_D2")) P.b_d2 = get("b_D2");   // files before the thirteenth round: kLodeBD2
  if (v.count("psi_min")) P.psi_lo = get("psi_min");   // ... and without a range (infinite: no clamp)
  if (v.count("psi_max")) P.psi_hi = get("psi_max");
  P.extended = v.count(ext_name(0)) > 0;
  P.state_limit = P.extended && v.count(ext_name(kNPsiA)) > 0;
  P.state_lode = P.state_limit && v.count(ext_name(kLambdaPsi)) > 0;
  P.state_volume = P.extended && v.count(ext_name(kNuCs)) > 0;
  const double excess = P.state_volume && v.count("anisotropy_excess") ? get("anisotropy_excess") : 0.0;
  P.excess_relaxes = excess == 1.0 || excess == 2.0;   // 1 relaxing, 2 bounded (nineteenth round)
  P.excess_bounded = excess == 2.0;
  P.start_unaligned = v.count("start_anisotropy") && get("start_anisotropy") == 1.0;   // files without the row: aligned
  P.dilatancy_gated = v.count("dilatancy_gate") && get("dilatancy_gate") == 1.0;   // ... ungated
  P.fabric_state = P.state_limit && v.count("fabric_limit") && get("fabric_limit") == 1.0;   // ... F_lim itself
  P.deviator_reference = v.count("deviator_volume") && get("deviator_volume") == 1.0;   // ... sigma_dev unchanged
  if (P.extended)
    for (int i = 0; i < kNumExt; ++i)
      if (i < kNumExtBase || v.count(ext_name(i))) P.ext[i] = get(ext_name(i));   // else the default (n_rate 1)
  return P;
}

double cusp_pressure(const double* iso) {
  if (!(iso[kNuCC] > iso[kNuC])) return kNaN;
  return isotropic_pressure(iso, iso[kNuCC]);
}

Parameters recentred(const Parameters& P, double nu_ref) {
  Parameters Q = P;
  const double d = nu_ref - P.nu_ref;
  for (int i = 0; i + 1 < kNumShear; i += 2) Q.shear[i] = P.shear[i] + P.shear[i + 1] * d;
  for (int i : {kNFA, kKappaA, kDilA, kNPsiA}) Q.ext[i] = P.ext[i] + P.ext[i + 1] * d;
  Q.nu_ref = nu_ref;
  return Q;
}

double lode_b_of(const std::string& mode, double b_d2) {
  if (mode == "D3" || mode.find("triaxial") != std::string::npos) return 0.0;
  // The laboratory tests of data/geotech (demkit/geotech_model.py names them TEST_PREP): triaxial
  // compression (constant sigma_3 or p) b = 0, extension b = 1, true triaxial TT_bNNN b = NNN/100.
  if (mode.rfind("TC_", 0) == 0) return 0.0;
  if (mode.rfind("TE_", 0) == 0) return 1.0;
  if (mode.rfind("TT_b", 0) == 0 && mode.size() >= 7 && std::isdigit(static_cast<unsigned char>(mode[4])) &&
      std::isdigit(static_cast<unsigned char>(mode[5])) && std::isdigit(static_cast<unsigned char>(mode[6])))
    return std::stoi(mode.substr(4, 3)) / 100.0;
  return b_d2;
}

const char* surface_name(Surface s) {
  return s == Surface::MatsuokaNakai ? "Matsuoka-Nakai" : s == Surface::LadeDuncan ? "Lade-Duncan" : "none";
}

const char* fabric_lode_name(FabricLode f) {
  return f == FabricLode::Principal ? "principal" : f == FabricLode::Opening ? "opening"
         : f == FabricLode::Overlap ? "overlap"
         : f == FabricLode::Extension ? "extension" : f == FabricLode::Weighted ? "weighted" : "norm";
}

CurveData read_curve(const std::string& path, const std::string& mode, double nu) {
  const Table t = read_table(path);
  CurveData c;
  c.mode = mode; c.nu = nu; c.source = path;
  c.eps = t.column("eps_d");
  const auto& n = t.column("n_packings");
  c.packings = n.empty() ? 0 : static_cast<int>(n.front());
  const std::pair<const char*, std::vector<double>*> mean[] = {{"p_star", &c.p}, {"s_dev", &c.s}, {"F_dev", &c.F}};
  const std::pair<const char*, std::vector<double>*> se[] = {{"p_star", &c.se_p}, {"s_dev", &c.se_s}, {"F_dev", &c.se_F}};
  const std::pair<const char*, std::vector<double>*> hw[] = {{"p_star", &c.hw_p}, {"s_dev", &c.hw_s}, {"F_dev", &c.hw_F}};
  for (auto& [q, v] : mean) *v = t.column(std::string(q) + "_mean");
  for (auto& [q, v] : se) *v = t.column(std::string(q) + "_se");
  for (std::size_t k = 0; k < 3; ++k) {
    const auto& hi = t.column(std::string(hw[k].first) + "_hi95");
    *hw[k].second = hi;
    for (std::size_t i = 0; i < hi.size(); ++i) (*hw[k].second)[i] = hi[i] - (*mean[k].second)[i];
  }
  const auto& nu_col = t.column("nu_mean");
  if (!nu_col.empty() && std::isfinite(nu_col.front())) c.nu = nu_col.front();
  for (const auto& [name, v] : {std::pair<const char*, const std::vector<double>*>{"eps_d", &c.eps}, {"p_star_mean", &c.p},
                                {"s_dev_mean", &c.s}, {"F_dev_mean", &c.F}})
    for (std::size_t i = 0; i < v->size(); ++i)
      if (!std::isfinite((*v)[i]))
        throw std::runtime_error(path + ": " + name + " is not a finite number at data row " + std::to_string(i + 1) +
                                 ": rewrite the ensemble curves with `dem fit DIR --force`");
  return c;
}

IsoData read_isotropic(const std::vector<std::string>& paths) {
  IsoData d;
  for (const auto& path : paths) {
    const Table t = read_table(path);
    const auto& nu = t.column("nu");
    const auto& p = t.column("p_star");
    const auto& C = t.column("C_nonrattler");
    for (std::size_t i = 0; i < nu.size(); ++i)
      if (p[i] > 1e-7 && C[i] > 0 && std::isfinite(nu[i])) { d.nu.push_back(nu[i]); d.p.push_back(p[i]); d.C.push_back(C[i]); }
  }
  return d;
}

bool PathData::has_isobaric() const {
  return std::any_of(isobaric.begin(), isobaric.end(), [](int v) { return v != 0; });
}
bool PathData::has_volume() const {
  for (std::size_t i = 1; i < isobaric.size(); ++i)
    if (!isobaric[i]) return true;
  return false;
}

PathData read_path(const std::string& path, const std::string& name, double nu) {
  const Table t = read_table(path);
  PathData d;
  d.name = name; d.nu = nu; d.source = path;
  d.acc = t.column("eps_d_accumulated");
  d.eps_signed = t.column("eps_d_signed");
  for (double v : t.column("direction")) d.direction.push_back(static_cast<int>(std::lround(v)));
  for (double v : t.column("isobaric")) d.isobaric.push_back(static_cast<int>(std::lround(v)));
  // Constant side stress (triaxial) rows: code 2 (Control::Triaxial; the column is optional,
  // older path ensembles have none).
  if (std::find(t.header.begin(), t.header.end(), "triaxial") != t.header.end()) {
    const auto& tri = t.column("triaxial");
    for (std::size_t i = 0; i < tri.size() && i < d.isobaric.size(); ++i)
      if (std::lround(tri[i]) != 0) d.isobaric[i] = 2;
  }
  const auto& n = t.column("n_packings");
  d.packings = n.empty() ? 0 : static_cast<int>(n.front());
  d.nu_m = t.column("nu_mean");
  const std::pair<const char*, std::vector<double>*> mean[] = {
      {"eps_v", &d.ev}, {"p_star", &d.p}, {"s_dev_signed", &d.s}, {"F_dev_signed", &d.F}};
  std::vector<double>* se[] = {&d.se_ev, &d.se_p, &d.se_s, &d.se_F};
  std::vector<double>* hw[] = {&d.hw_ev, &d.hw_p, &d.hw_s, &d.hw_F};
  for (std::size_t k = 0; k < 4; ++k) {
    *mean[k].second = t.column(std::string(mean[k].first) + "_mean");
    *se[k] = t.column(std::string(mean[k].first) + "_se");
    const auto& hi = t.column(std::string(mean[k].first) + "_hi95");
    hw[k]->resize(hi.size());
    for (std::size_t i = 0; i < hi.size(); ++i) (*hw[k])[i] = hi[i] - (*mean[k].second)[i];
  }
  const auto has = [&](const char* c) { return std::find(t.header.begin(), t.header.end(), c) != t.header.end(); };
  if (has("eps_zz_mean")) d.ezz = t.column("eps_zz_mean");
  if (has("sigma_r_p0_mean")) d.sr = t.column("sigma_r_p0_mean");
  if (!d.nu_m.empty() && std::isfinite(d.nu_m.front())) d.nu = d.nu_m.front();
  return d;
}

namespace {

// Size of the extension block Ceres sees for these options (ext_size).
int ext_block(const CalibrationOptions& o) {
  return ext_size(o.state_limit, o.fabric == FabricLode::Weighted, o.state_limit && o.state_lode, o.state_volume);
}

// The residuals of the D2 ensemble curves: p*, s and F along each, weighted by their standard errors.
void add_curve_residuals(ceres::Problem& problem, const std::vector<CurveData>& curves, const CalibrationOptions& o,
                         double nu_ref, bool X, std::vector<double*>& blocks_all, int& n_res) {
  for (const auto& c : curves) {
    auto* f = new CurveResidual{c.eps, c.p, c.s, c.F, weights(c.se_p, o.se_floor, c.source + " p_star"),
                                weights(c.se_s, o.se_floor, c.source + " s_dev"), weights(c.se_F, o.se_floor, c.source + " F_dev"),
                                c.nu, c.p.front(), c.s.front(), c.F.front(), nu_ref, o.max_step};
    f->extended = X;
    f->opt = calibration_ext(o, c.mode, X);
    auto* cost = new ceres::DynamicAutoDiffCostFunction<CurveResidual, 4>(f);
    cost->AddParameterBlock(kNumIso);
    cost->AddParameterBlock(kNumShear);
    if (X) cost->AddParameterBlock(ext_block(o));
    cost->SetNumResiduals(3 * static_cast<int>(c.eps.size()));
    problem.AddResidualBlock(cost, nullptr, blocks_all);
    n_res += 3 * static_cast<int>(c.eps.size());
  }
}

// The residuals of the path ensembles (calibrate-on paths): p* or eps_v, s and F signed, row by
// row, each weighted by its own standard errors; the forward D2 prefix left out when asked.
void add_path_residuals(ceres::Problem& problem, const std::vector<PathData>& paths, const CalibrationOptions& o,
                        double nu_ref, bool X, std::vector<double*>& blocks_all, int& n_res, double& numin) {
  for (const auto& d : paths) {
    check_path(d);
    const std::size_t n = d.acc.size();
    // sigma of the first residual: the SE of p* over the constant-volume rows, of eps_v over
    // the isobaric rows (each floored at 0.25 x its own median), row by row.
    std::vector<double> sp, sv;
    for (std::size_t i = 1; i < n; ++i) {
      if (d.isobaric[i]) sv.push_back(d.se_ev[i]);
      else sp.push_back(d.se_p[i]);
    }
    std::vector<double> w1(n, 0.0);
    const std::vector<double> wp = sp.empty() ? std::vector<double>() : weights(sp, o.se_floor, d.source + " p_star");
    const std::vector<double> wv = sv.empty() ? std::vector<double>() : weights(sv, o.se_floor, d.source + " eps_v");
    for (std::size_t i = 1, a = 0, b = 0; i < n; ++i) w1[i] = d.isobaric[i] ? wv[b++] : wp[a++];
    w1[0] = 0.0;
    std::vector<double> ws = weights(d.se_s, o.se_floor, d.source + " s_dev_signed");
    std::vector<double> wF = weights(d.se_F, o.se_floor, d.source + " F_dev_signed");
    std::size_t prefix = 0;   // rows 1..prefix: forward constant-volume shear from the start (a D2 run)
    if (o.skip_d2_prefix)
      while (prefix + 1 < n && d.direction[prefix + 1] > 0 && !d.isobaric[prefix + 1]) ++prefix;
    for (std::size_t i = 1; i <= prefix; ++i) w1[i] = ws[i] = wF[i] = 0.0;
    auto* f = new PathResidual{d.acc, d.p, d.ev, d.s, d.F, w1, ws, wF, d.direction, d.isobaric,
                               d.nu, d.p.front(), d.s.front(), d.F.front(), nu_ref, o.max_step};
    f->extended = X;
    f->opt = calibration_ext(o, d.name, X);
    auto* cost = new ceres::DynamicAutoDiffCostFunction<PathResidual, 4>(f);
    cost->AddParameterBlock(kNumIso);
    cost->AddParameterBlock(kNumShear);
    if (X) cost->AddParameterBlock(ext_block(o));
    cost->SetNumResiduals(3 * static_cast<int>(n));
    problem.AddResidualBlock(new JetValuedCost<PathResidual, 4>(f, cost), nullptr, blocks_all);
    n_res += 3 * static_cast<int>(n - 1 - prefix);   // weighted rows only
    // The jamming fractions' bound: below every state the isotropic law is evaluated at (none with the volume-form
    // state parameter: its elastic volume fraction starts on the law at the start pressure, start_state).
    if (!o.state_volume)
      for (double v : d.nu_m) numin = std::min(numin, v);
  }
}

// The isotropic laws fitted to the branch alone from `isob` (the `held` ones kept), and the branch's RMS scatter about
// them in p* and C.
struct IsoPrefit {
  std::vector<double> iso;
  double sp = 1.0, sc = 1.0;
};

IsoPrefit prefit_isotropic(const IsoData& iso, const std::vector<double>& isob, const std::set<int>& held, double numin) {
  IsoPrefit f{isob};
  ceres::Problem pre;
  for (std::size_t i = 0; i < iso.nu.size(); ++i)
    pre.AddResidualBlock(new ceres::AutoDiffCostFunction<IsoResidual, 2, kNumIso>(
                             new IsoResidual{iso.nu[i], iso.p[i], iso.C[i], 1.0, 1.0}), nullptr, f.iso.data());
  pre.SetParameterUpperBound(f.iso.data(), kNuC, numin * (1 - 1e-6));
  pre.SetParameterUpperBound(f.iso.data(), kNuCC, numin * (1 - 1e-6));
  pre.SetParameterLowerBound(f.iso.data(), kAlpha, 0.05);
  if (!held.empty())
    pre.SetManifold(f.iso.data(), new ceres::SubsetManifold(kNumIso, std::vector<int>(held.begin(), held.end())));
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 500;
  ceres::Solver::Summary sum;
  ceres::Solve(so, &pre, &sum);
  double rp = 0, rc = 0;
  for (std::size_t i = 0; i < iso.nu.size(); ++i) {
    const double dp = isotropic_pressure(f.iso.data(), iso.nu[i]) - iso.p[i];
    const double dc = coordination(f.iso.data(), iso.nu[i]) - iso.C[i];
    rp += dp * dp; rc += dc * dc;
  }
  const double dof = std::max<double>(1.0, iso.nu.size() - (kNumIso - static_cast<double>(held.size())) / 2.0);
  f.sp = std::max(std::sqrt(rp / dof), 1e-12);
  f.sc = std::max(std::sqrt(rc / dof), 1e-12);
  return f;
}

// The isotropic branch's residuals (p*(nu), C(nu)), weighted by the branch's scatter about the
// isotropic laws fitted alone (reduced chi2 = 1 for this block, so that neither block dominates by its number of
// points); held constant when the branch is not fitted. The block starts from that fit, or from the start file's
// values (o.start_iso_from_file). With one jamming fraction (o.shared_jamming) the weights stay those of the separate
// laws' fit (the data's scatter about the seven-coefficient laws), so that the tie's cost shows in chi2, and the
// block starts from the tied laws' own fit (nu_cC <= 0: coordination_jamming).
void add_isotropic_residuals(ceres::Problem& problem, const IsoData& iso, const CalibrationOptions& o,
                             const std::set<int>& held, std::vector<double>& isob, double numin, int& n_res) {
  if (!o.fit_isotropic) {
    problem.SetParameterBlockConstant(isob.data());
    return;
  }
  std::set<int> untied = held;
  if (o.shared_jamming) untied.erase(kNuCC);
  const IsoPrefit w = prefit_isotropic(iso, isob, untied, numin);
  if (o.shared_jamming) isob[kNuCC] = 0.0;
  const IsoPrefit f = o.shared_jamming ? prefit_isotropic(iso, isob, held, numin) : w;
  if (!o.start || !o.start_iso_from_file) isob = f.iso;
  for (std::size_t i = 0; i < iso.nu.size(); ++i)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<IsoResidual, 2, kNumIso>(
                                 new IsoResidual{iso.nu[i], iso.p[i], iso.C[i], 1.0 / w.sp, 1.0 / w.sc}),
                             nullptr, isob.data());
  n_res += 2 * static_cast<int>(iso.nu.size());
}

// The parameters' bounds: jamming fractions below every start state, positive alpha and p0, the
// rates' ranges (tighter for the frictional family, whose rate laws have stiff corners).
void set_bounds(ceres::Problem& problem, std::vector<double>& isob, std::vector<double>& shear,
                std::vector<double>& ext, double numin, bool X, bool state_limit, bool weighted, bool state_lode,
                bool state_volume) {
  problem.SetParameterUpperBound(isob.data(), kNuC, numin * (1 - 1e-6));
  problem.SetParameterUpperBound(isob.data(), kNuCC, numin * (1 - 1e-6));
  problem.SetParameterLowerBound(isob.data(), kAlpha, 0.05);
  problem.SetParameterLowerBound(isob.data(), kP0, 1e-9);
  for (int i : {kLnBetaSA, kLnBetaFA, kLnBetaPA}) {
    problem.SetParameterLowerBound(shear.data(), i, std::log(1e-3));
    problem.SetParameterUpperBound(shear.data(), i, std::log(5e3));
  }
  if (X) {
    // The frictional family reaches stiff corners of the rate laws (at mu = 1 a free fit took
    // beta_p to 6600 at nu = 0.80, beyond RK4's stability at max_step 5e-4): the rates are kept
    // at beta <= 300 at nu_ref and e^{+-40 (nu - nu_ref)} about it (<= 3300 at |nu - nu_ref| = 0.06).
    for (int i : {kLnBetaSA, kLnBetaFA, kLnBetaPA}) {
      problem.SetParameterUpperBound(shear.data(), i, std::log(300.0));
      problem.SetParameterLowerBound(shear.data(), i + 1, -40.0);
      problem.SetParameterUpperBound(shear.data(), i + 1, 40.0);
    }
    problem.SetParameterLowerBound(ext.data(), kNFA, -1.0);
    problem.SetParameterUpperBound(ext.data(), kNFA, 30.0);
    problem.SetParameterLowerBound(ext.data(), kKappaA, -0.9);
    problem.SetParameterUpperBound(ext.data(), kKappaA, 30.0);
    problem.SetParameterLowerBound(ext.data(), kChiD, -1.0);
    problem.SetParameterUpperBound(ext.data(), kChiD, 3.0);
    if (state_limit) {   // |n_psi| <= 10 at nu_ref: (p_ref/p)^10 moves the limit by 2.7 at a 10 % pressure excess
      problem.SetParameterLowerBound(ext.data(), kNPsiA, -10.0);
      problem.SetParameterUpperBound(ext.data(), kNPsiA, 10.0);
    }
    if (state_lode) {   // the exponent at most e^{+-5 ln 1.73} = 15 (1/15) times D2's in axisymmetric compression
      problem.SetParameterLowerBound(ext.data(), kLambdaPsi, -5.0);
      problem.SetParameterUpperBound(ext.data(), kLambdaPsi, 5.0);
    }
    if (state_volume) {   // the critical-state line within the packings' range; the state exponents >= 0 (a peak
                          // and a dilatancy onset that rise with the density), n_b at most e^{60 x 0.05} = 20 at psi = 0.05
      problem.SetParameterLowerBound(ext.data(), kNuCs, 0.40);
      problem.SetParameterUpperBound(ext.data(), kNuCs, 0.80);
      problem.SetParameterLowerBound(ext.data(), kLambdaCs, -0.1);
      problem.SetParameterUpperBound(ext.data(), kLambdaCs, 0.1);
      problem.SetParameterLowerBound(ext.data(), kDilA, 0.0);   // d_D >= 0: the dilatancy drives psi to 0, not away
      problem.SetParameterLowerBound(ext.data(), kNFA, 0.0);    // n_F >= 0 at the critical state, which loose and
                                                                 // dense packings both reach (r^n_F <= 1: a gate)
      problem.SetParameterLowerBound(ext.data(), kNB, 0.0);
      problem.SetParameterUpperBound(ext.data(), kNB, 60.0);
      problem.SetParameterLowerBound(ext.data(), kND, 0.0);
      problem.SetParameterUpperBound(ext.data(), kND, 150.0);   // e^{150 x 0.03} = 90 at a loose psi = -0.03
      problem.SetParameterLowerBound(ext.data(), kNRate, 0.0);  // the rates never rise with the pressure faster than
      problem.SetParameterUpperBound(ext.data(), kNRate, 3.0);  // the stiffness falls, nor fall as its cube
      problem.SetParameterLowerBound(ext.data(), kMPeak, -1.0);  // the peak exponent at most 50-fold over p* = 1e-4..5e-2
      problem.SetParameterUpperBound(ext.data(), kMPeak, 1.0);
      problem.SetParameterLowerBound(isob.data(), kC0, 0.0);   // the coordination law, read at nu_el, >= 0
    }
    if (weighted) {   // the switch between overlaps of 1e-4 and 0.5 d, no steeper than (delta/delta_w)^30
      problem.SetParameterLowerBound(ext.data(), kLnDeltaW, std::log(1e-4));
      problem.SetParameterUpperBound(ext.data(), kLnDeltaW, std::log(0.5));
      problem.SetParameterLowerBound(ext.data(), kNW, 0.0);
      problem.SetParameterUpperBound(ext.data(), kNW, 30.0);
    }
  }

}

// A covariance error at most this times max(1, |value|): a null direction of the Jacobian (null_directions).
constexpr double kNullSe = 1e-9;

}  // namespace

std::string Calibration::errors_not_determined() const {
  if (!against_margin.empty()) return "the optimum sits against the drained control's margin on " + against_margin;
  if (!rough.empty()) return "the cost is not smooth at the optimum (" + rough + ")";
  return "";
}

// DENSE_SVD's pseudo-inverse gives a direction the curves do not see (a fitted coefficient that does not act on them)
// a variance of 0 to rounding: that is "not determined", not "exact" (no DEM curve fixes a coefficient to 1e-9). Such
// errors become nan, and said; the held coefficients (nan already) are not looked at.
void null_directions(Calibration& cal) {
  std::vector<std::size_t> null;
  std::size_t quoted = 0;
  for (std::size_t a = 0; a < cal.se_cov.size() && a < cal.value.size(); ++a) {
    if (!std::isfinite(cal.se_cov[a])) continue;
    ++quoted;
    if (cal.se_cov[a] <= kNullSe * std::max(1.0, std::fabs(cal.value[a]))) null.push_back(a);
  }
  cal.undetermined.assign(cal.value.size(), false);
  for (std::size_t a : null) {
    cal.se_cov[a] = kNaN;
    cal.undetermined[a] = true;
  }
  if (null.size() > 1 && null.size() == quoted) {   // every direction: the optimum's Jacobian, not one coefficient
    cal.warnings.push_back("the covariance is 0 to rounding in every direction (a degenerate Jacobian at this optimum): "
                           "no covariance errors quoted; the jackknife's where its refits spread, which may understate them (the "
                           "refits start at this optimum, where the steps are as ill-conditioned)");
    return;
  }
  for (std::size_t a : null)
    cal.warnings.push_back(cal.names[a] + " is not determined by these curves (its covariance error is 0 to rounding: it "
                           "does not act on them); no standard error quoted");
}

namespace {

// The Jacobian at the optimum against central differences (check_jacobian), into cal.jacobian_disagreement (nan
// where not checked); smoothness_verdict reads it once the errors to quote are settled.
void jacobian_smoothness(ceres::Problem& problem, std::vector<double>& isob, std::vector<double>& shear,
                         std::vector<double>& ext, const CalibrationOptions& o, bool X, Calibration& cal) {
  cal.jacobian_disagreement.assign(cal.value.size(), kNaN);
  if (!o.check_jacobian) return;
  std::vector<double*> blocks = {shear.data()};
  std::vector<int> offset = {kNumIso};
  if (X) { blocks.push_back(ext.data()); offset.push_back(kNumIso + kNumShear); }
  if (o.fit_isotropic) { blocks.insert(blocks.begin(), isob.data()); offset.insert(offset.begin(), 0); }
  for (const JacobianColumn& c : check_jacobian(problem, blocks)) {
    const int at = offset[c.block] + c.index;
    if (at < static_cast<int>(cal.value.size())) cal.jacobian_disagreement[at] = c.disagreement;
  }
}

// Where a quoted coefficient's column disagrees: cal.rough and a warning. The covariance rests on that Jacobian, and
// the jackknife's refits, which start here, on its steps. Coefficients without a quoted error are not counted (their
// disagreement becomes nan): on a bound, or on a kink of a law, the covariance does not describe them anyway, and the
// law's derivative may be singular there (the frictionless default's nu_cC on the branch's lowest jammed point, where
// (nu/nu_cC - 1)^alpha starts, misses by 0.998).
void smoothness_verdict(Calibration& cal) {
  int worst = -1, above = 0, checked = 0;
  for (std::size_t a = 0; a < cal.jacobian_disagreement.size() && a < cal.se_cov.size(); ++a) {
    double& d = cal.jacobian_disagreement[a];
    if (std::isnan(d)) continue;
    if (std::isnan(cal.se_cov[a])) { d = kNaN; continue; }
    ++checked;
    if (!(d <= kRoughAbove)) ++above;
    if (worst < 0 || !(d <= cal.jacobian_disagreement[worst])) worst = static_cast<int>(a);
  }
  if (above == 0) return;
  cal.rough = std::to_string(above) + " of " + std::to_string(checked) + " coefficients' Jacobian columns miss the "
              "central differences of the residuals by more than " + fmt(kRoughAbove, 2) + ", " + cal.names[worst] +
              (std::isinf(cal.jacobian_disagreement[worst]) ? " not evaluated at a stepped point (its residuals not numbers)"
                                                             : "'s by " + fmt(cal.jacobian_disagreement[worst], 3));
  cal.warnings.push_back("the cost is not smooth at the optimum: " + cal.rough + " (docs/model.md, \"A cost that is "
                         "not smooth at its optimum\"): the covariance, and the jackknife's refits that start here, rest "
                         "on a Jacobian that is not the residuals' derivative, so parameters.csv quotes the errors as not "
                         "determined (se nan; se_covariance and se_jackknife keep the numbers). A fixed-step integration "
                         "across a point where the model is singular does this: e.g. an elastic state that crosses the "
                         "coordination law's nu_cC, where the bulk modulus has (nu/nu_cC - 1)^(alpha - 1)");
}

// The errors' last checks, once the held, bounded and kinked coefficients have lost theirs: the Jacobian's verdict
// over the coefficients still quoted (smoothness_verdict), then the covariance's null directions (null_directions).
// In that order a Jacobian degenerate in every direction (the relaxing three-pressure joint fit rerun in the
// twenty-second round) is still judged.
void settle_errors(Calibration& cal) {
  smoothness_verdict(cal);
  null_directions(cal);
}

// Covariance of all parameters (isotropic block zero when held), scaled by max(1, chi2/dof); returns it unscaled,
// row-major over the reported coefficients (empty where it could not be computed).
std::vector<double> covariance_errors(ceres::Problem& problem, std::vector<double>& isob, std::vector<double>& shear,
                                      std::vector<double>& ext, const CalibrationOptions& o, bool X, Calibration& cal) {
  const int np = kNumIso + kNumShear + (X ? ext_block(o) : 0);
  cal.se_cov.assign(np, kNaN);
  cal.corr.assign(np, std::vector<double>(np, kNaN));
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<const double*> blocks = {shear.data()};
  if (X) blocks.push_back(ext.data());
  if (o.fit_isotropic) blocks.insert(blocks.begin(), isob.data());
  std::vector<double> full;
  if (covariance_safe(problem) && cov.Compute(blocks, &problem)) {
    full.assign(np * np, 0.0);
    if (o.fit_isotropic) {
      cov.GetCovarianceMatrix(blocks, full.data());
    } else {
      const int ns = np - kNumIso;
      std::vector<double> sub(ns * ns);
      cov.GetCovarianceMatrix(blocks, sub.data());
      for (int a = 0; a < ns; ++a)
        for (int b = 0; b < ns; ++b) full[(kNumIso + a) * np + kNumIso + b] = sub[a * ns + b];
    }
    const double scale = std::max(1.0, cal.chi2_dof());
    for (int a = 0; a < np; ++a) {
      const double v = full[a * np + a] * scale;
      cal.se_cov[a] = (o.fit_isotropic || a >= kNumIso) ? std::sqrt(std::max(v, 0.0)) : kNaN;
    }
    for (int a = 0; a < np; ++a)
      for (int b = 0; b < np; ++b) {
        const double d = std::sqrt(full[a * np + a] * full[b * np + b]);
        cal.corr[a][b] = d > 0 ? full[a * np + b] / d : kNaN;
      }
  } else {
    cal.warnings.push_back("covariance could not be computed (rank-deficient or non-finite Jacobian): some parameters are not "
                           "determined by these curves");
  }
  jacobian_smoothness(problem, isob, shear, ext, o, X, cal);
  return full;
}

ceres::Solver::Summary solve(ceres::Problem& problem, int max_iterations);

// The cost over one quoted covariance error either way (check_error_scale), into cal.error_scale, once the errors to
// quote are settled: every coefficient with a quoted covariance error stepped along its linearised profile with the
// free coefficients that quote none (on a bound, kinked, not determined) held where they are. With o.profile, the
// same coefficients' profile intervals too (profile_intervals, into cal.profile): the others refitted at each point.
void check_quoted_errors(ceres::Problem& problem, std::vector<double>& isob, std::vector<double>& shear,
                         std::vector<double>& ext, const CalibrationOptions& o, bool X, const std::vector<double>& full,
                         Calibration& cal) {
  cal.error_scale.assign(cal.value.size(), ErrorScale{});
  cal.profile.clear();
  const std::size_t n = cal.se_cov.size();
  if (full.size() != n * n) return;
  std::vector<double*> blocks = {isob.data(), shear.data()};
  if (X) blocks.push_back(ext.data());
  std::vector<int> quoted, held;
  for (int a = 0; a < static_cast<int>(n); ++a) {
    if (std::isfinite(cal.se_cov[a]) && cal.se_cov[a] > 0) quoted.push_back(a);
    else if (full[a * n + a] > 0) held.push_back(a);
  }
  const double scale = std::max(1.0, cal.chi2_dof());
  if (o.check_jacobian) {
    const std::vector<ErrorScale> got = check_error_scale(problem, blocks, full, quoted, scale, 1.0, held);
    for (std::size_t k = 0; k < got.size(); ++k) cal.error_scale[quoted[k]] = got[k];
  }
  if (!o.profile) return;
  if (!o.profile_only.empty())
    quoted.erase(std::remove_if(quoted.begin(), quoted.end(), [&](int a) {
                   return std::find(o.profile_only.begin(), o.profile_only.end(), cal.names[a]) == o.profile_only.end();
                 }), quoted.end());
  const ProfileSolve refit = [&o](ceres::Problem& p) { return solve(p, o.max_iterations).IsSolutionUsable(); };
  const ProfileProgress said = [&](int k, int n, const ProfileInterval& p) {
    if (o.profile_progress) o.profile_progress(cal.names[quoted[k]], k, n, p);
  };
  if (o.profile_progress) o.profile_progress("", -1, static_cast<int>(quoted.size()), ProfileInterval{});
  const std::vector<ProfileInterval> got =
      profile_intervals(problem, blocks, full, quoted, scale, refit, held, 0.05, 10, 16, said);
  cal.profile.assign(cal.value.size(), ProfileInterval{});
  for (std::size_t k = 0; k < got.size(); ++k) cal.profile[quoted[k]] = got[k];
}

// Shear and extension coefficients that end on a bound of set_bounds: no standard error (the covariance describes the
// problem without the active bound, and the jackknife's refits, which start there, stay on it: a spread of 0), and said.
void bound_warnings(const ceres::Problem& problem, const std::vector<double>& shear, const std::vector<double>& ext,
                    bool X, int n_ext, Calibration& cal) {
  auto check = [&](const double* block, int i, int at, const char* name) {
    if (!std::isfinite(cal.se_cov[at])) return;   // held, or quoted without an error already
    const double v = block[i], tol = 1e-9 * std::max(1.0, std::fabs(v));
    const double lo = problem.GetParameterLowerBound(block, i), hi = problem.GetParameterUpperBound(block, i);
    if (std::fabs(v - lo) > tol && std::fabs(v - hi) > tol) return;
    cal.se_cov[at] = kNaN;
    cal.warnings.push_back(std::string(name) + " sits on its bound " + fmt(v, 6) + ": no standard error quoted (the "
                           "data would take it beyond; docs/model.md)");
  };
  for (int i = 0; i < kNumShear; ++i) check(shear.data(), i, kNumIso + i, shear_name(i));
  if (X)
    for (int i = 0; i < n_ext; ++i) check(ext.data(), i, kNumIso + kNumShear + i, ext_name(i));
}

/// Whether nu_c is bounded below by nu_cC (floor_nu_c): the volume-form state parameter, the isotropic block fitted,
/// nu_cC held and nu_c not.
bool nu_c_floored(const CalibrationOptions& o) {
  const auto holds = [&](int i) { return std::find(o.hold_iso.begin(), o.hold_iso.end(), i) != o.hold_iso.end(); };
  return o.state_volume && o.fit_isotropic && holds(kNuCC) && !holds(kNuC);
}

/// Whether C1 is bounded below by 0 (`--coordination rising`, the default since issue 31's twenty-third round): the
/// isotropic block fitted and C1 not held. The branch's coordination rises with the density at every mu; a fit free
/// to let it fall traded the branch's C for the paths' stiffness (docs/model.md, "A coordination that rises").
bool coordination_floored(const CalibrationOptions& o) {
  const bool held = std::find(o.hold_iso.begin(), o.hold_iso.end(), kC1) != o.hold_iso.end();
  return o.fit_isotropic && o.coordination_rises && !held;
}

/// C1 on its floor 0 (coordination_floored): a flat coordination law, C = C0, whose nu_cC and alpha are not read; no
/// errors quoted for the three, and said, with the branch's own rise of C that the paths pulled it from.
void coordination_warning(const IsoData& iso, const CalibrationOptions& o, const std::vector<double>& isob,
                          Calibration& cal) {
  if (!coordination_floored(o) || isob[kC1] > 1e-12 || iso.nu.empty()) return;
  for (int i : {kC1, kNuCC, kAlpha}) cal.se_cov[i] = kNaN;
  const auto lo = std::min_element(iso.nu.begin(), iso.nu.end()) - iso.nu.begin();
  const auto hi = std::max_element(iso.nu.begin(), iso.nu.end()) - iso.nu.begin();
  cal.warnings.push_back("C1 sits on its bound 0 (--coordination rising): the coordination law is flat, C = C0 = " +
                         fmt(isob[kC0], 4) + ", where the isotropic branch's C_nonrattler goes from " +
                         fmt(iso.C[lo], 4) + " at nu = " + fmt(iso.nu[lo], 4) + " to " + fmt(iso.C[hi], 4) +
                         " at nu = " + fmt(iso.nu[hi], 4) + ": the paths pull the law below the branch (nu_cC and "
                         "alpha are not read; no standard errors quoted). --coordination free lets it fall with the "
                         "density (docs/model.md, \"A coordination that rises\")");
}

/// Held isotropic coefficients have no error of their own. With one jamming fraction (`tied`) the fitted law is
/// written with nu_cC = nu_c (the same law as the tie's) and nu_c's error.
void held_errors(Calibration& cal, const std::set<int>& held, const std::vector<int>& held_x, bool tied) {
  for (int i : held) cal.se_cov[i] = kNaN;
  for (int i : held_x) cal.se_cov[kNumIso + kNumShear + i] = kNaN;
  if (!tied) return;
  cal.shared_jamming = true;
  cal.params.nu_cC = cal.params.nu_c;
  cal.value[kNuCC] = cal.value[kNuC];
  cal.se_cov[kNuCC] = cal.se_cov[kNuC];
}

// The highest start pressure p* among the fitted curves and paths, and which (its name and nu): with the volume-form
// state parameter the isotropic law must reach it (isotropic_reach, start_state).
double highest_start_pressure(const std::vector<CurveData>& curves, const std::vector<PathData>& paths, std::string* which) {
  double top = 0.0;
  const auto consider = [&](double p, const std::string& name, double nu) {
    if (p > top) { top = p; *which = name + " at nu = " + std::to_string(nu); }
  };
  for (const auto& c : curves) consider(c.p.front(), c.mode, c.nu);
  for (const auto& d : paths) consider(d.p.front(), d.name, d.nu);
  return top;
}

// A fit whose isotropic law ends at the highest start pressure (within kOnReach) sits on the edge of the elastic
// split's domain: beyond it that start has no elastic volume fraction and the cost is not a number, a bound Ceres
// does not see (the joint bounded variant's optimum, thirty-third round). p0, which scales the reach, quotes no error.
constexpr double kOnReach = 1e-4;
void reach_warning(const std::vector<CurveData>& curves, const std::vector<PathData>& paths, const CalibrationOptions& o,
                   const std::vector<double>& isob, Calibration& cal) {
  std::string which;
  const double top = highest_start_pressure(curves, paths, &which), reach = isotropic_reach(isob.data());
  if (!o.fit_isotropic || !(top > 0) || !(reach < top * (1 + kOnReach))) return;
  cal.se_cov[kP0] = kNaN;
  cal.warnings.push_back("the isotropic law ends at the highest start pressure (it reaches p* = " + fmt(reach, 7) +
                         " at most, the start of " + which + " is at " + fmt(top, 7) + "): the fit sits on the edge of the "
                         "elastic split's domain, a bound on p0, nu_c and the coordination law that Ceres does not see; "
                         "p0 quotes no standard error (docs/model.md, \"A start beyond the isotropic law's reach\")");
}

// What the data leave undetermined: the nu-slopes from one start volume fraction, jamming
// fractions on their bounds (no standard errors quoted for them).
void calibration_warnings(const std::vector<CurveData>& curves, const std::vector<PathData>& paths, const IsoData& iso,
                          const CalibrationOptions& o, const std::vector<double>& isob, double numin, bool one_nu,
                          bool X, Calibration& cal) {
  if (one_nu) {
    for (int i = 1; i < kNumShear; i += 2) cal.se_cov[kNumIso + i] = kNaN;
    if (X)
      for (int i : {kNFB, kKappaB, kDilB}) cal.se_cov[kNumIso + kNumShear + i] = kNaN;
    if (X && o.state_limit) cal.se_cov[kNumIso + kNumShear + kNPsiB] = kNaN;
    cal.warnings.push_back("one start volume fraction (nu = " + std::to_string(curves.empty() ? paths.front().nu : curves.front().nu) +
                           "): the nu-slopes (*_b) are not determined by the data; held at 0 without standard errors, "
                           "so the laws hold at this nu only. Calibrate on ensembles from several checkpoints "
                           "(protocol.checkpoints_unloading)");
  }
  for (int i : {kNuC, kNuCC})
    if (o.fit_isotropic && isob[i] >= numin * (1 - 2e-6)) {
      cal.se_cov[i] = kNaN;
      cal.warnings.push_back(std::string(iso_name(i)) + " sits on its bound (the lowest " +
                             (X && o.state_volume ? "isotropic-branch" : "start") + " volume fraction " +
                             std::to_string(numin) + "): no standard error quoted");
    }
  if (X && nu_c_floored(o) && isob[kNuC] <= isob[kNuCC] * (1 + 1e-9)) {
    cal.se_cov[kNuC] = kNaN;
    cal.warnings.push_back("nu_c sits on its bound, the held nu_cC (" + std::to_string(isob[kNuCC]) +
                           "; below it the isotropic law's stiffness would be unbounded on the paths): no standard "
                           "error quoted");
  }
  if (X && o.state_volume && std::isfinite(cusp_pressure(isob.data())))
    cal.warnings.push_back("nu_cC (" + std::to_string(isob[kNuCC]) + ") lies above nu_c (" + std::to_string(isob[kNuC]) +
                           "): the isotropic law's stiffness is unbounded at p* = " +
                           std::to_string(cusp_pressure(isob.data())) +
                           ", and a path through that pressure ends where its steps put it" +
                           (o.excess_relaxes ? std::string(" (with the relaxing excess the elastic state sits at p* - q, "
                                                           "below the path's pressure: a cusp below the tests' pressures "
                                                           "is met too)") : std::string()) +
                           ". Hold nu_cC (--hold-isotropic nu_cC): nu_c is then kept at or above it; or tie the two "
                           "(--jamming shared)");
  else if (o.fit_isotropic && std::isfinite(cusp_pressure(isob.data())))
    cal.warnings.push_back("nu_cC (" + std::to_string(isob[kNuCC]) + ") lies above nu_c (" + std::to_string(isob[kNuC]) +
                           "): the isotropic law's stiffness is unbounded at nu = nu_cC, which a path whose volume "
                           "fraction crosses it meets (a kink in an isobaric or drained path near jamming; constant-"
                           "volume curves do not). --jamming shared ties the two (docs/model.md, \"One jamming fraction\")");
  if (o.fit_isotropic && !iso.nu.empty()) {
    const double lowest = *std::min_element(iso.nu.begin(), iso.nu.end());
    if (std::fabs(isob[kNuCC] - lowest) < 1e-9) {
      cal.se_cov[kNuCC] = kNaN;
      cal.warnings.push_back("nu_cC sits on the lowest jammed point of the isotropic branch (" + std::to_string(lowest) +
                             "): the power law's onset is set by where the branch data start, no standard error quoted");
    }
  }
  coordination_warning(iso, o, isob, cal);
  if (X && o.state_volume) reach_warning(curves, paths, o, isob, cal);
}

/// The calibration's inputs checked (curves or paths with start values, held isotropic indices,
/// enough isotropic points); returns the held isotropic parameters.
std::set<int> checked_inputs(const std::vector<CurveData>& curves_in, const IsoData& iso, const CalibrationOptions& o,
                             const std::vector<PathData>& paths) {
  if (curves_in.empty() && (paths.empty() || !o.start))
    throw std::invalid_argument("model calibration: no curves to fit (need D2 ensemble curves, or path ensembles "
                                "with start values: --start PARAMETERS.csv)");
  for (int i : o.hold_iso)
    if (i < 0 || i >= kNumIso) throw std::invalid_argument("model calibration: hold_iso index out of range");
  if (!o.hold_iso.empty() && !o.start)
    throw std::invalid_argument("model calibration: isotropic parameters can only be held at given start values "
                                "(--hold-isotropic needs --start PARAMETERS.csv)");
  if (o.state_volume && (!o.extended || o.state_limit))
    throw std::invalid_argument("model calibration: the volume-form state parameter (--state-limit volume) belongs to the "
                                "extended family and replaces the pressure form: give --family extended and one "
                                "--state-limit");
  std::set<int> held(o.hold_iso.begin(), o.hold_iso.end());
  if (o.shared_jamming) {
    if (!o.fit_isotropic || held.count(kNuCC))
      throw std::invalid_argument("model calibration: one jamming fraction (--jamming shared) ties nu_cC to the fitted "
                                  "nu_c: fit the isotropic block and leave nu_cC out of --hold-isotropic");
    held.insert(kNuCC);
  }
  const std::size_t need_iso = held.empty() ? 8 : kNumIso - held.size() + 2;
  if (o.fit_isotropic && iso.nu.size() < need_iso)
    throw std::invalid_argument("model calibration: only " + std::to_string(iso.nu.size()) +
                                " isotropic-branch points (need >= " + std::to_string(need_iso) +
                                " jammed points of cycle_unloading.csv with p* > 0" +
                                (held.empty() ? ", or hold some isotropic parameters" : "") + ")");
  return held;
}

/// With the volume-form state parameter and nu_cC held (nu_c free), nu_c is kept at or above it, a start below moved
/// onto it: the isotropic law's stiffness is then bounded on every path (cusp_pressure).
void floor_nu_c(ceres::Problem& problem, std::vector<double>& isob, const CalibrationOptions& o) {
  if (!nu_c_floored(o)) return;
  isob[kNuC] = std::max(isob[kNuC], isob[kNuCC]);
  problem.SetParameterLowerBound(isob.data(), kNuC, isob[kNuCC]);
}

/// The isotropic block's floors: nu_c at the held nu_cC (floor_nu_c, volume-form state parameter) and C1 at 0
/// (coordination_floored), each start moved onto its floor where it lies below (Ceres refuses an infeasible start).
void isotropic_floors(ceres::Problem& problem, std::vector<double>& isob, const CalibrationOptions& o,
                      bool state_volume) {
  if (state_volume) floor_nu_c(problem, isob, o);
  if (!coordination_floored(o)) return;
  isob[kC1] = std::max(isob[kC1], 0.0);
  problem.SetParameterLowerBound(isob.data(), kC1, 0.0);
}

/// The extended family's start inside the bounds set_bounds sets (Ceres refuses an infeasible start).
void clamp_extended_start(std::vector<double>& shear, std::vector<double>& ext) {
  for (int i : {kLnBetaSA, kLnBetaFA, kLnBetaPA}) {
    shear[i] = std::min(std::max(shear[i], std::log(1e-3)), std::log(300.0));
    shear[i + 1] = std::min(std::max(shear[i + 1], -40.0), 40.0);
  }
  ext[kNFA] = std::min(std::max(ext[kNFA], -1.0), 30.0);
  ext[kKappaA] = std::min(std::max(ext[kKappaA], -0.9), 30.0);
  ext[kChiD] = std::min(std::max(ext[kChiD], -1.0), 3.0);
  if (ext[kLnDeltaW] == 0.0 && ext[kNW] == 0.0) {   // the `Weighted` rule's start (unread by the others): w = 1/2 at
    ext[kLnDeltaW] = std::log(kDeltaWStart);        // delta/d = 0.03, the middle of the friction study's overlaps
    ext[kNW] = 4.0;
  }
}

/// The number of distinct start pressures of the calibrated curves and paths: start p* sorted, a new one where it is
/// more than 1.5 times the last (a dense and a loose sample under the same confining pressure count once).
int start_pressures(const std::vector<CurveData>& curves, const std::vector<PathData>& paths) {
  std::vector<double> lp;
  for (const auto& c : curves) lp.push_back(std::log(std::max(c.p.front(), 1e-300)));
  for (const auto& d : paths) lp.push_back(std::log(std::max(d.p.front(), 1e-300)));
  std::sort(lp.begin(), lp.end());
  int n = lp.empty() ? 0 : 1;
  for (std::size_t i = 1; i < lp.size(); ++i)
    if (lp[i] - lp[i - 1] > std::log(1.5)) ++n;
  return n;
}

/// The extension coefficients held: the nu-slopes (*_b) from one start volume fraction (not determined by the
/// data), n_psi when the `Weighted` rule's block carries it with the limit off (at 0), and the `Weighted` rule's
/// two coefficients when the Lode-dependent state exponent's block carries them for another rule (at their start,
/// unread).
std::vector<int> held_ext(bool one_nu, bool state_limit, bool weighted, bool state_lode = false, bool state_volume = false,
                          int n_p = 1) {
  std::vector<int> held;
  if (state_volume) {   // chi_D at 1 (the phase transformation at r = 1 on the critical-state line), the other laws' entries
    held = {kDilB, kChiD, kNPsiA, kNPsiB, kLambdaPsi, kNuCs, kLambdaCs, kCCs};   // d_D's state dependence is psi's; the
                                                                       // critical-state line the end states'
    if (n_p < 2) held.push_back(kNRate);   // the rates' pressure exponent needs two start pressures (else held at its
    if (n_p < 3) held.push_back(kMPeak);   // start); the peak's, three (from two it trades with n_peak and the psi-laws)
    if (!weighted) held.insert(held.end(), {kLnDeltaW, kNW});
    if (one_nu) held.insert(held.end(), {kNFB, kKappaB});
    std::sort(held.begin(), held.end());
    return held;
  }
  if (one_nu) held = {kNFB, kKappaB, kDilB};
  if (one_nu && state_limit) held.push_back(kNPsiB);
  if (weighted && !state_limit) held.insert(held.end(), {kNPsiA, kNPsiB});
  if (state_lode && !weighted) held.insert(held.end(), {kLnDeltaW, kNW});
  return held;
}

/// The shear coefficients held (hold_ext says why).
/// With the volume-form state parameter s_max_b (the peak's state is psi's) and beta_p's slope; beta_p itself too
/// unless the anisotropic excess relaxes (without it the pressure stays on the isotropic law at nu_el: beta_p does
/// not act).
std::set<int> held_shear(bool X, bool one_nu, bool state_volume, bool excess_relaxes) {
  std::set<int> held;
  if (one_nu) held = {kSmaxB, kLnBetaSB, kFmaxB, kLnBetaFB, kAnisoB, kLnBetaPB};
  if (X && state_volume) held.insert({kSmaxB, kLnBetaPB});
  if (X && state_volume && !excess_relaxes) held.insert(kLnBetaPA);
  return held;
}

/// held_ext and the coefficients --hold names that the block of n_block entries carries, sorted, each once.
std::vector<int> with_user_held(std::vector<int> held, const std::vector<int>& user, int n_block) {
  for (int i : user)
    if (i < n_block) held.push_back(i);
  std::sort(held.begin(), held.end());
  held.erase(std::unique(held.begin(), held.end()), held.end());
  return held;
}

/// A held extension coefficient that keeps its start value (the others held are set to 0): one --hold names, the
/// unread `Weighted` pair (inside its bounds), the critical-state line (the end states') and the pressure exponents.
bool keeps_start(int i, const std::vector<int>& user) {
  static const std::set<int> own = {kLnDeltaW, kNW, kNuCs, kLambdaCs, kCCs, kNRate, kMPeak};
  return own.count(i) > 0 || std::find(user.begin(), user.end(), i) != user.end();
}

/// One start volume fraction: every nu-slope (*_b) held at 0; with the extension block, held_ext and --hold.
void hold_ext(ceres::Problem& problem, std::vector<double>& shear, std::vector<double>& ext, bool X, bool one_nu,
              bool state_limit, bool weighted, bool state_lode, bool state_volume, bool excess_relaxes, int n_p,
              const std::vector<int>& user) {
  // Held shear coefficients: the nu-slopes from one start volume fraction; with the volume-form state parameter s_max_b
  // at 0 (the limit's state dependence is psi's, s_lim e^{n_b psi}) and beta_p at its start unless the anisotropic
  // excess relaxes (else it does not act: the pressure stays on the isotropic law at nu_el).
  const std::set<int> held_s = held_shear(X, one_nu, state_volume, excess_relaxes);
  for (int i : held_s)
    if (i % 2 == 1) shear[i] = 0.0;
  if (!held_s.empty())
    problem.SetManifold(shear.data(), new ceres::SubsetManifold(kNumShear, std::vector<int>(held_s.begin(), held_s.end())));
  const std::vector<int> held = with_user_held(held_ext(one_nu, state_limit, weighted, state_lode, state_volume, n_p), user,
                                               ext_size(state_limit, weighted, state_lode, state_volume));
  if (!X || held.empty()) return;
  for (int i : held)
    if (!keeps_start(i, user)) ext[i] = 0.0;
  if (state_volume) ext[kChiD] = 1.0;
  problem.SetManifold(ext.data(), new ceres::SubsetManifold(ext_size(state_limit, weighted, state_lode, state_volume), held));
}

/// The calibration's solver options (dense QR, tight tolerances, one thread: the same bits on every run).
ceres::Solver::Options solver_options(int max_iterations) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.num_threads = 1;
  return so;
}

/// One Ceres solve of the calibration (a profile's refit).
ceres::Solver::Summary solve(ceres::Problem& problem, int max_iterations) {
  ceres::Solver::Summary sum;
  ceres::Solve(solver_options(max_iterations), &problem, &sum);
  return sum;
}

/// One Ceres solve of the calibration, the values of `blocks` one settle_window before the iteration limit kept in
/// `window_start` (empty if the fit ended before).
ceres::Solver::Summary solve(ceres::Problem& problem, int max_iterations, const std::vector<double*>& blocks,
                             std::vector<std::vector<double>>& window_start) {
  ceres::Solver::Options so = solver_options(max_iterations);
  WindowStart watch(problem, blocks, max_iterations - settle_window(max_iterations));
  so.update_state_every_iteration = true;   // a copy of the state for `watch`; the steps are the same
  so.callbacks.push_back(&watch);
  ceres::Solver::Summary sum;
  ceres::Solve(so, &problem, &sum);
  window_start = watch.values();
  return sum;
}

/// The warning solve_on_face leaves: how many coefficients it held (`n`, counting each once), how many of them it
/// released, and chi^2 before and after.
std::string face_note(std::size_t n, std::size_t freed, bool kinked, double first, double last, int iterations,
                      int passes) {
  const std::string s = n > 1 ? "s" : "";
  return "the fit ended with " + std::to_string(n) + " coefficient" + s + " on a bound" +
         (kinked ? " or on the kink of nu_cC at the branch's lowest point" : "") + " at chi2 " + fmt(first, 8) +
         ", and went on with " + (n > 1 ? "them" : "it") + " held there" +
         (freed ? " (" + std::to_string(freed) + " set free again where chi2 fell into the box)" : "") + " to " +
         fmt(last, 8) + " (" + std::to_string(iterations) + " iterations" +
         (passes > 1 ? " in " + std::to_string(passes) + " passes" : "") + "; "
         "Levenberg-Marquardt's projected steps stall at a bound; docs/model.md, \"A fit that stopped on a bound\")";
}

/// The fit, and where it ends with coefficients on a bound of the problem (or within kNearBound of one: moved onto
/// it), or with nu_cC on the isotropic branch's lowest jammed point (the coordination law's onset on a data point: a
/// kink of the cost), again with those held where they are (hold_on_bounds): Levenberg-Marquardt's projected steps
/// stall there before the free coefficients reach their minimum (issue 31, twenty-third round; docs/model.md, "A fit
/// that stopped on a bound"). Repeated while a pass ends on a bound not held before (twenty-fourth round), and, once
/// none is met, with the held ones whose chi^2 falls into the box set free (release_from_bounds; twenty-fifth round: an
/// active set, each entry released once), at most kFacePasses times. Returns the last summary.
ceres::Solver::Summary solve_on_face(ceres::Problem& problem, std::vector<double*> blocks, std::vector<double>& isob,
                                     const IsoData& iso, const CalibrationOptions& o, const std::set<int>& held,
                                     std::vector<std::string>& notes, std::vector<std::vector<double>>& window_start) {
  ceres::Solver::Summary last = solve(problem, o.max_iterations, blocks, window_start);
  const double first = 2 * last.final_cost;
  std::vector<std::pair<double*, int>> face, released;
  int passes = 0, iterations = 0;
  bool kinked = false;
  for (; passes < kFacePasses && last.IsSolutionUsable(); ++passes) {
    std::vector<std::pair<double*, int>> kink;
    if (o.fit_isotropic && !o.shared_jamming && !held.count(kNuCC) && !iso.nu.empty() &&
        std::fabs(isob[kNuCC] - *std::min_element(iso.nu.begin(), iso.nu.end())) < 1e-9)
      kink.emplace_back(isob.data(), kNuCC);
    const std::size_t before = face.size();
    if (hold_on_bounds(problem, blocks, kink, kNearBound, &face) == 0 && !release_once(problem, blocks, face, released))
      break;
    kinked = kinked || (!kink.empty() && face.size() > before);
    last = solve(problem, o.max_iterations, blocks, window_start);
    iterations += static_cast<int>(last.iterations.size());
  }
  if (passes == 0) return last;
  std::set<std::pair<double*, int>> all(face.begin(), face.end());
  all.insert(released.begin(), released.end());
  notes.push_back(face_note(all.size(), released.size(), kinked, first, 2 * last.final_cost,
                            iterations, passes));
  return last;
}

/// cal.ok from the last solve: Ceres converged, or stopped at its limit settled in chi^2 (settle.hpp; the note in
/// cal.settled and the warnings). Needs cal.chi2, n_residuals and n_free.
void judge_convergence(const ceres::Solver::Summary& sum, int max_iterations, Calibration& cal) {
  const double scale = std::max(1.0, cal.chi2_dof());
  const Settling st = settling(sum, settle_window(max_iterations), scale);
  cal.ok = sum.IsSolutionUsable() && (sum.termination_type == ceres::CONVERGENCE || st.settled);
  if (st.settled) {
    cal.settled = settle_note(st, scale);
    cal.message += "; settled: " + fall_phrase(st, scale);   // jackknife.md's and starts.md's message
    cal.warnings.push_back(cal.settled);
  } else if (!cal.ok) {
    cal.warnings.push_back("optimiser did not converge: " + sum.message +
                           (st.window > 0 ? " (" + fall_phrase(st, scale) + "; settled below " +
                                                    fmt(kSettleFraction, 2) + ")"
                                              : ""));
  }
}

/// A settled fit's coefficients that still moved over the window by more than a tenth of their covariance error:
/// appended to cal.settled and its warning (a flat valley along which the cost no longer falls, but a coefficient runs).
void moving_note(const std::vector<std::vector<double>>& window_start, Calibration& cal) {
  std::vector<double> before;
  for (const auto& b : window_start) before.insert(before.end(), b.begin(), b.end());
  std::string moving;   // the same order as cal.value (iso, shear, ext: the ext block longer than its quoted entries)
  for (std::size_t i = 0; i < cal.value.size() && i < before.size(); ++i) {
    const double moved = std::fabs(cal.value[i] - before[i]), se = cal.se_cov[i];
    if (std::isfinite(se) && se > 0 && moved > 0.1 * se)
      moving += (moving.empty() ? "" : ", ") + cal.names[i] + " by " + fmt(moved / se, 2) + " errors";
  }
  const std::string tail = moving.empty() ? "; no coefficient moved by more than 0.1 of its covariance error over them"
                                          : "; still moving over them: " + moving;
  cal.settled += tail;
  for (auto& w : cal.warnings)
    if (w.rfind("Ceres stopped at its limit", 0) == 0) w += tail;
}

/// The start's parameters with the fitted blocks and the options' family, surface, rules and limit.
Parameters fitted_params(const Parameters& start, const std::vector<double>& isob, const std::vector<double>& shear,
                         const std::vector<double>& ext, const CalibrationOptions& o, bool X) {
  Parameters P = start;
  P.set_iso(isob.data());
  std::copy(shear.begin(), shear.end(), P.shear);
  std::copy(ext.begin(), ext.end(), P.ext);
  P.extended = X;
  P.surface = X ? o.surface : Surface::None;
  P.fabric = X ? o.fabric : FabricLode::Norm;
  P.b_d2 = o.b_d2;
  P.state_limit = X && o.state_limit;
  P.state_lode = X && o.state_limit && o.state_lode;
  P.state_volume = X && o.state_volume;
  P.excess_relaxes = P.state_volume && o.excess_relaxes;
  P.excess_bounded = P.excess_relaxes && o.excess_bounded;
  P.start_unaligned = o.start_unaligned;
  P.dilatancy_gated = X && o.dilatancy_gated && !o.state_volume;
  P.fabric_state = P.state_limit && o.fabric_state;
  P.deviator_reference = X && o.deviator_reference && !o.state_volume;
  return P;
}

}  // namespace

/// Entries [pos, pos + n) of the reported parameters removed (names, values, errors, correlations):
/// coefficients the block carries but the law does not have.
void drop_entries(Calibration& cal, int pos, int n) {
  cal.names.erase(cal.names.begin() + pos, cal.names.begin() + pos + n);
  cal.value.erase(cal.value.begin() + pos, cal.value.begin() + pos + n);
  cal.se_cov.erase(cal.se_cov.begin() + pos, cal.se_cov.begin() + pos + n);
  if (cal.undetermined.size() >= static_cast<std::size_t>(pos + n))
    cal.undetermined.erase(cal.undetermined.begin() + pos, cal.undetermined.begin() + pos + n);
  if (cal.jacobian_disagreement.size() >= static_cast<std::size_t>(pos + n))
    cal.jacobian_disagreement.erase(cal.jacobian_disagreement.begin() + pos, cal.jacobian_disagreement.begin() + pos + n);
  if (cal.error_scale.size() >= static_cast<std::size_t>(pos + n))
    cal.error_scale.erase(cal.error_scale.begin() + pos, cal.error_scale.begin() + pos + n);
  if (cal.profile.size() >= static_cast<std::size_t>(pos + n))
    cal.profile.erase(cal.profile.begin() + pos, cal.profile.begin() + pos + n);
  cal.corr.erase(cal.corr.begin() + pos, cal.corr.begin() + pos + n);
  for (auto& row : cal.corr) row.erase(row.begin() + pos, row.begin() + pos + n);
}

namespace {

/// The volume-form state parameter's table: the entries its block carries for the other laws (n_psi, lambda_psi, and
/// the `Weighted` pair under another rule) removed, the last first.
void drop_unread_for_volume_state(Calibration& cal, bool weighted) {
  const int x = kNumIso + kNumShear;
  drop_entries(cal, x + kLambdaPsi, 1);
  drop_entries(cal, x + kNPsiA, weighted ? 2 : 4);
}

std::pair<double, double> end_state_line(const std::vector<PathData>& paths, bool linear);

/// A start file re-centred on this data's nu_ref; with the volume-form state parameter the laws are laws of psi: a
/// volume-form start as it is, another re-centred on the end states' critical volume fraction (its laws there taken
/// as the critical state's, psi = 0).
Parameters start_of(const Parameters& s, const CalibrationOptions& o, const std::vector<PathData>& paths, double nu_ref) {
  if (!(o.extended && o.state_volume)) return recentred(s, nu_ref);
  if (s.state_volume) return s;
  end_state_line(paths, o.csl_linear);   // its refusal without paths
  double nu_end = 0;   // the least-squares line's mean value over the end states: their mean volume fraction
  for (const auto& d : paths) nu_end += d.nu_m.back() / paths.size();
  return recentred(s, nu_end);
}

/// The critical-state line of the calibration paths' end states: least squares of their end volume fractions on
/// ln(p*/kPCsRef) of their end pressures (`linear`: on p* - kPCsRef), {nu_cs, slope} (slope 0 from one pressure).
std::pair<double, double> end_state_line(const std::vector<PathData>& paths, bool linear) {
  if (paths.empty())
    throw std::invalid_argument("model calibration: --state-limit volume needs paths that reach the critical state "
                                "(--calibrate-on a drained test, e.g. TC_s3_dense): their end states give the line");
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = static_cast<double>(paths.size());
  for (const auto& d : paths) {
    const double x = linear ? d.p.back() - kPCsRef : std::log(std::max(d.p.back(), 1e-12) / kPCsRef);
    const double y = d.nu_m.back();
    sx += x; sy += y; sxx += x * x; sxy += x * y;
  }
  const double var = sxx - sx * sx / n;
  const double lambda = var > 1e-9 ? (sxy - sx * sy / n) / var : 0.0;
  return {sy / n - lambda * sx / n, lambda};
}

/// The volume-form state parameter's start: the critical-state line of the end states (held in the fit), d_D >= 0,
/// the state exponents at 2 where zero (a peak 1.1 times the limit at psi = 0.05; from 5 the dense start of
/// data/geotech's mu = 0.5 runs away: a contraction that raises psi and the peak until the side stress vanishes).
void volume_state_start(const std::vector<PathData>& paths, std::vector<double>& ext, bool csl_linear) {
  ext[kDilA] = std::fabs(ext[kDilA]);
  ext[kNFA] = std::max(ext[kNFA], 0.0);
  if (ext[kNB] == 0.0) ext[kNB] = 2.0;
  if (ext[kND] == 0.0) ext[kND] = 2.0;
  const auto line = end_state_line(paths, csl_linear);
  ext[kNuCs] = line.first;
  ext[kLambdaCs] = csl_linear ? 0.0 : line.second;
  ext[kCCs] = csl_linear ? line.second : 0.0;
  ext[kNRate] = std::min(std::max(ext[kNRate], 0.0), 3.0);
  ext[kMPeak] = std::min(std::max(ext[kMPeak], -1.0), 1.0);
}

}  // namespace

void check_second_lode_angle(const std::vector<CurveData>& curves, const std::vector<PathData>& paths,
                             const std::string& what, const std::string& or_else, double b_d2) {
  for (const auto& c : curves)
    if (lode_b_of(c.mode, b_d2) != kLodeBD2) return;
  for (const auto& d : paths)
    if (lode_b_of(d.name, b_d2) != kLodeBD2) return;
  throw std::invalid_argument("model calibration: " + what + " acts only away from D2's Lode angle, and every calibrated "
                              "curve is at b = 1/2: add a second Lode angle (--calibrate-on D2,D3, or a triaxial path) " +
                              or_else);
}

void check_weighted_lode(const std::vector<CurveData>& curves, const std::vector<PathData>& paths) {
  check_second_lode_angle(curves, paths, "the weighted fabric rule's Lode weight (ln_delta_w, n_w)",
                          "or choose another --fabric-lode");   // a fabric rule: the strain's b
}

namespace {
// One start volume fraction: (nu - nu_ref) is zero on every curve, so the nu-slopes (*_b) are not determined by the
// data: held at 0, quoted without errors, and said (calibration_warnings).
bool one_start_volume_fraction(const std::vector<CurveData>& curves, const std::vector<PathData>& paths) {
  std::set<long long> nus_seen;
  for (const auto& c : curves) nus_seen.insert(std::llround(c.nu * 1e6));
  for (const auto& d : paths) nus_seen.insert(std::llround(d.nu * 1e6));
  return nus_seen.size() < 2;
}

// With the volume-form state parameter a fitted curve's or path's start pressure must lie within the isotropic law's
// reach (isotropic_reach), or the start has no elastic volume fraction (start_state) and Ceres stops before its first
// step ("Residual and Jacobian evaluation failed"). A start from another fit can lie beyond it: a jackknife refit
// from the full optimum whose left-out mean starts higher, where that optimum sits on the reach (thirty-third round:
// the joint bounded variant's). p_iso is proportional to p0, so p0 is raised until the reach exceeds the highest
// start pressure by kReachMargin, and said; with p0 held or the branch not fitted, the cause is said.
constexpr double kReachMargin = 1e-3;
void start_within_reach(const std::vector<CurveData>& curves, const std::vector<PathData>& paths, const std::set<int>& held,
                        bool p0_free, std::vector<double>& isob, std::vector<std::string>& said, std::string& moved) {
  std::string which;
  const double top = highest_start_pressure(curves, paths, &which);
  const double reach = isotropic_reach(isob.data());
  if (!(top > reach)) return;
  const std::string cause = "the start's isotropic law reaches p* = " + std::to_string(reach) +
                            " at most (nu <= 1), below the start pressure " + std::to_string(top) + " of " + which;
  if (!p0_free || held.count(kP0) || !(reach > 0)) {
    said.push_back(cause + ": that start has no elastic volume fraction and cannot be evaluated (hold p0 free, or "
                   "start from a fit whose law reaches it)");
    return;
  }
  const double from = isob[kP0];
  isob[kP0] *= top / reach * (1.0 + kReachMargin);
  moved = "p0 raised from " + std::to_string(from) + " to " + std::to_string(isob[kP0]);
  said.push_back(cause + ": " + moved + " at the start, so that every start state has an elastic volume fraction");
}

// The start values: the given start (start_of), or the data's own fits; the frictional family without a start from the
// group model's calibration (its nested case) with a moderate extension (a fabric gated by the mobilisation, a stress
// ratio linear for longer).
Parameters calibration_start(const std::vector<CurveData>& curves_in, const std::vector<CurveData>& curves,
                             const IsoData& iso, const CalibrationOptions& o, const std::vector<PathData>& paths,
                             double nu_ref) {
  Parameters start = o.start ? start_of(*o.start, o, paths, nu_ref) : start_values(curves, iso, nu_ref);
  if (o.extended && !o.start) {
    CalibrationOptions g = o;
    g.extended = false;
    g.profile = false;   // the start's errors are not read
    Parameters base = calibrate(curves_in, iso, g, paths).params;
    base.nu_ref = nu_ref;
    start = extended_start(curves, base, o);
  }
  start.nu_ref = nu_ref;
  return start;
}
}  // namespace

namespace {
// The first row at which p, s or F is not a number; -1 where every one is.
int first_nan_row(const std::vector<double>& p, const std::vector<double>& s, const std::vector<double>& F) {
  for (std::size_t i = 0; i < p.size(); ++i)
    if (!std::isfinite(p[i]) || !std::isfinite(s[i]) || !std::isfinite(F[i])) return static_cast<int>(i);
  return -1;
}
}  // namespace

std::string start_failure(const Parameters& P, const std::vector<CurveData>& curves, const std::vector<PathData>& paths) {
  const std::vector<double> iso = P.iso();
  const bool volume = P.extended && P.state_volume;
  auto beyond = [&](double p0) {
    return volume && std::isnan(isotropic_volume<double>(iso.data(), p0))
               ? " starts at p* = " + fmt(p0, 6) + ", above the isotropic law's reach (" + fmt(isotropic_reach(iso.data()), 6) +
                     "; docs/model.md, \"A start beyond the isotropic law's reach\")"
               : std::string();
  };
  for (const auto& c : curves) {
    const std::string what = c.mode + " nu=" + fmt(c.nu, 4), out = beyond(c.p.front());
    if (!out.empty()) return what + out;
    const ModelCurve m = predict_curve(P, c);
    const int at = first_nan_row(m.p, m.s, m.F);
    if (at >= 0) return what + " is not a number from eps_d = " + fmt(m.eps[at], 3);
  }
  for (const auto& d : paths) {
    const std::string what = d.name + " nu=" + fmt(d.nu, 4), out = beyond(d.p.front());
    if (!out.empty()) return what + out;
    PathPrediction m;
    try {
      m = predict_path(P, d);
    } catch (const std::invalid_argument& e) {
      return what + ": " + e.what();
    }
    const std::string why = path_not_a_number(m);
    if (!why.empty()) return what + why;
  }
  return "";
}

std::string path_not_a_number(const PathPrediction& m) {
  if (m.lost_row >= 1)
    return " loses its drained control after eps_d_accumulated = " + fmt(m.acc[m.lost_row - 1], 3) + " (a_A F/3 within " +
           fmt(100 * kTriaxialMargin, 2) + " % of 1, the pole; docs/model.md, \"Where the drained triaxial control is lost\")";
  const int at = first_nan_row(m.p, m.s, m.F);
  return at >= 0 ? " is not a number from eps_d_accumulated = " + fmt(m.acc[at], 3) : "";
}

double jamming_start_inside(double v, double numin, bool cusp) {
  if (v <= numin * (1 - 1e-6)) return v;
  return cusp ? numin - 0.005 : numin * (1 - 1e-5);
}

namespace {
// A calibration Ceres could not evaluate at its start: which curve is not a number there, and why, in its message
// (starts.md, jackknife.md) and warnings.
void note_start_failure(const std::vector<CurveData>& curves, const std::vector<PathData>& paths, Calibration& cal) {
  const std::string why = start_failure(cal.params, curves, paths);
  if (why.empty()) return;
  cal.message += "; at its start " + why;
  cal.warnings.push_back("the start cannot be evaluated: " + why);
}
// CalibrationOptions::evaluate_only: chi^2 of the problem as built at its start (nan where Ceres cannot evaluate it).
Calibration evaluated_start(ceres::Problem& problem, int n_res) {
  Calibration cal;
  double cost = 0;
  const bool ok = problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  cal.chi2 = ok && std::isfinite(cost) ? 2 * cost : std::nan("");
  cal.n_residuals = n_res;
  cal.message = "evaluated at the start (no fit)";
  return cal;
}
}  // namespace

Calibration calibrate(const std::vector<CurveData>& curves_in, const IsoData& iso, const CalibrationOptions& o,
                      const std::vector<PathData>& paths) {
  init_glog();
  const std::set<int> held = checked_inputs(curves_in, iso, o, paths);
  std::vector<CurveData> curves;
  double nu_mean = 0;
  for (const auto& c : curves_in) { curves.push_back(truncated(c, o.eps_max)); check_curve(curves.back()); nu_mean += c.nu; }
  if (curves.empty())
    for (const auto& d : paths) nu_mean += d.nu;
  nu_mean /= curves.empty() ? paths.size() : curves.size();
  const double nu_ref = o.nu_ref > 0 ? o.nu_ref : nu_mean;
  const bool X = o.extended;
  if (X && o.fabric == FabricLode::Weighted) check_weighted_lode(curves, paths);
  const Parameters start = calibration_start(curves_in, curves, iso, o, paths, nu_ref);
  std::vector<double> isob = start.iso();
  if (o.hold_from)
    for (int i : o.hold_iso) isob[i] = o.hold_from->iso()[i];
  std::vector<double> shear(start.shear, start.shear + kNumShear);
  std::vector<double> ext(start.ext, start.ext + kNumExt);
  if (X) clamp_extended_start(shear, ext);
  std::vector<double*> blocks_all = {isob.data(), shear.data()};
  if (X) blocks_all.push_back(ext.data());
  double numin = 1e9;
  // Both jamming fractions must lie below every start state (the curves' nu); branch points
  // below them are allowed (C = C0 there; p* < 0 is simply a large residual).
  if (!(X && o.state_volume))
    for (const auto& c : curves) numin = std::min(numin, c.nu);

  ceres::Problem problem;
  int n_res = 0;
  add_curve_residuals(problem, curves, o, nu_ref, X, blocks_all, n_res);
  add_path_residuals(problem, paths, o, nu_ref, X, blocks_all, n_res, numin);
  if (X && o.state_volume)   // the isotropic law's jamming fraction below its own branch only (start_state)
    numin = iso.nu.empty() ? 1.0 : *std::min_element(iso.nu.begin(), iso.nu.end());
  // Start values inside the jamming fractions' bounds (jamming_start_inside).
  for (int i : {kNuC, kNuCC}) isob[i] = jamming_start_inside(isob[i], numin, i == kNuCC || o.shared_jamming);
  add_isotropic_residuals(problem, iso, o, held, isob, numin, n_res);
  const bool weighted = X && o.fabric == FabricLode::Weighted;
  const bool state_lode = X && o.state_limit && o.state_lode;
  if (state_lode) check_second_lode_angle(curves, paths, "the state exponent's Lode dependence (lambda_psi)",
                                          "or choose --state-limit pressure", o.b_d2);
  const bool state_volume = X && o.state_volume;
  Calibration cal;   // its warnings and start_moved from start_within_reach on
  if (state_volume) {
    volume_state_start(paths, ext, o.csl_linear);
    isob[kC0] = std::max(isob[kC0], 0.0);
  }
  set_bounds(problem, isob, shear, ext, numin, X, o.state_limit, weighted, state_lode, state_volume);
  isotropic_floors(problem, isob, o, state_volume);
  if (state_volume) start_within_reach(curves, paths, held, o.fit_isotropic, isob, cal.warnings, cal.start_moved);   // after the floors
  if (o.fit_isotropic && !held.empty())
    problem.SetManifold(isob.data(), new ceres::SubsetManifold(kNumIso, std::vector<int>(held.begin(), held.end())));

  const bool one_nu = one_start_volume_fraction(curves, paths);
  const int n_p = start_pressures(curves, paths);
  hold_ext(problem, shear, ext, X, one_nu, o.state_limit, weighted, state_lode, state_volume, o.excess_relaxes, n_p, o.hold_ext);
  if (o.evaluate_only) return evaluated_start(problem, n_res);

  std::vector<std::vector<double>> window_start;
  const ceres::Solver::Summary sum = solve_on_face(problem, blocks_all, isob, iso, o, held, cal.warnings, window_start);
  cal.message = sum.BriefReport();
  if (sum.termination_type == ceres::FAILURE) cal.message += " (" + sum.message + ")";   // why, in starts.md
  cal.params = fitted_params(start, isob, shear, ext, o, X);
  if (sum.final_cost < 0) note_start_failure(curves, paths, cal);   // Ceres stopped before its first step
  const int n_ext = ext_size(cal.params.state_limit, weighted, state_lode, state_volume);
  const std::vector<int> held_x =
      X ? with_user_held(held_ext(one_nu, cal.params.state_limit, weighted, state_lode, state_volume, n_p), o.hold_ext, n_ext)
        : std::vector<int>();
  // a start Ceres could not evaluate reports a negative cost: no chi2 ("nan", the start "failed")
  cal.chi2 = sum.final_cost >= 0 ? 2 * sum.final_cost : std::nan("");
  cal.n_residuals = n_res;
  // Free parameters: the held ones (isotropic, the nu-slopes of one start volume fraction, held_ext) left out.
  cal.n_free = (o.fit_isotropic ? kNumIso - static_cast<int>(held.size()) : 0) + kNumShear - static_cast<int>(held_shear(X, one_nu, state_volume, o.excess_relaxes).size()) +
               (X ? n_ext - static_cast<int>(held_x.size()) : 0);
  judge_convergence(sum, o.max_iterations, cal);
  for (int i = 0; i < kNumIso; ++i) { cal.names.push_back(iso_name(i)); cal.value.push_back(isob[i]); }
  for (int i = 0; i < kNumShear; ++i) { cal.names.push_back(shear_name(i)); cal.value.push_back(shear[i]); }
  if (X)
    for (int i = 0; i < n_ext; ++i) { cal.names.push_back(ext_name(i)); cal.value.push_back(ext[i]); }

  const std::vector<double> cov = covariance_errors(problem, isob, shear, ext, o, X, cal);   // and jacobian_smoothness
  held_errors(cal, held, held_x, o.shared_jamming);
  calibration_warnings(curves, paths, iso, o, isob, numin, one_nu, X, cal);
  bound_warnings(problem, shear, ext, X, n_ext, cal);
  for (int i : held_shear(X, false, state_volume, o.excess_relaxes))   // s_max_b at 0, beta_p's slope, beta_p unless it acts
    cal.se_cov[kNumIso + i] = kNaN;
  settle_errors(cal);
  if (!cal.settled.empty()) moving_note(window_start, cal);
  check_quoted_errors(problem, isob, shear, ext, o, X, cov, cal);
  if (state_volume) drop_unread_for_volume_state(cal, weighted);
  else if (weighted && !cal.params.state_limit) drop_entries(cal, kNumIso + kNumShear + kNPsiA, 2);   // n_psi: not in this law
  if (state_lode && !weighted) drop_entries(cal, kNumIso + kNumShear + kLnDeltaW, 2);   // the `Weighted` pair: unread
  return cal;
}

Ext<double> prediction_ext(const Parameters& params, const std::string& mode, double* psi_seen) {
  Ext<double> ext{params.extended ? params.ext : nullptr, lode_b_of(mode), params.surface, params.fabric,
                  params.extended && params.state_limit, params.extended && params.state_lode,
                  params.extended && params.state_volume, lode_b_of(mode, params.b_d2), params.psi_lo, params.psi_hi,
                  psi_seen};
  ext.excess_relaxes = params.extended && params.state_volume && params.excess_relaxes;
  ext.excess_bounded = ext.excess_relaxes && params.excess_bounded;
  ext.start_unaligned = params.start_unaligned;
  ext.dilatancy_gated = params.dilatancy_gated;
  ext.fabric_state = ext.state_limit && params.fabric_state;
  ext.deviator_reference = params.deviator_reference && !ext.state_volume;
  return ext;
}

ModelCurve predict_curve(const Parameters& params, const CurveData& c, double eps_max, double max_step,
                         double* psi_seen) {
  const CurveData t = truncated(c, eps_max);
  if (t.eps.empty() || std::fabs(t.eps.front()) > 1e-12)
    throw std::invalid_argument("model prediction: " + c.source + " does not start at eps_d = 0");
  const std::vector<double> iso = params.iso();
  const Ext<double> ext = prediction_ext(params, c.mode, psi_seen);
  std::vector<StepReport> how;
  const auto st = monotone_shear<double>(iso.data(), params.shear, params.nu_ref, t.nu, t.p.front(), t.s.front(),
                                         t.F.front(), t.eps, max_step, ext, &how);
  ModelCurve m;
  m.eps = t.eps;
  for (std::size_t i = 0; i < st.size(); ++i) {
    const State<double>& y = st[i];
    m.p.push_back(y.p);
    m.s.push_back(observed(y.s, t.s.front(), ext.start_unaligned));
    m.F.push_back(observed(y.F, t.F.front(), ext.start_unaligned));
    m.nu.push_back(std::exp(y.ln_nu));
    m.halvings.push_back(how[i].halvings);
    m.graded.push_back(how[i].graded);
    m.split.push_back(how[i].split);
    m.relaxed.push_back(how[i].relaxed);
  }
  if (std::find(m.graded.begin(), m.graded.end(), true) != m.graded.end()) {   // the exponent the start had
    const Material<double> mat = start_material(iso.data(), params.shear, params.nu_ref, t.nu, t.p.front(), ext);
    m.gate_exponent_start = gate_exponent(mat, start_state(mat, t.nu, t.p.front(), t.s.front(), t.F.front()));
  }
  return m;
}

PathPrediction predict_path(const Parameters& params, const PathData& d, double max_step, double* psi_seen) {
  if (d.acc.empty() || std::fabs(d.acc.front()) > 1e-12)
    throw std::invalid_argument("model prediction: " + d.source + " does not start at eps_d_accumulated = 0");
  const std::vector<double> iso = params.iso();
  if (!(params.extended && params.state_volume)) check_start_scale(iso, d.nu, d.source);
  const Ext<double> ext = prediction_ext(params, d.name, psi_seen);
  const auto st = integrate_rows<double>(iso.data(), params.shear, params.nu_ref, d.nu, d.p.front(), d.s.front(),
                                         d.F.front(), d.acc, d.direction, d.isobaric, max_step, ext);
  PathPrediction m;
  m.acc = d.acc;
  m.excess_relaxes = ext.excess_relaxes;
  m.excess_bounded = ext.excess_bounded;
  const bool vol = params.extended && params.state_volume;
  for (const auto& r : st) {
    if (r.state.lost && m.lost_row < 0) m.lost_row = static_cast<int>(m.p.size());
    m.p.push_back(r.state.p);
    m.s.push_back(observed(r.state.s, d.s.front(), ext.start_unaligned));
    m.F.push_back(observed(r.state.F, d.F.front(), ext.start_unaligned));
    m.nu.push_back(std::exp(r.state.ln_nu)); m.ev.push_back(r.eps_vol / 3.0);
    m.p_el.push_back(vol ? isotropic_pressure(iso.data(), std::exp(r.state.ln_nu + r.state.e_pl)) : r.state.p);
    m.pole.push_back(r.pole);
    m.halvings.push_back(r.halvings);
    m.graded.push_back(r.graded);
    m.split.push_back(r.split);
    m.relaxed.push_back(r.relaxed);
  }
  if (std::find(m.graded.begin(), m.graded.end(), true) != m.graded.end()) {   // the exponent the start had
    const Material<double> mat = start_material(iso.data(), params.shear, params.nu_ref, d.nu, d.p.front(), ext);
    m.gate_exponent_start = gate_exponent(mat, start_state(mat, d.nu, d.p.front(), d.s.front(), d.F.front()));
  }
  return m;
}

double cusp_crossed(const Parameters& P, const PathPrediction& m) {
  const std::vector<double> iso = P.iso();
  const bool vol = P.extended && P.state_volume;
  double pc = cusp_pressure(iso.data());
  // A relaxing excess above p puts the elastic state below the law's jamming fraction (p_el < 0), where it can meet
  // the coordination law's nu_cC below nu_c (twenty-second round: the relaxing three-pressure fits whose cost is not
  // smooth). With one fraction (nu_cC = nu_c) the stiffness stays bounded there: x (nu/nu_c - 1)^(alpha - 1) -> 0.
  if (!std::isfinite(pc) && vol && m.excess_relaxes && P.nu_cC > 0 && P.nu_cC < P.nu_c)
    pc = isotropic_pressure(iso.data(), P.nu_cC);
  if (!std::isfinite(pc) || m.nu.empty()) return std::nan("");
  const std::vector<double>& x = vol ? m.p_el : m.nu;
  const double at = vol ? pc : P.nu_cC;
  const auto [lo, hi] = std::minmax_element(x.begin(), x.end());
  return *lo <= at && at <= *hi ? at : std::nan("");
}

double largest_excess_ratio(const PathPrediction& m, double* at) {
  double worst = 0.0;
  for (std::size_t i = 0; m.excess_relaxes && i < m.p.size() && i < m.p_el.size(); ++i) {
    if (!(m.p[i] > 0)) continue;
    const double r = (m.p[i] - m.p_el[i]) / m.p[i];
    if (r > worst) {
      worst = r;
      if (at) *at = m.acc[i];
    }
  }
  return worst;
}

std::pair<double, double> psi_range(const Parameters& params, const std::vector<CurveData>& curves,
                                    const std::vector<PathData>& paths, double eps_max, double max_step) {
  // The largest |psi| of the model's own states along the calibration curves, on both sides of the critical state:
  // a dense-only calibration (psi >= 0) still predicts loose states as far from the line as its dense ones were
  // (those predictions stay as they were); only states farther than any it held read the laws at that distance.
  const double inf = std::numeric_limits<double>::infinity();
  if (!(params.extended && params.state_volume)) return {-inf, inf};
  Parameters P = params;
  P.psi_lo = -inf;
  P.psi_hi = inf;
  double seen[2] = {inf, -inf};   // every evaluation of the right-hand side, RK4's stages included
  for (const auto& c : curves) predict_curve(P, c, eps_max, max_step, seen);
  for (const auto& d : paths) predict_path(P, d, max_step, seen);
  if (!(seen[0] <= seen[1])) return {-inf, inf};
  const double reach = std::max(std::fabs(seen[0]), std::fabs(seen[1]));   // the same distance on the other side of 0
  return {-reach, reach};
}

std::vector<PredictionError> prediction_errors(const ModelCurve& m, const CurveData& c) {
  std::vector<PredictionError> out;
  const std::vector<double>* mv[3] = {&m.p, &m.s, &m.F};
  const std::vector<double>* dv[3] = {&c.p, &c.s, &c.F};
  const std::vector<double>* hv[3] = {&c.hw_p, &c.hw_s, &c.hw_F};
  const char* names[3] = {"p_star", "s_dev", "F_dev"};
  for (int q = 0; q < 3; ++q) {
    PredictionError e;
    e.quantity = names[q];
    double ss = 0, hw = 0, bias = 0;
    int in = 0;
    // The first row is the start state itself (zero error by construction): left out.
    for (std::size_t i = 1; i < m.eps.size() && i < dv[q]->size(); ++i) {
      const double d = (*mv[q])[i] - (*dv[q])[i];
      ss += d * d;
      bias += d;
      e.max_abs = std::max(e.max_abs, std::fabs(d));
      const double h = (*hv[q])[i];
      hw += h;
      if (std::fabs(d) <= h) ++in;
      ++e.n;
    }
    if (e.n == 0) continue;
    e.rms = std::sqrt(ss / e.n);
    e.bias = bias / e.n;
    e.band = hw / e.n;
    e.rms_over_band = e.band > 0 ? e.rms / e.band : kNaN;
    e.max_over_band = e.band > 0 ? e.max_abs / e.band : kNaN;
    e.frac_in_band = static_cast<double>(in) / e.n;
    out.push_back(e);
  }
  return out;
}

void check_start_scale(const std::vector<double>& iso, double nu0, const std::string& source) {
  const double p_iso = isotropic_pressure(iso.data(), nu0);
  if (!(p_iso > 0))
    throw std::invalid_argument("model prediction: " + source + " starts at nu = " + std::to_string(nu0) +
                                ", at or below the isotropic law's jamming fraction nu_c = " + std::to_string(iso[kNuC]) +
                                ": p_iso(nu0) <= 0, so the start scale k = p0/p_iso(nu0) and the bulk modulus are not "
                                "positive and the path cannot be integrated; calibrate on an isotropic branch that "
                                "reaches below this nu (docs/model.md)");
}

namespace {
PredictionError error_over(const char* name, const std::vector<double>& model, const std::vector<double>& dem,
                           const std::vector<double>& hw, const std::vector<bool>& use) {
  PredictionError e;
  e.quantity = name;
  double ss = 0, hws = 0, bias = 0;
  int in = 0;
  for (std::size_t i = 1; i < model.size() && i < dem.size(); ++i) {
    if (!use[i]) continue;
    const double d = model[i] - dem[i];
    ss += d * d; bias += d;
    e.max_abs = std::max(e.max_abs, std::fabs(d));
    hws += hw[i];
    if (std::fabs(d) <= hw[i]) ++in;
    ++e.n;
  }
  if (e.n == 0) return e;
  e.rms = std::sqrt(ss / e.n);
  e.bias = bias / e.n;
  e.band = hws / e.n;
  e.rms_over_band = e.band > 0 ? e.rms / e.band : kNaN;
  e.max_over_band = e.band > 0 ? e.max_abs / e.band : kNaN;
  e.frac_in_band = static_cast<double>(in) / e.n;
  return e;
}
}  // namespace

std::vector<PredictionError> path_errors(const PathPrediction& m, const PathData& d) {
  std::vector<PredictionError> out;
  const std::size_t n = d.acc.size();
  std::vector<bool> all(n, true), vol(n), isob(n);
  // p* where it is not held (constant volume and constant side stress rows), eps_v where the
  // volume is free (isobaric and constant side stress rows).
  bool any_p = false;
  for (std::size_t i = 0; i < n; ++i) {
    vol[i] = d.isobaric[i] != 1; isob[i] = d.isobaric[i] != 0;
    if (i > 0 && vol[i]) any_p = true;
  }
  if (any_p) out.push_back(error_over("p_star", m.p, d.p, d.hw_p, vol));
  if (d.has_isobaric()) out.push_back(error_over("eps_v", m.ev, d.ev, d.hw_ev, isob));
  out.push_back(error_over("s_dev_signed", m.s, d.s, d.hw_s, all));
  out.push_back(error_over("F_dev_signed", m.F, d.F, d.hw_F, all));
  // Where the path starts as forward constant-volume shear (a D2 run) and then turns: the same
  // errors over the rows after the first turn only (what D2 cannot have told the model).
  std::size_t prefix = 0;
  while (prefix + 1 < n && d.direction[prefix + 1] > 0 && !d.isobaric[prefix + 1]) ++prefix;
  if (prefix > 0 && prefix + 1 < n) {
    std::vector<bool> after(n, false), after_vol(n, false);
    for (std::size_t i = prefix + 1; i < n; ++i) { after[i] = true; after_vol[i] = !d.isobaric[i]; }
    if (d.has_volume()) out.push_back(error_over("p_star (after turn)", m.p, d.p, d.hw_p, after_vol));
    out.push_back(error_over("s_dev_signed (after turn)", m.s, d.s, d.hw_s, after));
    out.push_back(error_over("F_dev_signed (after turn)", m.F, d.F, d.hw_F, after));
  }
  return out;
}

bool jackknife_refit_usable(const Calibration& refit, const Calibration& full) {
  return refit.ok && std::isfinite(refit.chi2_dof()) && refit.chi2_dof() <= 3.0 * std::max(full.chi2_dof(), 1.0);
}

namespace {
// Each sample's (n, sum of x, and after the means, sum (x - mean x)(y - mean y)) in first-appearance order.
struct SampleSums {
  std::vector<double> n, cross;
};
SampleSums sample_sums(const std::vector<double>& x, const std::vector<double>& y, const std::vector<int>& sample) {
  int groups = 0;
  for (std::size_t k = 0; k < x.size(); ++k) groups = std::max(groups, sample.empty() ? 1 : sample[k] + 1);
  SampleSums s{std::vector<double>(groups, 0.0), std::vector<double>(groups, 0.0)};
  auto g = [&](std::size_t k) { return sample.empty() ? 0 : sample[k]; };
  for (std::size_t k = 0; k < x.size(); ++k) s.n[g(k)] += 1;
  std::vector<double> mx(groups, 0.0), my(groups, 0.0);
  for (std::size_t k = 0; k < x.size(); ++k) { mx[g(k)] += x[k] / s.n[g(k)]; my[g(k)] += y[k] / s.n[g(k)]; }
  for (std::size_t k = 0; k < x.size(); ++k) s.cross[g(k)] += (x[k] - mx[g(k)]) * (y[k] - my[g(k)]);
  return s;
}
}  // namespace

double jackknife_covariance(const std::vector<double>& x, const std::vector<double>& y, const std::vector<int>& sample) {
  const SampleSums s = sample_sums(x, y, sample);
  double c = 0;
  for (std::size_t j = 0; j < s.n.size(); ++j)
    if (s.n[j] > 0) c += (s.n[j] - 1.0) / s.n[j] * s.cross[j];
  return c;
}

double jackknife_dof(const std::vector<double>& x, const std::vector<int>& sample) {
  const SampleSums s = sample_sums(x, x, sample);
  if (s.n.size() == 1) return s.n[0] - 1.0;
  double sum = 0, den = 0;
  for (std::size_t j = 0; j < s.n.size(); ++j) {
    if (s.n[j] < 2) continue;
    const double v = (s.n[j] - 1.0) / s.n[j] * s.cross[j];
    sum += v;
    den += v * v / (s.n[j] - 1.0);
  }
  return den > 0 ? sum * sum / den : std::nan("");
}

std::vector<double> jackknife_errors(const std::vector<std::vector<double>>& est, const Calibration& cal,
                                     bool csl_linear, std::vector<std::string>* warnings,
                                     const std::vector<int>& sample, std::vector<double>* dof) {
  std::vector<double> se(cal.value.size(), std::nan(""));
  if (dof) dof->assign(cal.value.size(), std::nan(""));
  if (est.empty()) return se;
  for (std::size_t i = 0; i < cal.value.size(); ++i) {
    std::vector<double> x;
    for (const auto& e : est) x.push_back(e[i]);
    const double var = jackknife_covariance(x, x, sample);
    // held parameters have no error of their own, but the critical-state line of --state-limit volume is held at the
    // end states of the data, which the jackknife moves: its spread is its error (the term --csl does not use is held
    // at 0 and has none: nan)
    const bool from_data = cal.names[i] == "nu_cs" || (cal.names[i] == "lambda_cs" && !csl_linear) ||
                           (cal.names[i] == "c_cs" && csl_linear);
    const bool undetermined = i < cal.undetermined.size() && cal.undetermined[i];   // its refits still spread
    // a spread of round-off only (thirty-third round: a coefficient that does not act, every refit within an ulp of
    // its start, quoted an error of 2e-15) is none
    const bool spread = std::any_of(x.begin(), x.end(), [&](double v) { return std::fabs(v - x[0]) > 1e-12 * std::fabs(x[0]); });
    if (std::isfinite(cal.se_cov[i]) || from_data || (undetermined && spread)) {
      se[i] = std::sqrt(var);
      if (dof) (*dof)[i] = jackknife_dof(x, sample);
    }
    if (std::isfinite(cal.se_cov[i]) && !spread) {   // every refit on the same value: a bound held it, no spread
      se[i] = std::nan("");
      if (dof) (*dof)[i] = std::nan("");
      if (warnings)
        warnings->push_back(cal.names[i] + ": every jackknife refit ends on the same value " +
                            table_number(est[0][i], 6) + " (a bound): no jackknife error quoted");
    }
  }
  return se;
}

}  // namespace demfit::model
