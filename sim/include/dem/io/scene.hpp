// Scene files: TOML text -> validated Model. Every Model field is a scene key; see
// data/scenes/paper_n9261.toml for the documented full list with units and defaults.
#pragma once
#include <stdexcept>
#include <string>
#include <vector>

#include "dem/core/errors.hpp"
#include "dem/core/model.hpp"

namespace dem {

/// Parses scene TOML text, applies overrides ("section.key=value", value in TOML syntax;
/// a bare word is taken as a string), validates, and returns a finalized Model.
/// `resolved_toml` (if non-null) receives the full scene with every key and its value,
/// suitable for writing next to results and for reloading.
/// Throws SceneError (unknown key, type mismatch, value out of range, parse error).
Model load_scene(const std::string& toml_text, const std::vector<std::string>& overrides = {},
                 std::string* resolved_toml = nullptr, const std::string& origin = "scene");

/// Reads a file and calls load_scene. Throws SceneError if the file cannot be read.
Model load_scene_file(const std::string& path, const std::vector<std::string>& overrides = {},
                      std::string* resolved_toml = nullptr);

/// Checks every range and cross-constraint of a model; throws SceneError naming the key.
void validate(const Model& model);

/// The built-in deformation modes: D2 (1,0,-1), D3 (1/2,1/2,-1), iso_compress (-1,-1,-1),
/// iso_expand (1,1,1), uniaxial_x/y/z (-1 on one axis: compression).
bool builtin_mode(const std::string& name, DeformationMode* mode);

/// The largest stress target [Pa] a path stage may ask for: max_overlap_fraction * k / (2 r_min),
/// where the overlaps reach the blow-up check's limit (p* = 2 r p / k).
inline double stress_target_limit(const Model& m) {
  return m.max_overlap_fraction * m.contact.reference_stiffness() / (2 * m.radius_min);
}

}  // namespace dem
