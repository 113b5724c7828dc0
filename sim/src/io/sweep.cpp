#include "dem/io/sweep.hpp"

#include <toml++/toml.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <map>
#include <sstream>

#include "dem/core/errors.hpp"
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"
#include "io/scene_text.hpp"
#include "io/sweep_toml.hpp"
#include "dem/io/toml_write.hpp"

namespace dem {

namespace {

[[noreturn]] void fail(const std::string& msg) { throw SceneError(msg); }

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t\r") - b + 1);
}

// A row name becomes a folder, DIR/rows/NAME: letters, digits, _ - and . (neither . nor - first).
bool row_name_ok(const std::string& s) {
  return !s.empty() && s.size() <= 64 && s[0] != '.' && s[0] != '-' && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

// A column name: section.key, one dot, both parts a TOML bare key; not the sweep itself.
void check_key(const std::string& key, const std::string& where) {
  const auto dot = key.find('.');
  const bool bare = !key.empty() && std::all_of(key.begin(), key.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
  if (!bare || dot == std::string::npos || dot == 0 || dot + 1 == key.size() || key.find('.', dot + 1) != std::string::npos)
    fail(where + ": column '" + key + "' must be a scene key section.key, e.g. contact.friction (or 'name' for the "
         "row names)");
  if (key.rfind("sweep.", 0) == 0) fail(where + ": column '" + key + "': a sweep cannot sweep its own [sweep] table");
}

std::vector<std::string> split_cells(const std::string& line, bool tabs) {
  std::vector<std::string> cells;
  if (tabs) {
    std::string cur;
    std::istringstream in(line);
    while (std::getline(in, cur, '\t')) cells.push_back(trim(cur));
    if (!line.empty() && line.back() == '\t') cells.push_back("");
  } else {
    std::istringstream in(line);
    for (std::string w; in >> w;) cells.push_back(w);
  }
  return cells;
}

// The TOML text of a value, as toml++ writes it in `v = ...` (strings quoted and escaped, arrays
// inline): the same text a `--set key=...` would give.
std::string toml_text(const toml::node& v) {
  if (const auto d = v.value_exact<double>(); d && std::isfinite(*d)) {   // the shortest text of the same double
    char b[40];
    for (int prec = 1; prec <= 17; ++prec) {
      std::snprintf(b, sizeof b, "%.*g", prec, *d);
      if (std::strtod(b, nullptr) == *d) break;
    }
    std::string t = b;
    return t.find_first_of(".e") == std::string::npos ? t + ".0" : t;   // still a TOML float
  }
  return toml_value_text(v);
}

}  // namespace

// Names, duplicates and emptiness: the checks shared by the table file and the scene's [sweep].
void check_sweep(Sweep& s) {
  if (s.keys.empty()) fail(s.source + ": the sweep names no scene key (give at least one section.key column)");
  std::map<std::string, std::string> seen_key;
  for (const auto& k : s.keys) {
    check_key(k, s.source);
    if (!seen_key.emplace(k, k).second) fail(s.source + ": column '" + k + "' is given twice");
  }
  if (s.rows.empty()) fail(s.source + ": the sweep has no rows (one row per parameter set)");
  const int width = s.rows.size() > 100 ? 3 : 2;
  std::map<std::string, std::string> names, values;
  for (std::size_t i = 0; i < s.rows.size(); ++i) {
    SweepRow& r = s.rows[i];
    if (r.name.empty()) {
      char b[32];
      std::snprintf(b, sizeof b, "row%0*zu", width, i);
      r.name = b;
    }
    if (!row_name_ok(r.name))
      fail(r.where + ": row name '" + r.name + "' must be 1-64 letters, digits, _, - or . (neither . nor - first): it names the "
           "folder rows/NAME, e.g. mu0.1");
    if (r.values.size() != s.keys.size())
      fail(r.where + ": the row has " + std::to_string(r.values.size()) + " values, the sweep " +
           std::to_string(s.keys.size()) + " keys (" + s.keys.front() + (s.keys.size() > 1 ? ", ..." : "") +
           "): every row gives one value per key");
    for (std::size_t k = 0; k < r.values.size(); ++k)
      if (r.values[k].empty()) fail(r.where + ": the value of " + s.keys[k] + " is empty");
    const auto n = names.emplace(r.name, r.where);
    if (!n.second) fail(r.where + ": row name '" + r.name + "' is also the name of " + n.first->second + ": names must differ");
    std::string joined;
    for (const auto& v : r.values) joined += v + '\x1f';
    const auto v = values.emplace(joined, r.where);
    if (!v.second)
      fail(r.where + ": the row sets the same values as " + v.first->second + " (it would compute the same ensemble "
           "twice): remove one");
  }
}

Sweep read_sweep_table(const std::string& path) {
  std::string text;
  try {
    text = read_regular_file(path, "sweep table", std::size_t(1) << 22);
  } catch (const std::runtime_error& e) {
    fail(e.what());
  }
  Sweep s;
  s.source = path;
  const bool tabs = text.find('\t') != std::string::npos;
  std::istringstream in(text);
  int line_no = 0, name_col = -1;
  bool header = true;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    std::vector<std::string> cells = split_cells(line, tabs);
    const std::string where = path + ":" + std::to_string(line_no);
    if (header) {
      header = false;
      for (std::size_t c = 0; c < cells.size(); ++c) {
        if (cells[c] == "name") {
          if (name_col >= 0) fail(where + ": two 'name' columns");
          name_col = static_cast<int>(c);
        } else {
          s.keys.push_back(cells[c]);
        }
      }
      continue;
    }
    const std::size_t want = s.keys.size() + (name_col >= 0 ? 1 : 0);
    if (cells.size() != want)
      fail(where + ": a ragged row: " + std::to_string(cells.size()) + " cells, the header has " + std::to_string(want) +
           (tabs ? " (cells are separated by tabs)" : " (cells are separated by spaces; a value with spaces needs a "
                                                       "tab-separated table)"));
    SweepRow r;
    r.where = where;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (static_cast<int>(c) == name_col) r.name = cells[c];
      else r.values.push_back(cells[c]);
    }
    if (name_col >= 0 && r.name.empty()) fail(where + ": the row's name is empty");
    s.rows.push_back(std::move(r));
  }
  check_sweep(s);
  return s;
}

Sweep parse_scene_sweep(const toml::table& root, const std::string& origin) {
  Sweep s;
  s.source = origin + " [sweep]";
  const toml::node* node = root.get("sweep");
  if (!node) return s;
  const toml::table* t = node->as_table();
  if (!t) fail(origin + ": 'sweep' must be a section [sweep] with keys = [...] and values = [[...], ...]");
  for (auto&& [k, v] : *t)
    if (k.str() != "keys" && k.str() != "values" && k.str() != "names")
      fail(s.source + ": unknown key '" + std::string(k.str()) + "'; [sweep] has keys, values and names");
  const toml::array* keys = t->get_as<toml::array>("keys");
  const toml::array* values = t->get_as<toml::array>("values");
  if (!keys || !values)
    fail(s.source + " needs keys = [\"section.key\", ...] and values = [[v1, ...], ...] (one inner array per row)");
  for (auto& k : *keys) {
    const auto str = k.value<std::string>();
    if (!str) fail(s.source + ": keys must be strings, e.g. keys = [\"contact.friction\"]");
    s.keys.push_back(*str);
  }
  const toml::array* names = t->get_as<toml::array>("names");
  if (t->get("names") && !names) fail(s.source + ": names must be an array of strings, one per row");
  if (names && names->size() != values->size())
    fail(s.source + ": names has " + std::to_string(names->size()) + " entries, values " +
         std::to_string(values->size()) + " rows");
  for (std::size_t i = 0; i < values->size(); ++i) {
    SweepRow r;
    r.where = s.source + " values[" + std::to_string(i) + "]";
    const toml::array* row = (*values)[i].as_array();
    if (!row) fail(r.where + " must be an array, one value per key, e.g. values = [[0.1], [0.5]]");
    for (auto& v : *row) r.values.push_back(toml_text(v));
    if (names) {
      const auto n = (*names)[i].value<std::string>();
      if (!n) fail(s.source + ": names[" + std::to_string(i) + "] must be a string");
      r.name = *n;
      if (r.name.empty()) fail(s.source + ": names[" + std::to_string(i) + "] is empty");
    }
    s.rows.push_back(std::move(r));
  }
  check_sweep(s);
  return s;
}

Sweep scene_sweep(const std::string& scene_path) {
  const std::string text = read_regular_file(scene_path, "scene file", std::size_t(1) << 24);
  toml::table root;
  try {
    root = toml::parse(scene_text_for_toml(text, scene_path), scene_path);   // not raw text: toml++'s UB on non-ASCII
  } catch (const toml::parse_error&) {
    load_scene(text, {}, nullptr, scene_path);   // reports the syntax error as the loader words it
    throw;
  }
  return parse_scene_sweep(root, scene_path);
}

std::vector<std::string> row_overrides(const Sweep& sweep, const SweepRow& row) {
  std::vector<std::string> o;
  for (std::size_t k = 0; k < sweep.keys.size(); ++k) o.push_back(sweep.keys[k] + "=" + row.values[k]);
  return o;
}

std::vector<std::string> resolve_sweep(const std::string& scene_path, const std::vector<std::string>& base_overrides,
                                       const Sweep& sweep) {
  std::vector<std::string> scenes;
  for (const auto& row : sweep.rows) {
    std::vector<std::string> ov = base_overrides;
    const auto mine = row_overrides(sweep, row);
    ov.insert(ov.end(), mine.begin(), mine.end());
    std::string resolved;
    try {
      load_scene_file(scene_path, ov, &resolved);
    } catch (const SceneError& e) {
      std::string sets;
      for (const auto& s : mine) sets += (sets.empty() ? "" : ", ") + s;
      fail("sweep row '" + row.name + "' (" + row.where + ": " + sets + "): " + e.what() +
           "; nothing was run: fix the row (every row is checked before any task starts)");
    }
    scenes.push_back(resolved);
  }
  return scenes;
}

std::string sweep_json(const Sweep& sweep, const std::vector<std::string>& base_overrides) {
  nlohmann::ordered_json j;
  j["source"] = sweep.source;
  j["keys"] = sweep.keys;
  j["base_overrides"] = base_overrides;
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  for (const auto& r : sweep.rows) {
    nlohmann::ordered_json values = nlohmann::ordered_json::object();
    for (std::size_t k = 0; k < sweep.keys.size(); ++k) values[sweep.keys[k]] = r.values[k];
    rows.push_back({{"name", r.name}, {"folder", "rows/" + r.name}, {"values", values}});
  }
  j["rows"] = rows;
  return j.dump(1) + "\n";
}

}  // namespace dem
