#include "demfit/table.hpp"

#include <nlohmann/json.hpp>

#include "dem/common/atomic_file.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <cerrno>
#include <cstring>
#include <map>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace demfit {

namespace {
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream ls(line);
  while (std::getline(ls, cur, ',')) out.push_back(cur);
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}
}  // namespace

nlohmann::ordered_json json_cell(const std::string& cell) {
  if (cell.empty()) return cell;
  const char* b = cell.c_str();
  char* end = nullptr;
  const long long i = std::strtoll(b, &end, 10);
  if (end && *end == 0 && end != b && cell.find_first_not_of("+-0123456789") == std::string::npos) return i;
  const double v = std::strtod(b, &end);
  if (end && *end == 0 && end != b) {
    if (std::isfinite(v)) return v;
    return nullptr;
  }
  return cell;
}

namespace {
// Text in LaTeX's text mode: every special character escaped (a machine dump must compile).
std::string tex_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '_': case '%': case '&': case '#': case '$': case '{': case '}': o += '\\'; o += c; break;
      case '~': o += "\\textasciitilde{}"; break;
      case '^': o += "\\textasciicircum{}"; break;
      case '\\': o += "\\textbackslash{}"; break;
      case '<': o += "$<$"; break;
      case '>': o += "$>$"; break;
      default: o += c;
    }
  }
  return o;
}
}  // namespace

std::size_t column_index(const Table& t, const std::string& name) {
  for (std::size_t k = 0; k < t.header.size(); ++k)
    if (t.header[k] == name) return k;
  throw std::logic_error("table " + t.source + " has no column '" + name + "'");
}

const std::vector<double>& Table::column(const std::string& name) const {
  for (std::size_t k = 0; k < header.size(); ++k)
    if (header[k] == name) return numeric[k];
  throw std::runtime_error(source + ": no column '" + name + "'");
}

Table read_table(const std::string& path) {
  // A regular file only: a device (/dev/zero) or a FIFO would never end (opened without blocking).
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot read " + path + " (" + std::strerror(errno) + ")");
  struct stat st {};
  const bool regular = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  ::close(fd);
  if (!regular) throw std::runtime_error(path + " is not a regular file (a device, FIFO or folder): give a curve CSV");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  return parse_table(in, path);
}

Table parse_table(std::istream& in, const std::string& path) {
  Table t;
  t.source = path;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line[0] == '#') t.comments.push_back(line);
    if (line.empty() || line[0] == '#') continue;
    auto cells = split(line);
    if (t.header.empty()) { t.header = cells; t.numeric.assign(cells.size(), {}); continue; }
    if (cells.size() != t.header.size())
      throw std::runtime_error(path + ":" + std::to_string(lineno) + ": " + std::to_string(cells.size()) +
                               " cells, header has " + std::to_string(t.header.size()));
    for (std::size_t k = 0; k < cells.size(); ++k) {
      char* end = nullptr;
      const double v = std::strtod(cells[k].c_str(), &end);
      t.numeric[k].push_back(end != cells[k].c_str() ? v : std::nan(""));
    }
    t.rows.push_back(std::move(cells));
  }
  if (t.header.empty()) throw std::runtime_error(path + ": no header line");
  return t;
}

namespace {
std::string csv_text(const Table& t) {
  std::ostringstream csv;
  for (std::size_t k = 0; k < t.header.size(); ++k) csv << (k ? "," : "") << t.header[k];
  csv << "\n";
  for (auto& r : t.rows) {
    for (std::size_t k = 0; k < r.size(); ++k) {
      std::string cell = r[k];
      if (cell.find(',') != std::string::npos || cell.find('"') != std::string::npos) {
        std::string q = "\"";
        for (char c : cell) { if (c == '"') q += '"'; q += c; }
        cell = q + "\"";
      }
      csv << (k ? "," : "") << cell;
    }
    csv << "\n";
  }
  return csv.str();
}
// The table as JSON (nlohmann-json): a cell that is a whole number is written as a number, an
// integer when it is one; NaN and infinities (not JSON numbers) as null; any other text as a string.
std::string json_text(const Table& t, const std::string& caption) {
  nlohmann::ordered_json js;
  js["caption"] = caption;
  js["null"] = "not a finite number (NaN or infinite)";
  js["rows"] = nlohmann::ordered_json::array();
  for (const auto& r : t.rows) {
    nlohmann::ordered_json row = nlohmann::ordered_json::object();
    for (std::size_t k = 0; k < t.header.size(); ++k) {
      const std::string& cell = k < r.size() ? r[k] : std::string();
      row[t.header[k]] = json_cell(cell);
    }
    js["rows"].push_back(std::move(row));
  }
  return js.dump(2) + "\n";
}
}  // namespace

void write_table_all(const Table& t, const std::string& stem, const std::string& caption) {
  write_table_all(t, stem, caption, "");
}

namespace {
std::string markdown_text(const Table& t, const std::string& caption) {
  std::ostringstream md;
  md << "<!-- " << caption << " -->\n|";
  for (auto& h : t.header) md << " " << h << " |";
  md << "\n|";
  for (std::size_t k = 0; k < t.header.size(); ++k) md << "---|";
  md << "\n";
  for (auto& r : t.rows) {
    md << "|";
    for (auto& c : r) md << " " << c << " |";
    md << "\n";
  }
  return md.str();
}

std::string tex_text(const Table& t, const std::string& caption) {
  std::ostringstream tex;
  tex << "% " << caption << " (needs \\usepackage{booktabs})\n\\begin{tabular}{" << std::string(t.header.size(), 'l')
      << "}\n\\toprule\n";
  for (std::size_t k = 0; k < t.header.size(); ++k) tex << (k ? " & " : "") << tex_escape(t.header[k]);
  tex << " \\\\\n\\midrule\n";
  for (auto& r : t.rows) {
    for (std::size_t k = 0; k < r.size(); ++k) tex << (k ? " & " : "") << tex_escape(r[k]);
    tex << " \\\\\n";
  }
  tex << "\\bottomrule\n\\end{tabular}\n";
  return tex.str();
}
}  // namespace

void write_table_all(const Table& t, const std::string& stem, const std::string& caption, const std::string& latex) {
  // All four or none: renamed into place only once every one is written.
  dem::write_files_atomic({{stem + ".csv", csv_text(t)}, {stem + ".json", json_text(t, caption)},
                           {stem + ".md", markdown_text(t, caption)},
                           {stem + ".tex", latex.empty() ? tex_text(t, caption) : latex}});
}

void write_table_all(const Table& machine, const Table& people, const std::string& stem, const std::string& caption) {
  dem::write_files_atomic({{stem + ".csv", csv_text(machine)}, {stem + ".json", json_text(machine, caption)},
                           {stem + ".md", markdown_text(people, caption)}, {stem + ".tex", tex_text(people, caption)}});
}

// ---- Tables for people -------------------------------------------------------------------

namespace {
// The integer n with its decimal point `decimals` digits from the right (negative: n * 10^-decimals).
std::string fixed_from_int(long long n, int decimals) {
  const bool neg = n < 0;
  const unsigned long long a = neg ? 0ULL - static_cast<unsigned long long>(n) : static_cast<unsigned long long>(n);
  std::string d = std::to_string(a);
  if (decimals > 0) {
    if (static_cast<int>(d.size()) <= decimals) d = std::string(decimals + 1 - d.size(), '0') + d;
    d.insert(d.size() - decimals, ".");
  } else if (decimals < 0 && a != 0) {
    d += std::string(-decimals, '0');
  }
  return (neg && a != 0 ? "-" : "") + d;
}
double pow10i(int k) {
  double r = 1;
  for (int i = 0; i < std::abs(k); ++i) r *= 10;
  return k < 0 ? 1 / r : r;
}
std::string sig3(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.3g", v);
  return b;
}
}  // namespace

Rounded round_to_error(double v, double e) {
  Rounded r;
  if (!std::isfinite(v)) { r.value = "nan"; return r; }
  if (!(std::isfinite(e) && e > 0)) { r.value = sig3(v); return r; }
  const double av = std::fabs(v);
  auto below_precision = [&] {        // an error far below the value's precision, or powers of ten
                                      // that underflow (below 1e-290): written unrounded
    r.value = table_number(v, 15);
    r.error_abs = table_number(e, 2);
    r.error = r.error_abs;
    return r;
  };
  if (std::max(av, e) < 1e-290) return below_precision();
  if (av >= 1e5 || (av < 1e-3 && e < 1e-3)) {
    r.exponent = static_cast<int>(std::floor(std::log10(std::max(av, e))));
    v /= pow10i(r.exponent);
    e /= pow10i(r.exponent);
  }
  if (!(e > 0)) return below_precision();   // e.g. 5e-324 next to 1e308 underflows to 0 (log10: -inf)
  int d = static_cast<int>(std::floor(std::log10(e)));
  double lead = e / pow10i(d);
  if (lead >= 10) { ++d; lead /= 10; }
  if (lead < 1) { --d; lead *= 10; }
  const int sig = lead < 2 ? 2 : 1;   // first digit 1: two significant digits
  const int place = d - sig + 1;      // power of ten of the last digit kept
  const double scale = place < 0 ? pow10i(-place) : 1 / pow10i(place);
  const double nv = std::round(v * scale), ne = std::round(e * scale);
  if (std::fabs(nv) > 1e15) return below_precision();
  const long long N = static_cast<long long>(nv), U = static_cast<long long>(ne);
  r.value = fixed_from_int(N, -place);
  r.error = place < 0 ? std::to_string(U) : fixed_from_int(U, -place);
  r.error_abs = fixed_from_int(U, -place);
  return r;
}

std::string format_paren(double value, double error) {
  const Rounded r = round_to_error(value, error);
  std::string s = r.value;
  if (!r.error.empty()) s += "(" + r.error + ")";
  if (r.exponent) s += "e" + std::to_string(r.exponent);
  return s;
}

std::string format_pm(double value, double error) {
  const Rounded r = round_to_error(value, error);
  if (r.error.empty()) return r.exponent ? r.value + "e" + std::to_string(r.exponent) : r.value;
  const std::string s = r.value + " \u00b1 " + r.error_abs;
  return r.exponent ? "(" + s + ")e" + std::to_string(r.exponent) : s;
}

namespace {
std::string tex_text(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '_': case '%': case '&': case '#': case '$': case '{': case '}': o += '\\'; o += c; break;
      case '~': o += "\\textasciitilde{}"; break;
      case '^': o += "\\textasciicircum{}"; break;
      case '\\': o += "\\textbackslash{}"; break;
      case '<': o += "$<$"; break;
      case '>': o += "$>$"; break;
      default: o += c;
    }
  }
  return o;
}
std::string mark_name(std::size_t k) {
  std::string s;
  for (++k; k > 0; k = (k - 1) / 26) s.insert(s.begin(), static_cast<char>('a' + (k - 1) % 26));
  return s;
}
// Distinct warning texts in order of appearance, and each row's marks.
struct Notes {
  std::vector<std::string> texts;
  std::vector<std::vector<std::string>> marks;
};
Notes notes_of(const std::vector<SummaryRow>& rows) {
  Notes n;
  for (const auto& r : rows) {
    std::vector<std::string> m;
    std::vector<std::string> texts = r.warnings;
    if (r.fitted && !r.not_usable.empty()) texts.insert(texts.begin(), "not usable: " + r.not_usable);
    for (const auto& w : texts) {
      auto it = std::find(n.texts.begin(), n.texts.end(), w);
      if (it == n.texts.end()) { n.texts.push_back(w); it = n.texts.end() - 1; }
      const std::string name = mark_name(static_cast<std::size_t>(it - n.texts.begin()));
      if (std::find(m.begin(), m.end(), name) == m.end()) m.push_back(name);
    }
    n.marks.push_back(m);
  }
  return n;
}
std::string joined(const std::vector<std::string>& v, const std::string& sep) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : sep) + x;
  return s;
}
std::string nu_text(double nu) { return table_number(nu, 4); }
std::string r2_text(double r2) {
  if (!std::isfinite(r2)) return "nan";
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", r2);
  return b;
}
int packings_of(const SummaryRow& r) { return r.packings > 0 ? r.packings : 1; }
const char* kExplainMd =
    "Each value is rounded to its standard error, given in parentheses in units of the last digit "
    "(0.197(2) = 0.197 \u00b1 0.002; the error to one significant digit, two when it starts with 1). "
    "K: packings averaged (1: a single run). Initial slope: dx/d\u03b5<sub>d</sub> at \u03b5<sub>d</sub> = 0 "
    "(G/p for s<sub>dev</sub>). \u201cnot usable\u201d: a fit whose numbers the data do not determine (ill-conditioned, "
    "not converged, on a bound, or a curve the law does not describe: the reason in its footnote; column `usable` of "
    "parameters.csv). Every digit and every diagnostic: parameters.csv / parameters.json.";
std::string md_quantity(const std::string& q) {
  const auto u = q.find('_');
  return u == std::string::npos ? q : q.substr(0, u) + "<sub>" + q.substr(u + 1) + "</sub>";
}
std::string tex_quantity(const std::string& q) {
  const auto u = q.find('_');
  return u == std::string::npos ? "$" + tex_text(q) + "$" : "$" + q.substr(0, u) + "_\\mathrm{" + q.substr(u + 1) + "}$";
}
// siunitx table-format of an S column from its cells ("0.197(2)", "-1.23(4)e-5", "{---}").
std::string table_format(const std::vector<std::string>& cells) {
  bool neg = false, expo_neg = false;
  int ints = 1, decs = 0, unc = 0, expo = 0;
  for (const auto& c : cells) {
    if (c.empty() || c[0] == '{') continue;
    std::size_t i = 0;
    if (c[i] == '-') { neg = true; ++i; }
    int n = 0;
    while (i < c.size() && std::isdigit(static_cast<unsigned char>(c[i]))) { ++n; ++i; }
    ints = std::max(ints, n);
    if (i < c.size() && c[i] == '.') {
      ++i; n = 0;
      while (i < c.size() && std::isdigit(static_cast<unsigned char>(c[i]))) { ++n; ++i; }
      decs = std::max(decs, n);
    }
    if (i < c.size() && c[i] == '(') {
      ++i; n = 0;
      while (i < c.size() && c[i] != ')') { ++n; ++i; }
      unc = std::max(unc, n);
      ++i;
    }
    if (i < c.size() && c[i] == 'e') {
      ++i;
      if (i < c.size() && c[i] == '-') { expo_neg = true; ++i; }
      expo = std::max(expo, static_cast<int>(c.size() - i));
    }
  }
  std::string f = (neg ? "-" : "") + std::to_string(ints) + "." + std::to_string(decs);
  if (unc) f += "(" + std::to_string(unc) + ")";
  if (expo) f += std::string("e") + (expo_neg ? "-" : "") + std::to_string(expo);
  return f;
}
}  // namespace

namespace {
bool any_peak(const std::vector<SummaryRow>& rows) {
  return std::any_of(rows.begin(), rows.end(),
                     [](const SummaryRow& r) { return r.fitted && !r.model.empty() && r.model != "saturating"; });
}
bool any_model(const std::vector<SummaryRow>& rows) {
  return std::any_of(rows.begin(), rows.end(), [](const SummaryRow& r) { return !r.model.empty(); });
}
std::string p_text(double p) {
  if (!std::isfinite(p)) return "";
  char b[32];
  std::snprintf(b, sizeof b, p < 1e-3 ? "%.0e" : "%.3f", p);
  return b;
}
// The four cells of the chosen model (model with p, x_peak, eps_peak, x_cs); Markdown or LaTeX.
std::array<std::string, 4> model_cells(const SummaryRow& r, bool tex) {
  if (!r.fitted || !r.not_usable.empty()) return {"", tex ? "{---}" : "", tex ? "{---}" : "", tex ? "{---}" : ""};
  const bool peak = r.model == "peak";
  const std::string p = p_text(r.selection_p);
  const std::string m = r.model.empty() ? "" : r.model + (p.empty() ? "" : " (p = " + p + ")");
  auto cell = [&](double v, double e) {
    const std::string c = format_paren(v, e);
    return c == "nan" ? std::string(tex ? "{---}" : "") : c;
  };
  // The larger model whose softening continues beyond the data has no critical state to show.
  const std::string crit = std::isfinite(r.x_crit) ? cell(r.x_crit, r.se_x_crit) : (tex ? "{---}" : "beyond the data");
  return {m, peak ? cell(r.x_peak, r.se_x_peak) : (tex ? "{---}" : ""), peak ? cell(r.eps_peak, r.se_eps_peak) : (tex ? "{---}" : ""),
          crit};
}
const char* kModelMd =
    "Model: the saturating law or the peak-and-soften law, chosen per curve by whether packings left out of the fit "
    "show the peak law's transient (one-sided t, K \u2212 1 dof; the peak law when p < 0.01; docs/model_selection.md).";
}  // namespace

SummaryRow summary_row(const std::string& mode, double nu, const std::string& quantity, int packings, double x_max,
                       double se_x_max, double beta, double se_beta, double slope, double se_slope, double r_squared,
                       const std::vector<std::string>& warnings) {
  SummaryRow r;
  r.mode = mode; r.nu = nu; r.quantity = quantity; r.packings = packings;
  r.x_max = x_max; r.se_x_max = se_x_max; r.beta = beta; r.se_beta = se_beta;
  r.slope = slope; r.se_slope = se_slope; r.r_squared = r_squared;
  r.warnings = warnings;
  return r;
}

std::string summary_markdown(const std::vector<SummaryRow>& rows, const std::string& caption) {
  const Notes n = notes_of(rows);
  const bool extra = any_peak(rows);
  std::ostringstream md;
  md << "**" << caption << "**\n\n";
  md << "| mode | \u03bd | quantity | K | x<sub>max</sub> | \u03b2 | initial slope | R\u00b2 |";
  if (extra) md << " model | x<sub>peak</sub> | \u03b5<sub>peak</sub> | x<sub>cs</sub> |";
  md << "\n|:--|--:|:--|--:|--:|--:|--:|--:|" << (extra ? ":--|--:|--:|--:|" : "") << "\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto& r = rows[i];
    std::string q = md_quantity(r.quantity);
    if (!n.marks[i].empty()) q += " <sup>" + joined(n.marks[i], ",") + "</sup>";
    md << "| " << r.mode << " | " << nu_text(r.nu) << " | " << q << " | " << packings_of(r) << " | ";
    if (r.fitted && !r.not_usable.empty())
      md << "not usable | | | |";
    else if (r.fitted)
      md << format_paren(r.x_max, r.se_x_max) << " | " << format_paren(r.beta, r.se_beta) << " | "
         << format_paren(r.slope, r.se_slope) << " | " << r2_text(r.r_squared) << " |";
    else
      md << "not fitted | | | |";
    if (extra)
      for (const auto& c : model_cells(r, false)) md << " " << c << " |";
    md << "\n";
  }
  md << "\n" << kExplainMd << "\n";
  if (any_model(rows))
    md << "\n" << kModelMd
       << (extra ? " x<sub>max</sub>, \u03b2, initial slope: the saturating law; x<sub>peak</sub>, \u03b5<sub>peak</sub>: "
                   "the peak law's maximum and where (model \u201ctwo-rate\u201d: the peak law without a peak, a slow second "
                   "stage); x<sub>cs</sub>: the critical state of the chosen model (\u201cbeyond the data\u201d where its softening "
                   "is not 95 % complete within them)."
                 : " The saturating law was chosen for every curve.")
       << "\n";
  if (!n.texts.empty()) md << "\n";
  for (std::size_t k = 0; k < n.texts.size(); ++k) md << "<sup>" << mark_name(k) << "</sup> " << n.texts[k] << "  \n";
  return md.str();
}

// The model's short name for the LaTeX table (its width fits A4 at \small with the peak columns).
static std::string model_short(const std::string& m) { return m == "saturating" ? "sat." : m; }

std::string summary_latex(const std::vector<SummaryRow>& rows, const std::string& caption) {
  const Notes n = notes_of(rows);
  const bool extra = any_peak(rows);
  // K as a column only when the rows differ in it; else once, in the note below the table.
  const bool k_column = std::any_of(rows.begin(), rows.end(), [&](const SummaryRow& r) {
    return packings_of(r) != packings_of(rows.front());
  });
  // S columns: nu, x_max, beta, slope, R^2, then (extra) p of the model test, x_peak, eps_peak, x_cs.
  std::vector<std::vector<std::string>> cells;
  for (const auto& r : rows) {
    std::vector<std::string> c;
    if (r.fitted && r.not_usable.empty())
      c = {nu_text(r.nu), format_paren(r.x_max, r.se_x_max), format_paren(r.beta, r.se_beta),
           format_paren(r.slope, r.se_slope), r2_text(r.r_squared)};
    else
      c = {nu_text(r.nu), "{---}", "{---}", "{---}", "{---}"};
    if (extra) {
      const auto m = model_cells(r, true);
      const std::string p = r.fitted && r.not_usable.empty() ? p_text(r.selection_p) : "";
      c.insert(c.end(), {p.empty() ? "{---}" : p, m[1], m[2], m[3]});
    }
    for (auto& x : c)
      if (x == "nan") x = "{---}";
    cells.push_back(c);
  }
  // With the peak law's columns the table drops the initial slope and R^2 (in parameters.md and .csv) and
  // narrows the column gaps, so that it fits A4 at \small (tests/python/test_tex.py).
  const bool full = !extra;
  std::vector<std::string> fmt;
  for (std::size_t k = 0; k < (extra ? 9u : 5u); ++k) {
    std::vector<std::string> col;
    for (const auto& c : cells) col.push_back(c[k]);
    fmt.push_back(table_format(col));
  }
  auto S = [&](std::size_t k) { return "S[table-format=" + fmt[k] + "]"; };
  std::ostringstream tex;
  tex << "% " << tex_text(caption) << "\n% needs \\usepackage{booktabs} and \\usepackage{siunitx}; values rounded to "
      << "their standard errors, given in parentheses in units of the last digit\n";
  if (!full) tex << "{\\setlength{\\tabcolsep}{4pt}%\n";
  tex << "\\begin{tabular}{l " << S(0) << " l" << (k_column ? " r" : "") << " " << S(1) << " " << S(2);
  if (full) tex << " " << S(3) << " " << S(4);
  if (extra) tex << " l " << S(6) << " " << S(7) << " " << S(8);   // the test's p: parameters.md
  tex << "}\n\\toprule\n";
  tex << "Mode & {$\\nu$} & Quantity" << (k_column ? " & {$K$}" : "") << " & {$x_\\mathrm{max}$} & {$\\beta$}";
  if (full) tex << " & {$\\left.\\mathrm{d}x/\\mathrm{d}\\varepsilon_\\mathrm{d}\\right|_0$} & {$R^2$}";
  if (extra) tex << " & Model & {$x_\\mathrm{peak}$} & {$\\varepsilon_\\mathrm{peak}$} & {$x_\\mathrm{cs}$}";
  tex << " \\\\\n\\midrule\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto& r = rows[i];
    std::string q = tex_quantity(r.quantity);
    if (!n.marks[i].empty()) q += "\\textsuperscript{" + joined(n.marks[i], ",") + "}";
    const auto& c = cells[i];
    tex << tex_text(r.mode) << " & " << c[0] << " & " << q;
    if (k_column) tex << " & " << packings_of(r);
    tex << " & " << c[1] << " & " << c[2];
    if (full) tex << " & " << c[3] << " & " << c[4];
    if (extra)
      tex << " & " << (r.fitted && r.not_usable.empty() ? tex_text(model_short(r.model)) : "") << " & " << c[6] << " & "
          << c[7] << " & " << c[8];
    tex << " \\\\\n";
  }
  tex << "\\bottomrule\n\\end{tabular}\n";
  if (!full) tex << "}\n";
  std::vector<std::string> below;
  if (!k_column && !rows.empty()) below.push_back("$K = " + std::to_string(packings_of(rows.front())) + "$ " +
                                 (packings_of(rows.front()) == 1 ? "run (no ensemble)." : "packings per curve."));
  if (extra) below.push_back("Model: the law chosen per curve (sat.: saturating; the test and its $p$: docs/model\\_selection.md); "
                             "the test's $p$, initial slopes and $R^2$: parameters.md.");
  for (std::size_t k = 0; k < n.texts.size(); ++k)
    below.push_back("\\textsuperscript{" + mark_name(k) + "}~" + tex_text(n.texts[k]));
  if (!below.empty()) {
    tex << "\n\\par\\smallskip{\\footnotesize\n";
    for (const auto& b : below) tex << b << "\\par\n";
    tex << "}\n";
  }
  return tex.str();
}

const std::map<std::string, std::string>& tex_symbols() {
  static const std::map<std::string, std::string> m = {
      {"s_dev", "$s_\\mathrm{dev}$"}, {"F_dev", "$F_\\mathrm{dev}$"}, {"p_star", "$p^*$"},
      {"x_max", "$x_\\mathrm{max}$"}, {"beta", "$\\beta$"}, {"x0", "$x_0$"}};
  return m;
}

PaperColumn paper_text(const Table& t, const std::string& header, const std::string& column,
                       const std::map<std::string, std::string>& as_tex) {
  const std::size_t k = column_index(t, column);
  return {header, [k, as_tex](const std::vector<std::string>& r) {
            const auto it = as_tex.find(r[k]);
            return it != as_tex.end() ? it->second : tex_text(r[k]);
          }, false};
}

PaperColumn paper_number(const Table& t, const std::string& header, const std::string& column,
                         const std::string& se_column) {
  const std::size_t k = column_index(t, column);
  const std::size_t e = se_column.empty() ? k : column_index(t, se_column);
  const bool with_error = !se_column.empty();
  return {header, [k, e, with_error](const std::vector<std::string>& r) {
            const double v = std::strtod(r[k].c_str(), nullptr), se = with_error ? std::strtod(r[e].c_str(), nullptr) : NAN;
            const std::string c = format_paren(v, se);
            return c == "nan" ? std::string("{---}") : c;
          }, true};
}

std::string paper_latex(const Table& t, const std::vector<PaperColumn>& cols, const std::string& caption,
                        const std::string& note) {
  std::vector<std::vector<std::string>> cells;
  for (const auto& r : t.rows) {
    std::vector<std::string> c;
    for (const auto& col : cols) c.push_back(col.cell(r));
    cells.push_back(c);
  }
  std::ostringstream tex;
  tex << "% " << tex_text(caption) << "\n% needs \\usepackage{booktabs} and \\usepackage{siunitx}; values rounded to "
      << "their standard errors, given in parentheses in units of the last digit; every digit: the .csv beside it\n";
  tex << "\\begin{tabular}{";
  for (std::size_t k = 0; k < cols.size(); ++k) {
    if (!cols[k].number) { tex << (k ? " l" : "l"); continue; }
    std::vector<std::string> col;
    for (const auto& c : cells) col.push_back(c[k]);
    tex << (k ? " " : "") << "S[table-format=" << table_format(col) << "]";
  }
  tex << "}\n\\toprule\n";
  for (std::size_t k = 0; k < cols.size(); ++k)
    tex << (k ? " & " : "") << (cols[k].number ? "{" + cols[k].header + "}" : cols[k].header);
  tex << " \\\\\n\\midrule\n";
  for (const auto& c : cells) {
    for (std::size_t k = 0; k < c.size(); ++k) tex << (k ? " & " : "") << c[k];
    tex << " \\\\\n";
  }
  tex << "\\bottomrule\n\\end{tabular}\n";
  if (!note.empty()) tex << "\n\\par\\smallskip{\\footnotesize " << note << "\\par}\n";
  return tex.str();
}

void write_fit_tables(const Table& t, const std::vector<SummaryRow>& rows, const std::string& stem,
                      const std::string& caption) {
  dem::write_files_atomic({{stem + ".csv", csv_text(t)}, {stem + ".json", json_text(t, caption)},
                     {stem + ".md", summary_markdown(rows, caption)}, {stem + ".tex", summary_latex(rows, caption)}});
}

std::string table_number(double v, int prec) {
  if (!std::isfinite(v)) return "nan";
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", prec, v);
  return b;
}

std::string table_number_exact(double v) {
  if (!std::isfinite(v)) return "nan";
  char b[64];
  const auto r = std::to_chars(b, b + sizeof b, v);
  return std::string(b, r.ptr);
}

std::string correlation_number(double rho) {
  if (!std::isfinite(rho)) return "nan";
  double r = std::round(rho * 1000.0) / 1000.0;
  if (r == 0.0) r = 0.0;   // -0 -> 0: the sign of a zero correlation is rounding
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", r);
  return b;
}

void write_text_file(const std::string& path, const std::string& content) { dem::write_file_atomic(path, content); }

}  // namespace demfit
