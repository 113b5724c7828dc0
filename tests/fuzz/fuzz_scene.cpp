// Scene reader: any text, with any --set overrides, gives a Model or a SceneError, never a crash
// or another exception. The input is the scene text, then optionally a line "%%" and one
// override (section.key=value, as --set takes it) per line after it. A scene accepted is written
// resolved (dem/io/toml_write.hpp), and that text must load again and resolve to itself: every
// run folder's scene.toml is read back this way (resume, `dem run --stages deviatoric`).
#include <algorithm>
#include <cstdlib>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "dem/io/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const std::size_t split = input.find("\n%%\n");
  const std::string text = input.substr(0, split);
  std::vector<std::string> overrides;
  if (split != std::string::npos)
    for (std::size_t at = split + 4; at <= input.size();) {
      const std::size_t end = std::min(input.find('\n', at), input.size());
      overrides.push_back(input.substr(at, end - at));
      at = end + 1;
    }
  std::string resolved;
  try {
    dem::load_scene(text, overrides, &resolved, "fuzz.toml");
  } catch (const dem::SceneError&) {
    return 0;
  }
  std::string again;
  try {
    dem::load_scene(resolved, {}, &again, "resolved.toml");
  } catch (const dem::SceneError&) {
    std::abort();   // an accepted scene whose resolved text is refused
  }
  if (again != resolved) std::abort();   // resolution is not a fixed point
  return 0;
}
