// Scene reader: any text, with any --set overrides, gives a Model or a SceneError, never a crash
// or another exception. The input is the scene text, then optionally a line "%%" and one
// override (section.key=value, as --set takes it) per line after it.
#include <algorithm>
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
  try {
    dem::load_scene(text, overrides, nullptr, "fuzz.toml");
  } catch (const dem::SceneError&) {
  }
  return 0;
}
