// Lanes of 4 and 8 doubles (history_kernels.hpp) pass between always-inline functions only: no
// ABI is crossed.
#pragma GCC diagnostic ignored "-Wpsabi"
#include "dem/forces/forces.hpp"
#include "dem/core/parallel.hpp"
#include "forces/history_kernels.hpp"
#include "forces/pair_kernels.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

namespace dem {

namespace {

using contact::NormalGeometry;
using contact::Separation;

// One pair of a model without history: the contact force on j [N] (minus it on i); false if the
// spheres do not touch. The arithmetic is the contact model's body (T = double), the one the
// vector kernels run on lanes of pairs.
template <bool Sheared, class CM>
inline bool contact_force(const CM& cm, const Vec3& xi, const Vec3& xj_image, const Vec3& vi,
                          const Vec3& vj, double ri, double rj, const VelGrad& rate, Vec3& f_on_j) {
  const Separation<double> sep = contact::separation(xi.x, xi.y, xi.z, ri, xj_image.x, xj_image.y, xj_image.z, rj);
  if (!contact::touching(sep)) return false;
  double vx, vy, vz;
  contact::relative_velocity<Sheared>(sep, vj.x - vi.x, vj.y - vi.y, vj.z - vi.z, contact::rate_lanes<double>(rate), vx, vy, vz);
  const NormalGeometry<double> g = contact::normal_geometry(sep, vx, vy, vz);
  const double fn = cm.normal_force(g);
  f_on_j = Vec3{g.nx, g.ny, g.nz} * fn;
  return true;
}

// Where a rotating model's pair sends its force and torques.
struct PairSums {
  Vec3 fj, ti, tj;   // force on j [N], torques on i and j [N m]
};

// One pair of a model with history (friction): force on j, torques, and the history advanced
// by one step of dt; false (history zeroed) if the spheres do not touch. The arithmetic is the
// contact model's body (T = double), the one the vector kernels run on lanes of pairs; the
// pair's dissipation is summed over its sliders first, then added to `dissipated`, as the
// kernels' adding pass does.
template <bool Sheared, class CM>
inline bool contact_force_history(const CM& cm, const Vec3& xi, const Vec3& xj_image, const Vec3& vi,
                                  const Vec3& vj, const Vec3& wi, const Vec3& wj, double ri, double rj, double mi,
                                  double mj, const VelGrad& rate, double dt, double* h, double* dissipated,
                                  PairSums& out) {
  const Separation<double> sep = contact::separation(xi.x, xi.y, xi.z, ri, xj_image.x, xj_image.y, xj_image.z, rj);
  if (!contact::touching(sep)) {
    for (int k = 0; k < CM::history; ++k) h[k] = 0.0;   // the contact ended: its springs with it
    return false;
  }
  const contact::PairForces<double> c =
      cm.template advance<Sheared>(sep, ri, rj, mi, mj, vj.x - vi.x, vj.y - vi.y, vj.z - vi.z, contact::v3(wi),
                                   contact::v3(wj), contact::rate_lanes<double>(rate), dt, h);
  out.fj = contact::vec3(c.fj);
  out.ti = contact::vec3(c.ti);
  out.tj = contact::vec3(c.tj);
  *dissipated += c.dissipated;
  return true;
}

// The reference pair loop (the simple form of the kernels below, PairKernel::reference):
// pairs of particles [begin, end), forces on j >= end go to spill[block_of[j]].
template <bool Sheared, class CM>
void pair_loop_reference(const CM& cm, const State& s, const NeighborList& list, const VelGrad& rate,
                         int begin, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                         const std::uint16_t* block_of) {
  Vec3 off[27];
  image_offsets(s.box, off);
  const Vec3* x = s.position.data();
  const Vec3* v = s.velocity.data();
  const double* rad = s.radius.data();
  const std::int32_t* first = list.first.data();
  const std::int32_t* partner = list.partner.data();
  const std::uint8_t* image = list.image.data();
  for (int i = begin; i < end; ++i) {
    Vec3 fi{0, 0, 0};
    const Vec3 xi = x[i], vi = v[i];
    const double ri = rad[i];
    for (int p = first[i]; p < first[i + 1]; ++p) {
      const int j = partner[p];
      Vec3 fj;
      if (!contact_force<Sheared>(cm, xi, x[j] + off[image[p]], vi, v[j], ri, rad[j], rate, fj)) continue;
      if (j < end) f[j] += fj; else spill[block_of[j]].push_back({j, fj});
      fi -= fj;
    }
    f[i] += fi;
  }
}

// The pair loop of a model with history (scalar; friction): forces and torques, spilled like
// the forces, history advanced in place (each pair belongs to one block: no races).
template <bool Sheared, class CM>
void pair_loop_history(const CM& cm, State& s, const NeighborList& list, const VelGrad& rate, double dt,
                       int begin, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                       std::vector<std::vector<SpilledForce>>& spill_torque, const std::uint16_t* block_of,
                       double* dissipated) {
  Vec3 off[27];
  image_offsets(s.box, off);
  const Vec3* x = s.position.data();
  const Vec3* v = s.velocity.data();
  static const Vec3 kNoSpin{0, 0, 0};
  const bool spin = CM::rotations;
  const Vec3* w = s.angular_velocity.data();
  Vec3* tq = s.torque.data();
  const double* rad = s.radius.data();
  const double* mass = s.mass.data();
  double* H = s.history.values.data();
  constexpr int kw = CM::history;
  for (int i = begin; i < end; ++i) {
    Vec3 fi{0, 0, 0}, ti{0, 0, 0};
    for (int p = list.first[i]; p < list.first[i + 1]; ++p) {
      const int j = list.partner[p];
      PairSums c;
      if (!contact_force_history<Sheared>(cm, x[i], x[j] + off[list.image[p]], v[i], v[j], spin ? w[i] : kNoSpin,
                                          spin ? w[j] : kNoSpin, rad[i], rad[j], mass[i], mass[j], rate, dt,
                                          H + static_cast<long>(kw) * p, dissipated, c))
        continue;
      if (j < end) {
        f[j] += c.fj;
        if (spin) tq[j] += c.tj;
      } else {
        spill[block_of[j]].push_back({j, c.fj});
        if (spin) spill_torque[block_of[j]].push_back({j, c.tj});
      }
      fi -= c.fj;
      ti += c.ti;
    }
    f[i] += fi;
    if (spin) tq[i] += ti;
  }
}

// Appends a spilled force field by field (a SpilledForce built on the stack and copied made
// the store-to-load forwarding fail: a quarter of the adding pass's time in a profile).
inline void queue_spill(std::vector<SpilledForce>& to, int j, const Vec3& f) {
  to.emplace_back();
  SpilledForce& s = to.back();
  s.j = j;
  s.f = f;
}

// Whether a force is not zero (+-0 in every component: adding it changes nothing), as
// `x != 0 || y != 0 || z != 0` (a NaN counts as not zero), from the bits without the sign: GCC
// compiles the comparisons to three ucomisd/setp/cmovne triples.
inline bool nonzero(double x, double y, double z) {
  std::uint64_t a, b, c;
  std::memcpy(&a, &x, 8);
  std::memcpy(&b, &y, 8);
  std::memcpy(&c, &z, 8);
  return ((a | b | c) << 1) != 0;
}

// Pass 2 of a chunk: the forces in list order, as pair_loop_reference adds them. `fi` and
// `current` carry the running sum of the pairs of particle `current` across chunks. The pairs
// whose j another block owns are queued after the loop, in list order (as add_history_chunk:
// with the queueing in the loop GCC keeps each pair's force in memory).
inline void add_chunk(const std::int32_t* pi, const std::int32_t* pj, int n, const double* fx, const double* fy,
                      const double* fz, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                      const std::uint16_t* block_of, int& current_sum, Vec3& fi_sum) {
  int current = current_sum;
  Vec3 fi = fi_sum;
  int spilled[kernels::kChunk], count = 0;
  for (int q = 0; q < n; ++q) {
    const int i = pi[q], j = pj[q];
    if (i != current) {   // f[i] += 0 (a particle without pairs) would change nothing: skipped
      f[current] += fi;
      fi = Vec3{0, 0, 0};
      current = i;
    }
    const Vec3 fj{fx[q], fy[q], fz[q]};
    if (j < end) f[j] += fj;
    else spilled[count++] = q;
    fi -= fj;
  }
  current_sum = current;
  fi_sum = fi;
  for (int k = 0; k < count; ++k) {
    const int q = spilled[k], j = pj[q];
    if (nonzero(fx[q], fy[q], fz[q])) queue_spill(spill[block_of[j]], j, Vec3{fx[q], fy[q], fz[q]});   // +-0: no-op
  }
}

template <bool Sheared>
void pair_loop_vector(PairKernel kernel, const ContactLaw& law, const State& s, const NeighborList& list,
                      const double* packed, const std::int32_t* pair_i, const VelGrad& rate, int begin, int end, Vec3* f,
                      std::vector<std::vector<SpilledForce>>& spill, const std::uint16_t* block_of) {
  Vec3 off3[27];
  image_offsets(s.box, off3);
  alignas(64) double off[27 * 4];
  for (int c = 0; c < 27; ++c) {
    off[4 * c] = off3[c].x; off[4 * c + 1] = off3[c].y; off[4 * c + 2] = off3[c].z; off[4 * c + 3] = 0.0;
  }
  const long p_begin = list.first[begin], p_end = list.first[end];
  const kernels::KernelInputs in{packed, pair_i, list.partner.data(), list.image.data(), off,
                                 contact::frictionless(law), rate, f, p_end};
  const kernels::KernelFn run = kernels::kernel_of(kernel, Sheared);
  constexpr int kChunk = kernels::kChunk;
  alignas(64) double fx[kChunk], fy[kChunk], fz[kChunk];
  int current = p_begin < p_end ? pair_i[p_begin] : begin;
  Vec3 fi{0, 0, 0};
  for (long p0 = p_begin; p0 < p_end; p0 += kChunk) {
    const int n = static_cast<int>(std::min<long>(kChunk, p_end - p0));
    run(in, p0, n, fx, fy, fz);
    add_chunk(pair_i + p0, list.partner.data() + p0, n, fx, fy, fz, end, f, spill, block_of, current, fi);
  }
  if (p_begin < p_end) f[current] += fi;
}

// The forces and torques on j of the chunk's pairs `spilled` (j a particle of another block),
// queued for its owner in list order (nonzero ones only: +-0 is a no-op).
template <bool Spin>
void spill_pairs(const std::int32_t* pj, const kernels::HistoryChunk& c, const int* spilled, int count,
                 std::vector<std::vector<SpilledForce>>& spill, std::vector<std::vector<SpilledForce>>& spill_torque,
                 const std::uint16_t* block_of) {
  for (int k = 0; k < count; ++k) {
    const int q = spilled[k], j = pj[q];
    if (nonzero(c.fx[q], c.fy[q], c.fz[q])) queue_spill(spill[block_of[j]], j, Vec3{c.fx[q], c.fy[q], c.fz[q]});
    if (Spin && nonzero(c.tjx[q], c.tjy[q], c.tjz[q]))
      queue_spill(spill_torque[block_of[j]], j, Vec3{c.tjx[q], c.tjy[q], c.tjz[q]});
  }
}

// Pass 2 of a chunk of a model with history: forces, torques and dissipation in list order, as
// pair_loop_history adds them (a pair out of contact carries -0.0 everywhere: no change).
// `current`, `fi`, `ti` carry the running sums of particle `current` across chunks.
// The running sums are copied into locals for the loop: through the references (one of them
// into ForceScratch, which may alias f and tq for all the compiler knows) every pair stored and
// reloaded them, a store-to-load chain that was a quarter of this pass's time. The pairs whose j
// another block owns are queued after the loop (spill_pairs): with the queueing (and its
// possible reallocation, a call) in the loop, GCC kept each pair's force on j in memory.
template <bool Spin>
void add_history_chunk(const std::int32_t* pi, const std::int32_t* pj, int n, const kernels::HistoryChunk& c, int end,
                       Vec3* f, Vec3* tq, std::vector<std::vector<SpilledForce>>& spill,
                       std::vector<std::vector<SpilledForce>>& spill_torque, const std::uint16_t* block_of,
                       int& current_sum, Vec3& fi_sum, Vec3& ti_sum, double& dissipated_sum) {
  int current = current_sum;
  Vec3 fi = fi_sum, ti = ti_sum;
  double dissipated = dissipated_sum;
  int spilled[kernels::kChunk], count = 0;   // pairs whose j another block owns: queued after the loop
  for (int q = 0; q < n; ++q) {
    const int i = pi[q], j = pj[q];
    if (i != current) {
      f[current] += fi;
      if (Spin) tq[current] += ti;
      fi = Vec3{0, 0, 0};
      ti = Vec3{0, 0, 0};
      current = i;
    }
    const Vec3 fj{c.fx[q], c.fy[q], c.fz[q]};
    if (j < end) {
      f[j] += fj;
      if (Spin) tq[j] += Vec3{c.tjx[q], c.tjy[q], c.tjz[q]};
    } else {
      spilled[count++] = q;
    }
    fi -= fj;
    if (Spin) ti += Vec3{c.tix[q], c.tiy[q], c.tiz[q]};
    dissipated += c.d[q];
  }
  current_sum = current;
  fi_sum = fi;
  ti_sum = ti;
  dissipated_sum = dissipated;
  spill_pairs<Spin>(pj, c, spilled, count, spill, spill_torque, block_of);
}

// The pair loop of a model with history on a vector kernel (history_kernels.hpp): the same bits
// as pair_loop_history.
template <bool Sheared, class CM>
void pair_loop_history_vector(PairKernel kernel, const CM& cm, State& s, const NeighborList& list,
                              const double* packed, const std::int32_t* pair_i, const VelGrad& rate, double dt,
                              int begin, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                              std::vector<std::vector<SpilledForce>>& spill_torque, const std::uint16_t* block_of,
                              double* dissipated) {
  Vec3 off3[27];
  image_offsets(s.box, off3);
  alignas(64) double off[27 * 4];
  for (int c = 0; c < 27; ++c) {
    off[4 * c] = off3[c].x; off[4 * c + 1] = off3[c].y; off[4 * c + 2] = off3[c].z; off[4 * c + 3] = 0.0;
  }
  const long p_begin = list.first[begin], p_end = list.first[end];
  const kernels::HistoryInputs<CM> in{packed, pair_i, list.partner.data(), list.image.data(), off,
                                      s.angular_velocity.data(), cm, rate, dt, s.history.values.data()};
  const kernels::HistoryKernelFn<CM> run = kernels::history_kernel_of<Sheared, CM>(kernel);
  static thread_local kernels::HistoryChunk chunk;
  Vec3* tq = s.torque.data();
  int current = p_begin < p_end ? pair_i[p_begin] : begin;
  Vec3 fi{0, 0, 0}, ti{0, 0, 0};
  for (long p0 = p_begin; p0 < p_end; p0 += kernels::kChunk) {
    const int n = static_cast<int>(std::min<long>(kernels::kChunk, p_end - p0));
    run(in, p0, n, chunk);
    add_history_chunk<CM::rotations>(pair_i + p0, list.partner.data() + p0, n, chunk, end, f, tq, spill,
                                     spill_torque, block_of, current, fi, ti, *dissipated);
  }
  if (p_begin < p_end) {
    f[current] += fi;
    if (CM::rotations) tq[current] += ti;
  }
}

void add_background_damping(const Model& m, State& s) {
  const double gb = m.background_damping;
  if (gb == 0.0) return;
  for (int i = 0; i < s.count(); ++i) s.force[i] -= s.velocity[i] * gb;
}

}  // namespace

void partition_pairs(const NeighborList& list, int blocks, ForceScratch& scratch) {
  blocks = std::max(1, blocks);
  if (scratch.list_builds == list.builds && scratch.blocks() == blocks) return;
  const int n = static_cast<int>(list.first.size()) - 1;
  const long total = list.first[n];
  scratch.bounds.assign(blocks + 1, n);
  scratch.bounds[0] = 0;
  for (int b = 1; b < blocks; ++b) {
    const long target = total * b / blocks;
    scratch.bounds[b] = static_cast<int>(
        std::lower_bound(list.first.begin(), list.first.end() - 1, target) - list.first.begin());
  }
  scratch.block_of.resize(n);
  for (int b = 0; b < blocks; ++b)
    std::fill(scratch.block_of.begin() + scratch.bounds[b], scratch.block_of.begin() + scratch.bounds[b + 1],
              static_cast<std::uint16_t>(b));
  scratch.spill.assign(blocks, std::vector<std::vector<SpilledForce>>(blocks));
  scratch.pair_i.resize(list.partner.size());
  scratch.packed.resize(8 * static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i)
    std::fill(scratch.pair_i.begin() + list.first[i], scratch.pair_i.begin() + list.first[i + 1], i);
  scratch.list_builds = list.builds;
}

// Four blocks by default: 1, 2, 3 and 4 threads sum every force in the same order.
constexpr int kDefaultBlocks = 4;

int block_count(int blocks_setting, int threads) {
  return std::clamp(blocks_setting > 0 ? blocks_setting : std::max(kDefaultBlocks, threads), 1, 65535);
}

void accumulate_pair_forces(const Model& model, State& state, const NeighborList& list,
                            const VelGrad& rate, int b, ForceScratch& scratch, Vec3* force) {
  for (auto& to : scratch.spill[b]) to.clear();
  const int begin = scratch.bounds[b], end = scratch.bounds[b + 1];
  auto& spill = scratch.spill[b];
  const std::uint16_t* block_of = scratch.block_of.data();
  contact::with_contact_model(model.contact, [&](const auto& cm) {
    using CM = std::decay_t<decltype(cm)>;
    if constexpr (CM::history_loop) {
      // A model without history (Hertz alone: per_pair) has no torques or sliders, and
      // begin_pair_loop set up neither: its loops get a dissipation they add zeros to.
      double no_dissipation = 0.0;
      auto& spill_torque = CM::history > 0 ? scratch.spill_torque[b] : spill;
      double* dissipated = CM::history > 0 ? &scratch.dissipated[b] : &no_dissipation;
      if constexpr (CM::history > 0) for (auto& to : spill_torque) to.clear();
      *dissipated = 0.0;
      if constexpr (CM::vectorised) {
        if (scratch.kernel != PairKernel::reference) {
          const std::int32_t* pair_i = scratch.pair_i.data();
          if (rate.sheared())
            pair_loop_history_vector<true>(scratch.kernel, cm, state, list, scratch.packed.data(), pair_i, rate,
                                           model.dt, begin, end, force, spill, spill_torque, block_of, dissipated);
          else
            pair_loop_history_vector<false>(scratch.kernel, cm, state, list, scratch.packed.data(), pair_i, rate,
                                            model.dt, begin, end, force, spill, spill_torque, block_of, dissipated);
          return;
        }
      }
      if (rate.sheared())
        pair_loop_history<true>(cm, state, list, rate, model.dt, begin, end, force, spill, spill_torque, block_of,
                                dissipated);
      else
        pair_loop_history<false>(cm, state, list, rate, model.dt, begin, end, force, spill, spill_torque, block_of,
                                 dissipated);
    } else if (scratch.kernel == PairKernel::reference) {
      if (rate.sheared()) pair_loop_reference<true>(cm, state, list, rate, begin, end, force, spill, block_of);
      else pair_loop_reference<false>(cm, state, list, rate, begin, end, force, spill, block_of);
    } else {
      const std::int32_t* pair_i = scratch.pair_i.data();
      if (rate.sheared())
        pair_loop_vector<true>(scratch.kernel, model.contact, state, list, scratch.packed.data(), pair_i, rate, begin,
                               end, force, spill, block_of);
      else
        pair_loop_vector<false>(scratch.kernel, model.contact, state, list, scratch.packed.data(), pair_i, rate, begin,
                                end, force, spill, block_of);
    }
  });
}

void apply_spilled_forces(int b, const ForceScratch& scratch, Vec3* force, Vec3* torque) {
  for (int from = 0; from < b; ++from)
    for (const SpilledForce& s : scratch.spill[from][b]) force[s.j] += s.f;
  if (torque && !scratch.spill_torque.empty())
    for (int from = 0; from < b; ++from)
      for (const SpilledForce& s : scratch.spill_torque[from][b]) torque[s.j] += s.f;
}

void begin_pair_loop(const Model& model, State& s, const NeighborList& list, ForceScratch& scratch) {
  if (!s.rotations() && s.history.width == 0) return;
  const int blocks = scratch.blocks();
  if (static_cast<int>(scratch.spill_torque.size()) != blocks)
    scratch.spill_torque.assign(blocks, std::vector<std::vector<SpilledForce>>(blocks));
  scratch.dissipated.assign(blocks, 0.0);
  std::fill(s.torque.begin(), s.torque.end(), Vec3{0, 0, 0});
  const std::size_t want = list.partner.size() * static_cast<std::size_t>(s.history.width);
  if (s.history.values.size() != want) place_history(s, list);   // e.g. a fresh state
  (void)model;
}

void end_pair_loop(State& s, const ForceScratch& scratch) {
  if (!s.rotations() && s.history.width == 0) return;
  for (double d : scratch.dissipated) s.friction_dissipated += d;
}

void pack_particles(const State& s, int begin, int end, ForceScratch& scratch) {
  if (scratch.packed.size() != 8 * static_cast<std::size_t>(s.count())) return;   // sized by partition_pairs
  double* P = scratch.packed.data();
  for (int i = begin; i < end; ++i) pack_particle(s.position[i], s.radius[i], s.velocity[i], s.mass[i], P + 8L * i);
}

void compute_forces(const Model& model, State& s, const NeighborList& list,
                    const VelGrad& rate, int threads, int blocks, ForceScratch& scratch) {
  s.force.assign(s.count(), Vec3{0, 0, 0});
  partition_pairs(list, blocks, scratch);
  pack_particles(s, 0, s.count(), scratch);
  begin_pair_loop(model, s, list, scratch);
  Vec3* f = s.force.data();
  Vec3* t = s.rotations() ? s.torque.data() : nullptr;
  if (threads <= 1) {
    for (int b = 0; b < blocks; ++b) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
    for (int b = 1; b < blocks; ++b) apply_spilled_forces(b, scratch, f, t);
  } else {
#pragma omp parallel num_threads(threads)
    {
      const ThreadRank rank = this_thread_rank();
      const int th = rank.index, nt = rank.count;
      for (int b = th; b < blocks; b += nt) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
#pragma omp barrier
      for (int b = th; b < blocks; b += nt) apply_spilled_forces(b, scratch, f, t);
    }
  }
  end_pair_loop(s, scratch);
  add_background_damping(model, s);
}

Vec3 minimum_image(const Box& box, const Vec3& xi, const Vec3& xj) {
  Vec3 d = xj - xi;
  if (!box.tilted()) {
    const Vec3 L = box.length;
    for (int k = 0; k < 3; ++k) d[k] -= L[k] * std::round(d[k] / L[k]);
    return d;
  }
  d -= box.lattice(0, 0, std::round(d.z / box.length.z));
  d -= box.lattice(0, std::round(d.y / box.length.y), 0);
  d -= box.lattice(std::round(d.x / box.length.x), 0, 0);
  return d;
}

void compute_forces_all_pairs(const Model& model, State& s, const VelGrad& rate, PairHistoryMap* history) {
  const int n = s.count();
  s.force.assign(n, Vec3{0, 0, 0});
  if (s.rotations()) s.torque.assign(n, Vec3{0, 0, 0});
  contact::with_contact_model(model.contact, [&](const auto& cm) {
    using CM = std::decay_t<decltype(cm)>;
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j) {
        const Vec3 xj = s.position[i] + minimum_image(s.box, s.position[i], s.position[j]);
        if constexpr (CM::history_loop) {
          // the record in the orientation (smaller id, larger id); this loop's pair is (i, j)
          const bool swapped = s.id[i] > s.id[j];
          const auto key = std::make_pair(std::min(s.id[i], s.id[j]), std::max(s.id[i], s.id[j]));
          std::vector<double> h(CM::history, 0.0);
          if constexpr (CM::history > 0)
            if (const auto it = history->find(key); it != history->end()) h = it->second;
          auto flip = [&] {
            if (swapped) for (int k = 0; k < CM::history; ++k) if ((s.history.odd >> k) & 1u) h[k] = -h[k];
          };
          flip();
          double dissipated = 0;
          PairSums c;
          const Vec3 wi = s.rotations() ? s.angular_velocity[i] : Vec3{0, 0, 0};
          const Vec3 wj = s.rotations() ? s.angular_velocity[j] : Vec3{0, 0, 0};
          const bool touch = rate.sheared()
              ? contact_force_history<true>(cm, s.position[i], xj, s.velocity[i], s.velocity[j], wi, wj, s.radius[i],
                                            s.radius[j], s.mass[i], s.mass[j], rate, model.dt, h.data(), &dissipated, c)
              : contact_force_history<false>(cm, s.position[i], xj, s.velocity[i], s.velocity[j], wi, wj, s.radius[i],
                                             s.radius[j], s.mass[i], s.mass[j], rate, model.dt, h.data(), &dissipated, c);
          flip();
          if constexpr (CM::history > 0) {
            if (!touch) { history->erase(key); continue; }
            (*history)[key] = h;
          } else if (!touch) {
            continue;
          }
          s.friction_dissipated += dissipated;
          s.force[j] += c.fj; s.force[i] -= c.fj;
          if (s.rotations()) { s.torque[i] += c.ti; s.torque[j] += c.tj; }
        } else {
          Vec3 fj;
          const bool touch = rate.sheared()
              ? contact_force<true>(cm, s.position[i], xj, s.velocity[i], s.velocity[j], s.radius[i], s.radius[j], rate, fj)
              : contact_force<false>(cm, s.position[i], xj, s.velocity[i], s.velocity[j], s.radius[i], s.radius[j], rate, fj);
          if (!touch) continue;
          s.force[j] += fj;
          s.force[i] -= fj;
        }
      }
  });
  add_background_damping(model, s);
}

PairHistoryMap history_by_ids(const State& s) {
  PairHistoryMap out;
  const int w = s.history.width;
  for (std::size_t r = 0; r < s.history.ids.size() / 2 && w > 0; ++r) {
    const double* v = s.history.values.data() + r * w;
    if (!std::any_of(v, v + w, [](double x) { return x != 0.0; })) continue;
    const std::int32_t a = s.history.ids[2 * r], b = s.history.ids[2 * r + 1];
    std::vector<double> h(v, v + w);
    if (a > b) for (int k = 0; k < w; ++k) if ((s.history.odd >> k) & 1u) h[k] = -h[k];
    out[{std::min(a, b), std::max(a, b)}] = h;
  }
  return out;
}

}  // namespace dem
