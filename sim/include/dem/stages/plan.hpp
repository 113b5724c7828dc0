// The run plan of a scene as data: which packings (ensemble members and their seeds), which
// checkpoints, which modes, and the estimated cost of each task. workflow/Snakefile builds its
// task graph from it (`dem info SCENE --json`), so the scene is parsed and validated in one place.
#pragma once
#include <string>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/io/work.hpp"   // the estimates of each task

namespace dem {

/// JSON: {"packings": K, "members": [{"name": "m000", "seed": S}, ...],
///        "series": "unloading" (protocol.modes_from),
///        "checkpoints": [{"phi": 0.8, "stem": "unloading_phi0.800"}, ...] (descending phi),
///        "modes": ["D2", ...], "prep_particle_steps": P, "mode_particle_steps": {"D2": M, ...},
///        "tasks": [planned_task_files], "threads": T}   (nlohmann-json; a non-finite number is null)
std::string plan_json(const Model& model);

/// The status file of every task of the ensemble workflow for this scene, relative to the
/// ensemble folder: members/mKKK/prep.json and members/mKKK/deviatoric/MODE_phiX.json.
std::vector<std::string> planned_task_files(const Model& model);

/// Readies DIR for the ensemble workflow: writes DIR/scene.toml (the resolved scene) unless it
/// holds exactly this text already (then the workflow continues where it stopped). A folder
/// with the results of another scene is refused, naming the differing lines. `force` removes
/// the results in DIR (of this scene or another) and starts afresh. Throws std::runtime_error.
/// First takes DIR/.dem-ensemble.lock (flock, exclusive, not waiting): a folder another
/// `dem ensemble` works on is refused, --force or not. Returns the lock's file descriptor (held
/// open, inherited by the workflow driver, which checks it).
int prepare_ensemble_folder(const std::string& dir, const std::string& resolved_scene, bool force);

/// Readies DIR for a parameter sweep (dem/io/sweep.hpp): DIR/rows/NAME/scene.toml per row (its
/// resolved scene: each row folder is an ordinary ensemble folder), then DIR/sweep.json. The same
/// sweep continues where it stopped; another sweep (other rows, values or scenes) is refused,
/// naming what differs, unless `force` (which removes DIR's rows/, sweep/ and logs/). An
/// ensemble folder (DIR/scene.toml) is refused. Takes the lock as prepare_ensemble_folder does.
int prepare_sweep_folder(const std::string& dir, const std::string& sweep_json,
                         const std::vector<std::pair<std::string, std::string>>& rows, bool force);

}  // namespace dem
