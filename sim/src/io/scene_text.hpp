#pragma once
// Internal to the readers of scene text (scene.cpp, sweep.cpp).
#include <string>

namespace dem {

/// Scene text as toml++ may read it: pure ASCII outside comments (their non-ASCII bytes become '?'),
/// no control characters, strings closed; toml++ 3.3.0 reaches undefined behaviour on the others
/// (fuzz findings, tests/fuzz/README.md). Every toml::parse of a scene's text goes through it.
/// Throws SceneError naming origin and line.
std::string scene_text_for_toml(const std::string& text, const std::string& origin);

}  // namespace dem
