// Reading `protocol.preparation` from the scene's TOML (private to the scene reader).
#pragma once
#include <toml++/toml.h>

#include <string>
#include <vector>

#include "dem/core/model.hpp"

namespace dem {

/// Reads `protocol.preparation` (an array of inline tables, spelling in preparation.hpp).
/// Rates and times are given in units of t_c and converted with `t_contact` [s]. Throws
/// SceneError naming the stage and the key on anything it cannot read.
std::vector<PrepStage> parse_preparation(const toml::array& stages, double t_contact, const std::string& origin);

}  // namespace dem
