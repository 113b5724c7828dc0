#include "dem/forces/neighbor_list.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
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
  int index_of(const Vec3& x) const {
    int c[3];
    if (tilted) {
      const Vec3 s = tilted->fractional(x);
      for (int k = 0; k < 3; ++k) {
        c[k] = static_cast<int>(std::floor(s[k] * n[k]));
        c[k] = std::min(std::max(c[k], 0), n[k] - 1);
      }
    } else {
      for (int k = 0; k < 3; ++k) {
        c[k] = static_cast<int>(x[k] * inv_size[k]);
        c[k] = std::min(std::max(c[k], 0), n[k] - 1);
      }
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
          " m: use more particles or a smaller skin");
    g.n[k] = std::max(1, static_cast<int>(width[k] / cutoff));
    g.inv_size[k] = g.n[k] / b.length[k];
  }
  if (tilted) g.tilted = &b;
  return g;
}

// The linked cells of one build: the cell of each particle and the members of each cell
// (particle indices, ascending within a cell: a counting sort, stable in i).
struct CellLists {
  std::vector<std::int32_t> cell_of, cell_start, cell_members;
};

CellLists bin_particles(const CellGrid& g, const std::vector<Vec3>& x) {
  const int n = static_cast<int>(x.size());
  const int ncell = g.n[0] * g.n[1] * g.n[2];
  CellLists c;
  c.cell_of.resize(n);
  c.cell_start.assign(ncell + 1, 0);
  c.cell_members.resize(n);
  for (int i = 0; i < n; ++i) { c.cell_of[i] = g.index_of(x[i]); ++c.cell_start[c.cell_of[i] + 1]; }
  for (int k = 0; k < ncell; ++k) c.cell_start[k + 1] += c.cell_start[k];
  std::vector<std::int32_t> fill(c.cell_start.begin(), c.cell_start.end() - 1);
  for (int i = 0; i < n; ++i) c.cell_members[fill[c.cell_of[i]]++] = i;
  return c;
}

// The 27-cell stencil of every cell as (neighbour cell, periodic image) entries. With fewer
// than 3 cells along an axis neighbour cells repeat: each distinct (cell, image) once.
struct Stencils {
  std::vector<std::int32_t> start, cell;
  std::vector<std::uint8_t> image;
  std::vector<std::uint8_t> offset;   ///< (dx+1) | (dy+1) << 2 | (dz+1) << 4: where it lies from the own cell
};

Stencils make_stencils(const CellGrid& g) {
  const int ncell = g.n[0] * g.n[1] * g.n[2];
  const bool small = g.n[0] < 3 || g.n[1] < 3 || g.n[2] < 3;
  Stencils st;
  st.start.assign(ncell + 1, 0);
  st.cell.reserve(27L * ncell);
  st.image.reserve(27L * ncell);
  st.offset.reserve(27L * ncell);
  for (int c = 0; c < ncell; ++c) {
    const int ci[3] = {c / (g.n[1] * g.n[2]), (c / g.n[2]) % g.n[1], c % g.n[2]};
    const std::size_t first = st.cell.size();
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const int d[3] = {dx, dy, dz};
          int cc[3], sh[3];
          for (int k = 0; k < 3; ++k) {
            int v = ci[k] + d[k];
            sh[k] = 0;
            if (v < 0) { v += g.n[k]; sh[k] = -1; }
            if (v >= g.n[k]) { v -= g.n[k]; sh[k] = 1; }
            cc[k] = v;
          }
          const int cell = (cc[0] * g.n[1] + cc[1]) * g.n[2] + cc[2];
          const int img = (sh[0] + 1) * 9 + (sh[1] + 1) * 3 + (sh[2] + 1);
          bool dup = false;
          if (small)
            for (std::size_t q = first; q < st.cell.size(); ++q) dup |= (st.cell[q] == cell && st.image[q] == img);
          if (!dup) {
            st.cell.push_back(cell);
            st.image.push_back(static_cast<std::uint8_t>(img));
            st.offset.push_back(static_cast<std::uint8_t>((dx + 1) | (dy + 1) << 2 | (dz + 1) << 4));
          }
        }
    st.start[c + 1] = static_cast<std::int32_t>(st.cell.size());
  }
  return st;
}

// Squared gaps between particle i and the cells around its own, per axis: gap2[k][d + 1] for
// the neighbour at offset d = -1, 0, 1 along axis k (0 for d = 0, and everywhere in a tilted
// cell, where cells are slabs of fractional coordinates: no pruning there) [m^2]. Shrunk by a
// margin far above the round-off of the cell index, so no cell that could hold a partner is pruned.
void cell_gaps2(const CellGrid& g, const Vec3& x, int cell, double gap2[3][3]) {
  for (int k = 0; k < 3; ++k) gap2[k][0] = gap2[k][1] = gap2[k][2] = 0.0;
  if (g.tilted) return;
  const int ci[3] = {cell / (g.n[1] * g.n[2]), (cell / g.n[2]) % g.n[1], cell % g.n[2]};
  for (int k = 0; k < 3; ++k) {
    const double size = 1.0 / g.inv_size[k], margin = 1e-9 * size * g.n[k];
    const double below = std::max(0.0, x[k] - ci[k] * size - margin);
    const double above = std::max(0.0, (ci[k] + 1) * size - x[k] - margin);
    gap2[k][0] = below * below;
    gap2[k][2] = above * above;
  }
}

// The listed partners of particle i (j > i, within r_i + r_j + skin), ascending in (j, image),
// in `found`: the same pairs in the same order as a test of every particle of the 27 cells.
// Skipped: cells whose members all precede i, and cells farther from x_i than r_i + r_max + skin.
void search_row(int i, const std::vector<Vec3>& x, const std::vector<double>& radius, double skin, double rmax,
                const CellGrid& g, const CellLists& cl, const Stencils& st, const Vec3 off[27],
                std::vector<std::pair<std::int32_t, std::uint8_t>>& found) {
  found.clear();
  const int c = cl.cell_of[i];
  const Vec3 xi = x[i];
  const double ri = radius[i];
  double gap2[3][3];
  cell_gaps2(g, xi, c, gap2);
  const double farthest = ri + rmax + skin, farthest2 = farthest * farthest;
  for (int q = st.start[c]; q < st.start[c + 1]; ++q) {
    const std::int32_t* m0 = cl.cell_members.data() + cl.cell_start[st.cell[q]];
    const std::int32_t* m1 = cl.cell_members.data() + cl.cell_start[st.cell[q] + 1];
    if (m0 == m1 || m1[-1] <= i) continue;             // members ascend: none with j > i
    const int d = st.offset[q];
    if (gap2[0][d & 3] + gap2[1][(d >> 2) & 3] + gap2[2][d >> 4] >= farthest2) continue;   // none can reach x_i
    const Vec3& o = off[st.image[q]];
    for (const std::int32_t* m = std::upper_bound(m0, m1, i); m < m1; ++m) {
      const int j = *m;
      const Vec3 d = x[j] + o - xi;
      const double reach = ri + radius[j] + skin;   // the operations of the oracle's cutoff, in order
      if (dot(d, d) < reach * reach) found.emplace_back(j, st.image[q]);
    }
  }
  std::sort(found.begin(), found.end());   // ascending j: a deterministic, cache-friendly order
}

// What a pair search needs: the grid, its cells and stencils, the image offsets.
struct SearchContext {
  const std::vector<Vec3>* x = nullptr;
  const std::vector<double>* radius = nullptr;
  double skin = 0, rmax = 0;
  CellGrid grid{};
  CellLists cells;
  Stencils stencils;
  Vec3 off[27];
};

void prepare_search(SearchContext& c, const std::vector<Vec3>& x, const std::vector<double>& radius, const Box& cell,
                    double skin) {
  c.x = &x;
  c.radius = &radius;
  c.skin = skin;
  c.rmax = max_radius_of(radius);
  c.grid = make_grid(cell, 2.0 * c.rmax + skin);
  c.cells = bin_particles(c.grid, x);
  c.stencils = make_stencils(c.grid);
  image_offsets(cell, c.off);
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
  std::vector<std::pair<std::int32_t, std::uint8_t>> found;
  for (int i = begin; i < end; ++i) {
    search_row(i, *c.x, *c.radius, c.skin, c.rmax, c.grid, c.cells, c.stencils, c.off, found);
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
