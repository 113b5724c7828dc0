#include "dem/engine.hpp"
#include "dem/parallel.hpp"
#include "dem/step_team.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

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
  blocks_ = block_count(model.blocks, threads_);
  chooser_ = TeamSizeChooser(threads_, model.adaptive_threads);
  skin_ = model.skin_over_rmin * model.radius_min;
  if (model.integrator == Integrator::SymplecticEuler) { kick_before_ = 1.0; kick_after_ = 0.0; }
  sllod_ = model.sllod;
  if (state.list_valid && state.position_at_build.size() == state.position.size()) {
    restore_neighbor_list(state, list_, skin_);
  } else {
    rebuild_neighbor_list(state, list_, skin_, true);
  }
  if (!forces_are_current || state.force.size() != state.position.size()) evaluate_forces();
}

Vec3 Engine::deform_box(const Vec3& rate) {
  Box& b = state_.box;
  if (b.reference.x == 0) { b.reference = b.length; b.log_strain = Vec3(0, 0, 0); }
  b.log_strain += rate * model_.dt;
  const Vec3 next{b.reference.x * std::exp(b.log_strain.x), b.reference.y * std::exp(b.log_strain.y),
                  b.reference.z * std::exp(b.log_strain.z)};
  const Vec3 factor{next.x / b.length.x, next.y / b.length.y, next.z / b.length.z};
  b.length = next;
  return factor;
}

double Engine::advance_particles(int begin, int end, const Vec3& factor, bool affine,
                                 const StalenessTest& test) {
  const double h = kick_before_ * model_.dt, dt = model_.dt;
  const Vec3 shrink{1.0 / factor.x, 1.0 / factor.y, 1.0 / factor.z};
  Vec3* x = state_.position.data();
  Vec3* v = state_.velocity.data();
  Vec3* f = state_.force.data();
  const double* m = state_.mass.data();
  double worst = 0;
  for (int i = begin; i < end; ++i) {
    v[i] += f[i] * (h / m[i]);                     // 1. kick
    x[i] += v[i] * dt;                             // 2. drift
    if (affine) {
      x[i] = hadamard(x[i], factor);               // 3. affine motion
      if (sllod_) v[i] = hadamard(v[i], shrink);   //    SLLOD: v' *= exp(-rate dt)
    }
    f[i] = Vec3{0, 0, 0};                          //    (forces are summed afresh in 5)
    if (test.limit2 >= 0) worst = std::max(worst, displacement2_since_build(state_, test, i));
  }
  return worst;
}

void Engine::rebuild_neighbors_if_stale(const StalenessTest& test, double max_displacement2) {
  if (test.limit2 < 0 || max_displacement2 >= test.limit2)
    rebuild_neighbor_list(state_, list_, skin_, true);
}

void Engine::finish_forces_and_kick(int begin, int end) {
  const double gb = model_.background_damping;
  const double h = kick_after_ * model_.dt;
  Vec3* v = state_.velocity.data();
  Vec3* f = state_.force.data();
  const double* m = state_.mass.data();
  for (int i = begin; i < end; ++i) {
    if (gb != 0.0) f[i] -= v[i] * gb;              // 5. background damping
    if (h != 0.0) v[i] += f[i] * (h / m[i]);       // 6. kick
  }
}

void Engine::evaluate_forces() {
  compute_forces(model_, state_, list_, rate_, threads_, blocks_, scratch_);
}

void Engine::step(const Vec3& strain_rate) {
  rate_ = strain_rate;
  const bool affine = !(strain_rate.x == 0 && strain_rate.y == 0 && strain_rate.z == 0);
  const Vec3 factor = affine ? deform_box(strain_rate) : Vec3{1, 1, 1};
  const StalenessTest test = staleness_test(state_, list_);   // box of this step, list of the last
  if (threads_ <= 1 && blocks_ <= 1) step_serial(factor, affine, test);
  else step_threaded(factor, affine, test);
  chooser_.step_done();
  state_.time += model_.dt;
  ++state_.step;
  if (model_.check_every_steps > 0 && state_.step % model_.check_every_steps == 0) check_sanity();
}

void Engine::step_serial(const Vec3& factor, bool affine, const StalenessTest& test) {
  const int n = state_.count();
  const double worst = advance_particles(0, n, factor, affine, test);
  rebuild_neighbors_if_stale(test, worst);
  partition_pairs(list_, 1, scratch_);
  accumulate_pair_forces(model_, state_, list_, rate_, 0, scratch_, state_.force.data());
  finish_forces_and_kick(0, n);
}

void Engine::step_threaded(const Vec3& factor, bool affine, const StalenessTest& test) {
  partition_pairs(list_, blocks_, scratch_);
  const int nt = chooser_.members();
  worst_displacement2_.assign(nt, 0.0);
  auto sync = [&] { if (nt > 1) team_->barrier(); };
  auto body = [&](int t) {
    // 1-3 on the blocks of the current list (any split would do: particles are independent).
    double worst = 0;
    for (int b = t; b < scratch_.blocks(); b += nt)
      worst = std::max(worst, advance_particles(scratch_.bounds[b], scratch_.bounds[b + 1],
                                                factor, affine, test));
    worst_displacement2_[t] = worst;
    sync();
    if (t == 0) {
      double all = 0;
      for (double w : worst_displacement2_) all = std::max(all, w);
      rebuild_neighbors_if_stale(test, all);
      partition_pairs(list_, blocks_, scratch_);
    }
    sync();
    // 5: own pairs, then (after every block has queued its spills) the spills, then 6. Each
    // block's arithmetic is the same whichever member runs it: the bits do not depend on nt.
    Vec3* f = state_.force.data();
    for (int b = t; b < scratch_.blocks(); b += nt)
      accumulate_pair_forces(model_, state_, list_, rate_, b, scratch_, f);
    sync();
    for (int b = t; b < scratch_.blocks(); b += nt) {
      apply_spilled_forces(b, scratch_, f);
      finish_forces_and_kick(scratch_.bounds[b], scratch_.bounds[b + 1]);
    }
  };
  if (nt == 1) { body(0); return; }
  if (!team_ || team_->size() != nt) team_ = std::make_unique<StepTeam>(nt);
  team_->run(body);
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
        << ": the integration diverged. The packing passed its checks at start (radii within the scene's bounds, "
        << "no coincident centres, overlaps below max_overlap_fraction), so the time step or the rate is too large: "
        << "reduce integration.dt_over_tc (now " << model_.dt_over_tc
        << "; dense packings are stable up to about 0.5, docs/stability.md) or the strain rate";
      throw BlowUp(m.str());
    }
  }
  // Largest overlap relative to the smaller radius, over listed pairs.
  double worst = 0;
  int wi = -1, wj = -1;
  for_each_contact(s, list_, [&](int i, int j, const Vec3&, double, double delta) {
    const double rel = delta / std::min(s.radius[i], s.radius[j]);
    if (rel > worst) { worst = rel; wi = i; wj = j; }
  });
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
