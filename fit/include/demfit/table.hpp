// Small CSV table: read the runner's curves ('#' comment lines, one header line) and write
// result tables as CSV, JSON, Markdown and LaTeX.
#pragma once
#include <cmath>
#include <functional>
#include <istream>
#include <map>

#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

namespace demfit {

struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::vector<std::vector<double>> numeric;   ///< per column, filled by read_table
  Table() = default;
  explicit Table(std::vector<std::string> h) : header(std::move(h)) {}
  void add_row(std::vector<std::string> r) { rows.push_back(std::move(r)); }
  /// Column by name as numbers. Throws std::runtime_error naming the missing column.
  const std::vector<double>& column(const std::string& name) const;
  std::string source;
  std::vector<std::string> comments;          ///< the '#' lines, filled by read_table
};

/// Reads a CSV file. Throws std::runtime_error if unreadable or ragged.
Table read_table(const std::string& path);
/// The same from a stream; `source` names it in messages.
Table parse_table(std::istream& in, const std::string& source);
/// A number for a table cell: %.{prec}g, "nan" for non-finite values.
std::string table_number(double v, int prec = 6);
/// A number for a machine table's cell that reads back as the same double: the shortest such text (std::to_chars),
/// "nan" for non-finite values. `dem model`'s parameters.csv values are written so (sixteenth round of issue 31: a
/// restart from six digits began up to 1.7 % above the optimum's cost).
std::string table_number_exact(double v);
/// A correlation coefficient for a table cell: three decimals ("%.3f"), "nan" for non-finite
/// values, and no "-0.000". A correlation that is zero in exact arithmetic comes out of a numerical
/// covariance as a rounding residue (1e-16..1e-13) whose value depends on the heap's alignment (the
/// vectorised reductions inside Eigen/Ceres peel differently), so printed in %g it made `dem model`'s
/// bytes depend on the output folder's path; three decimals are all a correlation carries.
std::string correlation_number(double rho);
/// A table cell as JSON: an integer, a finite number, null for NaN or an infinity (JSON has no
/// such numbers), else the text.
nlohmann::ordered_json json_cell(const std::string& cell);
/// Writes text to path atomically (path.part, then rename). Throws std::runtime_error.
void write_text_file(const std::string& path, const std::string& content);
/// Writes stem.csv, stem.json, stem.md, stem.tex atomically, all four or none. Throws
/// std::runtime_error when a write fails (full disk): then only *.part files are left.
void write_table_all(const Table& t, const std::string& stem, const std::string& caption);
/// The same with `latex` as stem.tex (a table for people, paper_latex) instead of the dump.
void write_table_all(const Table& t, const std::string& stem, const std::string& caption, const std::string& latex);
/// The same with stem.csv and stem.json from `machine` (every digit) and stem.md, stem.tex from `people` (the same
/// rows, rounded for reading).
void write_table_all(const Table& machine, const Table& people, const std::string& stem, const std::string& caption);
/// The index of a column by name; std::logic_error when there is none (a programming error).
std::size_t column_index(const Table& t, const std::string& name);

/// A column of a table for people: its LaTeX header and its cell of a machine row; `number`: a
/// siunitx S column (its table-format is taken from the cells).
struct PaperColumn {
  std::string header;
  std::function<std::string(const std::vector<std::string>&)> cell;
  bool number = false;
};
/// A text column; cells found in `as_tex` are replaced by their LaTeX (a formula), others escaped.
PaperColumn paper_text(const Table& t, const std::string& header, const std::string& column,
                       const std::map<std::string, std::string>& as_tex = {});
/// A number column: the value rounded to the standard error in `se_column` ("0.197(2)"), or to
/// 3 significant digits without one (se_column ""); "{---}" where it is not a finite number.
PaperColumn paper_number(const Table& t, const std::string& header, const std::string& column,
                         const std::string& se_column = "");
/// LaTeX of the names the tables use: quantities (s_dev, F_dev, p_star), parameters (x_max,
/// beta, x0), yes/no; for paper_text's as_tex.
const std::map<std::string, std::string>& tex_symbols();
/// A booktabs tabular of `cols` over the rows of t (needs booktabs and siunitx), `note` (LaTeX)
/// below it in \footnotesize.
std::string paper_latex(const Table& t, const std::vector<PaperColumn>& cols, const std::string& caption,
                        const std::string& note = "");

// ---- Tables for people -------------------------------------------------------------------
// A value rounded to its standard error. The rule: the error keeps one significant digit, two
// when its first digit is 1 (0.0014 would otherwise become 0.001, 30 % off); the value is
// rounded to the same decimal place. 0.196534 +- 0.00231554 -> 0.197(2); 12.7865 +- 1.282 ->
// 12.8(13); 1234.5 +- 23 -> 1230(20). Magnitudes >= 1e5 or both below 1e-3 go to scientific
// notation (1.23(2)e-5). A non-finite or non-positive error gives the value to 3 significant
// digits and an empty error.
struct Rounded {
  std::string value;      ///< "0.197" (mantissa when exponent != 0)
  std::string error;      ///< in the units of the value's last digit: "2"; "" when there is none
  std::string error_abs;  ///< the error as a number in the value's units: "0.002"
  int exponent = 0;       ///< power of ten (scientific notation), 0 for plain
};
Rounded round_to_error(double value, double error);
/// "0.197(2)", "1.23(2)e-5"; "nan" for a non-finite value; the value alone when no error.
std::string format_paren(double value, double error);
/// "0.197 ± 0.002" (UTF-8 ±), "(1.23 ± 0.02)e-5".
std::string format_pm(double value, double error);

/// One row of a fit's table for people.
struct SummaryRow {
  std::string mode;
  double nu = 0;
  std::string quantity;            ///< curve column: s_dev, F_dev
  int packings = 0;                ///< K; 0 for a single run (printed "1")
  double x_max = 0, se_x_max = 0, beta = 0, se_beta = 0, slope = 0, se_slope = 0, r_squared = 0;
  std::vector<std::string> warnings;   ///< full texts: become footnote marks
  bool fitted = true;              ///< false: "not fitted" (the reason is the warning)
  /// Why the fit is not usable (demfit::unusable_reason; "" when it is): its numbers are then not
  /// printed, "not usable" stands in their place with the reason as a footnote.
  std::string not_usable;
  /// The model chosen for the curve ("saturating", "peak"; "" where no choice was made, e.g. a
  /// single run) and, for the peak law, its peak and critical state (docs/model_selection.md).
  std::string model;
  double selection_p = NAN;        ///< p-value of the test that chose it
  double x_crit = NAN, se_x_crit = NAN;   ///< critical state of the chosen model (x_max or x_cs)
  double x_peak = NAN, se_x_peak = NAN, eps_peak = NAN, se_eps_peak = NAN;
};
/// The row of a saturating fit (the model fields left empty).
SummaryRow summary_row(const std::string& mode, double nu, const std::string& quantity, int packings, double x_max,
                       double se_x_max, double beta, double se_beta, double slope, double se_slope, double r_squared,
                       const std::vector<std::string>& warnings);
/// The Markdown and LaTeX (booktabs + siunitx S columns) texts of a fit's short table:
/// columns mode, nu, quantity, K, x_max, beta, initial slope, R^2 (the saturating law); when
/// some row chose the peak law, four more: model (with the test's p), x_peak, eps_peak and the
/// critical state x_cs of the chosen model. Each warning text gets one footnote mark (a, b, ...)
/// on the quantity cell and is listed once below the table.
std::string summary_markdown(const std::vector<SummaryRow>& rows, const std::string& caption);
std::string summary_latex(const std::vector<SummaryRow>& rows, const std::string& caption);
/// Writes stem.csv and stem.json (the full machine table t) and stem.md, stem.tex (the short
/// table of `rows`), all four or none, atomically.
void write_fit_tables(const Table& t, const std::vector<SummaryRow>& rows, const std::string& stem,
                      const std::string& caption);

}  // namespace demfit
