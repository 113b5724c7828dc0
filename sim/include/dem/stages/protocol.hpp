// The protocol runner: preparation (placement, compression, relaxation, cycle with
// checkpoints) and deviatoric modes from the checkpoints, writing the run folder.
//
// Run folder layout (DIR = --out):
//   DIR/manifest.json                 scene, version, command, per-stage status
//   DIR/scene.toml                    the resolved scene (every key with its value)
//   DIR/prep/<stage>.csv             one per preparation stage (built in: compress, relax,
//                                    cycle_loading, cycle_unloading; or protocol.preparation)
//   DIR/prep/after_<stage>.ckpt      end state of each preparation stage (resume points)
//   DIR/checkpoints/<series>_phi0.700.{ckpt,txt}   (series: unloading, loading, or the
//                                    stage's checkpoint_name; txt: YADE text packing)
//   DIR/deviatoric/D2_phi0.700.csv ...
//   DIR/vtk/<stage>_NNNN.vtu and DIR/vtk/<stage>.pvd
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/core/state.hpp"

namespace dem {
struct RebuildStats;   // dem/engine/engine.hpp
}

namespace dem {

struct RunOptions {
  std::string out_dir;                 ///< results folder (created)
  std::string stages = "all";          ///< "all", "prep" or "deviatoric"
  bool force = false;                  ///< allow overwriting finished results
  std::string scene_toml;              ///< resolved scene text (stored with results)
  std::string command_line;            ///< for the manifest
  bool quiet = false;                  ///< no progress lines
};

/// Runs the scene. Checks everything it can before writing anything (checkpoints present and
/// of the same material physics, kept curves of the same shear physics, memory). A rerun
/// without --force of an interrupted run resumes it: the preparation from the last finished
/// stage (DIR/prep/after_<stage>.ckpt), the deviatoric modes by keeping finished curves.
/// --force removes the outputs it replaces first. Throws SceneError (mixed physics),
/// std::runtime_error (existing results, I/O) or BlowUp (after writing the last good state
/// to DIR/failed_<stage>.ckpt).
void run_protocol(const Model& model, const RunOptions& options);


/// How a stage ends.
enum class StopKind { VolumeFractionUp, VolumeFractionDown, DeviatoricStrain, Relaxed };

struct StageSpec {
  std::string name;                  ///< file stem of its CSV
  Vec3 rate{0, 0, 0};                ///< box true-strain rate [1/s]
  StopKind stop = StopKind::Relaxed;
  double target = 0;                 ///< phi, or strain (eps_d; |eps_v| for isotropic shapes)
  std::vector<double> checkpoint_phis;   ///< volume fractions at which on_checkpoint is called
  double ke_ratio = 0;               ///< Relaxed: ends when E_kin < ke_ratio * max(E_pot, E_floor)
  double max_time = 0;               ///< Relaxed: ends after this duration at the latest [s]
  std::string definition;            ///< deviatoric: mode_definition(), written in the curve's preamble
  Vec3 shear{0, 0, 0};               ///< upper entries (L_xy, L_xz, L_yz) of the velocity gradient [1/s]
                                     ///< (simple shear); with them a DeviatoricStrain stop is on eps_d_eig
  VelGrad gradient() const { return {rate, shear}; }
};

/// Runs one stage on (model, state), writing its curve CSV to csv_path (atomically; a crash
/// leaves only csv_path.part). Strains are measured from the stage start. For every phi in
/// spec.checkpoint_phis crossed, the step is shortened to land on it exactly and
/// on_checkpoint(phi, state) is called. Returns the number of steps taken.
/// The CSV's comment lines include `# physics: HASH key=value ...` (shear_physics for
/// deviatoric stages, preparation_physics otherwise; checks.hpp). Throws std::runtime_error
/// when a write fails (full disk: only csv_path.part is left) and BlowUp after saving the
/// last good state as `failed_checkpoint` (default: csv_path + ".failed.ckpt"). `stats`, if
/// given, receives the neighbour list's rebuild statistics of the stage (Engine::rebuild_stats).
std::int64_t run_stage(const Model& model, State& state, const StageSpec& spec,
                       const std::string& csv_path, const std::string& vtk_dir,
                       const std::function<void(double, const State&)>& on_checkpoint,
                       bool quiet, const std::string& failed_checkpoint = "", RebuildStats* stats = nullptr);

/// Runs the loading path `mode.path` (stages in order, strains accumulated from the path start)
/// from `state`, writing one curve to csv_path (rows of every stage, the stage's name in the
/// `stage` column; path_columns() after the usual columns). Relative targets (multiples of p0)
/// are resolved with p0 = the pressure at the path start. Each stage ends on its stop
/// condition; a stage whose stop has not come after a strain of 4 or a time of 4 / rate_max is
/// stopped with an error naming it. A path of one strain-controlled stage ending on eps_d gives
/// the rows of run_stage on the same mode bit for bit. Errors as run_stage.
std::int64_t run_path(const Model& model, State& state, const DeformationMode& mode, const std::string& label,
                      const std::string& csv_path, bool quiet, const std::string& failed_checkpoint = "",
                      RebuildStats* stats = nullptr);

/// The columns a path curve has after curve_columns(): the applied box strain rate [1/s], the
/// servo's targets [Pa] (NaN where none), its relative error, and eps_d accumulated along the
/// path (sum of |d eps_d|: grows through a reversal, where eps_d itself dips to 0).
const std::vector<std::string>& path_columns();

}  // namespace dem
