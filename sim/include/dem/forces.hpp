// Contact and background-damping forces: one pair loop over the Verlet list (fast path) and
// a naive all-pairs loop (the oracle the fast path is tested against).
#pragma once
#include <vector>

#include "dem/contact_law.hpp"
#include "dem/neighbor_list.hpp"
#include "dem/state.hpp"

namespace dem {

/// Per-thread force buffers for the parallel half-list loop.
struct ForceScratch {
  std::vector<std::vector<Vec3>> per_thread;
};

/// Computes state.force for the current positions and fluctuation velocities:
///  - every listed pair in contact: normal force from the contact law, equal and opposite;
///    the overlap rate uses the full relative velocity, fluctuation plus affine flow
///    strain_rate (.) branch vector  [1/s . m];
///  - background damping -gamma_b * v on every particle [N].
/// Pairs are summed in list order. With threads > 1 each thread accumulates its static
/// block of particles into its own buffer and the buffers are added in thread order, so a
/// run is deterministic for a given thread count, and differs between thread counts only
/// by round-off of the summation order.
void compute_forces(const Model& model, State& state, const NeighborList& list,
                    const Vec3& strain_rate, int threads, ForceScratch& scratch);

/// The oracle: the same forces from a loop over all N(N-1)/2 pairs with the minimum-image
/// convention (valid when every box edge exceeds 2 * (2 r_max)). O(N^2); for tests.
void compute_forces_all_pairs(const Model& model, State& state, const Vec3& strain_rate);

}  // namespace dem
