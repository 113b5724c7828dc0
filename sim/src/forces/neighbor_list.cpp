#include "dem/forces/neighbor_list.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace dem {
double max_radius_of(const std::vector<double>& radius);

void image_offsets(const Box& box, Vec3 offsets[27]) {
  if (box.tilted()) {
    for (int sx = -1; sx <= 1; ++sx)
      for (int sy = -1; sy <= 1; ++sy)
        for (int sz = -1; sz <= 1; ++sz) offsets[(sx + 1) * 9 + (sy + 1) * 3 + (sz + 1)] = box.lattice(sx, sy, sz);
    return;
  }
  for (int sx = -1; sx <= 1; ++sx)
    for (int sy = -1; sy <= 1; ++sy)
      for (int sz = -1; sz <= 1; ++sz)
        offsets[(sx + 1) * 9 + (sy + 1) * 3 + (sz + 1)] =
            Vec3(sx * box.length.x, sy * box.length.y, sz * box.length.z);
}

namespace {

struct CellGrid {
  int n[3];
  double inv_size[3];
  const Box* tilted = nullptr;   ///< the cell when it is tilted: cells are slabs of fractional coordinates
  // Clamped while still a double: a cast of inf or NaN to int is undefined (UBSan: a box of 1e-300
  // or a position of 1e308 from demtk, tests/SANITIZE.md); in range the same cell as before.
  static int clamp_cell(double f, int cells) { return !(f >= 0) ? 0 : f >= cells ? cells - 1 : static_cast<int>(f); }
  int index_of(const Vec3& x) const {
    int c[3];
    if (tilted) {
      const Vec3 s = tilted->fractional(x);
      for (int k = 0; k < 3; ++k) c[k] = clamp_cell(std::floor(s[k] * n[k]), n[k]);
    } else {
      for (int k = 0; k < 3; ++k) c[k] = clamp_cell(x[k] * inv_size[k], n[k]);
    }
    return (c[0] * n[1] + c[1]) * n[2] + c[2];
  }
};

// Perpendicular widths of the cell (the distance between opposite faces) [m]: V / |b x c| etc.
Vec3 cell_widths(const Box& b) {
  const double Lx = b.length.x, Ly = b.length.y, Lz = b.length.z, xy = b.tilt.x, xz = b.tilt.y, yz = b.tilt.z;
  const double V = Lx * Ly * Lz;
  const Vec3 bc{Ly * Lz, -xy * Lz, xy * yz - Ly * xz};
  const Vec3 ca{0, Lz * Lx, -yz * Lx};
  return {V / norm(bc), V / norm(ca), Lz};
}

// At most kMaxCells cells. A box many cutoffs wide (a dilute gas far beyond any scene's, or an
// absurd box handed to demtk: fuzz_demtk under UBSan, tests/SANITIZE.md) would overflow the int
// cell index (n[0] n[1] n[2]) and allocate without bound. Fewer, wider cells find the same pairs (a
// cell only has to be at least the cutoff wide), so the cap changes no result; below it (every
// scene of the repository by orders of magnitude: 16.7 M cells) the grid is the one it always was.
constexpr std::int64_t kMaxCells = std::int64_t{1} << 24;

// Cells along one edge: floor(width / cutoff), clamped while a double (no cast of inf or NaN).
int cells_along(double q) {
  return !(q >= 1) ? 1 : q >= double(kMaxCells) ? int(kMaxCells) : static_cast<int>(q);
}

// Halves the longest edge's count until the grid has at most kMaxCells cells.
void cap_cell_count(int n[3]) {
  auto count = [&] { return std::int64_t{n[0]} * n[1] * n[2]; };
  while (count() > kMaxCells) {
    int* widest = std::max_element(n, n + 3);
    *widest = std::max(1, *widest / 2);
  }
}

// The grid of the box `b` (kept by pointer when tilted: b must outlive the grid).
CellGrid make_grid(const Box& b, double cutoff) {
  CellGrid g{};
  const bool tilted = b.tilted();
  const Vec3 width = tilted ? cell_widths(b) : b.length;
  for (int k = 0; k < 3; ++k) {
    if (width[k] < 2.0 * cutoff)
      throw std::runtime_error(
          std::string(tilted ? "perpendicular width of the tilted cell " : "box edge ") + std::to_string(width[k]) +
          " m is shorter than twice the neighbour cutoff " + std::to_string(cutoff) +
          " m: use more particles or a smaller skin (integration.skin_over_rmin, in units of the smallest radius)");
    g.n[k] = cells_along(width[k] / cutoff);
  }
  cap_cell_count(g.n);
  for (int k = 0; k < 3; ++k) g.inv_size[k] = g.n[k] / b.length[k];
  if (tilted) g.tilted = &b;
  return g;
}

// The linked cells of one build: the cell of each particle and the members of each cell
// (particle indices, ascending within a cell: a counting sort, stable in i). `ordered`: the
// particles are ordered by cell (as sort_by_cell leaves them), so the members of cell k are the
// consecutive indices cell_start[k] .. cell_start[k + 1] - 1.
struct CellLists {
  std::vector<std::int32_t> cell_of, cell_start, cell_members;
  bool ordered = false;
};

CellLists bin_particles(const CellGrid& g, const std::vector<Vec3>& x) {
  const int n = static_cast<int>(x.size());
  const int ncell = g.n[0] * g.n[1] * g.n[2];
  CellLists c;
  c.cell_of.resize(n);
  c.cell_start.assign(ncell + 1, 0);
  c.cell_members.resize(n);
  c.ordered = true;
  for (int i = 0; i < n; ++i) {
    c.cell_of[i] = g.index_of(x[i]);
    ++c.cell_start[c.cell_of[i] + 1];
    if (i > 0 && c.cell_of[i] < c.cell_of[i - 1]) c.ordered = false;
  }
  for (int k = 0; k < ncell; ++k) c.cell_start[k + 1] += c.cell_start[k];
  std::vector<std::int32_t> fill(c.cell_start.begin(), c.cell_start.end() - 1);
  for (int i = 0; i < n; ++i) c.cell_members[fill[c.cell_of[i]]++] = i;
  return c;
}

// Squared gaps between particle i and the cells around its own, per axis: gap2[k][d + 1] for
// the neighbour at offset d = -1, 0, 1 along axis k (0 for d = 0, and everywhere in a tilted
// cell, where cells are slabs of fractional coordinates: no pruning there) [m^2]. Shrunk by a
// margin far above the round-off of the cell index, so no cell that could hold a partner is pruned.
void cell_gaps2(const CellGrid& g, const Vec3& x, const int ci[3], double gap2[3][3]) {
  for (int k = 0; k < 3; ++k) gap2[k][0] = gap2[k][1] = gap2[k][2] = 0.0;
  if (g.tilted) return;
  for (int k = 0; k < 3; ++k) {
    const double size = 1.0 / g.inv_size[k], margin = 1e-9 * size * g.n[k];
    const double below = std::max(0.0, x[k] - ci[k] * size - margin);
    const double above = std::max(0.0, (ci[k] + 1) * size - x[k] - margin);
    gap2[k][0] = below * below;
    gap2[k][2] = above * above;
  }
}

// Cell coordinate c + d wrapped into [0, n), and the periodic shift (-1, 0, 1) that took it there.
struct Wrapped {
  int cell, shift;
};
inline Wrapped wrap_cell(int c, int d, int n) {
  const int v = c + d;
  return v < 0 ? Wrapped{v + n, -1} : v >= n ? Wrapped{v - n, 1} : Wrapped{v, 0};
}

// What a pair search needs: the grid, its cells, the image offsets.
struct SearchContext {
  const std::vector<Vec3>* x = nullptr;
  const std::vector<double>* radius = nullptr;
  double skin = 0, rmax = 0;
  CellGrid grid{};
  CellLists cells;
  Vec3 off[27];
  /// When the particles are ordered by cell, consecutive indices are searched four at a time
  /// from these copies of x, y, z, r (four far-away entries of padding).
  std::vector<double> soa_x, soa_y, soa_z, soa_r;
};

using Found = std::vector<std::pair<std::int32_t, std::uint8_t>>;

// The candidates j in [j0, j1) of particle i, image offset o, in `found` when within
// r_i + r_j + skin: four at a time from the search's copies of x, y, z, r (padded by four), with
// the oracle's operations in its order (no FMA: this file is built with -ffp-contract=off), so
// every lane decides as the scalar test does. One body; an AVX2 build of it where the CPU has it.
typedef double V4 __attribute__((vector_size(32)));
typedef std::int64_t M4 __attribute__((vector_size(32)));

__attribute__((always_inline)) inline void test_range_body(const SearchContext& c, int i, int j0, int j1,
                                                           const Vec3& o, int img, Found& found) {
  const Vec3 xi = (*c.x)[i];
  const double ri = (*c.radius)[i];
  const V4 ox{o.x, o.x, o.x, o.x}, oy{o.y, o.y, o.y, o.y}, oz{o.z, o.z, o.z, o.z};
  const V4 xx{xi.x, xi.x, xi.x, xi.x}, xy{xi.y, xi.y, xi.y, xi.y}, xz{xi.z, xi.z, xi.z, xi.z};
  const V4 rr{ri, ri, ri, ri}, sk{c.skin, c.skin, c.skin, c.skin};
  for (int j = j0; j < j1; j += 4) {
    V4 X, Y, Z, R;
    std::memcpy(&X, c.soa_x.data() + j, sizeof X);
    std::memcpy(&Y, c.soa_y.data() + j, sizeof Y);
    std::memcpy(&Z, c.soa_z.data() + j, sizeof Z);
    std::memcpy(&R, c.soa_r.data() + j, sizeof R);
    const V4 dx = X + ox - xx, dy = Y + oy - xy, dz = Z + oz - xz;
    const V4 reach = rr + R + sk;
    const M4 hit = dx * dx + dy * dy + dz * dz < reach * reach;
    unsigned bits = static_cast<unsigned>((hit[0] & 1) | (hit[1] & 2) | (hit[2] & 4) | (hit[3] & 8));
    if (j1 - j < 4) bits &= (1u << (j1 - j)) - 1;
    for (; bits; bits &= bits - 1) found.emplace_back(j + __builtin_ctz(bits), static_cast<std::uint8_t>(img));
  }
}

__attribute__((target("avx2"))) void test_range_avx2(const SearchContext& c, int i, int j0, int j1, const Vec3& o,
                                                     int img, Found& found) {
  test_range_body(c, i, j0, j1, o, img, found);
}
void test_range_generic(const SearchContext& c, int i, int j0, int j1, const Vec3& o, int img, Found& found) {
  test_range_body(c, i, j0, j1, o, img, found);
}
std::atomic<bool> search_avx2{__builtin_cpu_supports("avx2") != 0};

// Particle i's candidates among the members of one cell (periodic image img), appended to
// `found`: the general case, particles in any order (members ascend within a cell).
void search_cell(int i, const SearchContext& c, int cell, int img, Found& found) {
  const std::int32_t* m0 = c.cells.cell_members.data() + c.cells.cell_start[cell];
  const std::int32_t* m1 = c.cells.cell_members.data() + c.cells.cell_start[cell + 1];
  if (m0 == m1 || m1[-1] <= i) return;             // none with j > i
  const Vec3* x = c.x->data();
  const double* radius = c.radius->data();
  const Vec3 xi = x[i], o = c.off[img];
  const double ri = radius[i];
  for (const std::int32_t* m = std::upper_bound(m0, m1, i); m < m1; ++m) {
    const int j = *m;
    const Vec3 d = x[j] + o - xi;
    const double reach = ri + radius[j] + c.skin;   // the operations of the oracle's cutoff, in order
    if (dot(d, d) < reach * reach) found.emplace_back(j, static_cast<std::uint8_t>(img));
  }
}

// One column of cells (fixed x and y neighbour, z offsets -1, 0, 1 not pruned by their gap
// `gz`), image shifts sx, sy in x and y. Particles ordered by cell: neighbouring z cells without
// a wrap between them are one run of consecutive indices, tested from max(run start, i + 1).
void search_column(int i, const SearchContext& c, int wx, int sx, int wy, int sy, const int ci[3],
                   const bool keep_z[3], Found& found) {
  const CellGrid& g = c.grid;
  const int column = (wx * g.n[1] + wy) * g.n[2];
  int run_first = -1, run_last = -1, run_shift = 0;
  auto flush = [&] {
    if (run_first < 0) return;
    const int img = (sx + 1) * 9 + (sy + 1) * 3 + (run_shift + 1);
    if (!c.cells.ordered) {
      for (int z = run_first; z <= run_last; ++z) search_cell(i, c, column + z, img, found);
    } else {
      const int j0 = std::max(c.cells.cell_start[column + run_first], i + 1);
      const int j1 = c.cells.cell_start[column + run_last + 1];
      if (j0 < j1) (search_avx2.load(std::memory_order_relaxed) ? test_range_avx2 : test_range_generic)(c, i, j0, j1, c.off[img], img, found);
    }
    run_first = -1;
  };
  for (int dz = -1; dz <= 1; ++dz) {
    if (!keep_z[dz + 1]) continue;
    const Wrapped wz = wrap_cell(ci[2], dz, g.n[2]);
    if (run_first >= 0 && (wz.shift != run_shift || wz.cell != run_last + 1)) flush();
    if (run_first < 0) { run_first = wz.cell; run_shift = wz.shift; }
    run_last = wz.cell;
  }
  flush();
}

// The listed partners of particle i (j > i, within r_i + r_j + skin), ascending in (j, image),
// in `found`: the same pairs in the same order as a test of every particle of the 27 cells
// around i's. Skipped: cells whose members all precede i, and cells farther from x_i than
// r_i + r_max + skin.
void search_row(int i, const SearchContext& c, Found& found) {
  found.clear();
  const CellGrid& g = c.grid;
  const int cell = c.cells.cell_of[i];
  const int ci[3] = {cell / (g.n[1] * g.n[2]), (cell / g.n[2]) % g.n[1], cell % g.n[2]};
  double gap2[3][3];
  cell_gaps2(g, (*c.x)[i], ci, gap2);
  const double farthest = (*c.radius)[i] + c.rmax + c.skin, farthest2 = farthest * farthest;
  for (int dx = -1; dx <= 1; ++dx) {
    const Wrapped wx = wrap_cell(ci[0], dx, g.n[0]);
    for (int dy = -1; dy <= 1; ++dy) {
      const double gxy = gap2[0][dx + 1] + gap2[1][dy + 1];
      if (gxy >= farthest2) continue;   // no cell of the column can hold a partner
      const Wrapped wy = wrap_cell(ci[1], dy, g.n[1]);
      const bool keep_z[3] = {gxy + gap2[2][0] < farthest2, true, gxy + gap2[2][2] < farthest2};
      search_column(i, c, wx.cell, wx.shift, wy.cell, wy.shift, ci, keep_z, found);
    }
  }
  std::sort(found.begin(), found.end());   // ascending j: a deterministic, cache-friendly order
}

void prepare_search(SearchContext& c, const std::vector<Vec3>& x, const std::vector<double>& radius, const Box& cell,
                    double skin) {
  c.x = &x;
  c.radius = &radius;
  c.skin = skin;
  c.rmax = max_radius_of(radius);
  c.grid = make_grid(cell, 2.0 * c.rmax + skin);
  c.cells = bin_particles(c.grid, x);
  image_offsets(cell, c.off);
  if (!c.cells.ordered) return;
  const std::size_t n = x.size();
  const double far = std::numeric_limits<double>::infinity();
  for (auto* v : {&c.soa_x, &c.soa_y, &c.soa_z, &c.soa_r}) v->assign(n + 4, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    c.soa_x[i] = x[i].x; c.soa_y[i] = x[i].y; c.soa_z[i] = x[i].z; c.soa_r[i] = radius[i];
  }
  for (std::size_t i = n; i < n + 4; ++i) c.soa_x[i] = c.soa_y[i] = c.soa_z[i] = far;
}

// The rows [begin, end) of the list: their partners and images appended in row order, and each
// row's pair count in count[i - begin].
struct Rows {
  std::vector<std::int32_t> partner, count;
  std::vector<std::uint8_t> image;
};

void search_rows(const SearchContext& c, int begin, int end, Rows& out) {
  out.partner.clear();
  out.image.clear();
  out.count.assign(end - begin, 0);
  Found found;
  for (int i = begin; i < end; ++i) {
    search_row(i, c, found);
    for (auto& f : found) { out.partner.push_back(f.first); out.image.push_back(f.second); }
    out.count[i - begin] = static_cast<std::int32_t>(found.size());
  }
}

// The CSR list from rows searched in chunks, joined in row order (the same list for any chunks).
void join_rows(const std::vector<Rows>& chunks, int n, double rmax, NeighborList& list) {
  std::size_t total = 0;
  for (const Rows& r : chunks) total += r.partner.size();
  list.first.assign(n + 1, 0);
  list.partner.resize(total);
  list.image.resize(total);
  int i = 0;
  std::size_t at = 0;
  for (const Rows& r : chunks) {
    std::copy(r.partner.begin(), r.partner.end(), list.partner.begin() + static_cast<long>(at));
    std::copy(r.image.begin(), r.image.end(), list.image.begin() + static_cast<long>(at));
    at += r.partner.size();
    for (std::int32_t k : r.count) { list.first[i + 1] = list.first[i] + k; ++i; }
  }
  list.radius_max = rmax;
}

// Builds the CSR list from positions x (inside the cell) for the box `cell`, on this thread.
void build_pairs(const std::vector<Vec3>& x, const std::vector<double>& radius, const Box& cell,
                 NeighborList& list) {
  SearchContext c;
  prepare_search(c, x, radius, cell, list.skin);
  std::vector<Rows> rows(1);
  search_rows(c, 0, static_cast<int>(x.size()), rows[0]);
  join_rows(rows, static_cast<int>(x.size()), c.rmax, list);
}

void wrap_into_box(State& s) {
  const Vec3 L = s.box.length;
  if (s.box.tilted()) {
    // Subtract whole lattice vectors, c first (the only one with a z part), then b, then a.
    const Box& b = s.box;
    for (auto& x : s.position) {
      const double nz = std::floor(x.z / L.z);
      x -= b.lattice(0, 0, nz);
      const double ny = std::floor(b.fractional(x).y);
      x -= b.lattice(0, ny, 0);
      const double nx = std::floor(b.fractional(x).x);
      x -= b.lattice(nx, 0, 0);
    }
    return;
  }
  for (auto& x : s.position)
    for (int k = 0; k < 3; ++k) {
      x[k] -= L[k] * std::floor(x[k] / L[k]);
      if (x[k] >= L[k]) x[k] -= L[k];   // floor round-off at the upper edge
      if (x[k] < 0) x[k] = 0;
    }
}

template <class T>
void permute(std::vector<T>& v, const std::vector<std::int32_t>& order) {
  std::vector<T> out(v.size());
  for (std::size_t a = 0; a < order.size(); ++a) out[a] = v[order[a]];
  std::copy(out.begin(), out.end(), v.begin());   // in place: the buffer stays (demtk's numpy views alias it)
}

void sort_by_cell(State& s, double cutoff) {
  CellGrid g = make_grid(s.box, cutoff);
  // By cell, particles of a cell in their present order (a stable counting sort).
  const std::vector<std::int32_t> order = bin_particles(g, s.position).cell_members;
  permute(s.position, order); permute(s.velocity, order); permute(s.force, order);
  permute(s.radius, order); permute(s.mass, order); permute(s.id, order);
  if (s.rotations()) { permute(s.angular_velocity, order); permute(s.torque, order); }
}

}  // namespace

bool pair_search_avx2(bool on) {
  return search_avx2.exchange(on && __builtin_cpu_supports("avx2"));
}

double max_radius_of(const std::vector<double>& radius) {
  double r = 0;
  for (double ri : radius) r = std::max(r, ri);
  return r;
}

namespace {

std::uint64_t pair_key(std::int32_t a, std::int32_t b) {
  const auto lo = static_cast<std::uint32_t>(std::min(a, b)), hi = static_cast<std::uint32_t>(std::max(a, b));
  return (static_cast<std::uint64_t>(lo) << 32) | hi;
}

}  // namespace

void place_history(State& s, const NeighborList& list) {
  State::ContactHistory& h = s.history;
  const int w = h.width;
  if (w == 0) return;
  const std::size_t records = h.ids.size() / 2;
  if (h.values.size() != records * w) throw std::logic_error("place_history: history ids and values disagree");
  // Records that hold anything, by their pair (zero records are what a new pair gets anyway).
  std::unordered_map<std::uint64_t, std::size_t> where;
  where.reserve(records);
  for (std::size_t r = 0; r < records; ++r) {
    const double* v = h.values.data() + r * w;
    if (std::any_of(v, v + w, [](double x) { return x != 0.0; })) where.emplace(pair_key(h.ids[2 * r], h.ids[2 * r + 1]), r);
  }
  const std::size_t pairs = list.partner.size();
  std::vector<double> values(pairs * w, 0.0);
  std::vector<std::int32_t> ids(2 * pairs);
  const int n = static_cast<int>(list.first.size()) - 1;
  for (int i = 0; i < n; ++i)
    for (int p = list.first[i]; p < list.first[i + 1]; ++p) {
      const std::int32_t a = s.id[i], b = s.id[list.partner[p]];
      ids[2 * p] = a; ids[2 * p + 1] = b;
      if (where.empty()) continue;
      const auto it = where.find(pair_key(a, b));
      if (it == where.end()) continue;
      const std::size_t r = it->second;
      const bool swapped = h.ids[2 * r] != a;
      for (int k = 0; k < w; ++k) {
        const double v = h.values[r * w + k];
        values[p * w + k] = (swapped && ((h.odd >> k) & 1u)) ? -v : v;
      }
    }
  h.values.swap(values);
  h.ids.swap(ids);
}

namespace {

// Wraps, sorts, stores the build reference: everything of a build before the pair search.
void prepare_build(State& state, NeighborList& list, double skin, bool sort) {
  list.skin = skin;
  wrap_into_box(state);
  if (sort) sort_by_cell(state, 2.0 * max_radius_of(state.radius) + skin);
  state.position_at_build = state.position;
  state.length_at_build = state.box.length;
  state.tilt_at_build = state.box.tilt;
}

}  // namespace

struct ListRebuild::Impl {
  State* state = nullptr;
  NeighborList* list = nullptr;
  SearchContext context;
  std::vector<Rows> rows;
  std::vector<int> bounds;
};

ListRebuild::ListRebuild() : impl_(std::make_unique<Impl>()) {}
ListRebuild::~ListRebuild() = default;

void ListRebuild::begin(State& state, NeighborList& list, double skin, bool sort, int chunks) {
  Impl& m = *impl_;
  m.state = &state;
  m.list = &list;
  prepare_build(state, list, skin, sort);
  prepare_search(m.context, state.position, state.radius, state.box, skin);
  const int n = state.count();
  chunks = std::max(1, std::min(chunks, n));
  m.rows.resize(chunks);
  m.bounds.resize(chunks + 1);
  for (int k = 0; k <= chunks; ++k) m.bounds[k] = static_cast<int>(static_cast<long>(n) * k / chunks);
}

int ListRebuild::chunks() const { return static_cast<int>(impl_->rows.size()); }

void ListRebuild::search(int chunk) {
  Impl& m = *impl_;
  search_rows(m.context, m.bounds[chunk], m.bounds[chunk + 1], m.rows[chunk]);
}

void ListRebuild::finish() {
  Impl& m = *impl_;
  join_rows(m.rows, m.state->count(), m.context.rmax, *m.list);
  m.state->list_valid = true;
  ++m.list->builds;
  place_history(*m.state, *m.list);   // the history kept its old order (keyed by ids) meanwhile
}

void rebuild_neighbor_list(State& state, NeighborList& list, double skin, bool sort) {
  ListRebuild r;
  r.begin(state, list, skin, sort, 1);
  r.search(0);
  r.finish();
}

void restore_neighbor_list(const State& state, NeighborList& list, double skin) {
  list.skin = skin;
  Box cell;
  cell.length = state.length_at_build;
  cell.tilt = state.tilt_at_build;
  build_pairs(state.position_at_build, state.radius, cell, list);
}

StalenessTest staleness_test(const State& s, const NeighborList& list) {
  StalenessTest t;
  if (!s.list_valid || list.first.size() != s.position.size() + 1) return t;
  const Vec3& tb = s.tilt_at_build;
  if (s.box.tilted() || tb.x != 0 || tb.y != 0 || tb.z != 0) {
    // back = H_b H^-1 (upper triangular); lambda_min = 1 / (largest singular value of back).
    const Box& b = s.box;
    const Eigen::Matrix3d H{{b.length.x, b.tilt.x, b.tilt.y}, {0, b.length.y, b.tilt.z}, {0, 0, b.length.z}};
    const Vec3& Lb = s.length_at_build;
    const Eigen::Matrix3d Hb{{Lb.x, tb.x, tb.y}, {0, Lb.y, tb.z}, {0, 0, Lb.z}};
    const Eigen::Matrix3d back = Hb * H.inverse();
    t.general = true;
    const double U[6] = {back(0, 0), back(1, 1), back(2, 2), back(0, 1), back(0, 2), back(1, 2)};
    std::copy(U, U + 6, t.back);
    const Eigen::Matrix3d BtB = back.transpose() * back;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(BtB, Eigen::EigenvaluesOnly);
    const double sigma_max = std::sqrt(std::max(es.eigenvalues().maxCoeff(), 0.0));
    const double squeeze = std::max(0.0, 2.0 * list.radius_max * (sigma_max - 1.0));
    const double budget = list.skin - squeeze;
    if (!(budget > 0)) return t;
    t.limit2 = 0.25 * budget * budget;
    return t;
  }
  t.frame = Vec3{s.length_at_build.x / s.box.length.x, s.length_at_build.y / s.box.length.y,
                 s.length_at_build.z / s.box.length.z};
  const double lambda_min = 1.0 / std::max({t.frame.x, t.frame.y, t.frame.z});
  const double squeeze = std::max(0.0, 2.0 * list.radius_max * (1.0 / lambda_min - 1.0));
  const double budget = list.skin - squeeze;
  if (budget <= 0) return t;
  t.limit2 = 0.25 * budget * budget;   // u_max < budget / 2
  return t;
}

bool neighbor_list_stale(const State& s, const NeighborList& list) {
  const StalenessTest t = staleness_test(s, list);
  if (t.limit2 < 0) return true;
  for (int i = 0; i < s.count(); ++i)
    if (displacement2_since_build(s, t, i) >= t.limit2) return true;
  return false;
}

}  // namespace dem
