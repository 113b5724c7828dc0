// The time stepper: advances (Model, State) by one step, read as a list of named stages.
#pragma once
#include <stdexcept>
#include <string>

#include "dem/forces.hpp"
#include "dem/model.hpp"
#include "dem/neighbor_list.hpp"
#include "dem/state.hpp"

namespace dem {

/// Thrown when a sanity check fails (non-finite values, overlap beyond the allowed fraction,
/// runaway kinetic energy). what() names the check, the particle, and the likely cause.
struct BlowUp : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Engine {
 public:
  /// Binds to a validated model and a state. The state must hold N >= 2 particles.
  /// If the state's neighbour-list reference is valid (e.g. loaded from a checkpoint) the
  /// same list is rebuilt from it, so the run continues bit for bit; otherwise a fresh list
  /// is built (particles are wrapped and cell-sorted). Forces are then evaluated at the
  /// current positions unless `forces_are_current` (checkpoint restart).
  Engine(const Model& model, State& state, bool forces_are_current = false);

  /// One time step of model.dt with the box true-strain rate `strain_rate` [1/s] (diagonal):
  ///  1. kick       v += a*dt*F/m            (a = 1/2 Verlet, 1 symplectic Euler)
  ///  2. drift      x += dt*v                (fluctuation motion)
  ///  3. deform     L *= exp(rate*dt), x *= exp(rate*dt)   (affine motion of box and particles)
  ///  4. neighbours rebuild the Verlet list if it may miss a contact
  ///  5. forces     contact law over the list, background damping
  ///  6. kick       v += b*dt*F/m            (b = 1/2 Verlet, 0 symplectic Euler)
  ///  7. time, step counters
  void step(const Vec3& strain_rate);

  /// Runs the sanity checks now; throws BlowUp on failure. Called by step() every
  /// model.check_every_steps steps.
  void check_sanity() const;

  const NeighborList& neighbor_list() const { return list_; }
  const Vec3& last_strain_rate() const { return rate_; }
  int threads() const { return threads_; }

 private:
  void kick(double fraction);
  void drift();
  void deform_box(const Vec3& rate);
  void update_neighbors();
  void evaluate_forces();

  const Model& model_;
  State& state_;
  NeighborList list_;
  ForceScratch scratch_;
  Vec3 rate_{0, 0, 0};
  int threads_ = 1;
  double skin_ = 0;
  double kick_before_ = 0.5, kick_after_ = 0.5;
};

/// Number of OpenMP threads a model asks for (0 = all available).
int resolve_threads(int requested);

}  // namespace dem
