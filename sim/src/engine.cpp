#include "dem/engine.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace dem {

int resolve_threads(int requested) {
#ifdef _OPENMP
  return requested > 0 ? requested : omp_get_max_threads();
#else
  (void)requested;
  return 1;
#endif
}

Engine::Engine(const Model& model, State& state, bool forces_are_current)
    : model_(model), state_(state) {
  if (state.count() < 2) throw std::invalid_argument("Engine: the state holds fewer than 2 particles");
  threads_ = resolve_threads(model.threads);
  skin_ = model.skin_over_rmin * model.radius_min;
  if (model.integrator == Integrator::SymplecticEuler) { kick_before_ = 1.0; kick_after_ = 0.0; }
  if (state.list_valid && state.position_at_build.size() == state.position.size()) {
    restore_neighbor_list(state, list_, skin_);
  } else {
    rebuild_neighbor_list(state, list_, skin_, true);
  }
  if (!forces_are_current || state.force.size() != state.position.size()) evaluate_forces();
}

void Engine::kick(double fraction) {
  if (fraction == 0.0) return;
  const double h = fraction * model_.dt;
  const int n = state_.count();
  for (int i = 0; i < n; ++i) state_.velocity[i] += state_.force[i] * (h / state_.mass[i]);
}

void Engine::drift() {
  const double dt = model_.dt;
  const int n = state_.count();
  for (int i = 0; i < n; ++i) state_.position[i] += state_.velocity[i] * dt;
}

void Engine::deform_box(const Vec3& rate) {
  if (rate.x == 0 && rate.y == 0 && rate.z == 0) return;
  Box& b = state_.box;
  if (b.reference.x == 0) { b.reference = b.length; b.log_strain = Vec3(0, 0, 0); }
  b.log_strain += rate * model_.dt;
  const Vec3 next{b.reference.x * std::exp(b.log_strain.x), b.reference.y * std::exp(b.log_strain.y),
                  b.reference.z * std::exp(b.log_strain.z)};
  const Vec3 factor{next.x / b.length.x, next.y / b.length.y, next.z / b.length.z};
  b.length = next;
  for (auto& x : state_.position) x = hadamard(x, factor);
}

void Engine::update_neighbors() {
  if (neighbor_list_stale(state_, list_)) rebuild_neighbor_list(state_, list_, skin_, true);
}

void Engine::evaluate_forces() {
  compute_forces(model_, state_, list_, rate_, threads_, scratch_);
}

void Engine::step(const Vec3& strain_rate) {
  kick(kick_before_);
  drift();
  rate_ = strain_rate;
  deform_box(strain_rate);
  update_neighbors();
  evaluate_forces();
  kick(kick_after_);
  state_.time += model_.dt;
  ++state_.step;
  if (model_.check_every_steps > 0 && state_.step % model_.check_every_steps == 0) check_sanity();
}

void Engine::check_sanity() const {
  const State& s = state_;
  const int n = s.count();
  for (int i = 0; i < n; ++i) {
    const Vec3& x = s.position[i];
    const Vec3& v = s.velocity[i];
    if (!std::isfinite(x.x + x.y + x.z + v.x + v.y + v.z)) {
      std::ostringstream m;
      m << "non-finite position or velocity of particle " << s.id[i] << " at step " << s.step
        << ": the integration diverged; reduce integration.dt_over_tc (now "
        << model_.dt_over_tc << "; dense packings are stable up to about 0.5, docs/stability.md) or the strain rate";
      throw BlowUp(m.str());
    }
  }
  // Largest overlap relative to the smaller radius, over listed pairs.
  Vec3 off[27];
  image_offsets(s.box, off);
  double worst = 0;
  int wi = -1, wj = -1;
  for (int i = 0; i < n; ++i)
    for (int p = list_.first[i]; p < list_.first[i + 1]; ++p) {
      const int j = list_.partner[p];
      const Vec3 d = s.position[j] + off[list_.image[p]] - s.position[i];
      const double delta = s.radius[i] + s.radius[j] - norm(d);
      const double rel = delta / std::min(s.radius[i], s.radius[j]);
      if (rel > worst) { worst = rel; wi = i; wj = j; }
    }
  if (worst > model_.max_overlap_fraction) {
    std::ostringstream m;
    m << "overlap of " << worst << " x the smaller radius between particles " << s.id[wi]
      << " and " << s.id[wj] << " at step " << s.step << " (limit max_overlap_fraction = "
      << model_.max_overlap_fraction << "): the packing is compressed far beyond the contact "
      << "stiffness, or the time step (dt_over_tc = " << model_.dt_over_tc
      << ") or strain rate is too large (dense packings are stable up to dt_over_tc of about 0.5, "
      << "docs/stability.md)";
    throw BlowUp(m.str());
  }
}

}  // namespace dem
