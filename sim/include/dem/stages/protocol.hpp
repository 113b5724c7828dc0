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
#include <cstdint>
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

/// One stage of constant velocity gradient (run_stage). Built by one function per kind of stage:
/// mode_stage (a deviatoric mode), volume_stage (an isotropic compression or expansion of the
/// preparation), relax_stage (a relaxation); demtk.run_stage sets the fields from its arguments.
struct StageSpec {
  std::string name;                  ///< file stem of its CSV
  VelGrad gradient;                  ///< the velocity gradient [1/s]: its diagonal the box true-strain rate, its
                                     ///< upper entries (L_xy, L_xz, L_yz) simple shear (then a DeviatoricStrain
                                     ///< stop is on eps_d_eig)
  StopKind stop = StopKind::Relaxed;
  double target = 0;                 ///< phi, or strain (eps_d; |eps_v| for isotropic shapes)
  std::vector<double> checkpoint_phis;   ///< volume fractions at which on_checkpoint is called
  double ke_ratio = 0;               ///< Relaxed: ends when E_kin < ke_ratio * max(E_pot, E_floor)
  double max_time = 0;               ///< Relaxed: ends after this duration at the latest [s]
  std::string definition;            ///< deviatoric: mode_definition(), written in the curve's preamble
};

/// A deviatoric mode at protocol.deviatoric_rate up to protocol.eps_d_max; `name` is the curve's
/// stem and stage column ("" : the mode's name).
StageSpec mode_stage(const Model& model, const DeformationMode& mode, const std::string& name = "");
/// A compress or expand stage of the preparation to its target phi (checkpoint_phis left empty:
/// which of the stage's checkpoints lie ahead depends on where it starts, run_prep_stage).
StageSpec volume_stage(const PrepStage& stage);
/// A relax stage of the preparation.
StageSpec relax_stage(const PrepStage& stage);

/// Where a stage runner writes.
struct StageOutput {
  std::string csv;                   ///< the curve (atomically: a crash leaves only csv + ".part")
  std::string vtk_dir;               ///< VTK snapshots when output.vtk ("": none; run_stage only)
  std::string failed_checkpoint;     ///< the last good state on a blow-up ("": csv + ".failed.ckpt")
  bool quiet = true;                 ///< no progress lines
  RebuildStats* stats = nullptr;     ///< if given, receives the neighbour list's rebuild statistics
};

/// Runs one stage on (model, state), writing its curve CSV to out.csv. Strains are measured
/// from the stage start. For every phi in spec.checkpoint_phis crossed, the step is shortened to
/// land on it exactly and on_checkpoint(phi, state) is called. Returns the number of steps taken.
/// The CSV's comment lines include `# physics: HASH key=value ...` (shear_physics for
/// deviatoric stages, preparation_physics otherwise; checks.hpp). Throws std::runtime_error
/// when a write fails (full disk: only the .part is left) and BlowUp after saving the last good
/// state as out.failed_checkpoint.
std::int64_t run_stage(const Model& model, State& state, const StageSpec& spec, const StageOutput& out,
                       const std::function<void(double, const State&)>& on_checkpoint = nullptr);

/// Runs the loading path `mode.path` (stages in order, strains accumulated from the path start)
/// from `state`, writing one curve to out.csv (rows of every stage, the stage's name in the
/// `stage` column; path_columns() after the usual columns). Relative targets (multiples of p0)
/// are resolved with p0 = the pressure at the path start. Each stage ends on its stop
/// condition; a stage whose stop has not come after a strain of 4 or a time of 4 / rate_max is
/// stopped with an error naming it. A path of one strain-controlled stage ending on eps_d gives
/// the rows of run_stage on the same mode bit for bit. Errors as run_stage.
std::int64_t run_path(const Model& model, State& state, const DeformationMode& mode, const std::string& label,
                      const StageOutput& out);

/// One mode or [paths] entry of the scene from `state` (modified in place): run_stage of
/// mode_stage, or run_path. What `dem mode`, `dem run`'s deviatoric stages and demtk.run_mode
/// run; `name` as in mode_stage.
std::int64_t run_mode(const Model& model, State& state, const DeformationMode& mode, const std::string& name,
                      const StageOutput& out);

/// Saves the state as checkpoint <series>_phiX.XXX (the caller's files, or a Python callback).
using SaveCheckpoint = std::function<void(const std::string& series, double phi, const State&)>;

/// Whether a compress or expand stage has nothing to do from volume fraction phi0: already at
/// or past its target (run_prep_stage skips it).
bool prep_stage_skipped(const PrepStage& stage, double phi0);

/// One preparation stage as `dem run` and demtk.run_prep_stage run it: compress or expand
/// (run_stage of volume_stage, saving the stage's checkpoints it passes, those at its start and
/// end included), relax (relax_stage), or, stress controlled (pressure, uniaxial), a one-stage
/// path whose servo rate limit is the stage's rate, then its checkpoint at the phi reached.
/// Returns the steps, or -1 when skipped (prep_stage_skipped; said on stderr, nothing written).
std::int64_t run_prep_stage(const Model& model, const PrepStage& stage, State& state, const StageOutput& out,
                            const SaveCheckpoint& save);

/// The columns a path curve has after curve_columns(): the applied box strain rate [1/s], the
/// servo's targets [Pa] (NaN where none), its relative error, and eps_d accumulated along the
/// path (sum of |d eps_d|: grows through a reversal, where eps_d itself dips to 0).
const std::vector<std::string>& path_columns();

}  // namespace dem
