// `dem fit DIR` on an ensemble folder: members -> ensemble averages -> fits with errors
// between packings -> tables (same formats as a single run) -> plots.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "demfit/cli.hpp"
#include "demfit/ensemble.hpp"
#include "demfit/model_selection.hpp"
#include "demfit/table.hpp"

namespace fs = std::filesystem;

namespace demfit {

namespace {

std::string num(double v, int prec = 6) { return table_number(v, prec); }

// The string value of `key` in a task's status JSON (demkit.task); "" when absent, not a string,
// or the file is not JSON.
std::string json_field(const std::string& text, const std::string& key) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return "";
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : "";
}

struct MemberStatus { std::string member, status, message; };

// One (mode, nu) of the ensemble: the members that finished, and those that did not.
struct Cell {
  std::string mode, tag;   // tag: "phi0.800"
  double nu = 0;
  std::vector<std::string> members;
  std::vector<Table> curves;
  std::vector<MemberStatus> excluded;
  std::vector<std::string> warnings;   // the runner's warnings of used members (e.g. far from quasi-static)
};

std::string read_text(const fs::path& f) {
  std::ifstream in(f);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A planned task is done when its status file exists. A stored copy without any status files
// (data/*/members: the copies keep curves only) is judged by what a task leaves instead: a mode's
// curve (renamed into place complete), a preparation's unloading branch. A folder that has status
// files keeps them as the record, so a missing one is a task not done.
bool task_done(const fs::path& run, const std::string& task, bool stored_copy) {
  fs::path p = run / task;
  if (fs::exists(p)) return true;
  if (!stored_copy) return false;
  if (p.parent_path().filename() == "deviatoric") return fs::exists(p.replace_extension(".csv"));
  if (p.filename() == "prep.json") return fs::exists(p.parent_path() / "prep" / "cycle_unloading.csv");
  return false;
}

// No planned task has its status file: a stored copy of an ensemble (or nothing ran at all).
bool no_status_files(const fs::path& run, const std::vector<std::string>& tasks) {
  for (const auto& t : tasks)
    if (fs::exists(run / t)) return false;
  return true;
}

// A mode task's status file that says complete while its curve (the .csv beside it) is gone:
// the task is not done (a curve deleted by hand must not become a fit on one packing fewer).
bool curve_gone(const fs::path& status) {
  if (status.extension() != ".json" || status.parent_path().filename() != "deviatoric") return false;
  fs::path csv = status;
  csv.replace_extension(".csv");
  return json_field(read_text(status), "status") == "complete" && !fs::exists(csv);
}

std::map<std::pair<std::string, double>, Cell> collect_cells(const fs::path& run) {
  const std::regex name_re(R"(([A-Za-z0-9_-]+)_(phi([0-9.]+))\.json)");
  std::map<std::pair<std::string, double>, Cell> cells;
  std::set<std::pair<std::string, double>> path_cells;   // loading paths: not averaged
  std::vector<fs::path> member_dirs;
  for (auto& d : fs::directory_iterator(run / "members"))
    if (d.is_directory()) member_dirs.push_back(d.path());
  std::sort(member_dirs.begin(), member_dirs.end());
  const std::regex flat_re(R"(([A-Za-z0-9_-]+)_(phi([0-9.]+))\.csv)");
  for (const auto& md : member_dirs) {
    const std::string member = md.filename().string();
    if (!fs::is_directory(md / "deviatoric")) {
      // A stored folder of the earlier layout (data/figure3_n9261): the mode curves directly in the
      // member folder, without task status files; each curve there is a finished run.
      std::vector<fs::path> flat;
      for (auto& f : fs::directory_iterator(md)) flat.push_back(f.path());
      std::sort(flat.begin(), flat.end());
      for (const auto& f : flat) {
        std::smatch m;
        const std::string fname = f.filename().string();
        if (!std::regex_match(fname, m, flat_re)) continue;
        Cell& c = cells[{m[1].str(), std::stod(m[3].str())}];
        c.mode = m[1]; c.tag = m[2]; c.nu = std::stod(m[3].str());
        c.members.push_back(member);
        c.curves.push_back(read_table(f.string()));
      }
      continue;
    }
    const std::string prep_warning = fs::exists(md / "prep.json") ? json_field(read_text(md / "prep.json"), "warning") : "";
    std::vector<fs::path> files;
    for (auto& f : fs::directory_iterator(md / "deviatoric")) files.push_back(f.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      std::smatch m;
      const std::string fname = f.filename().string();
      // A curve without its status file: a stored copy (data/*/members keep the curves only); the curve
      // was renamed into place complete, so it is a finished run.
      const bool stored = std::regex_match(fname, m, flat_re) && !fs::exists(fs::path(f).replace_extension(".json"));
      if (!stored && !std::regex_match(fname, m, name_re)) continue;
      Cell& c = cells[{m[1].str(), std::stod(m[3].str())}];
      c.mode = m[1]; c.tag = m[2]; c.nu = std::stod(m[3].str());
      std::stringstream ss;
      if (stored) ss << R"({"status": "complete"})";
      else ss << std::ifstream(f).rdbuf();
      const std::string status = json_field(ss.str(), "status");
      const fs::path csv = md / "deviatoric" / (m[1].str() + "_" + m[2].str() + ".csv");
      if (status == "complete" && fs::exists(csv)) {
        Table t = read_table(csv.string());
        if (std::find(t.header.begin(), t.header.end(), "control_error_rel") != t.header.end()) {
          if (path_cells.insert({m[1].str(), std::stod(m[3].str())}).second)
            std::cerr << "dem fit: note: " << m[1].str() << "_" << m[2].str() << " is a loading path ([paths]); "
                      << "ensemble averages and fits cover the monotonic modes only\n";
          continue;
        }
        c.members.push_back(member);
        c.curves.push_back(std::move(t));
        for (const std::string& w : {prep_warning, json_field(ss.str(), "warning")})
          if (!w.empty()) c.warnings.push_back("member " + member + ": " + w);
      } else if (status == "complete") {   // its status stayed, its curve went: not a result
        c.excluded.push_back({member, "curve_missing", csv.filename().string() + " is gone although its status file "
                              "says complete: rerun the ensemble command to recompute it"});
      } else {
        std::string why = json_field(ss.str(), "message");
        if (why.empty()) why = json_field(ss.str(), "reason");
        c.excluded.push_back({member, status.empty() ? "unknown" : status, why});
      }
    }
  }
  for (const auto& k : path_cells) cells.erase(k);
  return cells;
}

// Rows with strictly increasing eps_d: the runner's last row lands exactly on eps_d_max one
// (shortened) step after a sampled row, and both can print as the same number; keep the later.
std::vector<std::size_t> increasing_rows(const Table& t) {
  const auto& e = t.column("eps_d");
  std::vector<std::size_t> rows;
  for (std::size_t i = 0; i < e.size(); ++i) {
    while (!rows.empty() && !(e[i] > e[rows.back()])) rows.pop_back();
    rows.push_back(i);
  }
  return rows;
}

std::vector<double> pick(const std::vector<double>& v, const std::vector<std::size_t>& rows) {
  std::vector<double> out;
  for (auto i : rows) out.push_back(v[i]);
  return out;
}

// Common grid: the first member's strains up to the shortest member's end (members share the
// sampling, so this is resampling by identity in practice).
std::vector<double> common_grid(const Cell& c) {
  double end = 1e300;
  for (const auto& t : c.curves) end = std::min(end, t.column("eps_d").back());
  std::vector<double> g;
  for (double e : pick(c.curves.front().column("eps_d"), increasing_rows(c.curves.front())))
    if (e <= end * (1 + 1e-12)) g.push_back(std::min(e, end));
  return g;
}

// Columns averaged: every numeric curve column but the step counter and the grid itself.
std::vector<std::string> averaged_columns(const Table& t) {
  std::vector<std::string> cols;
  for (std::size_t k = 0; k < t.header.size(); ++k) {
    const std::string& h = t.header[k];
    if (h == "step" || h == "eps_d" || h == "stage") continue;
    const auto& col = t.numeric[k];
    if (!col.empty() && std::all_of(col.begin(), col.end(), [](double v) { return std::isfinite(v); })) cols.push_back(h);
  }
  return cols;
}

std::vector<std::vector<double>> member_values(const Cell& c, const std::vector<double>& grid, const std::string& col) {
  std::vector<std::vector<double>> v;
  for (const auto& t : c.curves) {
    const auto rows = increasing_rows(t);
    v.push_back(resample(pick(t.column("eps_d"), rows), pick(t.column(col), rows), grid));
  }
  return v;
}

void write_ensemble_csv(const Cell& c, const std::vector<double>& grid, const std::string& path) {
  const auto cols = averaged_columns(c.curves.front());
  std::vector<Band> bands;
  for (const auto& col : cols) bands.push_back(band(member_values(c, grid, col)));
  std::ostringstream o;
  o.precision(10);
  o << "# dem ensemble curve: " << c.mode << " from nu = " << c.nu << ", " << c.members.size() << " packings (";
  for (std::size_t k = 0; k < c.members.size(); ++k) o << (k ? " " : "") << c.members[k];
  o << ")\n# each member resampled (linear) on the common eps_d grid; for every curve column X (units as in the "
       "member curves, docs/definitions.md):\n# X_mean mean over packings, X_sd their sample standard deviation, "
       "X_se = X_sd/sqrt(n_packings), X_lo95/X_hi95 = X_mean -/+ t_{n-1,0.975} X_se (95% confidence band of the mean)\n";
  if (!c.excluded.empty()) {
    o << "# excluded members:";
    for (auto& e : c.excluded) o << " " << e.member << " (" << e.status << ")";
    o << "\n";
  }
  o << "eps_d,n_packings";
  for (const auto& col : cols)
    for (const char* s : {"_mean", "_sd", "_se", "_lo95", "_hi95"}) o << "," << col << s;
  o << "\n";
  for (std::size_t i = 0; i < grid.size(); ++i) {
    o << grid[i] << "," << c.members.size();
    for (const auto& b : bands)
      for (double v : {b.mean[i], b.sd[i], b.se[i], b.lo[i], b.hi[i]}) o << "," << num(v, 10);
    o << "\n";
  }
  write_text_file(path, o.str());
}

Table parameter_table() {
  return Table({"mode", "nu", "quantity", "packings", "x0", "se_x0", "x_max", "se_x_max", "x_max_lo95", "x_max_hi95",
                "beta", "se_beta", "beta_lo95", "beta_hi95", "corr_xmax_beta", "initial_slope", "se_initial_slope",
                "eps_95", "r_squared", "rmse", "n", "eps_last", "error_method", "bootstrap_se_x_max",
                "bootstrap_se_beta", "member_sd_x_max", "member_sd_beta", "warnings",
                // appended: the model chosen per curve and the peak-and-soften law (docs/model_selection.md)
                "model", "selection_t", "selection_p", "transient_shown", "se_transient_shown",
                "heldout_mse_saturating", "heldout_mse_peak", "x_crit", "se_x_crit", "x_crit_lo95", "x_crit_hi95",
                "pk_x0", "se_pk_x0", "pk_x_cs", "se_pk_x_cs", "pk_beta", "se_pk_beta", "pk_A", "se_pk_A", "pk_gamma",
                "se_pk_gamma", "x_peak", "se_x_peak", "x_peak_lo95", "x_peak_hi95", "eps_peak", "se_eps_peak",
                "eps_peak_lo95", "eps_peak_hi95", "pk_initial_slope", "se_pk_initial_slope", "pk_r_squared", "pk_rmse",
                "selection_reason", "peak_warnings", "usable", "not_usable_because"});
}

// The peak law and the choice between the laws for one curve (the peak fit may fail: then the
// saturating law is kept and the reason says why).
struct Choice {
  PeakEnsembleFit peak;
  ModelChoice choice;
  bool peak_fitted = false;
};
Choice choose(const std::vector<double>& grid, const std::vector<std::vector<double>>& values, const EnsembleFit& f,
              const EnsembleFitOptions& eo) {
  Choice c;
  c.peak.value.fill(std::nan("")); c.peak.se.fill(std::nan("")); c.peak.lo.fill(std::nan("")); c.peak.hi.fill(std::nan(""));
  if (f.packings < 2) {
    c.choice.reason = "one packing: no model selection (the saturating law is kept)";
    return c;
  }
  try {
    c.peak = fit_peak_ensemble(grid, values, eo);
    c.peak_fitted = true;
    c.choice = choose_model(grid, values, f, c.peak, eo.fit);
  } catch (const std::exception& ex) {
    c.choice.reason = std::string("the peak law could not be fitted (") + ex.what() + "): the saturating law is kept";
  }
  return c;
}

// The one rule (demfit::unusable_reason) for the row's reported law: the saturating fit, or the
// peak law where the selection chose it.
std::string row_unusable(const EnsembleFit& f, const Choice& ch) {
  if (ch.choice.model == "saturating" || !ch.peak_fitted) return unusable_reason(f.fit);
  return ch.peak.fit.ok ? "" : "the chosen " + ch.choice.model + " law did not converge";
}

std::vector<std::string> choice_cells(const EnsembleFit& f, const Choice& c) {
  const bool peak = c.choice.model != "saturating";
  const auto& v = c.peak.value;
  const auto& se = c.peak.se;
  std::vector<std::string> cells = {c.choice.model, num(c.choice.t, 4), num(c.choice.p_value, 3), num(c.choice.shown),
                                    num(c.choice.se_shown), num(c.choice.mse_saturating), num(c.choice.mse_peak)};
  if (peak && !c.peak.fit.critical_state_reached)   // the softening continues beyond the data: no critical state
    for (int k = 0; k < 4; ++k) cells.push_back("nan");
  else if (peak)
    for (double x : {v[kPkXcs], se[kPkXcs], c.peak.lo[kPkXcs], c.peak.hi[kPkXcs]}) cells.push_back(num(x));
  else
    for (double x : {f.fit.x_max, f.fit.se_x_max, f.lo[1], f.hi[1]}) cells.push_back(num(x));
  for (int a : {kPkX0, kPkXcs, kPkBeta, kPkA, kPkGamma}) {
    cells.push_back(num(v[a]));
    cells.push_back(num(se[a]));
  }
  for (int a : {kPkXpeak, kPkEpsPeak})
    for (double x : {v[a], se[a], c.peak.lo[a], c.peak.hi[a]}) cells.push_back(num(x));
  cells.push_back(num(v[kPkSlope]));
  cells.push_back(num(se[kPkSlope]));
  cells.push_back(num(c.peak_fitted ? c.peak.fit.r_squared : std::nan(""), 5));
  cells.push_back(num(c.peak_fitted ? c.peak.fit.rmse : std::nan("")));
  cells.push_back(c.choice.reason);
  std::string w;
  for (const auto& s : c.peak.warnings) w += (w.empty() ? "" : "; ") + s;
  cells.push_back(w);
  return cells;
}

std::vector<std::string> parameter_row(const Cell& c, const std::string& q, const EnsembleFit& f, const std::string& w) {
  const FitResult& r = f.fit;
  return {c.mode, num(c.nu, 4), q, std::to_string(f.packings), num(r.x0), num(r.se_x0), num(r.x_max), num(r.se_x_max),
          num(f.lo[1]), num(f.hi[1]), num(r.beta), num(r.se_beta), num(f.lo[2]), num(f.hi[2]), num(r.corr[1][2], 3),
          num(r.initial_slope), num(r.se_initial_slope), num(r.eps_95), num(r.r_squared, 5), num(r.rmse),
          std::to_string(r.n), num(r.e_last, 4), f.error_method, num(f.boot_se[1]), num(f.boot_se[2]),
          num(f.member_sd[1]), num(f.member_sd[2]), w};
}

void write_members_table(const std::map<std::pair<std::string, double>, Cell>& cells, const fs::path& dir) {
  Table t({"mode", "nu", "member", "status", "message"});
  for (const auto& [key, c] : cells) {
    for (const auto& m : c.members) t.add_row({c.mode, num(c.nu, 4), m, "complete", ""});
    for (const auto& e : c.excluded) t.add_row({c.mode, num(c.nu, 4), e.member, e.status, e.message});
  }
  write_table_all(t, (dir / "members").string(), "Ensemble members per (mode, nu): used (complete) or left out, with the reason");
}

// Whether every task the scene plans has left its result: "" if so, else the note the tables carry
// ("ensemble incomplete: ..."). Sets `refuse` when the fit must not go on (incomplete without
// --partial; said on stderr); `missing` counts the tasks without a result.
std::string check_complete(const FitCommandOptions& o, const fs::path& run, bool& refuse, std::size_t& missing_count) {
  refuse = false;
  std::vector<std::string> missing;
  const bool stored_copy = no_status_files(run, o.planned_tasks);
  for (const auto& t : o.planned_tasks)
    if (!task_done(run, t, stored_copy)) missing.push_back(t);
    else if (curve_gone(run / t)) missing.push_back(t + " (its curve is gone)");
  std::string incomplete;
  if (!missing.empty()) {
    incomplete = "ensemble incomplete: " + std::to_string(missing.size()) + " of " +
                 std::to_string(o.planned_tasks.size()) + " planned tasks have no result";
    std::string list;
    for (std::size_t k = 0; k < missing.size() && k < 4; ++k) list += (k ? ", " : "") + missing[k];
    if (missing.size() > 4) list += ", ...";
    if (!o.partial) {
      std::cerr << "dem fit: " << run.string() << ": " << incomplete << " (" << list << "): nothing fitted; finish it "
                << "with `dem ensemble " << (run / "scene.toml").string() << " --out " << run.string()
                << "` (it continues where it stopped), or pass --partial to fit what is there\n";
      refuse = true;
      return incomplete;
    }
    std::cerr << "dem fit: warning: " << incomplete << " (" << list << "); fitting what is there (--partial): the "
              << "tables say so in their warnings\n";
  }
  missing_count = missing.size();
  return incomplete;
}

// The ensemble fits of a folder: the machine table and the rows for people, the usable fits by
// mode and quantity (nu-laws) and by cell (the paired D2/D3 test), and the counts of the summary.
struct EnsembleFits {
  Table params = parameter_table();
  std::vector<SummaryRow> summary;
  FitsByModeQuantity by_mode_q;
  std::map<std::tuple<std::string, double, std::string>, EnsembleFit> fits;
  std::map<std::pair<std::string, double>, std::vector<std::string>> fitted_members;
  int warnings = 0, fitted = 0, usable = 0;
  std::map<std::string, int> not_usable;   // reason -> count, for the summary line
};

// The ensemble fit of quantity q of one (mode, nu) cell: both laws, the choice between them, its
// rows; a cell that cannot be fitted gets a row saying why. `incomplete`: the folder's note.
void fit_cell_quantity(const Cell& c, const std::vector<double>& grid, const char* q, const std::string& incomplete,
                       const EnsembleFitOptions& eo, EnsembleFits& r) {
  std::string w = incomplete.empty() ? "" : incomplete + " (--partial)";
  for (const auto& mw : c.warnings) w += (w.empty() ? "" : "; ") + mw;
  for (const auto& e : c.excluded) w += (w.empty() ? "" : "; ") + ("member " + e.member + " left out: " + e.status);
  try {
    const auto values = member_values(c, grid, q);
    const EnsembleFit f = fit_ensemble(grid, values, eo);
    const Choice ch = choose(grid, values, f, eo);
    for (const auto& s : f.fit.warnings) {
      w += (w.empty() ? "" : "; ") + s;
      std::cerr << "dem fit: warning: " << c.mode << " nu=" << num(c.nu, 4) << " " << q << ": " << s << "\n";
      ++r.warnings;
    }
    const std::string why = row_unusable(f, ch);
    auto row = parameter_row(c, q, f, w);
    const auto extra = choice_cells(f, ch);
    row.insert(row.end(), extra.begin(), extra.end());
    row.push_back(why.empty() ? "yes" : "no");
    row.push_back(why);
    r.params.add_row(row);
    if (ch.choice.model != "saturating")
      std::cerr << "dem fit: " << c.mode << " nu=" << num(c.nu, 4) << " " << q << ": " << ch.choice.reason << "\n";
    std::vector<std::string> notes;
    for (const auto& e : c.excluded) notes.push_back("member " + e.member + " left out: " + e.status);
    notes.insert(notes.end(), f.fit.warnings.begin(), f.fit.warnings.end());
    const bool larger = ch.choice.model != "saturating";
    if (larger) notes.insert(notes.end(), ch.peak.warnings.begin(), ch.peak.warnings.end());
    SummaryRow sr = summary_row(c.mode, c.nu, q, f.packings, f.fit.x_max, f.fit.se_x_max, f.fit.beta, f.fit.se_beta,
                                f.fit.initial_slope, f.fit.se_initial_slope, f.fit.r_squared, notes);
    sr.model = ch.choice.model;
    sr.selection_p = ch.choice.p_value;
    const bool reached = !larger || ch.peak.fit.critical_state_reached;
    sr.x_crit = !reached ? std::nan("") : larger ? ch.peak.value[kPkXcs] : f.fit.x_max;
    sr.se_x_crit = !reached ? std::nan("") : larger ? ch.peak.se[kPkXcs] : f.fit.se_x_max;
    sr.x_peak = ch.peak.value[kPkXpeak];
    sr.se_x_peak = ch.peak.se[kPkXpeak];
    sr.eps_peak = ch.peak.value[kPkEpsPeak];
    sr.se_eps_peak = ch.peak.se[kPkEpsPeak];
    sr.not_usable = why;
    r.summary.push_back(sr);
    if (why.empty()) {
      r.by_mode_q[{c.mode, q}].emplace_back(c.nu, f.fit);
      r.fits[{c.mode, c.nu, q}] = f;
      ++r.usable;
    } else {
      ++r.not_usable[why];
      std::cerr << "dem fit: " << c.mode << " nu=" << num(c.nu, 4) << " " << q << ": not usable: " << why << "\n";
    }
    ++r.fitted;
  } catch (const std::exception& ex) {
    std::cerr << "dem fit: " << c.mode << " nu=" << num(c.nu, 4) << " " << q << ": not fitted: " << ex.what() << "\n";
    SummaryRow nf;
    nf.mode = c.mode; nf.nu = c.nu; nf.quantity = q; nf.packings = static_cast<int>(c.members.size());
    nf.fitted = false;
    nf.warnings = {std::string("not fitted: ") + ex.what()};
    r.summary.push_back(nf);
    ++r.not_usable["not fitted"];
    ++r.warnings;
  }
}

// D2 vs D3 from the same checkpoints, paired by member (shared_path.*).
void write_paired_shared_path(EnsembleFits& r, const fs::path& out) {
  Table shared({"nu", "quantity", "mode_a", "mode_b", "packings", "diff_x0", "se_diff_x0", "diff_x_max",
                "se_diff_x_max", "diff_beta", "se_diff_beta", "p_value", "max_gap", "same_path"});
  for (auto& [key, f2] : r.fits) {
    const auto& [mode, nu, q] = key;
    if (mode != "D2" || !r.fits.count({"D3", nu, q})) continue;
    if (r.fitted_members[{"D2", nu}] != r.fitted_members[{"D3", nu}]) {
      std::cerr << "dem fit: shared-path test nu=" << num(nu, 4) << " " << q << ": D2 and D3 have different members; skipped\n";
      continue;
    }
    try {
      const EnsembleSharedPath t = test_shared_path_ensemble(f2, r.fits.at({"D3", nu, q}));
      shared.add_row({num(nu, 4), q, "D2", "D3", std::to_string(t.packings), num(t.difference[0]), num(t.se[0]),
                      num(t.difference[1]), num(t.se[1]), num(t.difference[2]), num(t.se[2]), num(t.p_value, 3),
                      num(t.max_gap, 4), t.same_path ? "yes" : "no"});
    } catch (const std::exception& ex) {
      std::cerr << "dem fit: shared-path test nu=" << num(nu, 4) << " " << q << ": " << ex.what() << "\n";
    }
  }
  if (!shared.rows.empty()) {
    const std::string caption = "D2 vs D3 from the same packings: paired jackknife differences of (x0, x_max, beta) "
                                "against t (packings - 1 dof), Bonferroni p over the three; same_path: p >= 0.01";
    const std::string tex = paper_latex(
        shared,
        {paper_number(shared, "$\\nu$", "nu"), paper_text(shared, "Quantity", "quantity", tex_symbols()),
         paper_number(shared, "$K$", "packings"), paper_number(shared, "$\\Delta x_0$", "diff_x0", "se_diff_x0"),
         paper_number(shared, "$\\Delta x_\\mathrm{max}$", "diff_x_max", "se_diff_x_max"),
         paper_number(shared, "$\\Delta\\beta$", "diff_beta", "se_diff_beta"), paper_number(shared, "$p$", "p_value"),
         paper_text(shared, "Same path", "same_path")},
        caption, "D3 minus D2 from the same packings (only usable fits), paired jackknife errors; $p$: Bonferroni over "
                 "the three differences.");
    write_table_all(shared, (out / "shared_path").string(), caption, tex);
  }
}

}  // namespace

int run_ensemble_fit_command(const FitCommandOptions& o) {
  const fs::path run(o.run_dir), out = run / "fit", ens = run / "ensemble";
  // Complete or not: every task the scene plans must have left its status file.
  if (!o.plan_error.empty()) {
    std::cerr << "dem fit: " << run.string() << " looks like an ensemble folder (members/), but its scene.toml cannot "
              << "be read, so it is unknown which tasks it should hold: " << o.plan_error
              << "\n  (run `dem ensemble SCENE --out " << run.string() << "` to write it)\n";
    return 1;
  }
  bool refuse = false;
  std::size_t missing = 0;
  const std::string incomplete = check_complete(o, run, refuse, missing);
  if (refuse) return 1;
  auto cells = collect_cells(run);
  if (cells.empty() && (missing > 0 || o.planned_tasks.empty())) {
    std::cerr << "dem fit: no finished mode runs under " << (run / "members") << " (is the ensemble workflow finished?)\n";
    return 1;
  }
  // Every planned task finished, none a plain mode: an ensemble of loading paths only (e.g. the
  // shear tester, docs/powders.md). Nothing to fit: the tables are written empty, and said so.
  if (cells.empty())
    std::cerr << "dem fit: " << run.string() << ": only loading paths, which are not fitted; the tables are empty "
              << "(the paths' curves are in members/*/deviatoric/)\n";
  for (const fs::path& d : {out, ens}) fs::remove_all(d);   // no stale tables or averages of another run
  fs::create_directories(out);
  fs::create_directories(ens);
  write_members_table(cells, ens);

  EnsembleFitOptions eo;
  eo.fit.window_min = o.window_min;
  eo.fit.window_max = o.window_max;
  eo.fit.loss = o.loss == "huber" ? Loss::Huber : o.loss == "cauchy" ? Loss::Cauchy : Loss::None;
  EnsembleFits r;
  for (auto& [key, c] : cells) {
    for (const auto& e : c.excluded)
      std::cerr << "dem fit: warning: " << c.mode << " nu=" << num(c.nu, 4) << ": member " << e.member
                << " left out (" << e.status << (e.message.empty() ? "" : ": " + e.message) << ")\n";
    for (const auto& mw : c.warnings)
      std::cerr << "dem fit: warning: " << c.mode << " nu=" << num(c.nu, 4) << ": " << mw << "\n";
    if (c.members.empty()) continue;
    const auto grid = common_grid(c);
    write_ensemble_csv(c, grid, (ens / (c.mode + "_" + c.tag + ".csv")).string());
    r.fitted_members[key] = c.members;
    for (const char* q : {"s_dev", "F_dev"}) fit_cell_quantity(c, grid, q, incomplete, eo, r);
  }
  write_fit_tables(r.params, r.summary, (out / "parameters").string(),
                  "Saturating law x(eps_d) = x_max - (x_max - x0) exp(-beta eps_d) fitted to the ensemble mean; "
                  "standard errors and 95% intervals (t, packings - 1 dof) from the jackknife over packings; per curve "
                  "the model chosen between it and the peak-and-soften law (docs/model_selection.md)");

  write_paired_shared_path(r, out);
  write_nu_laws(r.by_mode_q, out.string());
  std::vector<std::string> unloading;
  for (auto& d : fs::directory_iterator(run / "members"))   // prep/ of a task's member, or the earlier flat layout
    unloading.push_back((d.path() / (fs::is_directory(d.path() / "prep") ? "prep" : "") / "cycle_unloading.csv").string());
  std::sort(unloading.begin(), unloading.end());
  write_isotropic(unloading, out.string());
  std::cerr << "dem fit: " << r.fitted << " ensemble fits written to " << out.string() << ": "
            << usable_summary(r.usable, r.summary.size(), r.not_usable)
            << " (" << r.warnings << " warnings)\n";
  if (!o.no_plots) {
    const std::string cmd = "PYTHONPATH=" + std::string(DEM_SOURCE_DIR) + " /usr/bin/python3 -m demkit.ensemble_plots \"" +
                            run.string() + "\"";
    if (std::system(cmd.c_str()) != 0) std::cerr << "dem fit: plotting failed (tables are written)\n";
  }
  return r.fitted > 0 || cells.empty() ? 0 : 1;   // an ensemble of paths only has nothing to fit: not an error
}

}  // namespace demfit
