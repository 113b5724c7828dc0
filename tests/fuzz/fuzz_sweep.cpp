// Sweep reader: any table file (`dem ensemble --sweep FILE`) or scene [sweep] table gives a Sweep
// whose rows the scene loader resolves, or a SceneError, never a crash or another exception. The
// first byte picks the door: even, a sweep table file (tabs or runs of spaces); odd, a scene file
// whose [sweep] section is read. Every accepted sweep is then resolved row by row against a small
// valid scene (the table) or against itself (the scene), and written as sweep.json.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "dem/core/errors.hpp"
#include "dem/io/sweep.hpp"

namespace {

std::string temp_path(const char* tag) {
  std::string p = std::string("/tmp/fuzz_sweep_") + std::to_string(getpid()) + "_" + tag;
  return p;
}

void write(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  if (!f) std::abort();   // the harness itself failed, not the reader
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const std::string base = temp_path("base.toml"), input = temp_path("input");
  static const bool once = (write(base, "[particles]\ncount = 60\n[output]\nvtk = false\n"), true);
  (void)once;
  const bool table = (data[0] & 1) == 0;
  write(input, std::string(reinterpret_cast<const char*>(data) + 1, size - 1));
  try {
    const dem::Sweep s = table ? dem::read_sweep_table(input) : dem::scene_sweep(input);
    if (!s.rows.empty()) {
      dem::resolve_sweep(table ? base : input, {}, s);
      dem::sweep_json(s, {});
    }
  } catch (const dem::SceneError&) {
  }
  return 0;
}
