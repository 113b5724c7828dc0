#include "demfit/cli.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <regex>
#include <sstream>

#include <nlohmann/json.hpp>

#include "demfit/fit.hpp"
#include "demfit/table.hpp"

namespace fs = std::filesystem;

namespace demfit {

void add_fit_options(CLI::App& app, FitCommandOptions& o) {
  app.add_option("run_dir", o.run_dir, "results folder of `dem run`")->required()->check(CLI::ExistingDirectory);
  app.add_option("--eps-min", o.window_min, "fit window: smallest eps_d");
  app.add_option("--eps-max", o.window_max, "fit window: largest eps_d (default: the curve's end)")->default_str("");
  app.add_option("--loss", o.loss, "robust loss: none | huber | cauchy")->check(CLI::IsMember({"none", "huber", "cauchy"}));
  app.add_option("--gap-tolerance", o.gap_tolerance, "D2/D3 'same path' tolerance on the fitted curves");
  app.add_flag("--no-plots", o.no_plots, "skip plots");
  app.add_flag("--partial", o.partial, "an ensemble folder whose tasks are not all finished: fit what is there "
                                       "(without it an incomplete ensemble is refused; the tables then say so)");
  app.add_flag("--independent-errors", o.independent_errors,
               "treat curve points as independent (no inflation of standard errors for correlated residuals)");
  app.add_flag("--force", o.force, "overwrite RUN_DIR/fit");
}

namespace {

// Ceres and GSL optima further apart than this (relative) are flagged.
constexpr double kMaxSolverGap = 1e-3;

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : "; ") + x;
  return s;
}

std::string num(double v, int prec = 6) { return table_number(v, prec); }

struct Curve { std::string mode; double phi; Table t; };

// The deviatoric curves to fit: those the run's manifest lists (a rerun may leave others, of
// other physics, in the folder), or every deviatoric/MODE_phiX.XXX.csv when there is no
// manifest (a folder of curves assembled by hand).
std::vector<fs::path> curve_files(const fs::path& run) {
  const std::regex name_re(R"(([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv)");
  std::vector<fs::path> files;
  if (fs::exists(run / "manifest.json")) {
    std::ifstream in(run / "manifest.json");
    const nlohmann::json manifest = nlohmann::json::parse(in, nullptr, false);
    if (manifest.is_discarded() || !manifest.contains("outputs") || !manifest["outputs"].is_array())
      throw std::runtime_error((run / "manifest.json").string() + " is not a manifest of `dem run` (no \"outputs\" "
                               "list): rerun the run, or remove it to fit every deviatoric/*.csv");
    for (const auto& o : manifest["outputs"]) {
      if (!o.is_object() || !o.contains("file") || !o["file"].is_string()) continue;
      const std::string file = o["file"].get<std::string>();
      if (file.rfind("deviatoric/", 0) != 0) continue;
      const fs::path f = run / file;
      if (fs::exists(f)) files.push_back(f);
      else std::cerr << "dem fit: warning: " << f.string() << " is listed in manifest.json but missing (run not finished?)\n";
    }
    for (auto& f : fs::directory_iterator(run / "deviatoric"))
      if (f.path().extension() == ".csv" && std::find(files.begin(), files.end(), f.path()) == files.end())
        std::cerr << "dem fit: note: " << f.path().string() << " is not listed in manifest.json: not fitted\n";
  } else {
    for (auto& f : fs::directory_iterator(run / "deviatoric")) files.push_back(f.path());
  }
  std::vector<fs::path> out;
  for (const auto& f : files)
    if (std::regex_match(f.filename().string(), name_re)) out.push_back(f);
  return out;
}

// The `# physics:` record of a curve ("" if it has none).
std::string physics_of(const Table& t) {
  for (const auto& c : t.comments)
    if (c.rfind("# physics: ", 0) == 0) return c.substr(11);
  return "";
}

// The key=value words of b that differ from a's.
std::string physics_difference(const std::string& a, const std::string& b) {
  std::istringstream ia(a), ib(b);
  std::vector<std::string> wa, wb;
  for (std::string w; ia >> w;) wa.push_back(w);
  for (std::string w; ib >> w;) wb.push_back(w);
  // Keys on one side only count too (a frictional record against a frictionless one).
  auto value_of = [](const std::vector<std::string>& words, const std::string& key) -> std::string {
    for (std::size_t i = 1; i < words.size(); ++i)
      if (words[i].rfind(key + "=", 0) == 0) return words[i].substr(key.size() + 1);
    return "(absent)";
  };
  std::string d;
  std::vector<std::string> seen;
  for (const auto* words : {&wa, &wb})
    for (std::size_t i = 1; i < words->size(); ++i) {
      const std::string key = (*words)[i].substr(0, (*words)[i].find('='));
      if (std::find(seen.begin(), seen.end(), key) != seen.end()) continue;
      seen.push_back(key);
      const std::string va = value_of(wa, key), vb = value_of(wb, key);
      if (va != vb) d += (d.empty() ? "" : "; ") + key + "=" + va + " vs " + vb;
    }
  return d;
}

// Curves of different physics (e.g. two stiffnesses) must not be fitted into one table.
void check_one_physics(const std::vector<Curve>& curves) {
  const Curve* first = nullptr;
  for (const auto& c : curves) {
    const std::string ph = physics_of(c.t);
    if (ph.empty()) continue;
    if (!first) { first = &c; continue; }
    const std::string ref = physics_of(first->t);
    if (ph != ref)
      throw std::runtime_error("the curves were computed with different physics and cannot be fitted into one table: " +
                               first->t.source + " vs " + c.t.source + ": " + physics_difference(ref, ph) +
                               ". Fit each physics in its own folder (or rerun with --force)");
  }
}

}  // namespace

void write_nu_laws(const FitsByModeQuantity& by_mode_q, const std::string& out_dir) {
  // Linear law around the mean nu, weighted by the SEs.
  Table laws({"mode", "quantity", "parameter", "law", "a", "se_a", "b", "se_b", "nu_ref", "r_squared", "n", "warnings"});
  for (auto& [key, list] : by_mode_q) {
    if (list.size() < 3) continue;
    double nu_ref = 0;
    for (auto& pr : list) nu_ref += pr.first;
    nu_ref /= list.size();
    for (const char* pname : {"x_max", "beta", "x0"}) {
      std::vector<double> x, y, s;
      for (auto& [phi, r] : list) {
        const double v = std::string(pname) == "x_max" ? r.x_max : std::string(pname) == "beta" ? r.beta : r.x0;
        const double se = std::string(pname) == "x_max" ? r.se_x_max : std::string(pname) == "beta" ? r.se_beta : r.se_x0;
        if (!std::isfinite(v)) continue;
        x.push_back(phi); y.push_back(v); s.push_back(std::isfinite(se) && se > 0 ? se : 0.0);
      }
      if (x.size() < 3) continue;
      bool all_se = std::all_of(s.begin(), s.end(), [](double v) { return v > 0; });
      try {
        CurveFit cf = fit_law("linear", x, y, {y[0], 0.0}, all_se ? s : std::vector<double>{}, nu_ref);
        std::string w;
        for (auto& ws : cf.warnings) w += (w.empty() ? "" : "; ") + ws;
        laws.add_row({key.first, key.second, pname, "a + b (nu - nu_ref)", num(cf.params[0]), num(cf.errors[0]),
                      num(cf.params[1]), num(cf.errors[1]), num(nu_ref, 4), num(cf.r_squared, 4), std::to_string(cf.n), w});
      } catch (const std::exception& ex) {
        std::cerr << "dem fit: nu law " << key.first << " " << key.second << " " << pname << ": " << ex.what() << "\n";
      }
    }
  }
  if (laws.rows.empty()) return;
  const std::string caption = "Fitted parameters as linear functions of the volume fraction nu";
  const auto& sym = tex_symbols();
  const std::string tex = paper_latex(
      laws,
      {paper_text(laws, "Mode", "mode"), paper_text(laws, "Quantity", "quantity", sym),
       paper_text(laws, "Parameter", "parameter", sym), paper_number(laws, "$a$", "a", "se_a"),
       paper_number(laws, "$b$", "b", "se_b"), paper_number(laws, "$\\nu_\\mathrm{ref}$", "nu_ref"),
       paper_number(laws, "$R^2$", "r_squared"), paper_number(laws, "$n$", "n")},
      caption, "Each parameter of the usable fits against $\\nu$: $a + b\\,(\\nu - \\nu_\\mathrm{ref})$, weighted by "
               "the fits' standard errors; warnings: nu\\_laws.csv.");
  write_table_all(laws, out_dir + "/nu_laws", caption, tex);

}

void write_isotropic(const std::vector<std::string>& unloading_csvs, const std::string& out_dir) {
  std::vector<double> x, yp, yc, caux;
  for (const auto& path : unloading_csvs) {
    if (!fs::exists(path)) continue;
    Table t = read_table(path);
    const auto& nu = t.column("nu");
    const auto& pstar = t.column("p_star");
    const auto& cnr = t.column("C_nonrattler");
    const auto& c = t.column("C");
    for (std::size_t i = 0; i < nu.size(); ++i)
      if (pstar[i] > 1e-7 && cnr[i] > 0) { x.push_back(nu[i]); yp.push_back(pstar[i]); yc.push_back(cnr[i]); caux.push_back(c[i]); }
  }
  Table iso({"law", "formula", "p0", "se_p0", "p1", "se_p1", "p2", "se_p2", "p3", "se_p3", "r_squared", "n"});
  if (x.size() < 6) return;
  const double numin = *std::min_element(x.begin(), x.end());
  try {
    CurveFit cf = fit_law("power", x, yc, {6.0, 5.0, numin * 0.98, 0.5});
    iso.add_row({"C_nonrattler(nu)", "p0 + p1 (nu/p2 - 1)^p3 (p2 = nu_c)", num(cf.params[0]), num(cf.errors[0]),
                 num(cf.params[1]), num(cf.errors[1]), num(cf.params[2]), num(cf.errors[2]), num(cf.params[3]),
                 num(cf.errors[3]), num(cf.r_squared, 5), std::to_string(cf.n)});
    std::vector<double> aux(x.size(), 0.0);
    aux.insert(aux.end(), caux.begin(), caux.end());
    CurveFit pf = fit_law("pressure", x, yp, {0.05, numin * 0.98, 0.0}, aux);
    iso.add_row({"p_star(nu)", "p0 (nu C / p1)(-eps)(1 - p2 eps), eps = ln(p1/nu)", num(pf.params[0]), num(pf.errors[0]),
                 num(pf.params[1]), num(pf.errors[1]), num(pf.params[2]), num(pf.errors[2]), "", "",
                 num(pf.r_squared, 5), std::to_string(pf.n)});
  } catch (const std::exception& ex) {
    std::cerr << "dem fit: isotropic laws: " << ex.what() << "\n";
  }
  if (iso.rows.empty()) return;
  const std::string caption = "Isotropic (unloading) branch: coordination and pressure laws";
  const std::map<std::string, std::string> laws_tex = {
      {"C_nonrattler(nu)", "$C_\\mathrm{nr}(\\nu)$"},
      {"p0 + p1 (nu/p2 - 1)^p3 (p2 = nu_c)", "$p_0 + p_1 (\\nu/p_2 - 1)^{p_3}$, $p_2 = \\nu_c$"},
      {"p_star(nu)", "$p^*(\\nu)$"},
      {"p0 (nu C / p1)(-eps)(1 - p2 eps), eps = ln(p1/nu)",
       "$p_0 \\frac{\\nu C}{p_1} (-\\epsilon)(1 - p_2 \\epsilon)$, $\\epsilon = \\ln(p_1/\\nu)$"}};
  const std::string tex = paper_latex(
      iso,
      {paper_text(iso, "Law", "law", laws_tex), paper_text(iso, "Form", "formula", laws_tex),
       paper_number(iso, "$p_0$", "p0", "se_p0"), paper_number(iso, "$p_1$", "p1", "se_p1"),
       paper_number(iso, "$p_2$", "p2", "se_p2"), paper_number(iso, "$p_3$", "p3", "se_p3"),
       paper_number(iso, "$R^2$", "r_squared"), paper_number(iso, "$n$", "n")},
      caption);
  write_table_all(iso, out_dir + "/isotropic", caption, tex);
}

namespace {

// The curves of a run folder (deviatoric/MODE_phiX.XXX.csv), loading paths left out (said).
std::vector<Curve> read_run_curves(const fs::path& run) {
  // Curves named MODE_phiX.XXX.csv
  const std::regex name_re(R"(([A-Za-z0-9_-]+)_phi([0-9.]+)\.csv)");
  std::vector<Curve> curves;
  for (const auto& f : curve_files(run)) {
    std::smatch m;
    const std::string fname = f.filename().string();
    std::regex_match(fname, m, name_re);
    Table t = read_table(f.string());
    if (std::find(t.header.begin(), t.header.end(), "control_error_rel") != t.header.end()) {
      std::cerr << "dem fit: note: " << f.string() << " is a loading path ([paths]: stages, stress control); the "
                << "saturating law is fitted to the monotonic modes only: plot it with `dem plot`\n";
      continue;
    }
    curves.push_back({m[1], std::stod(m[2]), std::move(t)});
  }
  return curves;
}

// The single-curve fits of a run folder: the machine table, the rows for people, the usable fits
// by mode and quantity (for the nu-laws), and the counts of the summary line.
struct CurveFits {
  Table params = Table({"mode", "nu", "quantity", "x0", "se_x0", "x_max", "se_x_max", "beta", "se_beta",
                "corr_xmax_beta", "initial_slope", "se_initial_slope", "eps_95", "r_squared", "rmse", "n",
                "eps_last", "gsl_max_rel_diff", "residual_autocorr", "se_inflation", "warnings", "usable",
                "not_usable_because"});
  std::vector<SummaryRow> summary;
  FitsByModeQuantity by_mode_q;
  int warnings = 0, usable = 0;
  std::map<std::string, int> not_usable;   // reason -> count, for the summary line
};

// Fits quantity q of curve c (Ceres, with the GSL cross-check) into `fits`; a curve that cannot
// be fitted gets a row saying why.
void fit_curve_quantity(const Curve& c, const char* q, const FitOptions& fo, CurveFits& fits) {
  const auto& e = c.t.column("eps_d");
  try {
    FitResult r = fit_saturating(e, c.t.column(q), fo);
    // Second, independent solver from the same start: the relative gap of the optima.
    double gsl_gap = std::nan("");
    try {
      std::vector<double> ew, yw;
      for (std::size_t i = 0; i < e.size(); ++i)
        if (e[i] >= fo.window_min && e[i] <= fo.window_max) { ew.push_back(e[i]); yw.push_back(c.t.column(q)[i]); }
      const auto g = fit_saturating_gsl(ew, yw, {r.x0, r.x_max, r.beta * 1.3});
      const double scale = std::max(std::fabs(r.x_max), std::fabs(r.x0));
      gsl_gap = std::max({std::fabs(g[0] - r.x0) / scale, std::fabs(g[1] - r.x_max) / scale,
                          std::fabs(g[2] - r.beta) / r.beta});
    } catch (const std::exception& ex) {
      r.warnings.push_back(std::string("GSL cross-check failed: ") + ex.what());
    }
    if (gsl_gap > kMaxSolverGap)
      r.warnings.push_back("Ceres and GSL optima differ by " + num(gsl_gap, 2) + " (relative, > " + num(kMaxSolverGap) +
                           "): the data do not pin down the optimum; treat the values with caution");
    if (!r.ok) throw std::runtime_error(join(r.warnings));
    std::string w;
    for (auto& s : r.warnings) {
      w += (w.empty() ? "" : "; ") + s;
      std::cerr << "dem fit: warning: " << c.mode << " nu=" << num(c.phi, 4) << " " << q << ": " << s << "\n";
      ++fits.warnings;
    }
    const std::string why = unusable_reason(r);
    fits.params.add_row({c.mode, num(c.phi, 4), q, num(r.x0), num(r.se_x0), num(r.x_max), num(r.se_x_max),
                    num(r.beta), num(r.se_beta), num(r.corr[1][2], 3), num(r.initial_slope),
                    num(r.se_initial_slope), num(r.eps_95), num(r.r_squared, 5), num(r.rmse), std::to_string(r.n),
                    num(r.e_last, 4), num(gsl_gap, 2), num(r.residual_autocorrelation, 3), num(r.se_inflation, 3), w,
                    why.empty() ? "yes" : "no", why});
    SummaryRow sr = summary_row(c.mode, c.phi, q, 0, r.x_max, r.se_x_max, r.beta, r.se_beta, r.initial_slope,
                                r.se_initial_slope, r.r_squared, r.warnings);
    sr.not_usable = why;
    fits.summary.push_back(sr);
    if (why.empty()) {
      fits.by_mode_q[{c.mode, q}].emplace_back(c.phi, r);
      ++fits.usable;
    } else {
      ++fits.not_usable[why];
    }
  } catch (const std::exception& ex) {
    std::cerr << "dem fit: " << c.mode << " nu=" << num(c.phi, 4) << " " << q << ": " << ex.what() << "\n";
    fits.params.add_row({c.mode, num(c.phi, 4), q, "nan", "nan", "nan", "nan", "nan", "nan", "nan", "nan", "nan",
                    "nan", "nan", "nan", "0", "nan", "nan", "nan", "nan", std::string("not fitted: ") + ex.what(),
                    "no", std::string("not fitted: ") + ex.what()});
    ++fits.not_usable["not fitted"];
    SummaryRow nf;
    nf.mode = c.mode; nf.nu = c.phi; nf.quantity = q; nf.fitted = false;
    nf.warnings = {std::string("not fitted: ") + ex.what()};
    fits.summary.push_back(nf);
    ++fits.warnings;
  }
}

// D2 vs D3 from the same volume fraction: the shared-path test of each quantity (shared_path.*).
void write_shared_path_tests(const std::vector<Curve>& curves, const FitCommandOptions& o, const FitOptions& fo,
                             const fs::path& out) {
  Table shared({"nu", "quantity", "mode_a", "mode_b", "f_statistic", "p_value", "max_gap", "same_path",
                "x_max_shared", "beta_shared"});
  for (auto& a : curves)
    for (auto& b : curves)
      if (a.mode == "D2" && b.mode == "D3" && std::fabs(a.phi - b.phi) < 1e-9)
        for (const char* q : {"s_dev", "F_dev"}) {
          try {
            SharedPathTest t = test_shared_path(a.t.column("eps_d"), a.t.column(q), b.t.column("eps_d"), b.t.column(q),
                                                o.gap_tolerance, fo);
            if (!t.first.ok || !t.second.ok || !t.shared.ok)
              throw std::runtime_error("a fit of the test is not usable (ill-conditioned or not converged): no verdict");
            shared.add_row({num(a.phi, 4), q, "D2", "D3", num(t.f_statistic, 4), num(t.p_value, 3), num(t.max_gap, 4),
                            t.same_path ? "yes" : "no", num(t.shared.x_max), num(t.shared.beta)});
          } catch (const std::exception& ex) {
            std::cerr << "dem fit: shared-path test nu=" << num(a.phi, 4) << " " << q << ": " << ex.what() << "\n";
          }
        }
  if (!shared.rows.empty()) {
    const std::string caption = "D2 vs D3: F-test of one shared law against two (corrected for correlated residuals unless "
                                "--independent-errors) and the largest gap between the fitted curves; same_path: p >= 0.01 "
                                "or gap <= --gap-tolerance";
    const std::string tex = paper_latex(
        shared,
        {paper_number(shared, "$\\nu$", "nu"), paper_text(shared, "Quantity", "quantity", tex_symbols()),
         paper_number(shared, "$F$", "f_statistic"), paper_number(shared, "$p$", "p_value"),
         paper_number(shared, "max.\\ gap", "max_gap"), paper_text(shared, "Same path", "same_path")},
        caption, "D2 against D3 from the same volume fraction: one law for both against one each (F-test).");
    write_table_all(shared, (out / "shared_path").string(), caption, tex);
  }

}

}  // namespace

int run_fit_command(const FitCommandOptions& o) {
  const fs::path run(o.run_dir);
  const fs::path dev = run / "deviatoric";
  const fs::path out = run / "fit";
  if (fs::exists(out / "parameters.csv") && !o.force) {
    std::cerr << "dem fit: " << out << " already holds fit results: pass --force to overwrite\n";
    return 1;
  }
  if (fs::is_directory(run / "members")) return run_ensemble_fit_command(o);
  if (!fs::is_directory(dev)) {
    std::cerr << "dem fit: " << dev << " does not exist: give a folder written by `dem run`\n";
    return 1;
  }
  FitOptions fo;
  fo.window_min = o.window_min;
  fo.window_max = o.window_max;
  fo.loss = o.loss == "huber" ? Loss::Huber : o.loss == "cauchy" ? Loss::Cauchy : Loss::None;
  fo.correct_autocorrelation = !o.independent_errors;

  std::vector<Curve> curves = read_run_curves(run);
  if (curves.empty()) {
    std::cerr << "dem fit: no MODE_phiX.XXX.csv curves in " << dev << " (is the run finished?)\n";
    return 1;
  }
  check_one_physics(curves);
  // The inputs are good: what this fit writes replaces all of fit/ (no table of an earlier fit,
  // e.g. a shared-path test of a mode no longer there, survives beside the new ones).
  fs::remove_all(out);
  fs::create_directories(out);
  std::sort(curves.begin(), curves.end(), [](auto& a, auto& b) { return a.mode != b.mode ? a.mode < b.mode : a.phi < b.phi; });

  CurveFits fits;
  for (auto& c : curves)
    for (const char* q : {"s_dev", "F_dev"}) fit_curve_quantity(c, q, fo, fits);
  write_fit_tables(fits.params, fits.summary, (out / "parameters").string(),
                   "Fitted saturating law x(eps_d) = x_max - (x_max - x0) exp(-beta eps_d); standard errors from the "
                   "curve's residuals (inflated for their autocorrelation)");

  write_shared_path_tests(curves, o, fo, out);

  write_nu_laws(fits.by_mode_q, out.string());
  write_isotropic({(run / "prep" / "cycle_unloading.csv").string()}, out.string());
  std::cerr << "dem fit: " << usable_summary(fits.usable, fits.params.rows.size(), fits.not_usable) << ", written to " << out.string()
            << " (" << fits.warnings << " warnings)\n";
  if (!o.no_plots) {
    const std::string cmd = "PYTHONPATH=" + std::string(DEM_SOURCE_DIR) + " /usr/bin/python3 -m demkit.plots \"" +
                            run.string() + "\" --fits";
    if (std::system(cmd.c_str()) != 0) std::cerr << "dem fit: plotting failed (tables are written)\n";
  }
  if (fits.not_usable.count("not fitted") && fits.not_usable.at("not fitted") == static_cast<int>(fits.params.rows.size())) {
    std::cerr << "dem fit: no curve could be fitted (see the reasons above and in parameters.csv): nothing to report\n";
    return 1;
  }
  return 0;
}

}  // namespace demfit
