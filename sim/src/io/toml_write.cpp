#include "dem/io/toml_write.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace dem {
namespace {

constexpr std::uint64_t kWrapColumns = 120;   // toml++'s width limit for an inline array
constexpr int kIndentColumns = 4;             // toml++'s indent string, "    "

// toml++ casts a double to size_t where the double may be negative (undefined behaviour). x86-64
// (as compiled for x86-64-v2: cvttsd2si) gives the truncated value as a signed 64-bit integer,
// reinterpreted modulo 2^64; +inf gives 0 and NaN 2^63 by the same instructions.
std::uint64_t size_cast_as_x86(double x) {
  if (std::isnan(x)) return std::uint64_t(1) << 63;
  if (std::isinf(x)) return x > 0 ? 0 : std::uint64_t(1) << 63;
  return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::trunc(x)));   // |x| <= 324 here
}

std::uint64_t number_columns(double magnitude, std::uint64_t weight) {
  return weight + size_cast_as_x86(std::log10(magnitude)) + 1u;
}

std::uint64_t integer_columns(std::int64_t v) {
  if (v == 0) return 1u;
  // toml++ negates the int64 itself, which overflows for INT64_MIN; here its magnitude, 2^63.
  return v < 0 ? number_columns(-static_cast<double>(v), 1u) : number_columns(static_cast<double>(v), 0u);
}

std::uint64_t float_columns(double v) {
  if (v == 0.0) return 3u;   // "0.0"
  return v < 0.0 ? number_columns(-v, 3u) : number_columns(v, 2u);
}

std::string scalar_text(const toml::node& v) {   // toml++'s own text of a scalar ("v = " cut off)
  toml::table t;
  t.insert("v", v);
  std::ostringstream o;
  o << t;
  return o.str().substr(4);
}

std::string key_text(const toml::key& k) {   // bare or quoted, as toml++ writes the key
  toml::table t;
  t.insert(k.str(), 0);
  std::ostringstream o;
  o << t;
  const std::string s = o.str();
  return s.substr(0, s.size() - 4);   // " = 0"
}

void write_value(const toml::node& v, int indent, std::string& out);

// toml_formatter::print(const array&): indent is toml++'s indent level when the array starts
// (-1 at the root).
void write_array(const toml::array& a, int indent, std::string& out) {
  if (a.empty()) {
    out += "[]";
    return;
  }
  const int level = std::max(indent, 0);
  const bool multiline = toml_inline_columns(a) + std::uint64_t(kIndentColumns * level) >= kWrapColumns;
  const int inner = multiline ? level + 1 : indent;
  out += multiline ? "[" : "[ ";
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (i > 0) out += multiline ? "," : ", ";
    if (multiline) out += '\n' + std::string(std::size_t(kIndentColumns * inner), ' ');
    write_value(a[i], inner, out);
  }
  out += multiline ? '\n' + std::string(std::size_t(kIndentColumns * level), ' ') + "]" : std::string(" ]");
}

// toml_formatter::print_inline(const table&).
void write_inline_table(const toml::table& t, int indent, std::string& out) {
  if (t.empty()) {
    out += "{}";
    return;
  }
  out += "{ ";
  bool first = true;
  for (auto&& [k, v] : t) {
    if (!first) out += ", ";
    first = false;
    out += key_text(k) + " = ";
    write_value(v, indent, out);
  }
  out += " }";
}

void write_value(const toml::node& v, int indent, std::string& out) {
  if (const auto* t = v.as_table()) return write_inline_table(*t, indent, out);
  if (const auto* a = v.as_array()) return write_array(*a, indent, out);
  out += scalar_text(v);
}

bool is_section_array(const toml::node& v) {   // [[name]]: toml++ writes these as tables
  const auto* a = v.as_array();
  return a && a->is_array_of_tables() && !(*a)[0].as_table()->is_inline();
}

// Replaces every array and inline table that toml++ would write inline by a placeholder string
// (a control character, which no scene can hold: scene_text_for_toml refuses them), keeping the
// originals in `held` in the order of their placeholders.
void hold_inline_values(toml::table& t, std::vector<std::unique_ptr<toml::table>>& held) {
  std::vector<std::string> inline_keys;
  for (auto&& [k, v] : t) {
    if (auto* sub = v.as_table(); sub && !sub->is_inline()) {
      hold_inline_values(*sub, held);
    } else if (is_section_array(v)) {
      for (auto& e : *v.as_array()) hold_inline_values(*e.as_table(), held);
    } else if (v.is_array() || v.is_table()) {
      inline_keys.emplace_back(k.str());
    }
  }
  for (const auto& k : inline_keys) {   // replaced after the walk: the walk holds references
    auto keep = std::make_unique<toml::table>();
    keep->insert("v", *t.get(k));
    held.push_back(std::move(keep));
    t.insert_or_assign(k, "\x01" + std::to_string(held.size() - 1) + "\x01");
  }
}

}  // namespace

std::uint64_t toml_inline_columns(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::table:
    case toml::node_type::array: {
      const bool table = n.is_table();
      if (table ? n.as_table()->empty() : n.as_array()->empty()) return 2u;   // "{}" or "[]"
      std::uint64_t weight = 3u;                                             // "{ }" or "[ ]"
      const auto add = [&weight](std::uint64_t w) { weight += w + 2u; return weight >= kWrapColumns; };
      if (table) {
        for (auto&& [k, v] : *n.as_table())
          if (add(k.length() + toml_inline_columns(v))) break;
      } else {
        for (auto& e : *n.as_array())
          if (add(toml_inline_columns(e))) break;
      }
      return weight;
    }
    case toml::node_type::string: return n.as_string()->get().size() + 2u;
    case toml::node_type::integer: return integer_columns(n.as_integer()->get());
    case toml::node_type::floating_point: return float_columns(n.as_floating_point()->get());
    case toml::node_type::boolean: return 5u;
    case toml::node_type::date:
    case toml::node_type::time: return 10u;
    case toml::node_type::date_time: return 30u;
    default: return 0u;
  }
}

std::string toml_value_text(const toml::node& value) {
  std::string out;
  write_value(value, -1, out);
  return out;
}

std::string toml_write(const toml::table& table) {
  toml::table copy = table;
  std::vector<std::unique_ptr<toml::table>> held;
  hold_inline_values(copy, held);
  std::ostringstream o;
  o << copy;
  std::string text = o.str();
  for (std::size_t i = 0; i < held.size(); ++i) {
    const std::string mark = scalar_text(toml::value<std::string>("\x01" + std::to_string(i) + "\x01"));
    const auto at = text.find(mark);
    if (at == std::string::npos || text.find(mark, at + 1) != std::string::npos)
      throw std::logic_error("toml_write: placeholder " + std::to_string(i) + " not written exactly once");
    const auto line = text.rfind('\n', at);
    const auto start = line == std::string::npos ? 0 : line + 1;
    const auto spaces = text.find_first_not_of(' ', start) - start;   // the key's indent
    std::string value;
    write_value(*held[i]->get("v"), int(spaces) / kIndentColumns, value);
    text.replace(at, mark.size(), value);
  }
  return text;
}

}  // namespace dem
