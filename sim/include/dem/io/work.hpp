// The work a scene asks for: the steps of each preparation stage, mode and path, estimated
// before anything runs, and the bound on them the scene loader checks (check_work). The run
// plan (dem/stages/plan.hpp) and `dem info` report them.
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

}  // namespace dem
