// The time stepper: advances (Model, State) by one step, read as a list of named stages.
#pragma once
#include <chrono>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "dem/core/errors.hpp"
#include "dem/forces/forces.hpp"
#include "dem/engine/step_team.hpp"
#include "dem/core/model.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/core/state.hpp"

namespace dem {

/// What the neighbour list cost and why it was rebuilt (statistics only: nothing here feeds
/// back into the step, so the bits never depend on it, nor on the timing it records).
struct RebuildStats {
  std::int64_t steps = 0;            ///< steps taken
  std::int64_t rebuilds = 0;         ///< list builds in those steps (not the one at construction)
  std::int64_t displacement_triggers = 0;   ///< rebuilds because a particle moved half the skin
  /// Of those, diagnosed (the first 32, then every 8th: the diagnosis reads every contact):
  std::int64_t by_rattler = 0;       ///< the farthest-moved particle is a rattler
  std::int64_t by_packing = 0;       ///< it belongs to the load-bearing packing
  std::int64_t by_deformation = 0;   ///< the box's stretch alone used up the skin
  std::int64_t by_flip = 0;          ///< flips of the sheared cell
  double seconds = 0;                ///< wall time of the rebuilds (wrap, sort, pairs, blocks, records) [s]
  double diagnosis_seconds = 0;      ///< wall time of the trigger diagnosis (not in `seconds`) [s]
  /// Per displacement trigger: the largest displacement since the build among non-rattlers
  /// over the largest among all particles (1 when a non-rattler triggered).
  std::vector<float> nonrattler_ratio;
  /// What happened after `earlier` (a copy of these statistics taken before).
  RebuildStats since(const RebuildStats& earlier) const;
  /// Median of nonrattler_ratio (0 when empty).
  double median_nonrattler_ratio() const;
  /// One JSON object: these counts, the rebuilds per 10^4 steps, the skin [m] and the share of
  /// `wall_s` spent in rebuilds (the run summary of `dem mode` and `dem bench`).
  std::string json(double wall_s, double skin_m) const;
};

/// The angular half-kick w_i += t_i h/I_i, I_i = 2/5 m_i r_i^2, for particles [begin, end): four
/// at a time with AVX2 where the CPU has it and `vector`, else one by one; the same bits either
/// way (tests/cpp/test_friction.cpp).
void kick_angular(Vec3* w, const Vec3* t, const double* m, const double* r, int begin, int end, double h,
                  bool vector);

class Engine {
 public:
  /// Binds to a validated model and a state. The state must hold N >= 2 particles.
  /// If the state's neighbour-list reference is valid (e.g. loaded from a checkpoint) the
  /// same list is rebuilt from it, so the run continues bit for bit; otherwise a fresh list
  /// is built (particles are wrapped and cell-sorted). Forces are then evaluated at the
  /// current positions unless `forces_are_current` (checkpoint restart).
  Engine(const Model& model, State& state, bool forces_are_current = false);

  /// One time step of model.dt with the box true-strain rate `rate` [1/s] (diagonal):
  ///  1. kick       v += a*dt*F/m            (a = 1/2 Verlet, 1 symplectic Euler)
  ///  2. drift      x += dt*v                (fluctuation motion)
  ///  3. deform     L *= exp(rate*dt), x *= exp(rate*dt)   (affine motion of box and particles);
  ///                SLLOD (model.sllod): v *= exp(-rate*dt), the -E_dot v' term of the peculiar motion
  ///  4. neighbours rebuild the Verlet list if it may miss a contact
  ///  5. forces     contact law over the list, then background damping
  ///  6. kick       v += b*dt*F/m            (b = 1/2 Verlet, 0 symplectic Euler)
  ///  7. time, step counters; sanity checks every model.check_every_steps steps
  /// Stages 1-3 (with the displacement test of 4) run as one pass over the particles and
  /// 5-6 as another, to read each particle's data from memory once per pass; the arithmetic
  /// is exactly that of the list. With threads > 1 each thread runs the passes on its own
  /// block of particles (ForceScratch), with one barrier before and one after the pair loop.
  void step(const Vec3& rate) { step(VelGrad(rate)); }
  /// The same with a velocity gradient `rate` = L [1/s] (upper triangular): the cell H follows dH/dt = L H
  /// (H_new = exp(L dt) H, its diagonal from the accumulated log strain as above), particles
  /// the affine map A = H_new H_old^-1, and SLLOD's fluctuation velocities A^-1 v' (the
  /// exact solution of dv'/dt = -L v'). A tilt beyond half an edge is flipped to the most
  /// orthogonal cell (Box), which rebuilds the neighbour list in the same step. A diagonal L
  /// in an untilted box is exactly step(Vec3).
  void step(const VelGrad& rate);

  /// Runs the sanity checks now; throws BlowUp on failure. Called by step() every
  /// model.check_every_steps steps.
  void check_sanity() const;

  const NeighborList& neighbor_list() const { return list_; }
  /// Rebuild counts, triggers and their wall time since construction (statistics).
  const RebuildStats& rebuild_stats() const { return stats_; }
  /// The Verlet skin the list is built with [m].
  double skin() const { return skin_; }
  /// The pair loop's implementation (default: the fastest this CPU runs, best_pair_kernel()).
  /// Every kernel gives the same bits; the choice is for tests and benchmarks.
  void set_pair_kernel(PairKernel kernel) { scratch_.kernel = kernel; }
  PairKernel pair_kernel() const { return scratch_.kernel; }
  const Vec3& last_strain_rate() const { return rate_.diag; }
  const VelGrad& last_velocity_gradient() const { return rate_; }
  /// Cell flips so far (statistics; each rebuilt the list).
  long flips() const { return flips_; }
  int threads() const { return threads_; }
  /// Members that ran the last step (threads(), or 1 when the adaptive choice found one
  /// thread faster on a busy machine; the results are the same bits either way).
  int active_threads() const { return chooser_.members(); }

 private:
  /// The map particles follow in stage 3: diagonal `factor` (orthorhombic box), or the
  /// upper-triangular A (and A^-1 for SLLOD) stored as (xx, yy, zz, xy, xz, yz).
  struct AffineMap {
    Vec3 factor{1, 1, 1};
    bool general = false;
    double A[6] = {1, 1, 1, 0, 0, 0};
    double A_inv[6] = {1, 1, 1, 0, 0, 0};
  };
  // Stages, on particle ranges [begin, end) so that the threaded step runs them per block.
  AffineMap deform_box(const VelGrad& rate, bool* flipped);   // 3 (box): the map particles follow
  double advance_particles(int begin, int end, const AffineMap& map, bool affine,
                           const StalenessTest& test);   // 1-3, zeroes F; returns max |u|^2
  void rebuild_neighbors_if_stale(const StalenessTest& test, double max_displacement2);  // 4 on this thread
  static bool rebuild_due(const StalenessTest& test, double max_displacement2);
  void begin_rebuild(const StalenessTest& test, int chunks);   // 4: statistics, wrap, sort, cells
  void finish_rebuild();                                        // 4: join the searched rows, blocks, records
  void diagnose_trigger(const StalenessTest& test);      // 4, statistics: who crossed the half skin
  void finish_forces_and_kick(int begin, int end);       // 5 (damping) and 6
  void kick_rotations(int begin, int end, double h);     // 1 and 6 for angular velocities (friction)
  void evaluate_forces();                                // 5 on its own (construction)
  void step_serial(const AffineMap& map, bool affine, const StalenessTest& test);
  void step_threaded(const AffineMap& map, bool affine, const StalenessTest& test);

  const Model& model_;
  State& state_;
  NeighborList list_;
  ListRebuild rebuild_;              ///< the rebuild in progress (its pair search shared by the team)
  std::chrono::steady_clock::time_point rebuild_started_;   ///< statistics
  ForceScratch scratch_;
  std::unique_ptr<StepTeam> team_;   ///< the threads of step_threaded (threads_ > 1)
  TeamSizeChooser chooser_{1, false};   ///< team or this thread alone, step by step
  std::vector<double> worst_displacement2_;   // per thread
  VelGrad rate_;
  RebuildStats stats_;
  bool flipped_ = false;             ///< this step flipped the cell (statistics)
  long flips_ = 0;
  int threads_ = 1;
  int blocks_ = 1;                   ///< pair-loop blocks (block_count of the model's setting)
  double skin_ = 0;
  double kick_before_ = 0.5, kick_after_ = 0.5;
  bool sllod_ = true;
};

/// Number of OpenMP threads a model asks for (0 = all available).
int resolve_threads(int requested);

}  // namespace dem
