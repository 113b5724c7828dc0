// A curve CSV being written: comment preamble, header, rows; every write checked, the file
// renamed into place only after a good close (a crash or a full disk leaves only PATH.part).
#pragma once
#include <fstream>
#include <string>
#include <vector>

#include "dem/io/checks.hpp"
#include "dem/core/model.hpp"

namespace dem {

/// The comment lines of every curve CSV (what the columns mean, the run's physics record, and
/// for deviatoric curves `# definition: ` + mode_definition()).
std::string curve_preamble(const Model& m, const std::string& stage, const Physics& physics,
                           const std::string& definition = "");

class CurveFile {
 public:
  /// Opens PATH.part and writes the preamble and the header (curve_columns() + `extra` + stage).
  /// Throws std::runtime_error if the file cannot be written.
  CurveFile(const std::string& path, const std::string& preamble, const std::vector<std::string>& extra = {});
  /// Appends `row` (no newline, no stage) and `stage`.
  void row(const std::string& row, const std::string& stage);
  /// Appends a comment line `# text` (after the rows: a summary known only at the end; every
  /// reader of curves skips '#' lines wherever they are).
  void comment(const std::string& text) { out_ << "# " << text << "\n"; }
  /// Flushes and throws std::runtime_error (naming `stage`) if any write failed (disk full?).
  void check(const std::string& stage);
  /// Closes, checks, and renames PATH.part to PATH.
  void commit(const std::string& stage);
  /// Closes without renaming (the .part stays, visibly partial).
  void abandon() { out_.close(); }
  const std::string& path() const { return path_; }

 private:
  std::string path_, part_;
  std::ofstream out_;
};

}  // namespace dem
