// Writing scene tables as TOML text (the scene and sweep readers write resolved scenes with it).
#pragma once
#include <toml++/toml.h>

#include <cstdint>
#include <string>

namespace dem {

/// The TOML text of a table, byte for byte what toml++ 3.3.0's `os << table` writes, without the
/// undefined behaviour its writer reaches on arrays (tests/SANITIZE.md, finding 1): to decide
/// whether an array fits on one line it casts log10 of a float to size_t, negative for any
/// |x| < 0.1. toml++ still writes every table, key and scalar; arrays and inline tables are
/// written here, with toml++'s layout (inline `[ a, b ]`, or one element per indented line when
/// its width estimate reaches 120 columns) and its estimate computed as x86-64 computes it (the
/// truncated log10 modulo 2^64), so the bytes of every scene written before stay the same.
std::string toml_write(const toml::table& table);

/// The text toml++ writes after `key = ` for one value (an array or inline table through
/// toml_write's own path).
std::string toml_value_text(const toml::node& value);

/// toml++'s estimate of a value's width on one line (`toml_formatter_count_inline_columns`), in
/// its unsigned arithmetic, without undefined behaviour (exposed for the tests).
std::uint64_t toml_inline_columns(const toml::node& value);

}  // namespace dem
