// Parameter sweeps: a list of rows, each a name and a set of scene overrides ("section.key=value",
// the `--set` syntax), from a table file (`dem ensemble SCENE --sweep table.tsv`, yade-batch style)
// or from the scene's own [sweep] table. Both become the same Sweep; every row is then loaded by
// the scene loader before anything runs (resolve_sweep), so a bad row is refused up front.
#pragma once
#include <string>
#include <vector>

namespace dem {

struct SweepRow {
  std::string name;                 ///< the row's folder, DIR/rows/NAME (letters, digits, _ - .)
  std::vector<std::string> values;  ///< one TOML value per key, in the order of Sweep::keys
  std::string where;                ///< "table.tsv:3" or "scene.toml [sweep] values[1]" (for messages)
};

struct Sweep {
  std::string source;               ///< the table file, or "SCENE [sweep]"
  std::vector<std::string> keys;    ///< "section.key" per column
  std::vector<SweepRow> rows;
};

/// Reads a sweep table: '#' comments and blank lines are skipped; the first line is the header,
/// `section.key` names (a column `name` gives the row names), then one row per parameter set, one
/// TOML value per cell (a bare word is taken as a string, as with --set). Cells are separated by
/// tabs, or, in a file without tabs, by runs of spaces (yade-batch). Throws SceneError naming the
/// line: ragged rows, empty cells, a repeated column, duplicate names or rows, no rows.
Sweep read_sweep_table(const std::string& path);

/// The [sweep] table of a scene file (empty rows when it has none); same checks as the table.
///   [sweep]
///   keys = ["contact.friction"]
///   values = [[0.0], [0.1], [0.5]]
///   names = ["mu0", "mu0.1", "mu0.5"]     # optional
Sweep scene_sweep(const std::string& scene_path);

/// The overrides of one row: "key=value" per column.
std::vector<std::string> row_overrides(const Sweep& sweep, const SweepRow& row);

/// Loads every row through the scene loader (scene file + base overrides + the row's values) and
/// returns each row's resolved scene text (without [sweep]: an ordinary ensemble scene). Throws
/// SceneError naming the row, where it was given and the loader's reason.
std::vector<std::string> resolve_sweep(const std::string& scene_path, const std::vector<std::string>& base_overrides,
                                       const Sweep& sweep);

/// DIR/sweep.json: the sweep's keys, rows (name, values, the row folder) and the base overrides.
std::string sweep_json(const Sweep& sweep, const std::vector<std::string>& base_overrides);

}  // namespace dem
