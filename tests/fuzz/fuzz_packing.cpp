// Packing reader: any text gives a valid State or a std::runtime_error naming the line.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const dem::State s = dem::parse_packing(in, 2000.0, "fuzz.txt");
    dem::validate_state(s, "fuzz.txt");   // what was accepted must be a valid state
  } catch (const std::runtime_error&) {
  }
  return 0;
}
