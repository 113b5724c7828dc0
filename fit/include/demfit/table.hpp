// Small CSV table: read the runner's curves ('#' comment lines, one header line) and write
// result tables as CSV, JSON, Markdown and LaTeX.
#pragma once
#include <istream>
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
/// Writes text to path atomically (path.part, then rename). Throws std::runtime_error.
void write_text_file(const std::string& path, const std::string& content);
/// Writes stem.csv, stem.json, stem.md, stem.tex atomically, all four or none. Throws
/// std::runtime_error when a write fails (full disk): then only *.part files are left.
void write_table_all(const Table& t, const std::string& stem, const std::string& caption);

}  // namespace demfit
