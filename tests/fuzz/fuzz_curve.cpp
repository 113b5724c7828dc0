// Curve reader of dem fit: any text gives a Table or a std::runtime_error.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "demfit/table.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const demfit::Table t = demfit::parse_table(in, "fuzz.csv");
    for (const auto& h : t.header) (void)t.column(h);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
