// Checkpoint reader: any bytes give a validated Checkpoint or a std::runtime_error. The
// checksum would stop almost every mutation at the door, so half of the inputs get a valid
// checksum appended (the first byte chooses): the parser behind it is fuzzed too.
#include <cstddef>
#include <cstdint>
#include <string>

#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"

namespace {
std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 14695981039346656037ULL;
  for (char c : s) { h ^= static_cast<unsigned char>(c); h *= 1099511628211ULL; }
  return h;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1) {
    const std::uint64_t h = fnv1a(bytes);
    bytes.append(reinterpret_cast<const char*>(&h), sizeof h);
  }
  try {
    const dem::Checkpoint c = dem::parse_checkpoint(bytes, "fuzz.ckpt");
    dem::validate_state(c.state, "fuzz.ckpt");
  } catch (const std::runtime_error&) {
  }
  return 0;
}
