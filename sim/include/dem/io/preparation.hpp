// The preparation as a list of stages (PrepStage, model.hpp): the built-in compress / relax /
// cycle list made from the scene's protocol keys, the `protocol.preparation` spelling of the
// same thing, their checks, and the record of them that goes into the physics of every output.
//
// Scene spelling (one stage per line: TOML inline tables cannot span lines; docs/control.md, "The preparation as a stage list"):
//   [protocol]
//   preparation = [
//     { name = "compress", kind = "compress", rate_tc = 1e-4, until = { phi = 0.64 } },
//     { name = "relax", kind = "relax", until = { ke_ratio = 1e-8 }, max_time_tc = 2e5 },
//     { name = "cycle_loading", kind = "compress", rate_tc = 2e-5, until = { phi = 0.82 }, checkpoint_name = "loading" },
//     { name = "cycle_unloading", kind = "expand", rate_tc = 2e-5, until = { phi = 0.64 }, checkpoint_name = "unloading", checkpoints = [0.80, 0.75, 0.70, 0.68] },
//   ]
//   modes_from = "unloading"      # the checkpoint series the deviatoric modes start from
// which is exactly the built-in preparation (same curves, checkpoints and physics record).
#pragma once
#include <string>
#include <vector>

#include "dem/core/model.hpp"

namespace dem {

/// The built-in preparation from the protocol keys (rates in 1/s, times in s already set):
/// compress to target_phi, relax, cycle_loading to cycle_phi_max (checkpoint series "loading"),
/// cycle_unloading back to target_phi (series "unloading").
std::vector<PrepStage> default_preparation(const Protocol& p);

/// Checks a stage list and the series the modes start from: names file-safe and unique,
/// rates in (0, 1e-2 / t_c], targets in (0, 0.9), checkpoints on the stage's side of its target
/// and not two with one file name, `modes_from` a series with checkpoints when there are modes.
/// Throws SceneError.
void validate_preparation(const Protocol& p, double t_contact, const std::string& origin);

/// Volume fractions of the checkpoints the deviatoric modes start from (series
/// `p.modes_from`), densest first.
std::vector<double> mode_checkpoints(const Protocol& p);

/// File stem of a checkpoint: "<series>_phiX.XXX".
std::string checkpoint_stem(const std::string& series, double phi);

/// One line (no spaces) that fixes the preparation's physics: every stage with its kind,
/// rate [1/t_c], target, relaxation criterion and checkpoints (not modes_from, which only
/// picks where the modes start). Equal for a scene that spells out
/// the built-in list and for the built-in list itself.
std::string preparation_record(const Protocol& p, double t_contact);

/// Particle-steps of the preparation, roughly (phi stages from their nominal start; the first
/// from protocol.initial_phi; relaxations not counted).
double preparation_particle_steps(const Model& m);

/// Short human-readable description of a stage, without its name ("compress to phi 0.64 at 0.0001/t_c").
std::string describe(const PrepStage& s, double t_contact);

}  // namespace dem
