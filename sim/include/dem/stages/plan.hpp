// The run plan of a scene as data: which packings (ensemble members and their seeds), which
// checkpoints, which modes, and the estimated cost of each task. workflow/Snakefile builds its
// task graph from it (`dem info SCENE --json`), so the scene is parsed and validated in one place.
#pragma once
#include <string>
#include <vector>

#include "dem/core/model.hpp"

namespace dem {

/// Steps of one deviatoric mode run (to eps_d_max) or loading path (its stages; estimated for
/// stops on stress, phi or a strain component).
double mode_steps(const Model& model, const DeformationMode& mode);
/// Estimated particle-steps of one mode or path run (N x mode_steps).
double mode_particle_steps(const Model& model, const DeformationMode& mode);

/// Estimated particle-steps of one preparation, for progress weights: the steps of its
/// compress/expand stages (preparation_particle_steps) times 3, a rough allowance for the
/// relaxations, whose length depends on the packing, and the list rebuilds of compression.
double prep_particle_steps(const Model& model);

/// Steps of each preparation stage, in order: compress/expand exact for the volume fraction
/// (ln phi moves by 3 rate dt per step), a relaxation at most its max_time_tc.
std::vector<double> preparation_stage_steps(const Model& model);

/// Bounds the work before anything runs, as memory is bounded: a stage or mode of more than
/// kMaxSteps time steps (or not finite, e.g. a rate of 1e-300) is refused with its step
/// estimate (SceneError naming it). The particle count is bounded by the memory check.
constexpr double kMaxSteps = 1e11;   // N = 1000: 1e14 particle-steps, about 50 days at 25 M/s
void check_work(const Model& model, const std::string& origin);

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
