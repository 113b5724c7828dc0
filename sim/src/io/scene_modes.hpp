// Reading the scene's modes and loading paths ([modes], [paths], protocol.modes): the part of
// the scene loader (scene.cpp) that reads the deformations. Private to io/.
#pragma once
#include <toml++/toml.h>

#include <map>
#include <string>
#include <vector>

#include "dem/core/model.hpp"

namespace dem {

using CustomModes = std::map<std::string, DeformationMode>;
using PathMap = std::map<std::string, std::vector<PathStage>>;

/// [modes]: name = [rx, ry, rz] (a diagonal shape) or an upper-triangular velocity gradient
/// [[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]]; an absent section is added empty (the resolved
/// scene lists it). Throws SceneError naming the entry.
CustomModes read_custom_modes(toml::table& root, const std::string& origin);

/// [paths] name = [ {stage}, {stage}, ... ] (rates as numbers, a gradient, or a mode's name),
/// each path checked by validate_path; an absent section is added empty.
PathMap parse_paths(toml::table& root, const std::string& origin, const CustomModes& custom);

/// protocol.modes resolved: a [modes] entry, a [paths] entry or a built-in mode.
std::vector<DeformationMode> resolve_modes(const std::vector<std::string>& names, const CustomModes& custom,
                                           const PathMap& paths, const std::string& origin);

/// Every rate entry of a mode or path stage times protocol.deviatoric_rate_tc (`dev_tc`) at most
/// 1e-2 per contact time (quasi-static), else SceneError naming it.
void check_mode_rates(const std::vector<DeformationMode>& modes, double dev_tc, const std::string& origin);

}  // namespace dem
