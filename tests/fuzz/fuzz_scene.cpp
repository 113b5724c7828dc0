// Scene reader: any text gives a Model or a SceneError, never a crash or another exception.
#include <cstddef>
#include <cstdint>
#include <string>

#include "dem/io/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    dem::load_scene(text, {}, nullptr, "fuzz.toml");
  } catch (const dem::SceneError&) {
  }
  return 0;
}
