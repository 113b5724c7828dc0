// Contact and background-damping forces: one pair loop over the Verlet list (fast path) and
// a naive all-pairs loop (the oracle the fast path is tested against).
#pragma once
#include <cstdint>
#include <vector>

#include "dem/contact_law.hpp"
#include "dem/neighbor_list.hpp"
#include "dem/state.hpp"

namespace dem {

/// A pair force owed to a particle of another thread's block: f is added to force[j] after
/// every block has run its pairs.
struct SpilledForce {
  std::int32_t j;
  Vec3 f;   ///< [N]
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
  std::int64_t list_builds = -1;                              ///< list.builds the split was made for
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
void accumulate_pair_forces(const Model& model, const State& state, const NeighborList& list,
                            const VelGrad& strain_rate, int b, ForceScratch& scratch, Vec3* force);

/// Adds to force[] the queued forces aimed at block b, from blocks 0..b-1 in order.
void apply_spilled_forces(int b, const ForceScratch& scratch, Vec3* force);

/// Computes state.force for the current positions and fluctuation velocities:
///  - every listed pair in contact: normal force from the contact law, equal and opposite;
///    the overlap rate uses the full relative velocity, fluctuation plus affine flow
///    L branch vector  [1/s . m] (L = strain_rate; a diagonal rate: rate (.) branch);
///  - background damping -gamma_b * v on every particle [N], added after the pair forces.
/// Pairs are summed in list order within `blocks` blocks (ForceScratch; block_count()), run
/// by `threads` threads: deterministic for a given block count, whatever the thread count.
void compute_forces(const Model& model, State& state, const NeighborList& list,
                    const VelGrad& strain_rate, int threads, int blocks, ForceScratch& scratch);

/// The oracle: the same forces from a loop over all N(N-1)/2 pairs with the minimum-image
/// convention (valid when every box edge exceeds 2 * (2 r_max)). In a tilted cell the image is
/// found by rounding the fractional coordinates of the separation, z, then y, then x (exact
/// for the upper-triangular cell while contacts are shorter than half of every edge).
/// O(N^2); for tests.
void compute_forces_all_pairs(const Model& model, State& state, const VelGrad& strain_rate);

/// The minimum-image separation x_j - x_i of the oracle [m].
Vec3 minimum_image(const Box& box, const Vec3& xi, const Vec3& xj);

}  // namespace dem
