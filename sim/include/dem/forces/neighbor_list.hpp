// Verlet neighbour list built with linked cells, aware of the box deformation.
//
// The list holds every pair (i < j) whose centre distance was below r_i + r_j + skin at the
// last build, with the periodic image of j stored per pair (so the force loop needs no
// minimum-image branches). Between builds positions are not wrapped; the image shifts scale
// with the box, so they stay valid.
//
// Rebuild criterion (conservative, exact bound): let u_max be the largest fluctuation
// displacement since the build, measured in the frame of the box at build time, and
// lambda_min the smallest stretch of the box since the build (L/L_build for a diagonal
// deformation; the smallest singular value of H H_build^-1 in a tilted cell). No unlisted
// pair can touch while
//     2 u_max + 2 r_max (1/lambda_min - 1)_+  <  skin.
// In a tilted cell the linked cells are slabs of the fractional coordinates, as many per
// axis as the cell's perpendicular width holds cutoffs, so the 27-cell stencil stays exact;
// a flip of the cell (a new set of lattice vectors) always rebuilds the list.
#pragma once
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "dem/core/state.hpp"

namespace dem {

struct NeighborList {
  std::vector<std::int32_t> first;     ///< CSR offsets, size N+1
  std::vector<std::int32_t> partner;   ///< j of each pair (j > i)
  std::vector<std::uint8_t> image;     ///< periodic image of j: (sx+1)*9+(sy+1)*3+(sz+1)
  double skin = 0;                     ///< [m]
  double radius_max = 0;               ///< [m], for the rebuild criterion
  std::int64_t builds = 0;             ///< number of rebuilds so far (statistics only)

  std::size_t pair_count() const { return partner.size(); }
};

/// Offsets of the 27 periodic images for the current box [m]: H (sx, sy, sz), s in {-1, 0, 1}.
void image_offsets(const Box& box, Vec3 offsets[27]);

/// Rebuilds the list: wraps positions into the box, optionally sorts particles by cell
/// (permuting every per-particle array of the state, for memory locality), stores the
/// build reference in the state. Throws std::runtime_error if the box is shorter than
/// twice the list cutoff 2*r_max + skin along any axis (too few particles for the box).
void rebuild_neighbor_list(State& state, NeighborList& list, double skin, bool sort_by_cell);

/// rebuild_neighbor_list in three phases, so that a team of threads shares the pair search:
/// begin (one thread: wrap, sort, build reference, linked cells), search(c) for every chunk
/// c < chunks() (any thread, chunks concurrently: rows are searched independently), finish (one
/// thread: the chunks' rows joined in order, the history placed). The list, and so the bits,
/// do not depend on the number of chunks or on which thread searched which.
class ListRebuild {
 public:
  ListRebuild();
  ~ListRebuild();
  void begin(State& state, NeighborList& list, double skin, bool sort_by_cell, int chunks);
  int chunks() const;
  void search(int chunk);
  void finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The pair search tests four candidates at a time from consecutive particles of a cell (the
/// cell-sorted order of a rebuild), in an AVX2 build of its loop where the CPU has AVX2. `on =
/// false` forces the generic build, which gives the same list (tests); returns the setting before.
bool pair_search_avx2(bool on);

/// Puts the state's per-contact history (State::ContactHistory: records keyed by the pair's
/// particle ids, in any order) into the order of `list`: a listed pair gets the record of the
/// same two particles (odd entries negated if they are listed the other way round), every other
/// pair zeros. Called by rebuild_neighbor_list (rebuilds, re-sorts, flips) and by the engine
/// after a checkpoint. A no-op when the history has width 0.
void place_history(State& state, const NeighborList& list);

/// Rebuilds the list from the state's stored build reference without moving or sorting
/// particles (used when continuing from a checkpoint, to get exactly the same list).
void restore_neighbor_list(const State& state, NeighborList& list, double skin);

/// The rebuild criterion in a form a fused particle pass can evaluate: the list is stale
/// when limit2 < 0, or when some particle has |x (.) frame - x_at_build|^2 >= limit2
/// (frame = L_at_build / L per axis [-], limit2 [m^2]). In a tilted cell (general) the map
/// back to the build frame is the upper-triangular H_build H^-1 (`back`: xx, yy, zz, xy, xz, yz).
struct StalenessTest {
  Vec3 frame{1, 1, 1};
  double limit2 = -1;
  bool general = false;
  double back[6] = {1, 1, 1, 0, 0, 0};
};

/// y = U x for an upper-triangular U stored as (xx, yy, zz, xy, xz, yz).
inline Vec3 upper_apply(const double* U, const Vec3& x) {
  return {U[0] * x.x + U[3] * x.y + U[4] * x.z, U[1] * x.y + U[5] * x.z, U[2] * x.z};
}
StalenessTest staleness_test(const State& state, const NeighborList& list);

/// Squared displacement of particle i since the build, in the build frame [m^2].
inline double displacement2_since_build(const State& s, const StalenessTest& t, int i) {
  const Vec3 u = (t.general ? upper_apply(t.back, s.position[i]) : hadamard(s.position[i], t.frame)) -
                 s.position_at_build[i];
  return dot(u, u);
}

/// True when the list may miss a contact (criterion in the file comment).
bool neighbor_list_stale(const State& state, const NeighborList& list);

/// Calls visit(i, j, d, r, delta) for every listed pair in contact, in list order: d is the
/// branch vector from i to the listed image of j [m], r = |d| [m], delta = r_i + r_j - r > 0
/// the overlap [m]. The one loop behind measurements, checks and output (not the force loop).
/// The same with the pair's index p in the list first: visit(p, i, j, d, r, delta) (p indexes
/// per-pair arrays such as State::history).
template <class Visit>
void for_each_listed_contact(const State& s, const NeighborList& list, Visit&& visit) {
  Vec3 off[27];
  image_offsets(s.box, off);
  for (int i = 0; i < s.count(); ++i)
    for (int p = list.first[i]; p < list.first[i + 1]; ++p) {
      const int j = list.partner[p];
      const Vec3 d = s.position[j] + off[list.image[p]] - s.position[i];
      const double reach = s.radius[i] + s.radius[j];
      const double r2 = dot(d, d);
      if (r2 >= reach * reach) continue;
      const double r = std::sqrt(r2);
      visit(static_cast<long>(p), i, j, d, r, reach - r);
    }
}

template <class Visit>
void for_each_contact(const State& s, const NeighborList& list, Visit&& visit) {
  for_each_listed_contact(s, list, [&](long, int i, int j, const Vec3& d, double r, double delta) {
    visit(i, j, d, r, delta);
  });
}

}  // namespace dem
