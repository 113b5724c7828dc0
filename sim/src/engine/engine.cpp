#include "dem/engine/engine.hpp"
#include "dem/engine/interrupt.hpp"
#include "dem/core/parallel.hpp"
#include "dem/engine/step_team.hpp"

#include "dem/measure/measure.hpp"

#include <immintrin.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
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
  contact::prepare_state(model.contact, state);   // rotations and history only if the model needs them
  if (state.list_valid && state.position_at_build.size() == state.position.size()) {
    restore_neighbor_list(state, list_, skin_);
    place_history(state, list_);   // a checkpoint's records, keyed by ids, into this list's order
  } else {
    rebuild_neighbor_list(state, list_, skin_, true);
  }
  partition_pairs(list_, blocks_, scratch_);
  pack_particles(state_, 0, state_.count(), scratch_);
  if (!forces_are_current || state.force.size() != state.position.size()) evaluate_forces();
}

namespace {

using M3 = double[3][3];

void mat_mul(const M3 a, const M3 b, M3 out) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double v = 0;
      for (int k = 0; k < 3; ++k) v += a[i][k] * b[k][j];
      out[i][j] = v;
    }
}

// exp(T) of an upper-triangular T with a small norm (L dt): Taylor series to 12 terms, exact to
// round-off for |T| < 0.5 (a nilpotent T, simple shear, ends after its first power anyway).
void small_exp(const M3 T, M3 out) {
  M3 term = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out[i][j] = term[i][j];
  for (int k = 1; k <= 12; ++k) {
    M3 next;
    mat_mul(term, T, next);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) { term[i][j] = next[i][j] / k; out[i][j] += term[i][j]; }
  }
}

// The inverse of the upper-triangular [[a, d, e], [0, b, f], [0, 0, c]].
void upper_inverse(const M3 H, M3 out) {
  const double a = H[0][0], b = H[1][1], c = H[2][2], d = H[0][1], e = H[0][2], f = H[1][2];
  const double inv[3][3] = {{1 / a, -d / (a * b), (d * f - b * e) / (a * b * c)}, {0, 1 / b, -f / (b * c)}, {0, 0, 1 / c}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out[i][j] = inv[i][j];
}

void to_upper6(const M3 m, double* u) {
  u[0] = m[0][0]; u[1] = m[1][1]; u[2] = m[2][2]; u[3] = m[0][1]; u[4] = m[0][2]; u[5] = m[1][2];
}

}  // namespace

Engine::AffineMap Engine::deform_box(const VelGrad& rate, bool* flipped) {
  Box& b = state_.box;
  *flipped = false;
  if (b.reference.x == 0) { b.reference = b.length; b.log_strain = Vec3(0, 0, 0); }
  const Vec3 old_length = b.length, old_tilt = b.tilt;
  b.log_strain += rate.diag * model_.dt;
  const Vec3 next{b.reference.x * std::exp(b.log_strain.x), b.reference.y * std::exp(b.log_strain.y),
                  b.reference.z * std::exp(b.log_strain.z)};
  AffineMap map;
  map.factor = Vec3{next.x / b.length.x, next.y / b.length.y, next.z / b.length.z};
  b.length = next;
  if (!rate.sheared() && !b.tilted()) return map;   // the orthorhombic box of the diagonal modes
  // Tilted cell: H_new = exp(L dt) H_old off the diagonal (the diagonal from the log strain).
  const double dt = model_.dt;
  const M3 T = {{rate.diag.x * dt, rate.shear.x * dt, rate.shear.y * dt},
                {0, rate.diag.y * dt, rate.shear.z * dt},
                {0, 0, rate.diag.z * dt}};
  M3 phi;
  small_exp(T, phi);
  const M3 H_old = {{old_length.x, old_tilt.x, old_tilt.y}, {0, old_length.y, old_tilt.z}, {0, 0, old_length.z}};
  M3 H_grown;
  mat_mul(phi, H_old, H_grown);
  b.tilt = Vec3{H_grown[0][1], H_grown[0][2], H_grown[1][2]};
  const M3 H_new = {{next.x, b.tilt.x, b.tilt.y}, {0, next.y, b.tilt.z}, {0, 0, next.z}};
  M3 inv_old, inv_new, A, A_inv;
  upper_inverse(H_old, inv_old);
  upper_inverse(H_new, inv_new);
  mat_mul(H_new, inv_old, A);       // particles keep their fractional coordinates
  mat_mul(H_old, inv_new, A_inv);   // SLLOD: v' <- exp(-L dt) v'
  map.general = true;
  to_upper6(A, map.A);
  to_upper6(A_inv, map.A_inv);
  // Flip to the most orthogonal equivalent cell: c - k b, c - k a, b - k a (the same lattice).
  // M (H = H_unflipped M) follows each flip, so the deformation gradient stays continuous.
  if (std::fabs(b.tilt.z) > 0.5 * b.length.y) {
    const double k = std::round(b.tilt.z / b.length.y);
    b.tilt.z -= k * b.length.y;
    b.tilt.y -= k * b.tilt.x;
    b.flips[1] -= static_cast<std::int32_t>(k) * b.flips[0];
    b.flips[2] -= static_cast<std::int32_t>(k);
    *flipped = true;
  }
  if (std::fabs(b.tilt.y) > 0.5 * b.length.x) {
    const double k = std::round(b.tilt.y / b.length.x);
    b.tilt.y -= k * b.length.x;
    b.flips[1] -= static_cast<std::int32_t>(k);
    *flipped = true;
  }
  if (std::fabs(b.tilt.x) > 0.5 * b.length.x) {
    const double k = std::round(b.tilt.x / b.length.x);
    b.tilt.x -= k * b.length.x;
    b.flips[0] -= static_cast<std::int32_t>(k);
    *flipped = true;
  }
  return map;
}

double Engine::advance_particles(int begin, int end, const AffineMap& map, bool affine,
                                 const StalenessTest& test) {
  const double h = kick_before_ * model_.dt, dt = model_.dt;
  const Vec3& factor = map.factor;
  const Vec3 shrink{1.0 / factor.x, 1.0 / factor.y, 1.0 / factor.z};
  Vec3* x = state_.position.data();
  Vec3* v = state_.velocity.data();
  Vec3* f = state_.force.data();
  const double* m = state_.mass.data();
  double* packed = scratch_.packed.size() == 8 * static_cast<std::size_t>(state_.count()) ? scratch_.packed.data()
                                                                                          : nullptr;
  const double* rad = state_.radius.data();
  double worst = 0;
  if (state_.rotations()) kick_rotations(begin, end, h);   // 1. kick (angular velocities)
  for (int i = begin; i < end; ++i) {
    v[i] += f[i] * (h / m[i]);                     // 1. kick
    x[i] += v[i] * dt;                             // 2. drift
    if (affine) {
      if (map.general) {                           // 3. affine motion (tilted cell)
        x[i] = upper_apply(map.A, x[i]);
        if (sllod_) v[i] = upper_apply(map.A_inv, v[i]);
      } else {
        x[i] = hadamard(x[i], factor);             // 3. affine motion
        if (sllod_) v[i] = hadamard(v[i], shrink); //    SLLOD: v' *= exp(-rate dt)
      }
    }
    f[i] = Vec3{0, 0, 0};                          //    (forces are summed afresh in 5)
    if (test.limit2 >= 0) worst = std::max(worst, displacement2_since_build(state_, test, i));
    if (packed) pack_particle(x[i], rad[i], v[i], m[i], packed + 8L * i);   // the pair kernels' records
  }
  return worst;
}

bool Engine::rebuild_due(const StalenessTest& test, double max_displacement2) {
  return test.limit2 < 0 || max_displacement2 >= test.limit2;
}

void Engine::begin_rebuild(const StalenessTest& test, int chunks) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  if (flipped_) ++stats_.by_flip;
  else if (test.limit2 < 0) ++stats_.by_deformation;
  else if (stats_.displacement_triggers++ < 32 || stats_.displacement_triggers % 8 == 0) diagnose_trigger(test);
  rebuild_started_ = Clock::now();
  stats_.diagnosis_seconds += std::chrono::duration<double>(rebuild_started_ - t0).count();
  rebuild_.begin(state_, list_, skin_, true, chunks);   // sorts the particles: repacked in finish_rebuild
}

void Engine::finish_rebuild() {
  rebuild_.finish();
  partition_pairs(list_, std::max(1, blocks_), scratch_);
  pack_particles(state_, 0, state_.count(), scratch_);
  ++stats_.rebuilds;
  stats_.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - rebuild_started_).count();
}

void Engine::rebuild_neighbors_if_stale(const StalenessTest& test, double max_displacement2) {
  if (!rebuild_due(test, max_displacement2)) return;
  begin_rebuild(test, 1);
  rebuild_.search(0);
  finish_rebuild();
}

// Which particle crossed the half skin: a rattler (measure()'s rule, on the contacts of the
// list about to be replaced) or one of the load-bearing packing, and how far the packing
// itself moved. Reads the state only.
void Engine::diagnose_trigger(const StalenessTest& test) {
  const int n = state_.count();
  std::vector<std::pair<int, int>> contacts;
  contacts.reserve(list_.pair_count());
  for_each_contact(state_, list_, [&](int i, int j, const Vec3&, double, double) { contacts.emplace_back(i, j); });
  const std::vector<char> rattler = rattler_flags(n, contacts);
  double all = -1, packing = 0;
  int farthest = 0;
  for (int i = 0; i < n; ++i) {
    const double u2 = displacement2_since_build(state_, test, i);
    if (u2 > all) { all = u2; farthest = i; }
    if (!rattler[i]) packing = std::max(packing, u2);
  }
  ++(rattler[farthest] ? stats_.by_rattler : stats_.by_packing);
  stats_.nonrattler_ratio.push_back(all > 0 ? static_cast<float>(std::sqrt(packing / all)) : 1.0f);
}

RebuildStats RebuildStats::since(const RebuildStats& e) const {
  RebuildStats d = *this;
  d.steps -= e.steps; d.rebuilds -= e.rebuilds; d.by_rattler -= e.by_rattler; d.by_packing -= e.by_packing;
  d.by_deformation -= e.by_deformation; d.by_flip -= e.by_flip;
  d.displacement_triggers -= e.displacement_triggers;
  d.seconds -= e.seconds; d.diagnosis_seconds -= e.diagnosis_seconds;
  const std::size_t k = std::min(e.nonrattler_ratio.size(), d.nonrattler_ratio.size());
  d.nonrattler_ratio.erase(d.nonrattler_ratio.begin(), d.nonrattler_ratio.begin() + static_cast<long>(k));
  return d;
}

double RebuildStats::median_nonrattler_ratio() const {
  if (nonrattler_ratio.empty()) return 0;
  std::vector<float> v = nonrattler_ratio;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

std::string RebuildStats::json(double wall_s, double skin_m) const {
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "{\"steps\": %lld, \"rebuilds\": %lld, \"rebuilds_per_1e4_steps\": %.4g, \"skin_m\": %.6g, "
                "\"rebuild_s\": %.4g, \"rebuild_share\": %.4g, \"trigger_rattler\": %lld, \"trigger_packing\": %lld, "
                "\"trigger_displacement\": %lld, \"trigger_deformation\": %lld, \"trigger_flip\": %lld, "
                "\"packing_over_max_displacement_median\": %.4g, "
                "\"diagnosis_s\": %.4g}",
                static_cast<long long>(steps), static_cast<long long>(rebuilds),
                steps > 0 ? 1e4 * static_cast<double>(rebuilds) / static_cast<double>(steps) : 0.0, skin_m, seconds,
                wall_s > 0 ? seconds / wall_s : 0.0, static_cast<long long>(by_rattler),
                static_cast<long long>(by_packing), static_cast<long long>(displacement_triggers),
                static_cast<long long>(by_deformation),
                static_cast<long long>(by_flip), median_nonrattler_ratio(), diagnosis_seconds);
  return buf;
}

namespace {

// Four particles at a time (AVX2): the scalar loop's operations on each component, so the same
// bits. The 12 doubles of four Vec3 are three vectors; the four factors h/I are spread over them
// as (c0 c0 c0 c1) (c1 c1 c2 c2) (c2 c3 c3 c3). Returns where the scalar loop takes over.
static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3: three packed doubles");
__attribute__((target("avx2"))) int kick_angular_avx2(Vec3* w, const Vec3* t, const double* m, const double* r,
                                                      int begin, int end, double h) {
  const __m256d hv = _mm256_set1_pd(h), two_fifths = _mm256_set1_pd(0.4);
  int i = begin;
  for (; i + 4 <= end; i += 4) {
    const __m256d rr = _mm256_loadu_pd(r + i);
    const __m256d inertia = _mm256_mul_pd(_mm256_mul_pd(_mm256_mul_pd(two_fifths, _mm256_loadu_pd(m + i)), rr), rr);
    const __m256d c = _mm256_div_pd(hv, inertia);
    const __m256d spread[3] = {_mm256_permute4x64_pd(c, 0x40), _mm256_permute4x64_pd(c, 0xA5),
                               _mm256_permute4x64_pd(c, 0xFE)};
    double* wd = &w[i].x;
    const double* td = &t[i].x;
    for (int k = 0; k < 3; ++k)
      _mm256_storeu_pd(wd + 4 * k,
                       _mm256_add_pd(_mm256_loadu_pd(wd + 4 * k), _mm256_mul_pd(_mm256_loadu_pd(td + 4 * k), spread[k])));
  }
  return i;
}

}  // namespace

void kick_angular(Vec3* w, const Vec3* t, const double* m, const double* r, int begin, int end, double h,
                  bool vector) {
  int i = begin;
  if (vector && __builtin_cpu_supports("avx2")) i = kick_angular_avx2(w, t, m, r, begin, end, h);
  for (; i < end; ++i) w[i] += t[i] * (h / (0.4 * m[i] * r[i] * r[i]));   // I = 2/5 m r^2
}

void Engine::kick_rotations(int begin, int end, double h) {
  if (h == 0.0) return;
  kick_angular(state_.angular_velocity.data(), state_.torque.data(), state_.mass.data(), state_.radius.data(), begin,
               end, h, true);
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
  if (state_.rotations()) kick_rotations(begin, end, h);
}

void Engine::evaluate_forces() {
  if (!state_.rotations()) {
    compute_forces(model_, state_, list_, rate_, threads_, blocks_, scratch_);
    return;
  }
  // The forces of the state as it is: the stored springs, not advanced (no time passes here;
  // the pair loop would add v_t dt), and no energy dissipated.
  Model at_rest = model_;
  at_rest.dt = 0.0;
  const std::vector<double> springs = state_.history.values;
  const double dissipated = state_.friction_dissipated;
  compute_forces(at_rest, state_, list_, rate_, threads_, blocks_, scratch_);
  state_.history.values = springs;
  state_.friction_dissipated = dissipated;
}

void Engine::step(const VelGrad& rate) {
  poll_interrupt();   // before anything changes: an interrupt leaves the last full step
  rate_ = rate;
  const bool affine = !rate.zero();
  bool flipped = false;
  const AffineMap map = affine ? deform_box(rate, &flipped) : AffineMap{};
  StalenessTest test = staleness_test(state_, list_);   // box of this step, list of the last
  if (flipped) { test.limit2 = -1; ++flips_; }        // new lattice vectors: rebuild
  flipped_ = flipped;
  if (threads_ <= 1 && blocks_ <= 1) step_serial(map, affine, test);
  else step_threaded(map, affine, test);
  end_pair_loop(state_, scratch_);   // the blocks' dissipation, in block order
  chooser_.step_done();
  ++stats_.steps;
  state_.time += model_.dt;
  ++state_.step;
  if (model_.check_every_steps > 0 && state_.step % model_.check_every_steps == 0) check_sanity();
}

void Engine::step_serial(const AffineMap& map, bool affine, const StalenessTest& test) {
  const int n = state_.count();
  const double worst = advance_particles(0, n, map, affine, test);
  rebuild_neighbors_if_stale(test, worst);
  partition_pairs(list_, 1, scratch_);
  begin_pair_loop(model_, state_, list_, scratch_);
  accumulate_pair_forces(model_, state_, list_, rate_, 0, scratch_, state_.force.data());
  finish_forces_and_kick(0, n);
}

void Engine::step_threaded(const AffineMap& map, bool affine, const StalenessTest& test) {
  partition_pairs(list_, blocks_, scratch_);
  const int nt = chooser_.members();
  worst_displacement2_.assign(nt, 0.0);
  auto sync = [&] { if (nt > 1) team_->barrier(); };
  auto body = [&](int t) {
    // 1-3 on the blocks of the current list (any split would do: particles are independent).
    double worst = 0;
    for (int b = t; b < scratch_.blocks(); b += nt)
      worst = std::max(worst, advance_particles(scratch_.bounds[b], scratch_.bounds[b + 1],
                                                map, affine, test));
    worst_displacement2_[t] = worst;
    sync();
    double all = 0;   // every member reads the same maxima: the same decision
    for (double w : worst_displacement2_) all = std::max(all, w);
    if (rebuild_due(test, all)) {   // 4, the pair search shared by the team (the same list for any nt)
      if (t == 0) begin_rebuild(test, nt);
      sync();
      for (int c = t; c < rebuild_.chunks(); c += nt) rebuild_.search(c);
      sync();
      if (t == 0) finish_rebuild();
    }
    if (t == 0) {
      partition_pairs(list_, blocks_, scratch_);
      begin_pair_loop(model_, state_, list_, scratch_);
    }
    sync();
    // 5: own pairs, then (after every block has queued its spills) the spills, then 6. Each
    // block's arithmetic is the same whichever member runs it: the bits do not depend on nt.
    Vec3* f = state_.force.data();
    for (int b = t; b < scratch_.blocks(); b += nt)
      accumulate_pair_forces(model_, state_, list_, rate_, b, scratch_, f);
    sync();
    for (int b = t; b < scratch_.blocks(); b += nt) {
      apply_spilled_forces(b, scratch_, f, state_.rotations() ? state_.torque.data() : nullptr);
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
  for (int i = 0; i < static_cast<int>(s.angular_velocity.size()); ++i) {
    const Vec3& w = s.angular_velocity[i];
    if (!std::isfinite(w.x + w.y + w.z)) {
      std::ostringstream m;
      m << "non-finite angular velocity of particle " << s.id[i] << " at step " << s.step
        << ": the rotations diverged; a tangential, rolling or twisting spring may be too stiff for the time step "
           "(`dem info` lists each sub-model's stability limit at this dt; keep the stiffness ratios near 2/7, or "
           "reduce integration.dt_over_tc = " << model_.dt_over_tc << ")";
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
