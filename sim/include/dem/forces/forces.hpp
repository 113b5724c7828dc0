// Contact and background-damping forces: one pair loop over the Verlet list (fast path) and
// a naive all-pairs loop (the oracle the fast path is tested against).
#pragma once
#include <cstddef>
#include <cstdint>
#include <map>
#include <new>
#include <string>
#include <vector>

#include "dem/contact/contact_model.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/core/state.hpp"

namespace dem {

/// A pair force owed to a particle of another thread's block: f is added to force[j] after
/// every block has run its pairs.
struct SpilledForce {
  std::int32_t j;
  Vec3 f;   ///< [N]
};

/// The implementation of the pair loop. All give the same bits (pair_kernels.hpp explains why):
/// `reference` is the plain scalar loop (the oracle of the others), `generic` the two-pass
/// chunked loop for any x86-64-v2 CPU, `avx2` and `avx512` the same loop vectorised for
/// those instruction sets (runtime dispatch: chosen by the CPU, or DEM_PAIR_KERNEL=name).
enum class PairKernel { reference, generic, avx2, avx512 };

/// The fastest kernel this CPU runs (avx2 where the CPU has it, else reference), or the one
/// named by DEM_PAIR_KERNEL (auto, avx512, avx2, generic, reference; throws
/// std::runtime_error naming the choices if the name is unknown or the CPU lacks it).
PairKernel best_pair_kernel();
bool pair_kernel_supported(PairKernel kernel);
std::vector<PairKernel> supported_pair_kernels();
const char* pair_kernel_name(PairKernel kernel);
PairKernel pair_kernel_from_name(const std::string& name);

/// std::allocator with a stated alignment [bytes] (for the packed particle records).
template <class T, std::size_t Align>
struct AlignedAllocator {
  using value_type = T;
  template <class U> struct rebind { using other = AlignedAllocator<U, Align>; };
  AlignedAllocator() = default;
  template <class U> AlignedAllocator(const AlignedAllocator<U, Align>&) {}
  T* allocate(std::size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(Align))); }
  void deallocate(T* p, std::size_t) { ::operator delete(p, std::align_val_t(Align)); }
  bool operator==(const AlignedAllocator&) const { return true; }
  bool operator!=(const AlignedAllocator&) const { return false; }
};

/// Work split of the half-list loop. Block b owns particles [bounds[b], bounds[b+1])
/// (contiguous, balanced by listed pairs). Its pairs add forces directly to its own
/// particles; a force on a particle of a later block c (neighbour across the block boundary or
/// across the periodic boundary) is queued in spill[b][c] and added by block c after every
/// block has run its pairs, from blocks 0..c-1 in order. No per-thread copy of the force array
/// is needed, and the summation order of every force depends on the blocks only: threads take
/// blocks round-robin, so a fixed block count gives the same bits for any thread count.
struct ForceScratch {
  std::vector<int> bounds;                                    ///< size blocks + 1
  std::vector<std::uint16_t> block_of;                        ///< block of each particle
  std::vector<std::vector<std::vector<SpilledForce>>> spill;  ///< [from block][to block]
  /// Torques owed to particles of later blocks (rotating models only; SpilledForce::f is the
  /// torque [N m]), and the energy each block's Coulomb limits removed this step [J].
  std::vector<std::vector<std::vector<SpilledForce>>> spill_torque;
  std::vector<double> dissipated;
  std::vector<std::int32_t> pair_i;                           ///< i of each listed pair
  /// One 64-byte record per particle for the vectorised kernels: x y z [m] r [m] vx vy vz
  /// [m/s] m [kg] (pack_particles fills it; sized by partition_pairs). The mass rides in the
  /// slot the velocities' block loads anyway (the history kernels' per-pair laws read it).
  std::vector<double, AlignedAllocator<double, 64>> packed;
  std::int64_t list_builds = -1;                              ///< list.builds the split was made for
  PairKernel kernel = best_pair_kernel();                     ///< the pair loop's implementation
  int blocks() const { return static_cast<int>(bounds.size()) - 1; }
};

/// The block count of a run: `integration.blocks` if set (> 0: results independent of the
/// thread count), else max(4, threads) (1-4 threads: the same bits).
int block_count(int blocks_setting, int threads);

/// Splits the particles into `blocks` contiguous ranges with about equal listed pairs
/// (no-op if the split already belongs to this list build and block count).
void partition_pairs(const NeighborList& list, int blocks, ForceScratch& scratch);

/// Adds the contact forces of the pairs of block b to force (which must hold the values to
/// add to, normally zero), queueing forces on later blocks in scratch.spill[b].
/// Safe to call concurrently for different blocks.
/// With a rotating model (friction) it also adds torques to state.torque, advances the
/// per-contact history of the block's pairs (state.history, in list order) and puts the energy
/// its Coulomb limits removed in scratch.dissipated[b].
void accumulate_pair_forces(const Model& model, State& state, const NeighborList& list,
                            const VelGrad& rate, int b, ForceScratch& scratch, Vec3* force);

/// Copies positions, radii, velocities and masses of particles [begin, end) into scratch.packed (the
/// records the vectorised kernels read). Call after the particles move and before
/// accumulate_pair_forces; a no-op until partition_pairs has sized the records.
void pack_particles(const State& state, int begin, int end, ForceScratch& scratch);

/// The record of particle i (pack_particles' body, for passes that move particles anyway).
inline void pack_particle(const Vec3& x, double r, const Vec3& v, double m, double* record) {
  record[0] = x.x; record[1] = x.y; record[2] = x.z; record[3] = r;
  record[4] = v.x; record[5] = v.y; record[6] = v.z; record[7] = m;
}

/// Adds to force[] the queued forces aimed at block b, from blocks 0..b-1 in order (and the
/// queued torques to torque[], when not null).
void apply_spilled_forces(int b, const ForceScratch& scratch, Vec3* force, Vec3* torque = nullptr);

/// Zeroes state.torque (rotating models) and sizes the history to the list (a fresh list
/// build already did); adds the blocks' dissipated energy, in block order, to
/// state.friction_dissipated. The engine calls these around its pair loop.
void begin_pair_loop(const Model& model, State& state, const NeighborList& list, ForceScratch& scratch);
void end_pair_loop(State& state, const ForceScratch& scratch);

/// Computes state.force for the current positions and fluctuation velocities:
///  - every listed pair in contact: normal force from the contact law, equal and opposite;
///    the overlap rate uses the full relative velocity, fluctuation plus affine flow
///    L branch vector  [1/s . m] (L = rate; a diagonal rate: rate (.) branch);
///  - background damping -gamma_b * v on every particle [N], added after the pair forces.
/// Pairs are summed in list order within `blocks` blocks (ForceScratch; block_count()), run
/// by `threads` threads: deterministic for a given block count, whatever the thread count.
void compute_forces(const Model& model, State& state, const NeighborList& list,
                    const VelGrad& rate, int threads, int blocks, ForceScratch& scratch);

/// The oracle: the same forces from a loop over all N(N-1)/2 pairs with the minimum-image
/// convention (valid when every box edge exceeds 2 * (2 r_max)). In a tilted cell the image is
/// found by rounding the fractional coordinates of the separation, z, then y, then x (exact
/// for the upper-triangular cell while contacts are shorter than half of every edge).
/// O(N^2); for tests.
/// With a rotating model the oracle also gives torques and advances the history, which it
/// keeps in `history` keyed by the pair's particle ids (id_i, id_j) with i < j by id; it must
/// then be given (tests pass the list's history converted with history_by_ids()).
using PairHistoryMap = std::map<std::pair<std::int32_t, std::int32_t>, std::vector<double>>;
void compute_forces_all_pairs(const Model& model, State& state, const VelGrad& rate,
                              PairHistoryMap* history = nullptr);

/// The state's history records with any non-zero entry, keyed by (smaller id, larger id),
/// odd entries in that orientation (for comparisons with the oracle).
PairHistoryMap history_by_ids(const State& state);

/// The minimum-image separation x_j - x_i of the oracle [m].
Vec3 minimum_image(const Box& box, const Vec3& xi, const Vec3& xj);

}  // namespace dem
