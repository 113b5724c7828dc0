// Checks made before anything runs: states read from files (against themselves and against
// the scene that will run them), the memory a scene needs, and the physics recorded with
// every output so that results of different physics are never mixed.
#pragma once
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/core/state.hpp"

namespace dem {

/// Structural validity of a state read from a file: array sizes agree, ids are a permutation
/// of 0..N-1, radii and masses finite and positive, positions and velocities finite, box
/// lengths finite and positive. Throws std::runtime_error naming `origin`, the problem and
/// the particle.
void validate_state(const State& state, const std::string& origin);

/// Throws when the state carries contact history (or rotations) that the model would drop:
/// another contact model's springs, spins under a frictionless law. Part of check_packing.
void check_history(const Model& model, const State& state, const std::string& origin);

/// A packing against the scene that will run it. t_c, dt and the Verlet skin come from the
/// scene's radius bounds, so radii must lie in [radius_min_m, radius_max_m] (relative
/// tolerance 1e-9); no two centres may coincide and no overlap may exceed
/// max_overlap_fraction of the smaller radius. Throws std::runtime_error naming the spheres
/// (ids) and the keys to set.
void check_packing(const Model& model, const State& state, const std::string& origin);

/// Rough peak memory [bytes] of a run of n spheres (state, its last good copy, neighbour
/// list, scratch): 0.6 kB per sphere (0.33 kB measured at N = 9261).
double estimated_memory_bytes(long long n);

/// Throws SceneError when a random placement of particles.count spheres needs more memory
/// than this machine has (instead of a bare std::bad_alloc hours later).
void check_memory(const Model& model);

/// The physical keys of a model with their values (%.17g), in a fixed order.
using Physics = std::vector<std::pair<std::string, std::string>>;

/// A number as physics records write it: 17 significant digits ("%.17g"), so equal records
/// mean equal doubles.
std::string physics_number(double v);
/// A list of numbers as "[a,b,c]" (physics_number each).
std::string physics_list(const std::vector<double>& v);
/// What a deviatoric curve depends on besides its start state: radius bounds (t_c), density,
/// contact law, integrator and dt_over_tc. Not the skin or the threads (round-off only).
Physics material_physics(const Model& model);
/// What a deviatoric curve of `mode` is, beyond its physics (one line, no spaces): a plain
/// mode's rate shape and protocol.eps_d_max; a path's stages (rate, targets, stop) and the
/// servo options. A kept curve whose definition differs from the scene's is not kept silently.
std::string mode_definition(const Model& model, const DeformationMode& mode);
/// material_physics plus protocol.deviatoric_rate_tc: the physics of a deviatoric curve.
Physics shear_physics(const Model& model);
/// material_physics plus everything the preparation depends on (count, seed, packing file,
/// phases, rates, checkpoint lists): the physics of the prep curves and checkpoints.
Physics preparation_physics(const Model& model);

/// 16 hex digits (FNV-1a 64 of the key=value pairs).
std::string physics_hash(const Physics& physics);
/// "HASH key=value key=value ..." (the `# physics:` line of every curve CSV).
std::string physics_line(const Physics& physics);
/// Inverse of physics_line (the hash is dropped); ignores malformed words.
Physics parse_physics_line(const std::string& line);
/// What a record without a key is read as (key -> value text): a sub-model's keys are written
/// only while it is on, and records older than a key had this value. One table.
const std::map<std::string, std::string>& record_defaults();
/// The keys whose values differ, e.g. "contact.stiffness_N_m = 1e+08 (checkpoint) vs 5e+07
/// (this scene)"; empty if none. `a_name`/`b_name` label the two sides. A key on one side only
/// is a difference unless the other side's record_defaults() value equals it (stated so).
std::string physics_diff(const Physics& a, const Physics& b, const std::string& a_name,
                         const std::string& b_name);

}  // namespace dem
