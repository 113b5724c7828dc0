// Reading the scene's [sweep] table from its TOML (private to the scene reader and dem/io/sweep.hpp).
#pragma once
#include <toml++/toml.h>

#include <string>

#include "dem/io/sweep.hpp"

namespace dem {

/// The [sweep] table of a parsed scene (no rows when it has none). Throws SceneError naming the
/// problem (structure, ragged rows, names, duplicates).
Sweep parse_scene_sweep(const toml::table& root, const std::string& origin);

/// The checks every sweep passes (keys, row names, value counts, duplicates); fills default names.
void check_sweep(Sweep& sweep);

}  // namespace dem
