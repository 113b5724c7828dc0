#include "dem/forces.hpp"
#include "dem/parallel.hpp"

#include <algorithm>
#include <cmath>

namespace dem {

namespace {

// One pair: the contact force on j [N] (minus it on i); false if the spheres do not touch.
template <bool Sheared, class Law>
inline bool contact_force(const Law& law, const Vec3& xi, const Vec3& xj_image, const Vec3& vi,
                          const Vec3& vj, double ri, double rj, const VelGrad& rate, Vec3& f_on_j) {
  const Vec3 d = xj_image - xi;
  const double r2 = dot(d, d);
  const double reach = ri + rj;
  if (r2 >= reach * reach) return false;
  const double r = std::sqrt(r2);
  const double inv_r = 1.0 / r;
  const Vec3 n = d * inv_r;                          // unit normal from i to j
  // fluctuation + affine relative velocity (L d; a diagonal L: the component-wise product)
  const Vec3 v_rel = (vj - vi) + (Sheared ? rate.apply(d) : hadamard(rate.diag, d));
  const double fn = law(reach - r, -dot(v_rel, n));
  f_on_j = n * fn;
  return true;
}

// Pairs of particles [begin, end): forces on j >= end go to spill[block_of[j]].
template <bool Sheared, class Law>
void pair_loop(const Law& law, const State& s, const NeighborList& list, const VelGrad& rate,
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
      if (!contact_force<Sheared>(law, xi, x[j] + off[image[p]], vi, v[j], ri, rad[j], rate, fj)) continue;
      if (j < end) f[j] += fj; else spill[block_of[j]].push_back({j, fj});
      fi -= fj;
    }
    f[i] += fi;
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
  scratch.list_builds = list.builds;
}

// Four blocks by default: 1, 2, 3 and 4 threads sum every force in the same order.
constexpr int kDefaultBlocks = 4;

int block_count(int blocks_setting, int threads) {
  return std::clamp(blocks_setting > 0 ? blocks_setting : std::max(kDefaultBlocks, threads), 1, 65535);
}

void accumulate_pair_forces(const Model& model, const State& state, const NeighborList& list,
                            const VelGrad& rate, int b, ForceScratch& scratch, Vec3* force) {
  const LinearSpringDashpot law(model.contact);
  for (auto& to : scratch.spill[b]) to.clear();
  if (rate.sheared())
    pair_loop<true>(law, state, list, rate, scratch.bounds[b], scratch.bounds[b + 1], force, scratch.spill[b],
                    scratch.block_of.data());
  else
    pair_loop<false>(law, state, list, rate, scratch.bounds[b], scratch.bounds[b + 1], force, scratch.spill[b],
                     scratch.block_of.data());
}

void apply_spilled_forces(int b, const ForceScratch& scratch, Vec3* force) {
  for (int from = 0; from < b; ++from)
    for (const SpilledForce& s : scratch.spill[from][b]) force[s.j] += s.f;
}

void compute_forces(const Model& model, State& s, const NeighborList& list,
                    const VelGrad& rate, int threads, int blocks, ForceScratch& scratch) {
  s.force.assign(s.count(), Vec3{0, 0, 0});
  partition_pairs(list, blocks, scratch);
  Vec3* f = s.force.data();
  if (threads <= 1) {
    for (int b = 0; b < blocks; ++b) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
    for (int b = 1; b < blocks; ++b) apply_spilled_forces(b, scratch, f);
  } else {
#pragma omp parallel num_threads(threads)
    {
      const ThreadRank rank = this_thread_rank();
      const int t = rank.index, nt = rank.count;
      for (int b = t; b < blocks; b += nt) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
#pragma omp barrier
      for (int b = t; b < blocks; b += nt) apply_spilled_forces(b, scratch, f);
    }
  }
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

void compute_forces_all_pairs(const Model& model, State& s, const VelGrad& rate) {
  const int n = s.count();
  const LinearSpringDashpot law(model.contact);
  s.force.assign(n, Vec3{0, 0, 0});
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const Vec3 d = minimum_image(s.box, s.position[i], s.position[j]);
      Vec3 fj;
      const bool touch = rate.sheared() ? contact_force<true>(law, s.position[i], s.position[i] + d, s.velocity[i],
                                                              s.velocity[j], s.radius[i], s.radius[j], rate, fj)
                                        : contact_force<false>(law, s.position[i], s.position[i] + d, s.velocity[i],
                                                               s.velocity[j], s.radius[i], s.radius[j], rate, fj);
      if (!touch) continue;
      s.force[j] += fj;
      s.force[i] -= fj;
    }
  add_background_damping(model, s);
}

}  // namespace dem
