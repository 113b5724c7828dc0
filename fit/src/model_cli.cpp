// `dem model DIR`: the incremental anisotropic model calibrated on the D2 ensemble curves and
// the isotropic branch, then used to predict the other modes (D3); tables, curves, plots.
#include "demfit/model_cli.hpp"

#include <cstring>
#include <cerrno>
#include <unistd.h>
#include <fcntl.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <tuple>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <regex>
#include <chrono>
#include <functional>
#include <sstream>
#include <stdexcept>

#include "demfit/ensemble.hpp"
#include "demfit/model_fit.hpp"
#include "demfit/table.hpp"

namespace fs = std::filesystem;

namespace demfit {

namespace {

using namespace demfit::model;

struct InputError : std::runtime_error { using std::runtime_error::runtime_error; };

std::string num(double v, int prec = 6) { return table_number(v, prec); }

struct CurveFile { std::string mode, tag; double nu; fs::path path; };

// The MODE_phiX.XXX.csv files of a folder, by mode then nu.
std::vector<CurveFile> curves_in(const fs::path& dir) {
  static const std::regex re(R"(([A-Za-z0-9_-]+)_(phi([0-9.]+))\.csv)");
  std::vector<CurveFile> out;
  for (auto& e : fs::directory_iterator(dir)) {
    std::smatch m;
    const std::string name = e.path().filename().string();
    if (std::regex_match(name, m, re)) out.push_back({m[1], m[2], std::stod(m[3]), e.path()});
  }
  std::sort(out.begin(), out.end(), [](const CurveFile& a, const CurveFile& b) {
    return a.mode != b.mode ? a.mode < b.mode : a.nu < b.nu;
  });
  return out;
}

// Every --start is a parameters.csv (none is `default`): only then may path ensembles alone be the
// calibration, since the default start comes from a monotone mode's saturating fits.
bool starts_from_files(const ModelCommandOptions& o) {
  if (!o.predict_with.empty()) return true;   // nothing fitted: the file's parameters
  return !o.start.empty() && std::find(o.start.begin(), o.start.end(), "default") == o.start.end();
}

std::vector<CurveFile> find_curves(const fs::path& dir, bool optional = false) {
  const fs::path ens = dir / "ensemble";
  if (optional && !fs::is_directory(ens)) return {};
  if (!fs::is_directory(ens))
    throw InputError(ens.string() + " does not exist: give an ensemble folder reduced by `dem fit DIR` "
                     "(it writes DIR/ensemble/MODE_phiX.csv), or calibrate on path ensembles alone with --start "
                     "PARAMETERS.csv (a monotone mode gives the start values otherwise)");
  return curves_in(ens);
}

std::vector<CurveFile> find_paths(const fs::path& dir) { return curves_in(dir); }

std::vector<fs::path> member_dirs(const fs::path& dir) {
  std::vector<fs::path> out;
  if (!fs::is_directory(dir / "members")) return out;
  for (auto& e : fs::directory_iterator(dir / "members"))
    if (e.is_directory()) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

fs::path unloading_of(const fs::path& member) {
  for (const fs::path& p : {member / "prep" / "cycle_unloading.csv", member / "cycle_unloading.csv"})
    if (fs::exists(p)) return p;
  return {};
}

fs::path member_curve(const fs::path& member, const CurveFile& c) {
  const std::string name = c.mode + "_" + c.tag + ".csv";
  for (const fs::path& p : {member / "deviatoric" / name, member / name})
    if (fs::exists(p)) return p;
  return {};
}

fs::path member_path_curve(const fs::path& member, const CurveFile& c) {
  const fs::path p = member / "paths" / (c.mode + "_" + c.tag + ".csv");
  return fs::exists(p) ? p : fs::path();
}

// Leave-one-out path ensemble mean; the member file is on the ensemble's rows
// (demkit/path_ensemble.py writes it so).
PathData leave_one_out_path(const PathData& d, const fs::path& member_csv) {
  const Table t = read_table(member_csv.string());
  const auto& acc = t.column("eps_d_accumulated");
  if (acc.size() != d.acc.size())
    throw InputError(member_csv.string() + " has " + std::to_string(acc.size()) + " rows, the ensemble " +
                     std::to_string(d.acc.size()) + ": rerun demkit.path_ensemble so members and means share the grid");
  for (std::size_t i = 0; i < acc.size(); ++i)
    if (std::fabs(acc[i] - d.acc[i]) > 1e-7)
      throw InputError(member_csv.string() + ": row " + std::to_string(i) + " is not on the ensemble's grid");
  PathData o = d;
  const double K = d.packings;
  // the volume fraction too: the path starts from the other packings' mean state, and --state-limit volume's
  // critical-state line is held at their end states (before the thirty-second round it stayed the full mean's, so
  // the jackknife missed the scatter of the start states)
  const std::pair<const char*, std::vector<double>*> q[] = {
      {"p_star", &o.p}, {"eps_v", &o.ev}, {"s_dev_signed", &o.s}, {"F_dev_signed", &o.F}, {"nu", &o.nu_m}};
  for (auto& [name, v] : q) {
    const auto& x = t.column(name);
    for (std::size_t i = 0; i < v->size(); ++i) (*v)[i] = (K * (*v)[i] - x[i]) / (K - 1);
  }
  if (!o.nu_m.empty()) o.nu = o.nu_m.front();
  return o;
}

// Leave-one-out ensemble mean: (K mean - x_k)/(K - 1), member k resampled on the curve's grid.
CurveData leave_one_out(const CurveData& c, const fs::path& member_csv) {
  const Table t = read_table(member_csv.string());
  CurveData o = c;
  const auto& e = t.column("eps_d");
  const double K = c.packings;
  const std::pair<const char*, std::vector<double>*> q[] = {{"p_star", &o.p}, {"s_dev", &o.s}, {"F_dev", &o.F}};
  for (auto& [name, v] : q) {
    const auto x = resample(e, t.column(name), c.eps);
    for (std::size_t i = 0; i < v->size(); ++i) (*v)[i] = (K * (*v)[i] - x[i]) / (K - 1);
  }
  return o;
}

std::string law_of(const std::string& n) {
  if (n == "p0" || n == "nu_c" || n == "gamma_p") return "p*(nu) = p0 (nu C(nu)/nu_c) x (1 + gamma_p x), x = ln(nu/nu_c)";
  if (n == "C0" || n == "C1" || n == "nu_cC" || n == "alpha") return "C(nu) = C0 + C1 (nu/nu_cC - 1)^alpha";
  if (n == "lambda_psi") return "state exponent at Lode parameter b: n_psi (c_3(1/2)/c_3(b))^lambda_psi";
  if (n == "chi_D") return "mobilisation r at which the plastic dilatancy changes sign (one value at every nu)";
  if (n == "nu_cs" || n == "lambda_cs" || n == "c_cs")
    return "critical-state line nu_cs(p) = nu_cs + lambda_cs ln(p*/1e-3) + c_cs (p* - 1e-3) (psi = nu - nu_cs(p))";
  if (n == "n_peak" || n == "m_peak")
    return "stress-ratio target s_lim exp(n_peak (p*/1e-3)^m_peak psi), psi = nu - nu_cs(p)";
  if (n == "n_dil") return "plastic dilatancy d_D (r - chi_D exp(-n_dil psi)), psi = nu - nu_cs(p)";
  if (n == "n_rate") return "rates beta_s, beta_F scaled by ((B/p)/(B/p at p* = 1e-3))^n_rate, B the isotropic law's stiffness";
  if (n == "ln_delta_w" || n == "n_w") return "Lode weight w = 1/(1 + exp(n_w (ln_delta_w - ln(delta/d)))), delta/d = pi p*/(C nu)";
  const std::string q = n.substr(0, n.size() - 2);
  return q + "(nu) = " + q + "_a + " + q + "_b (nu - nu_ref)";
}

std::string unit_of(const std::string& n) {
  if (n == "p0") return "p* (p = p* k/(2<r>))";
  if (n.size() > 2 && n.compare(n.size() - 2, 2, "_b") == 0) return "[coefficient_a] per unit nu";
  if (n.rfind("ln_beta", 0) == 0) return "ln(1/unit eps_d)";
  if (n == "ln_delta_w") return "ln(overlap/diameter)";
  return "-";
}

// With --profile: the profile interval's ends as two more columns of parameters.* (profile_lo68, profile_hi68; nan on
// rows not profiled or where an end was not found), so that the table a paper quotes from holds both intervals.
bool add_profile_columns(const Calibration& cal, Table& t) {
  bool any = false;
  for (const ProfileInterval& p : cal.profile) any = any || p.lower.refits + p.upper.refits > 0;
  if (!any) return false;
  t.header.push_back("profile_lo68");
  t.header.push_back("profile_hi68");
  for (std::size_t r = 0; r < t.rows.size(); ++r) {
    const bool has = r < cal.profile.size() && r < cal.value.size() &&
                     cal.profile[r].lower.refits + cal.profile[r].upper.refits > 0;
    t.rows[r].push_back(has ? num(cal.profile[r].lower.value) : "nan");
    t.rows[r].push_back(has ? num(cal.profile[r].upper.value) : "nan");
  }
  return true;
}

void write_parameter_tables(const Calibration& cal, int packings, const fs::path& out, const std::string& fit_label) {
  Table t({"parameter", "law", "value", "se", "se_method", "lo95", "hi95", "se_covariance", "se_jackknife", "units"});
  const bool jk = !cal.se_jackknife.empty();
  std::vector<std::string> exact;   // the values to the last bit (parameters.csv/json: a --start reads them back)
  for (std::size_t i = 0; i < cal.value.size(); ++i) {
    // t over the jackknife's degrees of freedom (K - 1; Welch-Satterthwaite's over several sets of packings)
    const double nu_t = i < cal.dof_jackknife.size() && std::isfinite(cal.dof_jackknife[i]) ? cal.dof_jackknife[i]
                                                                                              : packings - 1.0;
    const double tq = jk ? t_quantile(0.975, nu_t) : 1.959964;
    const std::string why = cal.errors_not_determined();   // the columns se_covariance, se_jackknife keep the numbers
    const double se = why.empty() ? cal.se()[i] : std::nan("");
    const bool tied = cal.shared_jamming && cal.names[i] == "nu_cC";
    const std::string method = !why.empty() ? "not determined: " + why
                               : jk ? "jackknife over packings" : "covariance x max(1, chi2/dof)";
    t.add_row({cal.names[i], tied ? "nu_cC = nu_c (one jamming fraction: --jamming shared)" : law_of(cal.names[i]),
               num(cal.value[i]), num(se), tied ? "nu_c's (tied): " + method : method, num(cal.value[i] - tq * se),
               num(cal.value[i] + tq * se), num(cal.se_cov[i]), jk ? num(cal.se_jackknife[i]) : "nan", unit_of(cal.names[i])});
    exact.push_back(table_number_exact(cal.value[i]));
  }
  t.add_row({"nu_ref", "centre of the nu-laws (fixed)", num(cal.params.nu_ref), "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (std::isfinite(cal.params.psi_lo) && std::isfinite(cal.params.psi_hi)) {   // files without the rows: no clamp
    t.add_row({"psi_min", "laws of psi held at their value here below it (the calibration's states; --no-psi-range)",
               num(cal.params.psi_lo, 17), "nan", "fixed", "nan", "nan", "nan", "nan", "-"});   // exact: --predict-with
    t.add_row({"psi_max", "laws of psi held at their value here above it (the calibration's states; --no-psi-range)",
               num(cal.params.psi_hi, 17), "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  }
  if (cal.params.excess_relaxes && !cal.params.excess_bounded)   // files without the row: permanent (read_parameters)
    t.add_row({"anisotropy_excess", "1: the anisotropy's pressure relaxes as an excess at beta_p (--anisotropy-pressure "
               "relaxing)", "1", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.excess_bounded)
    t.add_row({"anisotropy_excess", "2: the anisotropy's pressure relaxes as an excess at beta_p, its source gated by "
               "1 - (q/p)^2 (--anisotropy-pressure bounded)", "2", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.start_unaligned)   // files without the row: aligned (read_parameters)
    t.add_row({"start_anisotropy", "1: the start's deviators unaligned, s and F from 0 and observed as sqrt(x^2 + x0^2) "
               "(--start-anisotropy unaligned)", "1", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.dilatancy_gated)   // files without the row: ungated (read_parameters)
    t.add_row({"dilatancy_gate", "1: the plastic dilatancy gated by the mobilisation, d_D r (r - chi_D)(1 - F/F_lim) "
               "(--dilatancy-gate mobilisation)", "1", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.fabric_state)   // files without the row: F_lim itself (read_parameters)
    t.add_row({"fabric_limit", "1: the fabric driven to F_lim times the stress ratio's state factor (p_ref/p)^n_psi "
               "(--fabric-limit state)", "1", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.deviator_reference)   // files without the row: sigma_dev unchanged by the volume (read_parameters)
    t.add_row({"deviator_volume", "1: under a volume change sigma_dev scales with p_ref(nu) (--deviator-volume "
               "reference)", "1", "nan", "fixed", "nan", "nan", "nan", "nan", "-"});
  if (cal.params.b_d2 != kLodeBD2)   // files without the row: 1/2 (read_parameters)
    t.add_row({"b_D2", "stress Lode parameter b of D2 curves and paths (fixed; --d2-lode)", num(cal.params.b_d2), "nan",
               "fixed", "nan", "nan", "nan", "nan", "-"});
  t.add_row({"chi2_per_dof", "weighted residuals of the joint fit", num(cal.chi2_dof()), "nan",
             std::to_string(cal.n_residuals) + " residuals", "nan", "nan", "nan", "nan", "-"});
  // A fit that stopped short says so in its table (the values are where it stopped; --start goes on)
  if (!cal.ok)
    t.add_row({"converged", "no: " + cal.message, "nan", "nan", "not converged", "nan", "nan", "nan", "nan", "-"});
  else if (!cal.settled.empty())   // at the iteration limit, chi^2 settled (demfit/settle.hpp): converged, and why
    t.add_row({"settled", "yes: " + cal.settled, "nan", "nan", "settled", "nan", "nan", "nan", "nan", "-"});
  const bool profiled = add_profile_columns(cal, t);
  Table machine = t;
  for (std::size_t i = 0; i < exact.size(); ++i) machine.rows[i][2] = exact[i];
  write_table_all(machine, t, (out / "parameters").string(),
                  "Incremental anisotropic model: joint fit of the isotropic branch and the ensemble curves of " + fit_label +
                  " (docs/model.md); 95 % intervals: estimate -/+ t se; value: every digit in .csv/.json, six in .md/.tex" +
                  (profiled ? std::string("; profile_lo68/hi68 (--profile): where chi^2 rises by max(1, chi2/dof) with "
                                          "the rest refitted, a 68 % interval (nan: the end not found; profile.csv says "
                                          "how each end was reached)")
                            : std::string()));
  std::vector<std::string> h = {"parameter"};
  for (const auto& n : cal.names) h.push_back(n);
  Table c(h);
  for (std::size_t a = 0; a < cal.names.size(); ++a) {
    std::vector<std::string> r = {cal.names[a]};
    for (std::size_t b = 0; b < cal.names.size(); ++b) r.push_back(correlation_number(cal.corr[a][b]));
    c.add_row(r);
  }
  write_table_all(c, (out / "correlations").string(), "Correlations of the model parameters (covariance of the joint fit)");
}

void write_laws_table(const Parameters& P, const std::vector<double>& nus, const fs::path& out) {
  Table t({"nu [-]", "s_max [-]", "beta_s [1/eps_d]", "F_max [-]", "beta_F [1/eps_d]", "a_A [-]", "beta_p [1/eps_d]",
           "B [p*]", "p_iso [p*]", "C_iso [-]", "G_over_p_initial [-]"});
  const auto iso = P.iso();
  for (double nu : nus) {
    const Local<double> L = local(P.shear, nu, P.nu_ref);
    t.add_row({num(nu, 4), num(L.s_max), num(L.beta_s), num(L.F_max), num(L.beta_F), num(L.a_A), num(L.beta_p),
               num(bulk_modulus(iso.data(), nu)), num(isotropic_pressure(iso.data(), nu)), num(coordination(iso.data(), nu)),
               num(L.beta_s * L.s_max)});
  }
  write_table_all(t, (out / "laws").string(), "The calibrated nu-laws evaluated at the ensemble's volume fractions "
                                              "(G/p at s = 0: beta_s s_max)");
}

// With the volume-form state parameter the laws are laws of psi: evaluated at the critical state (psi = 0) and at each
// calibration path's start state psi0 = nu0 - nu_cs(p0), with the peak target's factor e^{n_b psi} and the dilatancy's
// phase transformation e^{-n_d psi}.
void write_state_laws_table(const Parameters& P, const std::vector<PathData>& paths, const fs::path& out) {
  Table t({"state", "psi [-]", "s_max [-]", "peak_factor [-]", "phase_transformation [-]", "beta_s [1/eps_d]", "F_max [-]",
           "beta_F [1/eps_d]", "a_A [-]", "d_D [-]", "n_F [-]", "kappa_s [-]"});
  std::vector<std::tuple<std::string, double, double>> rows = {{"critical state", 0.0, kPCsRef}};
  for (const auto& d : paths)
    rows.push_back({d.name + " start (nu " + num(d.nu, 4) + ", p* " + num(d.p.front(), 4) + ")",
                    state_psi(P.ext, d.nu, d.p.front()), d.p.front()});
  for (const auto& [label, psi, p] : rows) {
    const Local<double> L = local(P.shear, P.nu_ref + psi, P.nu_ref);
    const LocalExt<double> X = local_ext(P.ext, P.nu_ref + psi, P.nu_ref);
    t.add_row({label, num(psi, 4), num(L.s_max), num(std::exp(peak_exponent(P.ext, p) * psi)), num(std::exp(-P.ext[kND] * psi)),
               num(L.beta_s), num(L.F_max), num(L.beta_F), num(L.a_A), num(X.d_D), num(X.n_F), num(X.kappa_s)});
  }
  write_table_all(t, (out / "laws").string(), "The calibrated laws of the state psi = nu - nu_cs(p) (--state-limit volume), "
                                              "at the critical state and at the calibration paths' start states");
}

void write_model_curve(const ModelCurve& m, const CurveData& c, const std::string& role, const fs::path& path) {
  std::ostringstream o;
  o << "# dem model: model curve and DEM ensemble (" << c.packings << " packings) for " << c.mode << " from nu = "
    << c.nu << " (" << role << "); p_star, s_dev, F_dev dimensionless; *_lo95/_hi95: the ensemble's 95 % band\n";
  o << "eps_d,p_star_model,s_dev_model,F_dev_model,nu_model,p_star_mean,p_star_lo95,p_star_hi95,s_dev_mean,s_dev_lo95,"
       "s_dev_hi95,F_dev_mean,F_dev_lo95,F_dev_hi95\n";
  for (std::size_t i = 0; i < m.eps.size(); ++i)
    o << num(m.eps[i], 8) << "," << num(m.p[i], 8) << "," << num(m.s[i], 8) << "," << num(m.F[i], 8) << ","
      << num(m.nu[i], 8) << "," << num(c.p[i], 8) << "," << num(c.p[i] - c.hw_p[i], 8) << "," << num(c.p[i] + c.hw_p[i], 8)
      << "," << num(c.s[i], 8) << "," << num(c.s[i] - c.hw_s[i], 8) << "," << num(c.s[i] + c.hw_s[i], 8) << ","
      << num(c.F[i], 8) << "," << num(c.F[i] - c.hw_F[i], 8) << "," << num(c.F[i] + c.hw_F[i], 8) << "\n";
  write_text_file(path.string(), o.str());
}

void write_path_curve(const PathPrediction& m, const PathData& d, const std::string& role, const fs::path& path) {
  std::ostringstream o;
  const bool triaxial = std::find(d.isobaric.begin(), d.isobaric.end(), 2) != d.isobaric.end();
  o << "# dem model: model and DEM path ensemble (" << d.packings << " packings) for the path " << d.name
    << " from nu = " << d.nu << " (" << role << "); s_dev, F_dev signed along the first loading direction; eps_v = tr(E)/3 "
       "(extension positive); *_lo95/_hi95: the ensemble's 95 % band; isobaric: 1 where p was held, 2 where the side "
       "stress was held (triaxial); eps_zz_model = (tr E - 2 eps_d)/3, the axial strain of an axisymmetric strain "
       "(docs/model.md); sigma_r_p0 = side stress p (1 - s/3) over p(row 0); *_dem: the DEM means (nan if not in the "
       "ensemble)" << (m.excess_relaxes ? "; q_star_model: the relaxing anisotropic excess p* - p_iso(nu_el)" : "")
    << (triaxial ? "; pole_ratio_model: a_A F/3 = A/(3B) on rows under the drained triaxial control (nan elsewhere): "
                   "the control is lost from " + num(1 - kTriaxialMargin) + " on" : "") << "\n";
  o << "eps_d_accumulated,eps_d_signed,isobaric,p_star_model,s_dev_model,F_dev_model,eps_v_model,nu_model";
  for (const char* q : {"p_star", "s_dev", "F_dev", "eps_v"}) o << "," << q << "_mean," << q << "_lo95," << q << "_hi95";
  o << ",eps_zz_model,eps_zz_dem,sigma_r_p0_model,sigma_r_p0_dem";
  if (m.excess_relaxes) o << ",q_star_model";
  if (triaxial) o << ",pole_ratio_model";
  o << "\n";
  double eps_d_model = 0;   // the model's signed eps_d since the start (its own path: direction x |d eps_d|)
  for (std::size_t i = 0; i < m.acc.size(); ++i) {
    if (i > 0) eps_d_model += d.direction[i] * (m.acc[i] - m.acc[i - 1]);
    const double nan = std::nan("");
    o << num(m.acc[i], 8) << "," << num(d.eps_signed[i], 8) << "," << d.isobaric[i] << "," << num(m.p[i], 8) << ","
      << num(m.s[i], 8) << "," << num(m.F[i], 8) << "," << num(m.ev[i], 8) << "," << num(m.nu[i], 8);
    const std::pair<const std::vector<double>*, const std::vector<double>*> q[] = {
        {&d.p, &d.hw_p}, {&d.s, &d.hw_s}, {&d.F, &d.hw_F}, {&d.ev, &d.hw_ev}};
    for (const auto& [v, h] : q)
      o << "," << num((*v)[i], 8) << "," << num((*v)[i] - (*h)[i], 8) << "," << num((*v)[i] + (*h)[i], 8);
    o << "," << num(model::axial_strain(3.0 * m.ev[i], eps_d_model), 8) << "," << num(i < d.ezz.size() ? d.ezz[i] : nan, 8)
      << "," << num(m.p[i] * (1.0 - m.s[i] / 3.0) / m.p.front(), 8) << "," << num(i < d.sr.size() ? d.sr[i] : nan, 8);
    if (m.excess_relaxes) o << "," << num(m.p[i] - m.p_el[i], 8);
    if (triaxial) o << "," << num(m.pole[i], 8);
    o << "\n";
  }
  write_text_file(path.string(), o.str());
}

// a_A(nu) and ln beta_p(nu) at the ensemble's volume fractions: standard errors and their
// correlation from the covariance (and from the leave-one-out estimates where the jackknife ran).
void write_identifiability(const Calibration& cal, const std::vector<std::vector<double>>& jack,
                           const std::vector<int>& sample, const std::vector<double>& nus, const std::string& fit_label,
                           const fs::path& out) {
  const int np = static_cast<int>(cal.value.size());
  auto cov = [&](int a, int b) { return cal.corr[a][b] * cal.se_cov[a] * cal.se_cov[b]; };
  const int aA = kNumIso + kAnisoA, aB = kNumIso + kAnisoB, pA = kNumIso + kLnBetaPA, pB = kNumIso + kLnBetaPB;
  Table t({"calibrated_on", "nu [-]", "a_A [-]", "se_a_A_cov", "se_a_A_jk", "ln_beta_p [ln(1/eps_d)]", "se_ln_beta_p_cov",
           "se_ln_beta_p_jk", "corr_cov [-]", "corr_jk [-]"});
  std::vector<double> grid = nus;
  grid.insert(grid.begin(), cal.params.nu_ref);
  for (std::size_t g = 0; g < grid.size(); ++g) {
    const double d = grid[g] - cal.params.nu_ref;
    // x = a + b d: var = C_aa + 2 d C_ab + d^2 C_bb; cov(x, y) = C_ac + d (C_ad + C_bc) + d^2 C_bd
    const double vx = cov(aA, aA) + 2 * d * cov(aA, aB) + d * d * cov(aB, aB);
    const double vy = cov(pA, pA) + 2 * d * cov(pA, pB) + d * d * cov(pB, pB);
    const double cxy = cov(aA, pA) + d * (cov(aA, pB) + cov(aB, pA)) + d * d * cov(aB, pB);
    double sx = std::nan(""), sy = std::nan(""), rj = std::nan("");
    if (!jack.empty() && static_cast<int>(jack.front().size()) == np) {
      std::vector<double> xs, ys;
      for (const auto& e : jack) { xs.push_back(e[aA] + d * e[aB]); ys.push_back(e[pA] + d * e[pB]); }
      const double sxx = jackknife_covariance(xs, xs, sample), syy = jackknife_covariance(ys, ys, sample);
      sx = std::sqrt(sxx); sy = std::sqrt(syy);
      rj = sxx > 0 && syy > 0 ? jackknife_covariance(xs, ys, sample) / std::sqrt(sxx * syy) : std::nan("");
    }
    const Local<double> L = local(cal.params.shear, grid[g], cal.params.nu_ref);
    t.add_row({fit_label, num(grid[g], 4) + (g == 0 ? " (nu_ref)" : ""), num(L.a_A), num(std::sqrt(std::max(vx, 0.0))), num(sx),
               num(std::log(L.beta_p)), num(std::sqrt(std::max(vy, 0.0))), num(sy),
               correlation_number(vx > 0 && vy > 0 ? cxy / std::sqrt(vx * vy) : std::nan("")), correlation_number(rj)});
  }
  write_table_all(t, (out / "identifiability").string(),
                  "Identifiability of the anisotropy modulus a_A and the pressure relaxation rate beta_p at each nu: "
                  "standard errors and correlation from the covariance of the joint fit (scaled by max(1, chi2/dof)) and "
                  "from the jackknife over packings (nan where it did not run); calibrated on " + fit_label);
}

// Paths with no DEM counterpart here: undrained cyclic shear with reversals and isobaric D2 from a D2 curve's start
// state, by the calibration's own family and options (prediction_ext; before the twenty-eighth round the group model's
// right-hand side whatever the family).
void write_model_paths(const Parameters& P, const CurveData& c, const std::string& tag, const fs::path& dir) {
  const auto iso = P.iso();
  const std::pair<std::string, std::vector<Segment>> paths[] = {
      {"cyclic", {{0.1, Control::Volume, 0, 0, 50}, {-0.2, Control::Volume, 0, 0, 100}, {0.2, Control::Volume, 0, 0, 100},
                  {-0.2, Control::Volume, 0, 0, 100}}},
      {"isobaric", {{0.3, Control::Isobaric, 0, 0, 150}}}};
  for (const auto& [name, path] : paths) {
    const auto pts = integrate<double>(iso.data(), P.shear, P.nu_ref, c.nu, c.p.front(), c.s.front(), c.F.front(), path,
                                       prediction_ext(P, c.mode));
    std::ostringstream o;
    o << "# dem model: model-only path '" << name << "' from the start state of nu = " << c.nu
      << " (no DEM ensemble of this path here); s_dev, F_dev signed along the first loading direction; "
         "eps_vol the full volumetric strain tr(E) (= 3 eps_v of the curves)\n";
    o << "eps_d_accumulated,eps_d,eps_vol,nu,p_star,s_dev,F_dev\n";
    for (const auto& q : pts)
      o << num(q.eps_d_acc, 8) << "," << num(q.eps_d, 8) << "," << num(q.eps_vol, 8) << "," << num(std::exp(q.state.ln_nu), 8)
        << "," << num(q.state.p, 8) << "," << num(observed(q.state.s, c.s.front(), P.start_unaligned), 8) << ","
        << num(observed(q.state.F, c.F.front(), P.start_unaligned), 8) << "\n";
    write_text_file((dir / (name + "_" + tag + ".csv")).string(), o.str());
  }
}

// ---- Families, the held-out test, the summary table (docs/model.md, "The frictional extension") ----

// What `dem model` reads: the fitted and the other mean curves and path ensembles with their
// files, the label of the fitted set, the members and the isotropic branch.
struct ModelInputs {
  std::vector<CurveData> fit_curves, other;
  std::vector<CurveFile> fit_files, other_files;
  std::vector<PathData> fit_paths, other_paths;
  std::vector<CurveFile> fit_path_files, other_path_files;
  std::string fit_label;
  std::vector<fs::path> members;
  std::vector<std::string> iso_files;
  IsoData iso;
  int K = 0;
};

struct StartOutcome {   // one start of a multi-start calibration (starts.csv)
  std::string start;      ///< the --start entry: a parameters.csv or `default`
  double chi2_dof = 0;
  bool converged = false;
  std::string message;
};

struct JackRefit {   // one leave-one-out refit of the jackknife (jackknife.csv)
  std::string packing;    ///< the member left out
  std::string start;      ///< where the kept refit started: the full fit's optimum or another --start
  double chi2_dof = 0;
  bool converged = false;
  bool usable = false;    ///< jackknife_refit_usable against the full fit
  int tries = 0;          ///< refits run for this packing (1, or 1 + the other starts)
  std::string message;
};

struct FamilyFit {
  Calibration cal;
  std::vector<StartOutcome> starts;        ///< every start tried (more than one: --start A,B,...)
  std::size_t chosen_start = 0;
  std::vector<JackRefit> refits;           ///< the jackknife's leave-one-out refits, in packing order
  std::vector<std::vector<double>> jack;   ///< leave-one-out estimates
  std::vector<int> jack_sample;            ///< per estimate, its sample of packings (JackSamples; one: all 0)
  int samples = 1;                         ///< how many samples of packings the jackknife ran over
  std::vector<double> heldout;             ///< per left-out packing: its own fitted curves' (and paths') mean squared
                                           ///< standardised error under the fit without it
  std::vector<double> heldout_paths;       ///< ... its own predicted paths' (heldout_path_score; NaN: none)
  std::vector<double> heldout_followed;    ///< ... over the predicted paths the fit without it follows
  std::vector<std::string> heldout_not_followed;   ///< ... the paths it does not, and why ("" none)
  /// A refit's optimum at which the fit's own data score lower than the fit ended (full_fit_basin; empty names: none),
  /// written to basin_start/ for a --start
  Calibration basin_start;
};

// Adds ((model - member)/sd)^2 over the rows > 0 that `on` selects (up to the model's length) to ss and their count to
// n: sd = the between-packing SD (se sqrt(K)) floored at 0.25 of the median of the positive se over those rows (row 0
// included), as the fit's weights (heldout_score, heldout_path_score).
void add_standardised_squares(const std::vector<double>& model, const std::vector<double>& member,
                              const std::vector<double>& se, const std::vector<bool>& on, int K, double& ss, long& n) {
  std::vector<double> pos;
  for (std::size_t i = 0; i < se.size(); ++i) if (on[i] && se[i] > 0 && std::isfinite(se[i])) pos.push_back(se[i]);
  if (pos.empty()) return;
  std::nth_element(pos.begin(), pos.begin() + pos.size() / 2, pos.end());
  const double floor = 0.25 * pos[pos.size() / 2];
  for (std::size_t i = 1; i < model.size(); ++i) {
    if (!on[i]) continue;
    const double sd = std::max(se[i], floor) * std::sqrt(static_cast<double>(K));
    const double r = (model[i] - member[i]) / sd;
    ss += r * r;
    ++n;
  }
}

// Adds the member's own path (MEMBER_CSV, on the ensemble D's grid), predicted from its own start state by P, to ss
// and n: ((model - member)/sd)^2 over rows > 0 and p* (constant-volume rows) or eps_v (rows at held pressure), s_dev
// and F_dev signed, sd as add_standardised_squares with D's own packings. False where the laws cannot start it. Where
// WHY is given, it says why the path is not followed ("" where its squares are finite): the laws cannot start it, or
// it loses its drained control or is not a number from some strain on (its squares are added all the same).
bool add_path_squares(const Parameters& P, const PathData& ensemble, const fs::path& member_csv, double& ss, long& n,
                      std::string* why = nullptr) {
  const Table t = read_table(member_csv.string());
  PathData d = ensemble;
  if (t.column("eps_d_accumulated").size() != d.acc.size())
    throw InputError(member_csv.string() + " is not on its ensemble's grid: rerun demkit.path_ensemble");
  d.p = t.column("p_star"); d.ev = t.column("eps_v"); d.s = t.column("s_dev_signed"); d.F = t.column("F_dev_signed");
  d.nu_m = t.column("nu");
  d.nu = d.nu_m.front();
  d.source = member_csv.string();   // the member's own file in what predict_path says
  PathPrediction m;
  try {
    m = predict_path(P, d);
  } catch (const std::invalid_argument& e) {   // the laws cannot start this packing's own path
    if (why) *why = std::string("cannot start: ") + e.what();
    return false;
  }
  std::vector<bool> held(d.acc.size()), vol(d.acc.size()), all(d.acc.size(), true);
  for (std::size_t i = 0; i < d.acc.size(); ++i) { held[i] = d.isobaric[i] != 0; vol[i] = !held[i]; }
  const int K = ensemble.packings;
  double ss1 = 0;
  add_standardised_squares(m.p, d.p, ensemble.se_p, vol, K, ss1, n);
  add_standardised_squares(m.ev, d.ev, ensemble.se_ev, held, K, ss1, n);
  add_standardised_squares(m.s, d.s, ensemble.se_s, all, K, ss1, n);
  add_standardised_squares(m.F, d.F, ensemble.se_F, all, K, ss1, n);
  ss += ss1;
  if (why) {   // the drained control's pole, or the first row not a number (model_fit's path_not_a_number)
    *why = path_not_a_number(m);
    if (!why->empty()) why->erase(0, 1);
    else if (!std::isfinite(ss1)) *why = "its squares are not a number";
  }
  return true;
}

// The left-out member's own fitted curves and paths (those it holds), predicted from its own start states by the fit
// of the other packings: mean of ((model - member)/sd)^2 over rows > 0 and p*, s_dev, F_dev (paths: as
// add_path_squares), sd = the between-packing SD (se sqrt(K), K the curve's own packings) floored at 0.25 of its
// median, as the fit's weights. NaN where the member holds none or the laws cannot start one of its paths. (Before the
// thirty-second round the fitted paths were not scored: a calibration on paths alone had no held-out score.)
double heldout_score(const Parameters& P, const ModelInputs& in, const fs::path& member, double eps_max) {
  double ss = 0;
  long n = 0;
  for (std::size_t j = 0; j < in.fit_curves.size(); ++j) {
    const fs::path mc = member_curve(member, in.fit_files[j]);
    if (mc.empty()) continue;
    const Table t = read_table(mc.string());
    CurveData c = in.fit_curves[j];
    const auto& e = t.column("eps_d");
    c.p = resample(e, t.column("p_star"), c.eps);
    c.s = resample(e, t.column("s_dev"), c.eps);
    c.F = resample(e, t.column("F_dev"), c.eps);
    c.nu = t.column("nu").front();
    const ModelCurve m = predict_curve(P, c, eps_max);
    const std::vector<bool> all(c.se_p.size(), true);
    add_standardised_squares(m.p, c.p, c.se_p, all, c.packings, ss, n);
    add_standardised_squares(m.s, c.s, c.se_s, all, c.packings, ss, n);
    add_standardised_squares(m.F, c.F, c.se_F, all, c.packings, ss, n);
  }
  for (std::size_t j = 0; j < in.fit_paths.size(); ++j) {
    const fs::path mp = member_path_curve(member, in.fit_path_files[j]);
    if (!mp.empty() && !add_path_squares(P, in.fit_paths[j], mp, ss, n)) return std::nan("");
  }
  return n > 0 ? ss / n : std::nan("");
}

// Packing k's own predicted path ensembles (those not fitted: the isobaric D2 paths of a D2 + D3 calibration), each
// from its own start state, by the fit of the other packings: add_path_squares' mean (score: NaN where no member holds
// such a path, where the laws cannot start one, or where the model is lost on it), and the same over the paths the
// fit follows (followed), with those it does not named and why (not_followed). The held-out score of a prediction,
// which heldout_score (fitted curves only) does not see.
struct HeldoutPaths {
  double score = std::nan(""), followed = std::nan("");
  std::string not_followed;
};
HeldoutPaths heldout_path_score(const Parameters& P, const std::vector<PathData>& paths,
                                const std::vector<CurveFile>& files, const fs::path& member) {
  double ss = 0, ss_f = 0;
  long n = 0, n_f = 0;
  bool every = true;
  HeldoutPaths h;
  for (std::size_t j = 0; j < paths.size(); ++j) {
    const fs::path mp = member_path_curve(member, files[j]);
    if (mp.empty()) continue;
    std::string why;
    double ss1 = 0;
    long n1 = 0;
    every = add_path_squares(P, paths[j], mp, ss1, n1, &why) && every;
    ss += ss1; n += n1;
    if (why.empty()) { ss_f += ss1; n_f += n1; continue; }
    h.not_followed += (h.not_followed.empty() ? "" : "; ") + paths[j].name + " nu=" + num(paths[j].nu, 4) + " (" + why + ")";
  }
  h.score = every && n > 0 ? ss / n : std::nan("");
  h.followed = n_f > 0 ? ss_f / n_f : std::nan("");
  return h;
}

// Packing MEMBER's held-out scores of its own predicted paths under P (heldout_path_score), into ff.
void add_heldout_paths(const Parameters& P, const ModelInputs& in, const fs::path& member, FamilyFit& ff) {
  const HeldoutPaths h = heldout_path_score(P, in.other_paths, in.other_path_files, member);
  ff.heldout_paths.push_back(h.score);
  ff.heldout_followed.push_back(h.followed);
  ff.heldout_not_followed.push_back(h.not_followed);
}

// Held-out test between the group model and the frictional family: d_k = score_group - score_ext
// per left-out packing; the extended family is chosen when mean(d) - t_{K-1,0.975} SE(d) > 0 (it
// predicts packings it was not fitted on better, beyond the spread between packings); otherwise
// the group model, the simpler. Returns true when the extended family is chosen.
bool write_selection(const FamilyFit& g, const FamilyFit& x, int K, const fs::path& out) {
  Table t({"packing_left_out", "heldout_group [-]", "heldout_extended [-]", "difference [-]"});
  std::vector<double> d;
  for (std::size_t k = 0; k < g.heldout.size() && k < x.heldout.size(); ++k) {
    d.push_back(g.heldout[k] - x.heldout[k]);
    t.add_row({std::to_string(k), num(g.heldout[k], 4), num(x.heldout[k], 4), num(d.back(), 4)});
  }
  double mean = 0, ss = 0;
  for (double v : d) mean += v / d.size();
  for (double v : d) ss += (v - mean) * (v - mean);
  const double se = d.size() > 1 ? std::sqrt(ss / (d.size() - 1) / d.size()) : std::nan("");
  const double tq = d.size() > 1 ? t_quantile(0.975, d.size() - 1) : std::nan("");
  const bool ext = d.size() > 1 && mean - tq * se > 0;
  t.add_row({"mean", "nan", "nan", num(mean, 4)});
  t.add_row({"se", "nan", "nan", num(se, 4)});
  t.add_row({"chosen", ext ? "extended" : "group", "chi2/dof " + num(g.cal.chi2_dof(), 4) + " / " + num(x.cal.chi2_dof(), 4),
             "nan"});
  fs::create_directories(out);
  write_table_all(t, (out / "selection").string(),
                  "Held-out test of the two model families over " + std::to_string(K) +
                  " packings: each packing's own fitted curves predicted by the fit without it, mean squared error in "
                  "units of the between-packing SD; the extended family is chosen when the mean difference exceeds "
                  "t_{K-1,0.975} x its SE (docs/model.md)");
  return ext;
}

struct SummaryRow {
  std::string mode;
  double nu;
  std::string role, quantity;
  double rms_over_band;
};

// Where a fitted or predicted path meets the isotropic law's cusp (cusp_crossed): "" where it does not.
std::string cusp_on_path(const Parameters& P, const PathPrediction& m) {
  const double at = cusp_crossed(P, m);
  if (!std::isfinite(at)) return "";
  const bool vol = P.extended && P.state_volume;
  const std::string head = std::string("crosses the isotropic law's cusp (") +
                           (vol ? (m.excess_relaxes ? "elastic p* - q = " : "p* = ") + num(at) : "nu = nu_cC = " + num(at));
  if (vol && m.excess_relaxes && !(P.nu_cC > P.nu_c))   // below the law's jamming fraction: q above p
    return head + ", below the law's jamming fraction nu_c = " + num(P.nu_c) + ", nu_cC = " + num(P.nu_cC) + "): the "
           "excess q exceeds p*, and the stiffness is unbounded there, so the path bends where its steps put it and a "
           "fit's cost is not smooth; --anisotropy-pressure bounded keeps q below p* (docs/model.md, \"A cost that is "
           "not smooth at its optimum\")";
  return head + ", nu_cC above nu_c = " + num(P.nu_c) + "): its stiffness is unbounded there and the path bends or ends "
         "where its steps put it; --jamming shared ties the two fractions (docs/model.md, \"One jamming fraction\")";
}

// A curve's or path's start pressure above what the volume-form model's isotropic law reaches on [nu_c, 1]
// (isotropic_volume NaN: a coordination law with C1 < 0 that falls again), said on stderr; nothing where it reaches it.
void warn_beyond_reach(const Parameters& P, const std::string& name, double nu, double p0, const std::string& role) {
  if (!(P.extended && P.state_volume)) return;
  const std::vector<double> iso = P.iso();
  if (!std::isnan(isotropic_volume<double>(iso.data(), p0))) return;
  double at = P.nu_c;
  const double top = isotropic_reach(iso.data(), &at);   // the law's largest pressure, for the message
  std::cerr << "dem model: warning: " << name << " nu=" << num(nu, 4) << " (" << role << ") starts at p* = " << num(p0)
            << ", above the isotropic law's reach (its largest p* on [nu_c, 1] is " << num(top) << " at nu = " << num(at, 4)
            << "; C1 = " << num(iso[kC1]) << (iso[kC1] < 0 ? ": the coordination falls with the density" : "")
            << "): no elastic state holds that pressure, so its p* and s_dev are not numbers (docs/model.md, \"A cost that is "
               "not smooth at its optimum\")\n";
}

// Where the relaxing excess q exceeds the path's pressure (largest_excess_ratio above 1): "" where it does not.
std::string excess_on_path(const PathPrediction& m) {
  double at = 0.0;
  const double r = largest_excess_ratio(m, &at);
  if (!(r > 1.0)) return "";   // with the bounded excess only where p* falls faster than q can follow
  return "has a relaxing anisotropic excess q up to " + num(r, 3) + " times p* (at eps_d_accumulated = " + num(at, 3) +
         "): its elastic state lies below the isotropic law's jamming fraction, a negative isotropic pressure, outside "
         "the law's domain; a_A/beta_p are too large for it" +
         std::string(m.excess_bounded ? "" : "; --anisotropy-pressure bounded keeps q below p*") +
         " (docs/model.md, \"How large the relaxing excess grows\")";
}

// Where the drained triaxial control was lost (PathPrediction::lost_row): "" where every row was reached.
std::string lost_on_path(const PathPrediction& m) {
  if (m.lost_row < 1) return "";
  return "cannot hold its side stress after eps_d_accumulated = " + num(m.acc[m.lost_row - 1], 3) + ": the anisotropy "
         "modulus A = a_A B F came within " + num(100 * kTriaxialMargin) + " % of 3B, the pole where the drained volume "
         "change per unit shear diverges; the model curve stops there (nan) and its error is inf (docs/model.md, "
         "\"Where the drained triaxial control is lost\")";
}

// A start integrated on graded pieces (model::singular_start), and split where its gate is not integrable: "" where
// the start was not graded. M: PathPrediction or ModelCurve.
template <class M>
std::string graded_on_path(const M& m) {
  if (!std::isfinite(m.gate_exponent_start)) return "";
  return "starts where the fabric gate's exponent n_F = " + num(m.gate_exponent_start, 3) + " is negative: the gate "
         "r_F^n_F is unbounded where no contact has opened yet, and the first interval is integrated on a graded grid "
         "from the start (docs/model.md, \"RK4's step where the law is stiff\"; a fixed step reads the gate's floor and "
         "moves the fabric towards its limit in one step, as every calibration before the thirty-sixth round did)" +
         (std::find(m.split.begin(), m.split.end(), true) != m.split.end()
              ? std::string("; at n_F < -1 the gate is not integrable (the fabric reaches its limit at once, and its "
                            "rate on the gate's floor is beyond any RK4 step), and the fabric's relaxation is taken "
                            "exactly on the graded pieces (split_step)")
              : std::string());
}

// Where RK4's fixed step was halved (model::advance: outside RK4's stable range, or the drained control not held) or
// the excess pressure's relaxation taken exactly: "" where the fixed step was kept on every row. M: PathPrediction or
// ModelCurve, AT its rows' strain, named X (eps_d_accumulated, eps_d).
template <class M>
std::string refined_on_path(const M& m, const std::vector<double>& at, const std::string& x) {
  int halved = -1, relaxed = -1, most = 0;
  bool unheld = false;
  for (std::size_t i = 0; i < m.halvings.size(); ++i) {
    if (m.halvings[i] != 0 && halved < 0) halved = static_cast<int>(i);
    if (m.relaxed[i] && relaxed < 0) relaxed = static_cast<int>(i);
    most = std::max(most, m.halvings[i]);
    unheld = unheld || m.halvings[i] < 0;
  }
  if (halved < 1 && relaxed < 1) return "";
  auto from = [&](int i) { return " from " + x + " = " + num(at[i - 1], 3) + " on"; };
  std::string how;
  if (halved > 0)
    how = (most > 0 ? "needed RK4 steps down to 1/" + std::to_string(1 << most) + " of the fixed step"
                    : std::string("was not held by any RK4 step")) + from(halved);
  if (relaxed > 0)
    how += (how.empty() ? "" : "; ") + std::string("took the excess pressure's relaxation exactly (split_step)") +
           from(relaxed);
  return how + ": the fixed step lies outside RK4's stable range there or does not hold the drained control (the law "
               "is stiff; docs/model.md, \"RK4's step where the law is stiff\")" +
         (unheld && (most > 0 || relaxed > 0) ? "; on some rows no step down to 1/" + std::to_string(1 << kMaxHalvings) +
                                                    " held it, so the curve there is not converged" : std::string());
}

// A drained path that comes within kPoleNear of where its control is lost (PathPrediction::pole): the fit cannot
// cross the margin (a lost path's residuals are NaN, its step rejected), so an optimum found there is the margin's, not
// the data's (twenty-first round: the bounded three-pressure mu = 0.1 joint calibration, a_A F/3 = 0.8999989); ""
// otherwise.
constexpr double kPoleNear = 1e-3;
std::string margin_optimum_on_path(const PathPrediction& m, bool fitted) {
  int at = -1;
  for (std::size_t i = 0; i < m.pole.size(); ++i)
    if (std::isfinite(m.pole[i]) && (at < 0 || m.pole[i] > m.pole[at])) at = static_cast<int>(i);
  const double lost_from = 1 - kTriaxialMargin;
  if (at < 0 || m.pole[at] < lost_from - kPoleNear) return "";
  return "comes within " + num(lost_from - m.pole[at], 2) + " of where its drained control is lost (a_A F/3 = " +
         num(m.pole[at], 8) + " at eps_d_accumulated = " + num(m.acc[at], 3) + "; lost from " + num(lost_from) +
         "): " + (fitted ? "the calibration's optimum sits against that margin, which the fit cannot cross, not at a "
                           "minimum of the misfit; its errors describe the margin's constraint, and "
                         : "a calibration whose fit ended there (an optimum against the margin) is not at a minimum of "
                           "its misfit, and ") +
         "a change of the coefficients in their last digits (a restart) may lose the path (docs/model.md, \"A "
         "calibration against the margin\")";
}

// The first fitted path (name and nu) along which the calibration sits against the drained control's margin; ""
// if none.
std::string path_against_margin(const Parameters& P, const std::vector<PathData>& paths) {
  for (const auto& d : paths) {
    try {
      if (!margin_optimum_on_path(predict_path(P, d), true).empty()) return d.name + " nu=" + num(d.nu, 4);
    } catch (const std::invalid_argument&) {   // a start the laws cannot hold: write_results names it
    }
  }
  return "";
}

/// With the volume-form state parameter, a drained path (its last row at held p or side stress) whose model volume still
/// moves at its end: |d nu/d eps_d| over the last 0.1 of strain above 0.01 and five times the DEM's there (nu = nu0
/// e^{-3 eps_v}). The permanent anisotropic pressure has no steady state where |a_A F| exceeds the dilatancy's reach;
/// "" otherwise (docs/model.md, "A relaxing anisotropic pressure").
std::string drift_on_path(const Parameters& P, const PathPrediction& m, const PathData& d) {
  constexpr double tail = 0.1;
  if (!(P.extended && P.state_volume) || m.acc.size() < 2 || d.isobaric.back() == 0 || m.acc.back() < 2 * tail) return "";
  std::size_t i = 0;
  while (i + 1 < m.acc.size() && m.acc[i + 1] <= m.acc.back() - tail) ++i;
  const double de = m.acc.back() - m.acc[i];
  const double model = std::fabs(m.nu.back() - m.nu[i]) / de;
  const double dem = d.nu * std::fabs(std::exp(-3 * d.ev.back()) - std::exp(-3 * d.ev[i])) / de;
  if (!(model > 0.01 && model > 5 * dem)) return "";
  return "still moves at its end: |d nu/d eps_d| = " + num(model, 3) + " over the last " + num(tail) + " of strain, the "
         "DEM's " + num(dem, 3) + (P.excess_relaxes ? std::string(" (no steady state by the path's end)") :
         std::string(": with the permanent anisotropic pressure a constant-p path is steady only where the dilatancy "
                     "cancels a_A F; --anisotropy-pressure relaxing ends it on the critical-state line (docs/model.md, "
                     "\"A relaxing anisotropic pressure\")"));
}

// What a path's prediction M of D (ROLE: fitted or predicted) met on the way, one stderr line each: the isotropic law's
// reach and cusp, a relaxing excess above p, the drained control lost or its margin, a volume still moving at the end
// (warnings), and where the integration was graded or its step halved (notes).
void say_path_notes(const Parameters& P, const PathPrediction& m, const PathData& d, const std::string& role) {
  warn_beyond_reach(P, d.name, d.nu, d.p.front(), role);
  const std::string cusp = cusp_on_path(P, m);
  if (!cusp.empty()) std::cerr << "dem model: warning: " << d.name << " (" << role << ") " << cusp << "\n";
  const std::string where = d.name + " nu=" + num(d.nu, 4) + " (" + role + ") ";
  const std::string lost = lost_on_path(m);
  const std::string warnings[] = {excess_on_path(m), lost, lost.empty() ? margin_optimum_on_path(m, role == "fitted") : "",
                                  drift_on_path(P, m, d)};
  for (const auto& w : warnings)
    if (!w.empty()) std::cerr << "dem model: warning: " << where << w << "\n";
  for (const auto& n : {graded_on_path(m), refined_on_path(m, m.acc, "eps_d_accumulated")})
    if (!n.empty()) std::cerr << "dem model: note: " << where << n << "\n";
}

// One stderr line a reader can quote: how many curves lie within one band half-width RMS, the worst fitted and the
// worst predicted curve with its quantity, and chi2/dof (issue 31's targets: every curve within 1, chi2/dof <= 3).
// curve_worst: each judged curve's worst quantity as write_summary's table has it (inf: diverged); rows: the
// quantities, read for the names of the worst fitted and predicted one.
void say_verdict(const std::vector<SummaryRow>& rows, const std::vector<double>& curve_worst, const Calibration& cal) {
  const SummaryRow* top[2] = {nullptr, nullptr};             // fitted, predicted
  double top_x[2] = {-1, -1};                                 // their errors (inf: diverged)
  for (const auto& r : rows) {
    if (r.quantity.find("after turn") != std::string::npos || r.role.find("not integrable") != std::string::npos) continue;
    const double x = std::isfinite(r.rms_over_band) ? r.rms_over_band : std::numeric_limits<double>::infinity();
    const int k = r.role == "fitted" ? 0 : 1;
    if (x > top_x[k]) { top[k] = &r; top_x[k] = x; }
  }
  int within = 0;
  for (double x : curve_worst) within += x <= 1;
  const auto name = [&top_x](const SummaryRow* r, int k) {
    return r ? num(top_x[k], 3) + " (" + r->mode + " nu=" + num(r->nu, 4) + " " + r->quantity + ")" : std::string("none");
  };
  std::cerr << "dem model: " << within << " of " << curve_worst.size() << " curves within 1 band half-width (RMS); worst "
            << "fitted " << name(top[0], 0) << ", worst predicted " << name(top[1], 1) << "; chi2/dof "
            << (std::isfinite(cal.chi2) ? num(cal.chi2_dof(), 4) : std::string("nan (nothing fitted)")) << " (summary.md)\n";
}

// One line per curve: RMS error over the band half-width of p* (or eps_v where p is held),
// s_dev and F_dev, fitted and predicted, with the calibration's chi2/dof: the table of issue 31.
void write_summary(const std::vector<SummaryRow>& rows, const Calibration& cal, const std::string& fit_label,
                   const fs::path& out) {
  Table t({"mode", "nu [-]", "role", "p_star [band]", "eps_v [band]", "s_dev [band]", "F_dev [band]", "worst [band]"});
  std::vector<std::pair<std::string, double>> keys;
  for (const auto& r : rows)
    if (std::find(keys.begin(), keys.end(), std::make_pair(r.mode, r.nu)) == keys.end()) keys.push_back({r.mode, r.nu});
  // A quantity the curve has but whose error is not finite (the model's curve went to inf or nan: it diverged) is
  // "inf", and so is the curve's worst and the calibration's: never left out of the maximum. A path the laws cannot
  // start (role "not integrable": no model curve) is "nan" in every cell, not determined, its role saying why.
  const auto cell = [](double x) { return std::isinf(x) ? std::string("inf") : num(x, 3); };
  double worst_all = 0;
  std::vector<double> curve_worst;   // each judged curve's worst (the verdict line counts those within 1)
  int diverged = 0;
  for (const auto& [mode, nu] : keys) {
    double v[4] = {std::nan(""), std::nan(""), std::nan(""), std::nan("")};   // nan: the curve has no such quantity
    std::string role;
    for (const auto& r : rows) {
      if (r.mode != mode || r.nu != nu || r.quantity.find("after turn") != std::string::npos) continue;
      role = r.role;
      if (role.find("not integrable") != std::string::npos) continue;   // no model curve: not determined, not diverged
      const int q = r.quantity == "p_star" ? 0 : r.quantity == "eps_v" ? 1 : r.quantity.rfind("s_dev", 0) == 0 ? 2 : 3;
      v[q] = std::isfinite(r.rms_over_band) ? r.rms_over_band : std::numeric_limits<double>::infinity();
    }
    double worst = std::nan("");   // nan: no quantity judged
    for (double x : v) if (!std::isnan(x)) worst = std::isnan(worst) ? x : std::max(worst, x);
    if (!std::isnan(worst)) { worst_all = std::max(worst_all, worst); curve_worst.push_back(worst); }
    if (std::isinf(worst)) ++diverged;
    t.add_row({mode, num(nu, 4), role, cell(v[0]), cell(v[1]), cell(v[2]), cell(v[3]), cell(worst)});
  }
  t.add_row({"calibration", "nan", "chi2/dof " + num(cal.chi2_dof(), 4), "nan", "nan", "nan", "nan", cell(worst_all)});
  say_verdict(rows, curve_worst, cal);
  if (diverged)
    std::cerr << "dem model: " << diverged << " curves not finite (the model diverged along them): \"inf\" in "
              << (out / "summary.md").string() << "\n";
  write_table_all(t, (out / "summary").string(),
                  std::string("RMS of model - DEM mean over the mean 95 % band half-width per curve (") +
                      (cal.params.extended ? std::string("extended family, ") + surface_name(cal.params.surface) + " surface, fabric limit " +
                                                  fabric_lode_name(cal.params.fabric) +
                                                  (cal.params.state_lode ? ", state-dependent limit (pressure, Lode-dependent exponent)"
                                                   : cal.params.state_limit ? ", state-dependent limit (pressure)"
                                                   : cal.params.state_volume ? ", state parameter nu - nu_cs(p)" : "")
                                           : "group model") +
                      ", calibrated on " + fit_label + "); p_star on constant-volume rows, eps_v where p is held");
}

// --out before the calibration (minutes): a folder, or one that can be made, and writable.
void check_output_folder(const fs::path& out) {
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_directory(out, ec))
    throw InputError("--out " + out.string() + " is a file, not a folder: give a folder (it is created if missing), "
                     "e.g. --out " + (out.parent_path() / "model").string());
  fs::create_directories(out, ec);
  if (ec)
    throw InputError("--out " + out.string() + ": the folder cannot be created (" + ec.message() + "): give a folder "
                     "you can write, e.g. --out DIR/model");
  const fs::path probe = out / ".dem-model-write-test";
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0)
    throw InputError("--out " + out.string() + " is not writable (" + std::string(std::strerror(errno)) + "): give "
                     "a folder you can write, e.g. --out DIR/model");
  ::close(fd);
  fs::remove(probe, ec);
}


// The ensemble folder's curves, path ensembles and isotropic branch, split by --calibrate-on.
ModelInputs read_model_inputs(const ModelCommandOptions& o, const fs::path& dir) {
  ModelInputs in;
  auto& [fit_curves, other, fit_files, other_files, fit_paths, other_paths, fit_path_files, other_path_files,
         fit_label, members_out, iso_files_out, iso_out, K_out] = in;
  // With --start the path ensembles alone may be the calibration (the laboratory set of issue 31):
  // DIR need not hold ensemble curves then.
  const auto files = find_curves(dir, starts_from_files(o));
  std::vector<std::string> fit_names = o.calibrate_on.empty() ? std::vector<std::string>{o.calibrate_mode} : o.calibrate_on;
  if (!o.predict_with.empty()) fit_names.clear();   // --predict-with: nothing fitted, everything predicted
  auto fitted = [&](const std::string& n) { return std::find(fit_names.begin(), fit_names.end(), n) != fit_names.end(); };
  std::vector<std::string> known;
  for (const auto& f : files) {
    CurveData c = read_curve(f.path.string(), f.mode, f.nu);
    known.push_back(f.mode);
    if (fitted(f.mode)) { fit_curves.push_back(c); fit_files.push_back(f); }
    else { other.push_back(c); other_files.push_back(f); }
  }
  if (fit_curves.empty() && !starts_from_files(o))
    throw InputError("no ensemble curve of the fitted modes (" + o.calibrate_mode + ", --calibrate-on) under " +
                     (dir / "ensemble").string() + ": run the ensemble with mode D2 (or pick another with --calibrate-mode); "
                     "paths alone cannot be the calibration (a monotone mode gives the start values) unless --start "
                     "PARAMETERS.csv gives them");
  // Path ensembles (demkit/path_ensemble.py): --paths, or DIR/paths when it exists.
  fs::path paths_dir = o.paths.empty() ? dir / "paths" : fs::path(o.paths);
  if (!o.paths.empty() && !fs::is_directory(paths_dir))
    throw InputError("--paths " + o.paths + " is not a folder: give the output of `python3 -m demkit.path_ensemble` "
                     "(PATH_phiX.csv files)");
  if (fs::is_directory(paths_dir)) {
    const auto pf = find_paths(paths_dir);
    if (pf.empty() && !o.paths.empty())
      throw InputError("--paths " + o.paths + " holds no PATH_phiX.csv (path ensembles of `python3 -m demkit.path_ensemble`)");
    for (const auto& f : pf) {
      PathData d = read_path(f.path.string(), f.mode, f.nu);
      known.push_back(f.mode);
      if (fitted(f.mode)) { fit_paths.push_back(d); fit_path_files.push_back(f); }
      else { other_paths.push_back(d); other_path_files.push_back(f); }
    }
  }
  for (const auto& n : fit_names)
    if (std::find(known.begin(), known.end(), n) == known.end())
      throw InputError("--calibrate-on " + n + ": no ensemble curve " + n + "_phiX.csv under " + (dir / "ensemble").string() +
                       " nor path ensemble under " + paths_dir.string());
  if (fit_curves.empty() && fit_paths.empty() && o.predict_with.empty())
    throw InputError("--calibrate-on names no curve or path ensemble under " + dir.string() + ": give the paths to fit "
                     "(e.g. --calibrate-on TC_s3_dense)");
  for (const auto& n : fit_names) fit_label += (fit_label.empty() ? "" : "+") + n;
  members_out = member_dirs(dir);
  const auto& members = members_out;
  std::vector<std::string>& iso_files = iso_files_out;
  iso_files = o.isotropic;
  if (iso_files.empty())
    for (const auto& m : members)
      if (!unloading_of(m).empty()) iso_files.push_back(unloading_of(m).string());
  if (iso_files.empty())
    throw InputError("no isotropic branch: neither DIR/members/*/prep/cycle_unloading.csv nor DIR/members/*/cycle_unloading.csv "
                     "exists; pass the unloading curves with --isotropic FILE...");
  for (const auto& f : iso_files)
    if (!fs::exists(f)) throw InputError("--isotropic " + f + " does not exist");
  iso_out = read_isotropic(iso_files);

  K_out = !fit_curves.empty() ? fit_curves.front().packings : !fit_paths.empty() ? fit_paths.front().packings
          : !other.empty() ? other.front().packings : other_paths.empty() ? 0 : other_paths.front().packings;
  return in;
}

// --start, read once: one entry per start, nullptr for `default` (CalibrationOptions::start points at one of them).
std::vector<std::unique_ptr<Parameters>> start_params;

// The starts of the calibration from --start, checked and read (none given: the default start alone).
void read_starts(const ModelCommandOptions& o, CalibrationOptions& co) {
  start_params.clear();
  for (const auto& f : o.start) {
    if (f == "default") {
      start_params.push_back(nullptr);
      continue;
    }
    if (!fs::is_regular_file(f))
      throw InputError("--start " + f + " is not a file: give the parameters.csv of a `dem model` run, or `default` "
                       "(the start from the data's own saturating fits)");
    try {
      start_params.push_back(std::make_unique<Parameters>(read_parameters(f)));
    } catch (const std::runtime_error& e) {
      throw InputError("--start " + f + ": " + e.what());
    }
  }
  co.start = start_params.empty() ? nullptr : start_params.front().get();
  co.start_iso_from_file = o.start_isotropic != "branch";
}

// --d2-lode as a number: 1/2 when not given or "normal" (set after the fit, or from the --predict-with file).
double d2_lode_number(const ModelCommandOptions& o) {
  if (o.d2_lode.empty() || o.d2_lode == "normal") return kLodeBD2;
  char* end = nullptr;
  const double b = std::strtod(o.d2_lode.c_str(), &end);
  if (end == o.d2_lode.c_str() || *end != '\0' || !(b > 0.0 && b < 1.0))
    throw InputError("--d2-lode " + o.d2_lode + ": give the stress Lode parameter b of D2 as a number between 0 and 1 "
                     "(0.5 the strain's; the constant-volume D2 of data/geotech/constant_volume ends at 0.32-0.39), or "
                     "normal (the plane-strain b of the Lode surface through the calibrated limit)");
  return b;
}

// --profile's comma-separated names, each a coefficient of the model (isotropic, shear or extension).
std::vector<std::string> profile_names(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream ss(list);
  for (std::string n; std::getline(ss, n, ',');) {
    bool known = iso_index(n) >= 0 || ext_index(n) >= 0;
    for (int i = 0; i < kNumShear; ++i) known = known || n == shear_name(i);
    if (!known)
      throw InputError("--profile " + list + ": " + (n.empty() ? "an empty name" : "'" + n + "' is not a coefficient") +
                       "; give `all` or names as parameters.csv writes them (e.g. p0,alpha,s_max_a,a_A_a)");
    out.push_back(n);
  }
  return out;
}

// One stderr line per profiled coefficient: its interval, the time so far and about how long the rest will take (the
// clock starts at the call with k = -1, before the first).
std::function<void(const std::string&, int, int, const ProfileInterval&)> profile_progress() {
  const auto t0 = std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  return [t0](const std::string& name, int k, int n, const ProfileInterval& p) {
    if (k < 0) {
      *t0 = std::chrono::steady_clock::now();
      return;
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - *t0).count();
    std::cerr << "dem model: profile " << k + 1 << "/" << n << " " << name << ": [" << num(p.lower.value) << ", "
              << num(p.upper.value) << "] (" << std::llround(s) << " s; about " << std::llround(s / (k + 1) * (n - k - 1))
              << " s left)\n";
  };
}

// The calibration's options from the command's (--eps-max, --family, --surface, --fabric-lode checked).
// The frictional family's options that add no coefficient (the anisotropic excess, the start's alignment, the dilatancy
// gate, the fabric's state limit, the deviator's volume scaling), checked against the family and the state limit.
void read_extension_options(const ModelCommandOptions& o, CalibrationOptions& co) {
  co.excess_relaxes = o.anisotropy_pressure == "relaxing" || o.anisotropy_pressure == "bounded";
  co.excess_bounded = o.anisotropy_pressure == "bounded";
  co.start_unaligned = o.start_anisotropy == "unaligned";
  co.dilatancy_gated = o.dilatancy_gate == "mobilisation";
  if (co.dilatancy_gated && (o.family != "extended" || co.state_volume))
    throw InputError("--dilatancy-gate mobilisation: the gate acts on the extended family's plastic dilatancy d_D (r - "
                     "chi_D); give --family extended without --state-limit volume (whose dilatancy is driven by psi)");
  co.fabric_state = o.fabric_limit == "state";
  if (co.fabric_state && (o.family != "extended" || !co.state_limit) && o.predict_with.empty())
    throw InputError("--fabric-limit state: the fabric follows the stress ratio's state factor (p_ref/p)^n_psi, which "
                     "only the pressure-form state limit has; add --family extended --state-limit pressure (or "
                     "pressure-lode)");
  co.deviator_reference = o.deviator_volume == "reference";
  if (co.deviator_reference && (o.family != "extended" || co.state_volume))
    throw InputError("--deviator-volume reference: sigma_dev scaling with the isotropic reference pressure under a "
                     "volume change belongs to the extended family without the volume-form state parameter (whose "
                     "elastic split moves the stress by the elastic volume change alone); give --family extended "
                     "without --state-limit volume");
  if (co.excess_relaxes && !co.state_volume && o.predict_with.empty())
    throw InputError("--anisotropy-pressure " + o.anisotropy_pressure + ": the relaxing excess belongs to the volume-form "
                     "state parameter (without it the anisotropic pressure always relaxes at beta_p); add --state-limit volume");
}

CalibrationOptions calibration_options(const ModelCommandOptions& o) {
  CalibrationOptions co;
  co.eps_max = o.eps_max;
  if (o.max_iterations < 1) throw InputError("--max-iterations " + std::to_string(o.max_iterations) + ": give a positive number");
  co.max_iterations = o.max_iterations;
  read_starts(o, co);
  if (o.start_isotropic == "branch" && o.start.empty())
    throw InputError("--start-isotropic branch says where a --start fit's isotropic block starts, and no --start was "
                     "given: add --start PARAMETERS.csv, or leave it out (without a start the block starts from the "
                     "branch's own fit)");
  if (!o.hold_isotropic.empty() && !start_params.empty() && !start_params.front())
    throw InputError("--hold-isotropic holds parameters at the values of the first --start file, and the first is "
                     "`default`: put a parameters.csv first");
  for (const auto& n : o.hold_isotropic) {
    const int i = iso_index(n);
    if (i < 0)
      throw InputError("--hold-isotropic " + n + ": not an isotropic parameter; give some of p0, nu_c, gamma_p, C0, C1, "
                       "nu_cC, alpha");
    if (!co.start)
      throw InputError("--hold-isotropic needs --start PARAMETERS.csv (the values they are held at)");
    co.hold_iso.push_back(i);
  }
  co.hold_from = co.hold_iso.empty() ? nullptr : co.start;
  co.shared_jamming = o.jamming == "shared";
  co.coordination_rises = o.coordination == "rising";
  co.profile = !o.profile.empty();
  if (co.profile && o.profile != "all") co.profile_only = profile_names(o.profile);
  if (co.profile) co.profile_progress = profile_progress();
  if (co.shared_jamming && std::find(co.hold_iso.begin(), co.hold_iso.end(), kNuCC) != co.hold_iso.end())
    throw InputError("--jamming shared ties nu_cC to the fitted nu_c, and --hold-isotropic holds nu_cC: leave nu_cC out "
                     "of --hold-isotropic (or use --jamming separate)");
  for (const auto& n : o.hold) {
    const int i = ext_index(n);
    if (i < 0) {
      std::string all;
      for (int j = 0; j < kNumExt; ++j) all += std::string(j ? ", " : "") + ext_name(j);
      throw InputError("--hold " + n + ": not a coefficient of the frictional extension; give some of " + all +
                       " (isotropic ones: --hold-isotropic)");
    }
    if (o.family != "extended")
      throw InputError("--hold " + n + " holds a coefficient of the frictional extension: give --family extended");
    co.hold_ext.push_back(i);
  }
  if (o.family != "group" && o.family != "extended" && o.family != "auto")
    throw InputError("--family " + o.family + ": give group (the incremental anisotropic model), extended (with the "
                     "frictional extension) or auto (both, chosen by the held-out test)");
  if (o.surface == "ld") co.surface = Surface::LadeDuncan;
  else if (o.surface == "mn") co.surface = Surface::MatsuokaNakai;
  else if (o.surface == "none") co.surface = Surface::None;
  else throw InputError("--surface " + o.surface + ": give ld (Lade-Duncan), mn (Matsuoka-Nakai) or none");
  if (o.fabric_lode == "principal") co.fabric = FabricLode::Principal;
  else if (o.fabric_lode == "norm") co.fabric = FabricLode::Norm;
  else if (o.fabric_lode == "opening") co.fabric = FabricLode::Opening;
  else if (o.fabric_lode == "overlap") co.fabric = FabricLode::Overlap;
  else if (o.fabric_lode == "extension") co.fabric = FabricLode::Extension;
  else if (o.fabric_lode == "weighted") co.fabric = FabricLode::Weighted;
  else throw InputError("--fabric-lode " + o.fabric_lode + ": give principal (the largest principal deviatoric fabric "
                        "saturates at every Lode angle), norm (F_dev saturates at F_max at every Lode angle), opening "
                        "(principal, and the fabric gated by the minor principal stress), overlap (the default: principal, "
                        "and the fabric gated by the fraction of contacts opened by the extension strain), extension "
                        "(overlap, and the fabric's rate per unit extension strain) or weighted (the Lode dependence of "
                        "the onset and the rate weighted by the contact overlap; needs a second Lode angle in --calibrate-on)");
  if (o.state_limit == "pressure" || o.state_limit == "pressure-lode") co.state_limit = true;
  else if (o.state_limit == "volume") co.state_volume = true;
  else if (o.state_limit != "none")
    throw InputError("--state-limit " + o.state_limit + ": give none (the default: the stress-ratio limit s_max(nu) on the "
                     "Lode surface), pressure (that limit times (p_ref/p)^n_psi, the state parameter in pressure form, "
                     "n_psi(nu) fitted) or pressure-lode (pressure, with n_psi scaled by (c_3(b_ref)/c_3(b))^lambda_psi, "
                     "lambda_psi fitted; needs a second Lode angle in --calibrate-on) or volume (the state parameter "
                     "psi = nu - nu_cs(p): the limit times e^{n_b psi}, the dilatancy d_D (r - e^{-n_d psi}), the "
                     "critical-state line from the calibration paths' end states, --csl); "
                     "docs/model.md");
  co.state_lode = o.state_limit == "pressure-lode";
  co.b_d2 = d2_lode_number(o);
  if (o.csl != "linear" && o.csl != "log")
    throw InputError("--csl " + o.csl + ": give linear (the default: the critical-state line nu_cs + c_cs (p* - 1e-3), "
                     "a rigid-grain critical state compressed by the contacts) or log (nu_cs + lambda_cs ln(p*/1e-3)); "
                     "docs/model.md, \"The critical-state line of soft spheres\"");
  co.csl_linear = o.csl == "linear";
  if (co.state_volume && o.family != "extended")
    throw InputError("--state-limit volume: the volume-form state parameter belongs to the extended family; give "
                     "--family extended");
  read_extension_options(o, co);
  const int n_block = ext_size(co.state_limit, co.fabric == FabricLode::Weighted, co.state_lode, co.state_volume);
  for (int i : co.hold_ext)
    if (i >= n_block)
      throw InputError(std::string("--hold ") + ext_name(i) + ": this law does not have it (--state-limit " +
                       o.state_limit + ", --fabric-lode " + o.fabric_lode + "); n_rate, m_peak, nu_cs, lambda_cs, "
                       "n_peak, n_dil and c_cs belong to --state-limit volume");
  return co;
}

// The jackknife's packings: the members (DIR/members/*) that hold a fitted mean curve or path, each in the sample of
// the members that hold the same ones. One sample where every packing holds every fitted curve; two in the joint
// calibration (the friction study's packings behind D2 + D3, the laboratory's behind TC_s3; docs/model.md, "A
// jackknife over two sets of packings"). `why` is not empty where a fitted curve's packings are not its holders.
struct JackSamples {
  std::vector<std::size_t> member;   ///< the jackknife's packings, indices into ModelInputs::members
  std::vector<int> sample;           ///< each one's sample (0, 1, ... in the order of first appearance)
  std::vector<int> size;             ///< each sample's packings
  std::string why;                   ///< why the jackknife cannot run ("" when it can)
};
JackSamples jackknife_samples(const ModelInputs& in) {
  JackSamples s;
  const std::size_t nc = in.fit_files.size(), n = nc + in.fit_path_files.size();
  std::vector<int> holders(n, 0);
  std::map<std::string, int> ids;
  for (std::size_t m = 0; m < in.members.size(); ++m) {
    std::string held(n, '0');
    for (std::size_t j = 0; j < n; ++j)
      if (!(j < nc ? member_curve(in.members[m], in.fit_files[j])
                   : member_path_curve(in.members[m], in.fit_path_files[j - nc])).empty()) {
        held[j] = '1';
        ++holders[j];
      }
    if (held.find('1') == std::string::npos) continue;   // a packing of predicted curves only: not refitted
    const auto it = ids.emplace(held, static_cast<int>(ids.size())).first;
    if (it->second == static_cast<int>(s.size.size())) s.size.push_back(0);
    ++s.size[it->second];
    s.member.push_back(m);
    s.sample.push_back(it->second);
  }
  for (std::size_t j = 0; j < n && s.why.empty(); ++j) {
    const CurveFile& f = j < nc ? in.fit_files[j] : in.fit_path_files[j - nc];
    const int K = j < nc ? in.fit_curves[j].packings : in.fit_paths[j - nc].packings;
    if (holders[j] != K)
      s.why = "DIR/members holds " + std::to_string(holders[j]) + " member curves of " + f.mode + "_" + f.tag +
              " (its mean is over " + std::to_string(K) + " packings)";
  }
  for (std::size_t g = 0; g < s.size.size() && s.why.empty(); ++g)
    if (s.size[g] < 2) s.why = "a set of packings holding its own fitted curves has one packing (none to leave out)";
  if (s.member.empty() && s.why.empty()) s.why = "no member holds a fitted curve";
  return s;
}

// A refit whose start was moved within the isotropic law's reach (Calibration::start_moved, model_fit's
// start_within_reach): " (p0 raised from A to B: ...)" for jackknife.md's start column; "" else.
std::string moved_start(const Calibration& c) {
  return c.start_moved.empty() ? "" : " (" + c.start_moved + ": the left-out mean starts above the start's isotropic reach)";
}

// Packing k's leave-one-out data: every fitted mean curve and path it holds without it (the others as they are), and
// the isotropic branch without its own states (refit_without, basin_check).
struct LooInputs {
  std::vector<CurveData> curves;
  IsoData iso;
  std::vector<PathData> paths;
};
LooInputs leave_out(const ModelInputs& in, int k) {
  const fs::path& member = in.members[k];
  LooInputs L;
  for (std::size_t j = 0; j < in.fit_curves.size(); ++j) {
    const fs::path mc = member_curve(member, in.fit_files[j]);
    L.curves.push_back(mc.empty() ? in.fit_curves[j] : leave_one_out(in.fit_curves[j], mc));
  }
  std::vector<std::string> iso_k;
  const std::string own = unloading_of(member).string();
  for (const auto& f : in.iso_files) if (f != own) iso_k.push_back(f);
  L.iso = read_isotropic(iso_k);
  for (std::size_t j = 0; j < in.fit_paths.size(); ++j) {
    const fs::path mp = member_path_curve(member, in.fit_path_files[j]);
    L.paths.push_back(mp.empty() ? in.fit_paths[j] : leave_one_out_path(in.fit_paths[j], mp));
  }
  return L;
}

// The options of a jackknife refit: the full fit's, without the Jacobian check and the profile (their errors are not
// read).
CalibrationOptions refit_options(const CalibrationOptions& co_f) {
  CalibrationOptions cj = co_f;
  cj.check_jacobian = false;
  cj.profile = false;
  return cj;
}

// Packing k left out of every fitted mean curve and path and of the isotropic branch, refitted from the full
// fit's optimum. A refit that did not reach an optimum like the full fit's (jackknife_refit_usable: failed at
// its start, not converged, or far above), or ended above kRetryAbove times the full fit's chi2/dof (at least 1),
// is run again from each other --start until one ends below, and the best is kept: a usable one before an unusable
// one, then converged before not, then the lowest chi2/dof. (Leave-one-out refits of the stored calibrations end
// at 0.9-1.35 times the full fit's; the bounded mu = 1 dense one without m2 at 2.9 times, a poorer optimum.)
constexpr double kRetryAbove = 1.5;
JackRefit refit_without(const ModelInputs& in, const CalibrationOptions& co_f, const ModelCommandOptions& o,
                        const FamilyFit& ff, int k, Calibration& best) {
  const fs::path& member = in.members[k];
  const LooInputs L = leave_out(in, k);
  JackRefit r{member.filename().string(), "the full fit's optimum", 0, false, false, 0, ""};
  CalibrationOptions cj = refit_options(co_f);
  auto rank = [&](const Calibration& c) {   // usable, converged, then evaluated: higher is better
    return 4 * jackknife_refit_usable(c, ff.cal) + 2 * c.ok + !std::isnan(c.chi2);
  };
  for (std::size_t i = 0; i <= start_params.size(); ++i) {
    const bool settled = r.usable && best.chi2_dof() <= kRetryAbove * std::max(1.0, ff.cal.chi2_dof());
    if (i > 0 && (i - 1 == ff.chosen_start || settled)) continue;
    cj.start = i == 0 ? &ff.cal.params : start_params[i - 1].get();
    Calibration c = calibrate(L.curves, L.iso, cj, L.paths);
    ++r.tries;
    const bool better = i == 0 || rank(c) > rank(best) || (rank(c) == rank(best) && c.chi2_dof() < best.chi2_dof());
    if (better) {
      best = std::move(c);
      r.start = (i == 0 ? std::string("the full fit's optimum") : "--start " + o.start[i - 1]) + moved_start(best);
      r.usable = jackknife_refit_usable(best, ff.cal);
    }
  }
  r.chi2_dof = best.chi2_dof();
  r.converged = best.ok;
  r.message = best.message;
  return r;
}

// chi^2 of a leave-one-out data set at cj.start, as a refit from it would begin (nan where it cannot be evaluated).
double evaluated_chi2(const LooInputs& L, CalibrationOptions cj) {
  cj.evaluate_only = true;
  try {
    return calibrate(L.curves, L.iso, cj, L.paths).chi2;
  } catch (const std::invalid_argument&) {
    return std::nan("");
  }
}

// The jackknife's basin check (issue 31, thirty-fifth round): each refit's own data evaluated at every other refit's
// optimum. A refit starts from the full fit's optimum (or another --start) and Levenberg-Marquardt only descends, so
// where another refit's optimum scores lower on this refit's data than this refit ended, this one stopped in a
// poorer basin: it is run again from the lowest such optimum and the new optimum kept where it ends lower. One pass;
// an evaluation costs one residual evaluation, a restart one refit. (The thirty-fourth round's restarts ended in
// other basins: lab_dense without m2 and m3, bounded mu = 0.1 dense without m3.)
constexpr double kBasinBelow = 1e-6;   // relative: lower than the refit's own chi2 by more than round-off

// The refit (index into FITS, not SKIP) whose optimum scores lowest on L below LOWEST (lowered to its chi2 there);
// FITS.size() where none does.
std::size_t lowest_optimum(const LooInputs& L, CalibrationOptions cj, const std::vector<Calibration>& fits,
                           std::size_t skip, double& lowest) {
  std::size_t from = fits.size();
  for (std::size_t j = 0; j < fits.size(); ++j) {
    if (j == skip || std::isnan(fits[j].chi2)) continue;
    cj.start = &fits[j].params;
    const double c = evaluated_chi2(L, cj);
    if (c < lowest) { lowest = c; from = j; }
  }
  return from;
}

void basin_check(const ModelInputs& in, const CalibrationOptions& co_f, const JackSamples& js, FamilyFit& ff,
                 std::vector<Calibration>& fits) {
  const std::size_t n = fits.size();
  CalibrationOptions cj = refit_options(co_f);
  for (std::size_t k = 0; k < n; ++k) {
    if (std::isnan(fits[k].chi2)) continue;
    const LooInputs L = leave_out(in, static_cast<int>(js.member[k]));
    double lowest = fits[k].chi2 * (1 - kBasinBelow);
    const std::size_t from = lowest_optimum(L, cj, fits, k, lowest);
    if (from == n) continue;
    JackRefit& r = ff.refits[k];
    cj.start = &fits[from].params;
    Calibration c = calibrate(L.curves, L.iso, cj, L.paths);
    ++r.tries;
    const std::string was = num(r.chi2_dof, 4);
    const bool lower = !std::isnan(c.chi2) && c.chi2 < fits[k].chi2;
    std::cerr << "dem model: basin check: the refit without " << r.packing << " (chi2/dof " << was << ") scores "
              << num(lowest / std::max(1, c.n_residuals - c.n_free), 4) << " at the refit without "
              << ff.refits[from].packing << "'s optimum; run again from it: chi2/dof " << num(c.chi2_dof(), 4)
              << (lower ? ", kept" : ", not lower: the first kept") << "\n";
    if (!lower) continue;
    fits[k] = std::move(c);
    r.start = "the refit without " + ff.refits[from].packing + "'s optimum (basin check; from " + r.start +
              " it ended at chi2/dof " + was + ")";
    r.chi2_dof = fits[k].chi2_dof();
    r.converged = fits[k].ok;
    r.usable = jackknife_refit_usable(fits[k], ff.cal);
    r.message = fits[k].message;
  }
}

// The basin check of the full fit (thirty-fifth round): its own data evaluated at every refit's optimum. Where one
// scores lower than the fit ended, the fit stopped in a poorer basin: said in a warning, and the lowest such optimum
// kept in ff.basin_start (written to basin_start/parameters.csv, a --start to fit again from).
void full_fit_basin(const ModelInputs& in, const CalibrationOptions& co_f, FamilyFit& ff,
                    const std::vector<Calibration>& fits) {
  if (std::isnan(ff.cal.chi2)) return;
  const LooInputs all{in.fit_curves, in.iso, in.fit_paths};
  double lowest = ff.cal.chi2 * (1 - kBasinBelow);
  const std::size_t from = lowest_optimum(all, refit_options(co_f), fits, fits.size(), lowest);
  if (from == fits.size()) return;
  Calibration& b = ff.basin_start;   // a start, not a result: its chi2 the fit's data's there, no errors
  b = fits[from];
  b.chi2 = lowest;
  b.n_residuals = ff.cal.n_residuals;
  b.n_free = ff.cal.n_free;
  b.se_cov.assign(b.value.size(), std::nan(""));
  b.se_jackknife.clear();
  b.ok = true;
  b.settled.clear();
  ff.cal.warnings.push_back(
      "the fit's own data score chi2/dof " + num(lowest / std::max(1, ff.cal.n_residuals - ff.cal.n_free), 4) +
      " at the optimum of the refit without " + ff.refits[from].packing + ", below the fit's " +
      num(ff.cal.chi2_dof(), 4) + (ff.cal.ok ? ": the fit stopped in a poorer basin" : ": the fit had not converged") +
      ". That optimum is in basin_start/parameters.csv "
      "in the output folder: fit again with --start from it (docs/model.md, \"The jackknife's basin check\")");
}

// Jackknife over packings: the same fit with each packing left out of every mean curve and path it holds and of the
// isotropic branch (jackknife_samples: one set of packings, or several behind different fitted curves); the held-out
// score of each left-out packing (its own fitted curves predicted by the fit without it).
void jackknife(const ModelInputs& in, const CalibrationOptions& co_f, const ModelCommandOptions& o, FamilyFit& ff) {
  Calibration& cal = ff.cal;
  if (!o.jackknife || in.K < 2) return;
  const JackSamples js = jackknife_samples(in);
  if (!js.why.empty()) {
    cal.warnings.push_back("jackknife skipped: " + js.why + "; errors from the covariance instead");
    return;
  }
  std::vector<std::vector<double>>& est = ff.jack;   // leave-one-out estimates (for the jackknife correlations)
  std::string failed;   // refits that did not reach an optimum comparable to the full fit's
  const std::size_t n = js.member.size();
  std::vector<Calibration> fits(n);
  for (std::size_t k = 0; k < n; ++k) {
    const JackRefit r = refit_without(in, co_f, o, ff, static_cast<int>(js.member[k]), fits[k]);
    ff.refits.push_back(r);
    std::cerr << "dem model: jackknife " << k + 1 << "/" << n << " (" << r.packing << " left out): chi2/dof = "
              << num(r.chi2_dof, 4) << (r.tries > 1 ? " (from " + r.start + ", after " + std::to_string(r.tries) +
                                                       " starts)" : std::string()) << "\n";
  }
  if (o.basin_check) {
    basin_check(in, co_f, js, ff, fits);
    full_fit_basin(in, co_f, ff, fits);
  }
  for (std::size_t k = 0; k < n; ++k) {
    const fs::path& member = in.members[js.member[k]];
    const JackRefit& r = ff.refits[k];
    est.push_back(fits[k].value);
    ff.heldout.push_back(heldout_score(fits[k].params, in, member, o.eps_max));
    add_heldout_paths(fits[k].params, in, member, ff);
    if (!r.usable)
      failed += (failed.empty() ? "" : ", ") + r.packing + " left out (chi2/dof " + num(r.chi2_dof, 4) +
                (r.converged ? "" : ", not converged") + ")";
  }
  ff.jack_sample = js.sample;
  ff.samples = static_cast<int>(js.size.size());
  if (!failed.empty()) {   // a failed refit's values are its start's or a poor optimum's: not the packings' scatter
    ff.jack.clear();
    cal.warnings.push_back("jackknife not used: its refit " + failed + " did not reach an optimum like the full fit's "
                           "(chi2/dof " + num(cal.chi2_dof(), 4) + "), so the spread of the refits is not the "
                           "packings' scatter (not even from the other --start values, if given); errors from the "
                           "covariance instead (jackknife.md lists every refit; docs/model.md, \"The jackknife's "
                           "refits\")");
    return;
  }
  cal.se_jackknife = jackknife_errors(est, cal, co_f.csl_linear, &cal.warnings, ff.samples > 1 ? js.sample
                                      : std::vector<int>{}, &cal.dof_jackknife);
  const int smallest = *std::min_element(js.size.begin(), js.size.end());
  if (smallest < 4) {   // as `dem fit` says for its fits
    double worst = 1;
    for (std::size_t i = 0; i < cal.value.size(); ++i)
      if (cal.se_jackknife[i] > 0 && cal.se_cov[i] > 0) worst = std::max(worst, cal.se_cov[i] / cal.se_jackknife[i]);
    cal.warnings.push_back("only " + std::to_string(smallest) + " packings" + (ff.samples > 1 ? " in a set" : "") +
                           ": a jackknife over fewer than 4 packings is itself very uncertain (here up to " +
                           num(worst, 3) + "x below the covariance errors) and its intervals under-cover; set "
                           "[ensemble] packings >= 4 for errors between packings");
  }
}

// One family: calibration, jackknife over packings, and the held-out score of each left-out packing.
FamilyFit fit_family(const ModelInputs& in, const CalibrationOptions& co, const ModelCommandOptions& o, bool extended) {
  const auto& fit_curves = in.fit_curves; const auto& fit_paths = in.fit_paths; const IsoData& iso = in.iso;
  FamilyFit ff;
  Calibration& cal = ff.cal;
  CalibrationOptions co_f = co;
  co_f.extended = extended;
  std::cerr << "dem model: family " << (extended ? "extended" : "group") << "\n";
  const std::size_t n_starts = std::max<std::size_t>(1, start_params.size());
  co_f.profile = co.profile && n_starts == 1;   // several starts: the chosen one's profile below
  for (std::size_t i = 0; i < n_starts; ++i) {
    if (!start_params.empty()) co_f.start = start_params[i].get();
    Calibration ci;
    try {
      ci = calibrate(fit_curves, iso, co_f, fit_paths);
    } catch (const std::invalid_argument& e) {
      throw InputError((n_starts > 1 ? "--start " + o.start[i] + ": " : std::string()) + e.what());
    }
    std::cerr << "dem model: " << (n_starts > 1 ? "start " + o.start[i] + ": " : std::string()) << ci.message
              << (std::isnan(ci.chi2) ? "  failed (not evaluated at its start)" : "  chi2/dof = " + num(ci.chi2_dof(), 4))
              << "\n";
    if (n_starts > 1) ff.starts.push_back({o.start[i], ci.chi2_dof(), ci.ok, ci.message});
    // the lowest chi2/dof of the converged fits (of all, if none converged)
    const bool better = i == 0 || (ci.ok && !cal.ok) || (std::isnan(cal.chi2) && !std::isnan(ci.chi2)) ||
                        (ci.ok == cal.ok && ci.chi2_dof() < cal.chi2_dof());
    if (better) {
      cal = std::move(ci);
      ff.chosen_start = i;
    }
  }
  co_f.start = start_params.empty() ? nullptr : start_params[ff.chosen_start].get();
  if (n_starts > 1)
    std::cerr << "dem model: the fit from start " << o.start[ff.chosen_start] << " has the lowest chi2/dof ("
              << num(cal.chi2_dof(), 4) << "; starts.md)\n";
  if (co.profile && n_starts > 1) {   // the chosen start again (a deterministic fit: the same one), with its profile intervals
    co_f.profile = true;
    cal = calibrate(fit_curves, iso, co_f, fit_paths);
    co_f.profile = false;
  }

  jackknife(in, co_f, o, ff);
  cal.against_margin = path_against_margin(cal.params, in.fit_paths);
  if (!cal.against_margin.empty())
    cal.warnings.push_back("the optimum sits against the drained control's margin on " + cal.against_margin + " (docs/"
                           "model.md, \"A calibration against the margin\"): the fit stopped where that path would be "
                           "lost, not at a minimum of the misfit, so its errors (covariance or jackknife, whose refits are "
                           "held there too) describe how the margin moves, not how the data determine the coefficients: "
                           "parameters.csv quotes them as not determined (se nan; the columns se_covariance and "
                           "se_jackknife keep the numbers)");
  return ff;
}

// The Jacobian check's largest disagreement (Calibration::jacobian_disagreement), one line on stderr; nothing where
// it did not run.
void report_jacobian_check(const Calibration& cal) {
  int worst = -1, checked = 0, above = 0;
  for (std::size_t i = 0; i < cal.jacobian_disagreement.size(); ++i) {
    const double d = cal.jacobian_disagreement[i];
    if (std::isnan(d)) continue;
    ++checked;
    above += !(d <= kRoughAbove);
    if (worst < 0 || !(d <= cal.jacobian_disagreement[worst])) worst = static_cast<int>(i);
  }
  if (worst < 0) return;
  std::cerr << "dem model: the Jacobian against central differences of the residuals at the optimum: largest "
               "disagreement "
            << (std::isinf(cal.jacobian_disagreement[worst]) ? std::string("inf (a stepped point not evaluated)")
                                                              : num(cal.jacobian_disagreement[worst], 3))
            << " (" << cal.names[worst] << "; "
            << (cal.rough.empty() ? "smooth" : "not smooth") << "; " << above << " of " << checked << " columns above "
            << num(kRoughAbove) << ")\n";
}

// How the quoted coefficients' costs over one covariance error fall (report_error_scale): below 1/kQuadraticWithin
// on either side (the error understated), above kQuadraticWithin, a bound within the error; and the one furthest from 1.
struct ErrorScaleCount {
  int quoted = 0, below = 0, above = 0, bound = 0, furthest = -1;
};
ErrorScaleCount count_error_scale(const Calibration& cal, const std::vector<bool>& quoted) {
  ErrorScaleCount c;
  double furthest = -1;
  for (std::size_t i = 0; i < quoted.size(); ++i) {
    if (!quoted[i]) continue;
    ++c.quoted;
    const ErrorScale& e = cal.error_scale[i];
    bool below = false, above = false, bound = false;
    for (double r : {e.minus, e.plus}) {
      bound = bound || std::isnan(r);
      below = below || r < 1 / kQuadraticWithin;
      above = above || r > kQuadraticWithin;
      const double dev = r > 0 ? std::fabs(std::log(r)) : std::isnan(r) ? -1 : std::numeric_limits<double>::infinity();
      if (dev > furthest) { furthest = dev; c.furthest = static_cast<int>(i); }
    }
    c.below += below; c.above += above; c.bound += bound;
  }
  return c;
}

// The cost over one covariance error either way (Calibration::error_scale): error_scale.{csv,md,tex,json}, a row per
// checked coefficient, and one line on stderr over those parameters.csv quotes an error for; nothing where the check
// did not run.
void report_error_scale(const Calibration& cal, const fs::path& out) {
  Table t({"parameter", "value", "se_covariance", "quoted", "chi2_rise_minus [-]", "chi2_rise_plus [-]",
           "curvature [-]", "offset [se]", "se_held_over_se [-]"});
  std::vector<bool> quoted(cal.error_scale.size(), false);
  for (std::size_t i = 0; i < cal.error_scale.size() && i < cal.value.size(); ++i) {
    const ErrorScale& e = cal.error_scale[i];
    if (std::isnan(e.conditional)) continue;   // not checked
    quoted[i] = std::isfinite(cal.se()[i]) && cal.errors_not_determined().empty();
    // a quadratic about a minimum offset by delta errors rises by 1 -+ 2 delta: the mean is its curvature, over the
    // quadratic model's, and (minus - plus)/4 where its minimum lies along the profile
    t.add_row({cal.names[i], num(cal.value[i]), num(cal.se_cov[i]), quoted[i] ? "yes" : "no", num(e.minus, 4),
               num(e.plus, 4), num((e.minus + e.plus) / 2, 4), num((e.minus - e.plus) / 4, 3), num(e.conditional, 4)});
  }
  if (t.rows.empty()) return;
  write_table_all(t, (out / "error_scale").string(),
                  "The cost over one covariance error: chi^2 one covariance error either way along each checked "
                  "coefficient's linearised profile (the other checked coefficients at the quadratic model's conditional "
                  "optimum; the free ones that quote no error, on a bound or not determined, held where they are), over "
                  "the quadratic model's rise max(1, chi2/dof); 1 where the cost is quadratic over the error, below 1 "
                  "where it is flatter (the error understated), nan where a bound lies within it, inf where the model "
                  "is not evaluated there; curvature: their mean (1 for the quadratic model's); offset: (minus - plus)/4, "
                  "where a quadratic rising so has its minimum, in errors along the profile (0 at a "
                  "minimum); se_held_over_se: that error with the unquoted ones held, over se_covariance; "
                  "quoted: whether parameters.csv quotes an error for it (docs/model.md, \"The cost over one quoted "
                  "error\")");
  const ErrorScaleCount c = count_error_scale(cal, quoted);
  if (c.furthest < 0) return;
  const ErrorScale& w = cal.error_scale[c.furthest];
  std::cerr << "dem model: the cost over one covariance error either way: of " << c.quoted << " quoted coefficients "
            << c.below << " rise by less than 1/" << num(kQuadraticWithin) << " of the quadratic's (the error "
            << "understated), " << c.above << " by more than " << num(kQuadraticWithin) << ", " << c.bound
            << " reach a bound within it; furthest " << cal.names[c.furthest] << " (" << num(w.minus, 3) << ", "
            << num(w.plus, 3) << ") (error_scale.csv)\n";
}

// How a profile end was found (ProfileEnd): the rise reached, the coefficient's bound, a failed refit, or neither
// within the refits and the reach.
std::string profile_end_kind(const ProfileEnd& e) {
  if (e.failed) return "refit failed";
  if (e.bound) return "bound";
  if (std::isnan(e.value)) return "not reached";
  return std::fabs(e.rise - 1) <= 0.05 ? "found" : "not settled";
}

// The profile intervals (Calibration::profile; --profile): profile.{csv,md,tex,json}, a row per coefficient with a
// quoted covariance error, and one line on stderr: how many ends lie outside [1/sqrt(kQuadraticWithin),
// sqrt(kQuadraticWithin)] covariance errors (where check_error_scale's rise is outside [1/2, 2]), end on a bound or
// are not reached, and whether a refit found a chi2 below the fit's.
void report_profile(const Calibration& cal, const fs::path& out) {
  Table t({"parameter", "value", "se_covariance", "profile_lower", "profile_upper", "lower_over_se [-]",
           "upper_over_se [-]", "end_lower", "end_upper", "rise_lower [-]", "rise_upper [-]", "refits",
           "chi2_below_fit"});
  const double within = std::sqrt(kQuadraticWithin);
  int rows = 0, outside = 0, bound = 0, open = 0, below = 0;
  double lowest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < cal.profile.size() && i < cal.value.size(); ++i) {
    const ProfileInterval& p = cal.profile[i];
    if (p.lower.refits + p.upper.refits == 0) continue;   // no quoted error: not profiled
    const double se = cal.se_cov[i], lo = (cal.value[i] - p.lower.value) / se, hi = (p.upper.value - cal.value[i]) / se;
    t.add_row({cal.names[i], num(cal.value[i]), num(se), num(p.lower.value), num(p.upper.value), num(lo, 3),
               num(hi, 3), profile_end_kind(p.lower), profile_end_kind(p.upper), num(p.lower.rise, 3),
               num(p.upper.rise, 3), std::to_string(1 + p.lower.refits + p.upper.refits), num(p.below_optimum)});
    ++rows;
    bool out_of = false;
    for (double r : {lo, hi}) out_of = out_of || (std::isfinite(r) && (r > within || r < 1 / within));
    outside += out_of && !p.lower.bound && !p.upper.bound;
    bound += p.lower.bound || p.upper.bound;
    open += std::isnan(p.lower.value) || std::isnan(p.upper.value);
    if (!std::isnan(p.below_optimum)) { ++below; lowest = std::min(lowest, p.below_optimum); }
  }
  if (rows == 0) return;
  write_table_all(t, (out / "profile").string(),
                  "Profile intervals: each coefficient with a quoted covariance error held at trial values and every "
                  "other free coefficient refitted, until chi^2 rises by max(1, chi2/dof) over the fit's; "
                  "profile_lower/upper: the interval's ends (the coefficient's bound where end = bound, nan where the "
                  "rise was not reached within 16 errors or a refit failed); lower/upper_over_se: their distance from "
                  "the value in covariance errors (1 where the cost is quadratic); rise: chi^2's rise over the scale at "
                  "the end (1 within 0.05 where found); refits: those made for the row; chi2_below_fit: the lowest "
                  "chi^2 a refit reached below the fit's (nan: none; else the fit was not at its minimum) "
                  "(docs/model.md, \"Profile intervals\")");
  std::cerr << "dem model: profile intervals: of " << rows << " coefficients, " << outside << " have an end beyond "
            << num(within, 3) << " or within 1/" << num(within, 3) << " covariance errors, " << bound
            << " end on a bound, " << open << " have an end not found; "
            << (below ? "for " + std::to_string(below) + " a refit went below the fit's chi2 (lowest " + num(lowest, 8) +
                            "): the fit was not at its minimum"
                      : std::string("no refit went below the fit's chi2"))
            << " (profile.csv)\n";
}

// One family's held-out scores (`--family group|extended` with the jackknife; `auto` writes them in
// selection.csv): per left-out packing, the score the paired test between two runs' rules reads
// (demkit/model_state_limit.py).
void write_heldout(const FamilyFit& ff, const fs::path& out) {
  if (ff.heldout.empty()) return;
  // a path some refit does not follow: the score over those it does, and which and why (thirty-fifth round)
  const bool lost = std::any_of(ff.heldout_not_followed.begin(), ff.heldout_not_followed.end(),
                                [](const std::string& w) { return !w.empty(); });
  const bool paths = lost || std::any_of(ff.heldout_paths.begin(), ff.heldout_paths.end(), [](double v) { return !std::isnan(v); });
  Table t(paths ? std::vector<std::string>{"packing_left_out", "heldout_extended [-]", "heldout_predicted_paths [-]"}
                : std::vector<std::string>{"packing_left_out", "heldout_extended [-]"});
  const bool sets = ff.samples > 1;   // several sets of packings: each row's packing and set
  if (lost) t.header.insert(t.header.end(), {"heldout_followed_paths [-]", "paths_not_followed"});
  if (sets) t.header.insert(t.header.begin() + 1, {"packing", "set"});
  for (std::size_t k = 0; k < ff.heldout.size(); ++k) {
    std::vector<std::string> r{std::to_string(k), num(ff.heldout[k], 4)};
    if (paths) r.push_back(num(ff.heldout_paths[k], 4));
    if (lost) r.insert(r.end(), {num(ff.heldout_followed[k], 4), ff.heldout_not_followed[k]});
    if (sets) r.insert(r.begin() + 1, {ff.refits[k].packing, std::to_string(ff.jack_sample[k])});
    t.add_row(r);
  }
  write_table_all(t, (out / "heldout").string(),
                  "Held-out score per left-out packing: its own fitted curves (and fitted paths) predicted by the fit without it, mean "
                  "squared error in units of the between-packing SD (docs/model.md, the held-out test); the column name "
                  "is selection.csv's, whatever the family" +
                      std::string(paths ? "; heldout_predicted_paths: the same for its own predicted path ensembles "
                                          "(p* or eps_v, s_dev, F_dev signed; docs/model.md, \"Where plastic flow starts\")"
                                        : "") +
                      std::string(lost ? "; nan where the fit without it cannot start or follow one of them; "
                                         "heldout_followed_paths: the same over the paths it follows, "
                                         "paths_not_followed the others and why" : ""));
}

// The jackknife's leave-one-out refits: each one's chi2/dof, whether it converged and was usable (an optimum like
// the full fit's: jackknife_refit_usable), and where it started; the jackknife errors are quoted only when every
// refit is usable (otherwise the covariance's, and parameters.md's se_jackknife is nan).
void write_refits(const FamilyFit& ff, const fs::path& out) {
  if (ff.refits.empty()) return;
  Table t({"packing_left_out", "chi2_per_dof [-]", "full_fit_chi2_per_dof [-]", "converged", "usable", "start", "tries",
           "message"});
  const bool sets = ff.samples > 1;   // several sets of packings: which set each one is in
  if (sets) t.header.insert(t.header.begin() + 1, "set");
  for (std::size_t k = 0; k < ff.refits.size(); ++k) {
    const JackRefit& r = ff.refits[k];
    std::vector<std::string> row{r.packing, num(r.chi2_dof, 6), num(ff.cal.chi2_dof(), 6), r.converged ? "yes" : "no",
                                 r.usable ? "yes" : "no", r.start, std::to_string(r.tries), r.message};
    if (sets) row.insert(row.begin() + 1, std::to_string(k < ff.jack_sample.size() ? ff.jack_sample[k] : 0));
    t.add_row(row);
  }
  write_table_all(t, (out / "jackknife").string(),
                  std::string("The jackknife's refits, one per packing left out of every fitted mean it holds and of "
                              "the isotropic branch; ") +
                      (sets ? "set: the packings holding the same fitted curves (the errors sum each set's part, "
                              "(n-1)/n sum (x - its mean)^2; docs/model.md, \"A jackknife over two sets of "
                              "packings\"); " : "") +
                      "usable: converged with chi2/dof at most 3 max(1, the full fit's); a refit that was not, or "
                      "ended above 1.5 max(1, the full fit's), is run again from each other --start and the best kept; "
                      "a refit whose own data score lower at another refit's optimum is run again from the lowest such "
                      "optimum and kept where it ends lower (the basin check; start says so); "
                      "the jackknife errors are used only when every refit is usable");
  if (ff.jack.size() != ff.refits.size()) return;   // the errors are the covariance's: no estimates to give
  std::vector<std::string> head{"packing_left_out"};
  if (sets) head.push_back("set");
  head.insert(head.end(), ff.cal.names.begin(), ff.cal.names.end());
  Table e(head), e6(head);   // every digit (csv, json), six (md, tex)
  for (std::size_t k = 0; k < ff.jack.size(); ++k) {
    std::vector<std::string> row{ff.refits[k].packing};
    if (sets) row.push_back(std::to_string(ff.jack_sample[k]));
    std::vector<std::string> row6 = row;
    for (double v : ff.jack[k]) { row.push_back(table_number_exact(v)); row6.push_back(num(v)); }
    e.add_row(row);
    e6.add_row(row6);
  }
  write_table_all(e, e6, (out / "jackknife_estimates").string(),
                  "Each jackknife refit's coefficients (the leave-one-out estimates, every digit), in parameters.csv's "
                  "order: se_jackknife^2 = sum over the sets of (n-1)/n sum (x - the set's mean)^2");
}

// A multi-start calibration's starts (--start A,B,...): each one's chi2/dof and whether it converged, and which
// was kept (the jackknife refits start from the kept optimum).
void write_starts(const FamilyFit& ff, const fs::path& out) {
  if (ff.starts.empty()) return;
  Table t({"start", "chi2_per_dof [-]", "converged", "kept", "message"});
  for (std::size_t i = 0; i < ff.starts.size(); ++i) {
    const auto& s = ff.starts[i];
    t.add_row({s.start, num(s.chi2_dof, 6), s.converged ? "yes" : "no", i == ff.chosen_start ? "yes" : "no", s.message});
  }
  write_table_all(t, (out / "starts").string(),
                  "The calibration from each --start (`default`: the start from the data's own saturating fits); the "
                  "lowest chi2/dof of the converged fits is kept (of all, if none converged), and the jackknife refits start from it");
}

// One family's tables, curves and figures in `out`.
// basin_start/parameters.* (full_fit_basin): the refit's optimum a fit can start from again (a former run's is gone:
// clear_former_results).
void write_basin_start(const FamilyFit& ff, int K, const fs::path& out, const std::string& fit_label) {
  if (ff.basin_start.names.empty()) return;
  fs::create_directories(out / "basin_start");
  write_parameter_tables(ff.basin_start, K, out / "basin_start", fit_label + ": the optimum of a jackknife refit at "
                         "which the fit's own data score lower than the fit ended (the basin check; a --start, not a "
                         "result: no errors)");
}

void write_results(const ModelInputs& in, const FamilyFit& ff, const fs::path& out, const ModelCommandOptions& o) {
  const auto& fit_curves = in.fit_curves; const auto& fit_files = in.fit_files;
  const auto& other = in.other; const auto& other_files = in.other_files;
  const auto& fit_paths = in.fit_paths; const auto& fit_path_files = in.fit_path_files;
  const auto& other_paths = in.other_paths; const auto& other_path_files = in.other_path_files;
  const std::string& fit_label = in.fit_label;
  const int K = in.K;
  const Calibration& cal = ff.cal;
  const std::vector<std::vector<double>>& jack_est = ff.jack;
  fs::create_directories(out / "curves");
  write_parameter_tables(cal, K, out, fit_label);
  write_basin_start(ff, K, out, fit_label);
  std::vector<double> nus;
  for (const auto& c : fit_curves) nus.push_back(c.nu);
  if (fit_curves.empty())
    for (const auto& d : fit_paths) nus.push_back(d.nu);
  if (cal.params.extended && cal.params.state_volume) write_state_laws_table(cal.params, fit_paths, out);
  else write_laws_table(cal.params, nus, out);

  Table pred({"mode", "nu", "role", "quantity", "n", "rms [quantity]", "max_abs [quantity]", "bias [quantity]",
              "band_halfwidth [quantity]", "rms_over_band [-]", "max_over_band [-]", "frac_in_band [-]"});
  std::vector<SummaryRow> summary;
  auto evaluate = [&](const CurveData& c, const CurveFile& f, const std::string& role) {
    warn_beyond_reach(cal.params, c.mode, c.nu, c.p.front(), role);
    const ModelCurve m = predict_curve(cal.params, c, o.eps_max);
    for (const auto& n : {graded_on_path(m), refined_on_path(m, m.eps, "eps_d")})
      if (!n.empty()) std::cerr << "dem model: note: " << c.mode << " nu=" << num(c.nu, 4) << " (" << role << ") " << n << "\n";
    write_model_curve(m, c, role, out / "curves" / (f.mode + "_" + f.tag + ".csv"));
    for (const auto& e : prediction_errors(m, c)) {
      summary.push_back({c.mode, c.nu, role, e.quantity, e.rms_over_band});
      pred.add_row({c.mode, num(c.nu, 4), role, e.quantity, std::to_string(e.n), num(e.rms, 4), num(e.max_abs, 4),
                    num(e.bias, 4), num(e.band, 4), num(e.rms_over_band, 3), num(e.max_over_band, 3), num(e.frac_in_band, 3)});
      std::cerr << "dem model: " << c.mode << " nu=" << num(c.nu, 4) << " " << role << " " << e.quantity
                << ": rms " << num(e.rms, 3) << " = " << num(e.rms_over_band, 3) << " band, max " << num(e.max_over_band, 3)
                << " band, in band " << num(100 * e.frac_in_band, 3) << " %\n";
    }
  };
  for (std::size_t j = 0; j < fit_curves.size(); ++j) evaluate(fit_curves[j], fit_files[j], "fitted");
  for (std::size_t j = 0; j < other.size(); ++j) evaluate(other[j], other_files[j], "predicted");
  auto evaluate_path = [&](const PathData& d, const CurveFile& f, const std::string& role) {
    PathPrediction m;
    try {
      m = predict_path(cal.params, d);
    } catch (const std::invalid_argument& e) {   // a start state the calibrated laws cannot hold (nu0 <= nu_c)
      if (role == "fitted") throw InputError(e.what());
      std::cerr << "dem model: warning: " << e.what() << "\n";
      summary.push_back({d.name, d.nu, role + ", not integrable (nu0 <= nu_c)", "s_dev", std::nan("")});
      pred.add_row({d.name, num(d.nu, 4), role + ", not integrable (nu0 <= nu_c)", "all", "0", "nan", "nan", "nan", "nan",
                    "nan", "nan", "nan"});
      return;
    }
    say_path_notes(cal.params, m, d, role);
    fs::create_directories(out / "curves" / "paths");
    write_path_curve(m, d, role, out / "curves" / "paths" / (f.mode + "_" + f.tag + ".csv"));
    for (const auto& e : path_errors(m, d)) {
      if (e.n == 0) continue;
      summary.push_back({d.name, d.nu, role, e.quantity, e.rms_over_band});
      pred.add_row({d.name, num(d.nu, 4), role, e.quantity, std::to_string(e.n), num(e.rms, 4), num(e.max_abs, 4),
                    num(e.bias, 4), num(e.band, 4), num(e.rms_over_band, 3), num(e.max_over_band, 3), num(e.frac_in_band, 3)});
      std::cerr << "dem model: " << d.name << " nu=" << num(d.nu, 4) << " " << role << " " << e.quantity << ": rms "
                << num(e.rms, 3) << " = " << num(e.rms_over_band, 3) << " band, max " << num(e.max_over_band, 3)
                << " band, in band " << num(100 * e.frac_in_band, 3) << " %\n";
    }
  };
  for (std::size_t j = 0; j < fit_paths.size(); ++j) evaluate_path(fit_paths[j], fit_path_files[j], "fitted");
  for (std::size_t j = 0; j < other_paths.size(); ++j) evaluate_path(other_paths[j], other_path_files[j], "predicted");
  write_table_all(pred, (out / "prediction").string(),
                  "Model against the DEM ensemble mean per mode, nu and quantity: RMS, max and mean (bias) of "
                  "model - DEM over eps_d > 0, in the quantity's units and relative to the mean 95 % band half-width; "
                  "role: fitted (calibration curves) or predicted (not fitted); paths: s_dev, F_dev signed along the first "
                  "loading direction, p_star on constant-volume rows, eps_v (= tr E/3) on isobaric rows; calibrated on " + fit_label);
  write_identifiability(cal, jack_est, ff.samples > 1 ? ff.jack_sample : std::vector<int>{}, nus, fit_label, out);
  for (std::size_t j = 0; j < fit_curves.size(); ++j)   // D2 paths, from the D2 curves' start states (a D3 curve has the
    if (fit_curves[j].mode == "D2")                      // same tag: it overwrote them before the twenty-eighth round)
      write_model_paths(cal.params, fit_curves[j], fit_files[j].tag, out / "curves");

  write_summary(summary, cal, fit_label, out);
  for (const auto& w : cal.warnings) std::cerr << "dem model: warning: " << w << "\n";
  report_jacobian_check(cal);
  report_error_scale(cal, out);
  report_profile(cal, out);
  std::cerr << "dem model: tables and curves written to " << out.string() << "\n";
  if (!o.no_plots) {
    const std::string cmd = "PYTHONPATH=" + std::string(DEM_SOURCE_DIR) + " /usr/bin/python3 -m demkit.model_plots \"" +
                            out.string() + "\"";
    if (std::system(cmd.c_str()) != 0) std::cerr << "dem model: plotting failed (tables are written)\n";
  }
}

// The inputs read and checked against the options (the weighted fabric rule needs a second Lode angle);
// on a refusal the output folder that check_output_folder made, still empty, is removed again.
ModelInputs checked_inputs(const ModelCommandOptions& o, const CalibrationOptions& co, const fs::path& dir,
                           const fs::path& out, bool out_existed) {
  try {
    ModelInputs in = read_model_inputs(o, dir);
    if (co.state_volume && o.predict_with.empty() && in.fit_paths.empty())
      throw InputError("--state-limit volume takes its critical-state line from the end states of drained paths, and "
                       "--calibrate-on names none: calibrate on a drained triaxial test (e.g. --calibrate-on TC_s3_dense "
                       "with --start PARAMETERS.csv), or choose --state-limit none or pressure");
    if (o.d2_lode == "normal" && o.predict_with.empty()) {
      // lode_b_of(name, -1) is -1 only for D2 and paths made of D2: the names whose b --d2-lode sets
      for (const auto& c : in.fit_curves)
        if (lode_b_of(c.mode, -1.0) < 0)
          throw InputError("--d2-lode normal reads D2's b from the calibrated limit, and --calibrate-on fits " + c.mode +
                           " (a D2 curve), which needs it during the fit: give --d2-lode a number (e.g. 0.35)");
      for (const auto& d : in.fit_paths)
        if (lode_b_of(d.name, -1.0) < 0)
          throw InputError("--d2-lode normal reads D2's b from the calibrated limit, and --calibrate-on fits the path " +
                           d.name + " (made of D2), which needs it during the fit: give --d2-lode a number (e.g. 0.35)");
    }
    if (o.family != "group" && co.fabric == FabricLode::Weighted && o.predict_with.empty()) {   // nothing fitted with
      try {                                                                                        // --predict-with
        check_weighted_lode(in.fit_curves, in.fit_paths);
      } catch (const std::invalid_argument& e) {
        throw InputError(e.what());
      }
    }
    return in;
  } catch (...) {
    std::error_code ec;
    if (!out_existed && fs::is_empty(out, ec)) fs::remove(out, ec);
    throw;
  }
}

// Whether the law of P reads extension entry i, as read_parameters tells the laws apart (the n_psi pair: the state
// limit; lambda_psi: its Lode exponent; nu_cs on: the volume-form state parameter; the Weighted pair where the rule or
// the file has it): a predicted run writes those rows only, so that its parameters.csv predicts the same again.
bool ext_entry_read(const Parameters& P, int i) {
  if (i < kNumExtBase) return true;
  if (i == kNPsiA || i == kNPsiB) return P.state_limit;
  if (i == kLnDeltaW || i == kNW) return P.fabric == FabricLode::Weighted || P.ext[i] != 0.0;
  if (i == kLambdaPsi) return P.state_lode;
  return P.state_volume;
}

// `--predict-with PARAMETERS.csv`: no calibration; the file's parameters (the family, surface and fabric rule of the
// options, the state limit as the file has it) predict every curve and path, the --calibrate-on ones included.
FamilyFit prediction_only(const ModelCommandOptions& o, const CalibrationOptions& co, ModelInputs& in) {
  FamilyFit ff;
  Calibration& cal = ff.cal;
  try {
    cal.params = read_parameters(o.predict_with);
  } catch (const std::exception& e) {
    throw InputError("--predict-with: " + std::string(e.what()));
  }
  Parameters& P = cal.params;
  if (P.extended != (o.family == "extended"))
    throw InputError("--predict-with " + o.predict_with + " holds the " + (P.extended ? "extended" : "group") +
                     " family's parameters: give --family " + (P.extended ? "extended" : "group"));
  P.surface = P.extended ? co.surface : Surface::None;
  P.fabric = P.extended ? co.fabric : FabricLode::Norm;
  if (!o.d2_lode.empty()) P.b_d2 = o.d2_lode == "normal" ? plane_strain_lode_b(P.surface, P.shear[kSmaxA]) : co.b_d2;
  if (!o.start_anisotropy.empty()) P.start_unaligned = co.start_unaligned;   // else the file's (row start_anisotropy)
  if (!o.dilatancy_gate.empty()) P.dilatancy_gated = co.dilatancy_gated;   // else the file's (row dilatancy_gate)
  if (!o.fabric_limit.empty()) {   // else the file's (row fabric_limit)
    if (co.fabric_state && !P.state_limit)
      throw InputError("--fabric-limit state: " + o.predict_with + " has no pressure-form state limit (no n_psi_a row); "
                       "the fabric follows that limit's state factor");
    P.fabric_state = co.fabric_state;
  }
  if (!o.deviator_volume.empty()) {   // else the file's (row deviator_volume)
    if (co.deviator_reference && P.state_volume)
      throw InputError("--deviator-volume reference: " + o.predict_with + " has the volume-form state parameter (a "
                       "nu_cs row), whose elastic split moves the stress by the elastic volume change alone");
    P.deviator_reference = co.deviator_reference;
  }
  if (!o.anisotropy_pressure.empty()) {   // else the file's (row anisotropy_excess)
    if (co.excess_relaxes && !P.state_volume)
      throw InputError("--anisotropy-pressure " + o.anisotropy_pressure + ": " + o.predict_with + " has no volume-form "
                       "state parameter (no nu_cs row); the relaxing excess belongs to --state-limit volume calibrations");
    P.excess_relaxes = co.excess_relaxes;
    P.excess_bounded = co.excess_bounded;
  }
  // The laws of psi: the file's range; without one, that of the curves --calibrate-on names (the states that
  // calibration held; here they are predicted with the rest); --no-psi-range: unbounded
  if (!o.psi_range) {
    P.psi_lo = -std::numeric_limits<double>::infinity();
    P.psi_hi = std::numeric_limits<double>::infinity();
  } else if (!std::isfinite(P.psi_lo) && !o.calibrate_on.empty()) {
    const auto named = [&](const std::string& n) {
      return std::find(o.calibrate_on.begin(), o.calibrate_on.end(), n) != o.calibrate_on.end();
    };
    std::vector<CurveData> cs;
    std::vector<PathData> ps;
    for (const auto& c : in.other) if (named(c.mode)) cs.push_back(c);
    for (const auto& d : in.other_paths) if (named(d.name)) ps.push_back(d);
    std::tie(P.psi_lo, P.psi_hi) = psi_range(P, cs, ps, o.eps_max);
  }
  const std::vector<double> iso = P.iso();
  if (P.extended && P.state_volume && std::isfinite(cusp_pressure(iso.data())))
    cal.warnings.push_back("the isotropic law of " + o.predict_with + " has nu_cC above nu_c: its stiffness is unbounded "
                           "at p* = " + num(cusp_pressure(iso.data())) + ", and a path through that pressure ends where "
                           "its steps put it (docs/model.md, \"The isotropic law's cusp\"; recalibrate with nu_cC held or --jamming shared)");
  for (int i = 0; i < kNumIso; ++i) { cal.names.push_back(iso_name(i)); cal.value.push_back(iso[i]); }
  for (int i = 0; i < kNumShear; ++i) { cal.names.push_back(shear_name(i)); cal.value.push_back(P.shear[i]); }
  if (P.extended)
    for (int i = 0; i < kNumExt; ++i)
      if (ext_entry_read(P, i)) { cal.names.push_back(ext_name(i)); cal.value.push_back(P.ext[i]); }
  cal.se_cov.assign(cal.value.size(), std::nan(""));
  cal.corr.assign(cal.value.size(), std::vector<double>(cal.value.size(), std::nan("")));
  cal.ok = true;
  cal.chi2 = std::nan("");   // nothing fitted: chi2/dof "nan" in the tables
  cal.n_residuals = 1;
  cal.message = "no calibration: parameters from " + o.predict_with;
  for (std::size_t j = 0; j < in.fit_curves.size(); ++j) { in.other.push_back(in.fit_curves[j]); in.other_files.push_back(in.fit_files[j]); }
  for (std::size_t j = 0; j < in.fit_paths.size(); ++j) {
    in.other_paths.push_back(in.fit_paths[j]);
    in.other_path_files.push_back(in.fit_path_files[j]);
  }
  in.fit_curves.clear(); in.fit_files.clear(); in.fit_paths.clear(); in.fit_path_files.clear();
  in.fit_label = "nothing (predicted with " + o.predict_with + ")";
  return ff;
}

// A former run's results in OUT (--force), removed once this run's are ready to be written: every table `dem model`
// writes (a run without the jackknife writes no jackknife.*, and an old one must not stand beside the new tables), its
// curves, the other family's folder and basin_start/, and its plots. Nothing else in OUT is touched.
void clear_former_results(const fs::path& out) {
  static const char* const kStems[] = {"parameters", "correlations", "laws", "prediction", "summary", "identifiability",
                                       "error_scale", "profile", "jackknife", "jackknife_estimates", "heldout",
                                       "selection", "starts"};
  std::error_code ec;
  for (const char* stem : kStems)
    for (const char* ext : {".csv", ".json", ".md", ".tex"}) fs::remove(out / (std::string(stem) + ext), ec);
  for (const char* dir : {"curves", "basin_start", "group", "extended"}) fs::remove_all(out / dir, ec);
  for (const auto& e : fs::directory_iterator(out, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file() && name.rfind("model_", 0) == 0 && e.path().extension() == ".png") fs::remove(e.path(), ec);
  }
}

int run(const ModelCommandOptions& o) {
  const fs::path dir(o.dir);
  if (!fs::is_directory(dir)) throw InputError(o.dir + " is not a folder: give an ensemble folder reduced by `dem fit`");
  const fs::path out = o.out.empty() ? dir / "model" : fs::path(o.out);
  if (fs::exists(out / "parameters.csv") && !o.force)
    throw InputError(out.string() + " already holds model results: pass --force to overwrite, or --out another folder");
  const CalibrationOptions co = calibration_options(o);   // bad options refused before anything is written
  const bool out_existed = fs::exists(out);
  check_output_folder(out);
  ModelInputs in = checked_inputs(o, co, dir, out, out_existed);
  if (!o.predict_with.empty()) {
    FamilyFit ff;
    try {
      ff = prediction_only(o, co, in);
    } catch (const InputError&) {   // the file refused (its family, its law): the folder made above goes again
      std::error_code ec;
      if (!out_existed && fs::is_empty(out, ec)) fs::remove(out, ec);
      throw;
    }
    clear_former_results(out);
    write_results(in, ff, out, o);
    return 0;
  }
  std::cerr << "dem model: fitting " << in.fit_curves.size() << " mode curves, " << in.fit_paths.size() << " path curves ("
            << in.fit_label << ") and " << in.iso.nu.size() << " isotropic points\n";
  const int K = in.K;
  std::vector<std::string> fams = o.family == "auto" ? std::vector<std::string>{"group", "extended"}
                                                     : std::vector<std::string>{o.family};
  std::vector<FamilyFit> fits;
  for (const auto& fam : fams) fits.push_back(fit_family(in, co, o, fam == "extended"));
  if (o.d2_lode == "normal")   // the plane-strain b of the calibrated limit (no D2 curve was fitted: checked_inputs)
    for (auto& ff : fits) ff.cal.params.b_d2 = plane_strain_lode_b(ff.cal.params.surface, ff.cal.params.shear[kSmaxA]);
  if (o.psi_range)   // the laws of psi kept within the calibration's own states: its fitted curves do not move
    for (auto& ff : fits)
      std::tie(ff.cal.params.psi_lo, ff.cal.params.psi_hi) = psi_range(ff.cal.params, in.fit_curves, in.fit_paths, o.eps_max);
  clear_former_results(out);
  std::size_t chosen = 0;
  if (fits.size() == 2) {
    chosen = write_selection(fits[0], fits[1], K, out) ? 1 : 0;
    std::cerr << "dem model: held-out test chooses the " << fams[chosen] << " family (selection.md)\n";
  }
  if (fits.size() == 1) write_heldout(fits[0], out);
  int rc = 0;
  for (std::size_t f = 0; f < fits.size(); ++f) {
    const fs::path dest = fits.size() == 2 && f != chosen ? out / fams[f] : out;
    write_results(in, fits[f], dest, o);
    write_starts(fits[f], dest);
    write_refits(fits[f], dest);
    if (f == chosen && !fits[f].cal.ok) rc = 1;
  }
  if (rc)
    std::cerr << "dem model: the " << fams[chosen] << " family's calibration did not converge (parameters.md says "
              << "why: row `converged`); its tables are written, and the exit status is 1. To go on from its values: "
              << "--start " << (out / "parameters.csv").string() << " [--max-iterations N]\n";
  return rc;
}

}  // namespace

// The frictional family's options that add no coefficient (twenty-eighth round on): the start's alignment, the dilatancy
// gate, the fabric's state limit, the deviator's volume scaling.
void add_extension_options(CLI::App& app, ModelCommandOptions& o) {
  app.add_option("--start-anisotropy", o.start_anisotropy, "the start's deviators: aligned (the default: the measured "
                 "s_dev and F_dev of the first row taken as aligned with the loading, integrated from) or unaligned (the "
                 "random deviators of a finite isotropic packing: s and F integrated from 0 as the aligned parts, "
                 "compared with the data as sqrt(x^2 + x0^2)); with --predict-with the file's unless given "
                 "(docs/model.md, \"An unaligned start\")")
      ->check(CLI::IsMember({"aligned", "unaligned"}));
  app.add_option("--dilatancy-gate", o.dilatancy_gate, "the extended family's plastic dilatancy d_D (r - chi_D)(1 - "
                 "F/F_lim): none (the default: at its largest contraction d_D chi_D from the first step) or mobilisation "
                 "(times the mobilisation r, so that it starts at 0 as the DEM's volume under constant pressure does); "
                 "with --predict-with the file's unless given (docs/model.md, \"An unaligned start\")")
      ->check(CLI::IsMember({"none", "mobilisation"}));
  app.add_option("--fabric-limit", o.fabric_limit, "the extended family's fabric limit with --state-limit pressure(-lode): "
                 "fixed (the default: F_lim whatever the state) or state (F_lim times the stress ratio's state factor "
                 "(p_ref/p)^n_psi, so that the fabric softens with the stress ratio; no coefficient added); with "
                 "--predict-with the file's unless given (docs/model.md, \"The fabric's state limit\")")
      ->check(CLI::IsMember({"fixed", "state"}));
  app.add_option("--deviator-volume", o.deviator_volume, "the extended family's deviatoric stress under a volume "
                 "change: fixed (the default: sigma_dev moves with the volume through the anisotropy A alone) or "
                 "reference (it also scales with the isotropic reference pressure p_ref(nu), as the DEM's does after "
                 "its peak; constant-volume curves do not see it; no coefficient added); with --predict-with the file's "
                 "unless given (docs/model.md, \"The deviatoric stress under a volume change\")")
      ->check(CLI::IsMember({"fixed", "reference"}));
}

void add_model_options(CLI::App& app, ModelCommandOptions& o) {
  app.add_option("dir", o.dir, "ensemble folder reduced by `dem fit` (ensemble/MODE_phiX.csv, members/)")->required();
  app.add_option("--out", o.out, "output folder (default DIR/model)");
  app.add_option("--isotropic", o.isotropic, "unloading-branch curves (default DIR/members/*/[prep/]cycle_unloading.csv)")
      ->default_str("");
  app.add_option("--calibrate-mode", o.calibrate_mode, "mode whose curves are fitted; all others are predicted");
  app.add_option("--paths", o.paths, "path ensembles PATH_phiX.csv of demkit.path_ensemble (default DIR/paths if it exists)");
  app.add_option("--calibrate-on", o.calibrate_on, "modes and paths fitted, comma-separated (e.g. D2,reversal,isobaric; "
                 "default: --calibrate-mode); all others are predicted")->delimiter(',')->default_str("");
  app.add_option("--eps-max", o.eps_max, "fit and compare only eps_d <= this [-] (default: all)")->default_str("");
  app.add_flag_callback("--no-jackknife", [&o] { o.jackknife = false; },
                        "errors from the covariance only (faster; default: jackknife over the packings)");
  app.add_flag_callback("--no-basin-check", [&o] { o.basin_check = false; },
                        "keep each jackknife refit where it ended (default: a refit whose data score lower at another "
                        "refit's optimum is run again from there, and the fit is checked the same way; tables made "
                        "before issue 31's thirty-fifth round were made without)");
  app.add_flag("--no-plots", o.no_plots, "skip the matplotlib plots");
  app.add_option("--family", o.family, "group (the incremental anisotropic model), extended (with the frictional "
                 "extension: docs/model.md) or auto (both; the held-out test chooses, the other goes to OUT/FAMILY)");
  app.add_option("--surface", o.surface, "Lode-angle surface of the extended family: ld (Lade-Duncan), mn "
                 "(Matsuoka-Nakai), none");
  app.add_option("--fabric-lode", o.fabric_lode, "Lode rule of the extended family's fabric limit: principal (the "
                 "largest principal deviatoric fabric saturates at every Lode angle), norm (F_dev saturates at F_max), opening "
                 "(principal, and the fabric gated by the minor principal stress), overlap (the default: principal, and "
                 "the fabric gated by the fraction of contacts opened by the extension strain), extension (overlap, and "
                 "the fabric's rate per unit extension strain), weighted (the onset's and the rate's Lode dependence "
                 "raised to a weight that rises with the contact overlap, two coefficients; needs a second Lode angle "
                 "in --calibrate-on, e.g. D2,D3; docs/model.md)");
  app.add_option("--state-limit", o.state_limit, "extended family's stress-ratio limit: none (the default) or pressure "
                 "(s_lim (p_ref/p)^n_psi, a state parameter in pressure form, n_psi(nu) fitted: a peak that falls as p "
                 "rises at constant volume or nu falls under constant p) or pressure-lode (n_psi scaled by "
                 "(c_3(1/2)/c_3(b))^lambda_psi at the test's Lode parameter b, lambda_psi fitted; needs a second Lode "
                 "angle in --calibrate-on) or volume (psi = nu - nu_cs(p), the volume-form state parameter: the limit "
                 "times e^{n_b psi} and the dilatancy d_D (r - e^{-n_d psi}), so that drained tests end on the "
                 "critical-state line of the calibration paths' end states (--csl) from dense and loose starts alike; "
                 "needs drained --calibrate-on paths; docs/model.md)");
  app.add_option("--csl", o.csl, "with --state-limit volume, the critical-state line's form: linear (the default, "
                 "nu_cs + c_cs (p* - 1e-3): a rigid-grain critical state compressed by the contacts, which reaches the "
                 "steady states of dense constant-volume shear) or log (nu_cs + lambda_cs ln(p*/1e-3))");
  app.add_option("--predict-with", o.predict_with, "parameters.csv of another `dem model` run: no calibration, every "
                 "curve and path predicted with those parameters (give the --family, --surface and --fabric-lode that "
                 "run was given; e.g. a dense preparation's calibration predicting the loose one)")
      ->check(CLI::ExistingFile);
  app.add_option("--d2-lode", o.d2_lode, "stress Lode parameter b of D2 curves and paths: a number in (0, 1) or "
                 "normal (the plane-strain b of the Lode surface through the calibrated limit s_max_a: its deviatoric "
                 "normal has no intermediate component); default 0.5, with --predict-with the file's (docs/model.md)")
      ->default_str("");
  app.add_flag_callback("--no-psi-range", [&o] { o.psi_range = false; },
                        "with --state-limit volume: read the laws of psi unbounded (default: held at their values at the "
                        "edges of the calibration's own states, rows psi_min and psi_max; with --predict-with the file's "
                        "range, or without one the --calibrate-on curves')");
  app.add_option("--max-iterations", o.max_iterations, "Ceres iterations of each fit (default 1000; a fit stopped there counts as converged where chi2 settled: docs/model.md \"A fit that settles\")");
  app.add_option("--start", o.start, "parameters.csv of another `dem model` run: the start values (re-centred on "
                 "this data's nu_ref; the isotropic block too unless --start-isotropic branch); with it the path ensembles alone may be calibrated (--calibrate-on PATHS). "
                 "Several, comma-separated, `default` for the start from the data's own fits: the fit is made from "
                 "each and the lowest chi2/dof kept (OUT/starts.md); the fits of the extended family are multi-modal")
      ->delimiter(',')->default_str("");
  app.add_option("--hold", o.hold, "frictional-extension coefficients held at their start values (the --start file's, "
                 "or the default of a file without them: n_rate 1), e.g. n_rate; comma-separated")
      ->delimiter(',');
  app.add_option("--start-isotropic", o.start_isotropic, "where the isotropic block of a --start fit starts: file (the "
                 "file's values, default: a restart from a stored optimum starts there) or branch (the isotropic "
                 "branch's own fit: for a start from another material's laws, which miss this branch)")
      ->check(CLI::IsMember({"file", "branch"}))->default_str("file");
  app.add_option("--hold-isotropic", o.hold_isotropic, "isotropic parameters held at their values in the (first) --start file, "
                 "comma-separated (e.g. gamma_p,nu_cC,alpha: a branch of two pressure levels fixes two of the pressure "
                 "law's three)")->delimiter(',')->default_str("");
  app.add_option("--jamming", o.jamming, "the isotropic laws' jamming fractions: separate (nu_c for the pressure, "
                 "nu_cC for the coordination law; default) or shared (nu_cC = nu_c: one jamming fraction, the "
                 "stiffness bounded at every nu; docs/model.md \"One jamming fraction\")")
      ->check(CLI::IsMember({"separate", "shared"}))->default_str("separate");
  app.add_option("--coordination", o.coordination, "the coordination law C(nu) = C0 + C1 (nu/nu_cC - 1)^alpha of a "
                 "fitted isotropic block: rising (C1 >= 0, the default: the branch's coordination rises with the "
                 "density) or free (C1 of either sign, as fits before issue 31's twenty-third round; a falling law "
                 "can make the isotropic pressure peak below nu = 1; docs/model.md \"A coordination that rises\")")
      ->check(CLI::IsMember({"rising", "free"}))->default_str("rising");
  app.add_option("--anisotropy-pressure", o.anisotropy_pressure, "with --state-limit volume, the anisotropy's "
                 "pressure A d eps_d: permanent (the default: it moves the elastic state and never relaxes, so a "
                 "constant-p path is steady only where the dilatancy cancels a_A F) or relaxing (an excess over the "
                 "isotropic law that relaxes at beta_p, fitted: steady at psi = 0) or bounded (the same, its source "
                 "gated by 1 - (q/p)^2 so that the excess q stays below p and the elastic state jammed); with "
                 "--predict-with the file's unless given (docs/model.md, \"A relaxing anisotropic pressure\", \"A "
                 "bounded excess\")")
      ->check(CLI::IsMember({"permanent", "relaxing", "bounded"}))->default_str("permanent");
  add_extension_options(app, o);
  app.add_option("--profile", o.profile, "profile intervals: `all` (every coefficient with a quoted covariance "
                 "error) or comma-separated names (e.g. p0,alpha): each held at trial values and the rest refitted "
                 "until chi2 rises by max(1, chi2/dof) either way (profile.{csv,md}; 1-10 refits per end; docs/model.md "
                 "\"Profile intervals\")");
  app.add_flag("--force", o.force, "overwrite an existing output folder");
}

int run_model_command(const ModelCommandOptions& o) {
  try {
    return run(o);
  } catch (const InputError& e) {
    std::cerr << "dem model: " << e.what() << "\n";
    return 2;
  } catch (const std::runtime_error& e) {   // unreadable or ragged CSV, missing column
    std::cerr << "dem model: bad input: " << e.what() << " (the ensemble CSVs must be those `dem fit` writes)\n";
    return 2;
  }
}

}  // namespace demfit
