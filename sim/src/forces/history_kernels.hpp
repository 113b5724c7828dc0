// The vectorised pair kernels of the models with per-contact history (friction, rolling,
// twisting, Luding's normal law), internal to forces.cpp. Templates on the composed contact
// model (anything with_contact_model hands over whose sub-models have lane bodies:
// ContactModel::vectorised), so a new sub-model with a lane-templated body runs here without
// being named.
//
// The design is pair_kernels.hpp's: two passes over chunks of kChunk listed pairs. (1) The
// kernel gathers W pairs into lanes (W = 2 generic, 4 AVX2, 8 AVX-512), loads their history
// (stored per listed pair: contiguous for a chunk), calls the model's one body
// (ContactModel::advance, the same the scalar reference loop calls with T = double), and writes
// per pair the force on j, the torques on i and j, the dissipated energy (all -0.0 for a pair
// out of contact: adding them changes nothing) and the new history (zero out of contact). Every
// operation is the scalar code's IEEE operation in its order (no FMA: the file that includes
// this is built with -ffp-contract=off; sqrt and division are exact), so every lane gives the
// reference bits. (2) A scalar pass adds them in list order as pair_loop_history does; the
// dissipation is summed in the same order.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <cstdint>
#include <cstring>

#include "dem/contact/contact_model.hpp"
#include "forces/pair_kernels.hpp"

namespace dem::kernels {

/// Per pair of a chunk: force on j [N], torques on i and j [N m], dissipated energy [J].
struct HistoryChunk {
  alignas(64) double fx[kChunk];
  alignas(64) double fy[kChunk];
  alignas(64) double fz[kChunk];
  alignas(64) double tix[kChunk];
  alignas(64) double tiy[kChunk];
  alignas(64) double tiz[kChunk];
  alignas(64) double tjx[kChunk];
  alignas(64) double tjy[kChunk];
  alignas(64) double tjz[kChunk];
  alignas(64) double d[kChunk];
};

template <class CM>
struct HistoryInputs {
  const double* packed;        ///< per particle: x y z r vx vy vz m (ForceScratch::packed) [m, m/s, kg]
  const std::int32_t* pair_i;  ///< i of each pair
  const std::int32_t* partner;
  const std::uint8_t* image;
  const double* off;           ///< 27 image offsets, x y z 0 each [m]
  const Vec3* w;               ///< angular velocities [1/s] (rotating models)
  CM model;
  VelGrad rate;                ///< [1/s]
  double dt;                   ///< [s]
  double* history;             ///< State::history.values (CM::history per listed pair)
};

#define DEM_HK __attribute__((always_inline)) inline

/// Lanes of T to W doubles at `to` (the 64-byte aligned chunk arrays, q a multiple of W).
template <class T> DEM_HK void store(double* to, T v) { *reinterpret_cast<T*>(to) = v; }

typedef double V2 __attribute__((vector_size(16)));
typedef double V4 __attribute__((vector_size(32)));
template <class T> DEM_HK T load_unaligned(const double* from) {
  T v;
  std::memcpy(&v, from, sizeof(T));
  return v;
}
template <class T> DEM_HK void store_unaligned(double* to, T v) { std::memcpy(to, &v, sizeof(T)); }

/// Where lane l's row starts: base + stride * idx[l] (particle records, image offsets: the index
/// read again at each use, so that 8 lanes do not keep 8 addresses per record in registers) or
/// base + stride * l (the history of consecutive pairs).
template <class Index> struct Indexed {
  const double* base;
  const Index* idx;
  long stride;
  DEM_HK const double* operator[](int l) const { return base + stride * idx[l]; }
};
struct Consecutive {
  double* base;
  long stride;
  DEM_HK double* operator[](int l) const { return base + stride * l; }
};

/// Lanes first .. of rows (the upper half of 8 lanes).
template <class Rows> struct Shifted {
  const Rows& rows;
  int first;
  DEM_HK auto operator[](int l) const { return rows[first + l]; }
};

/// Width 4 by hand (AVX2 intrinsics, as the frictionless kernel's load4): with GCC's vector
/// shuffles, GCC 12 loads each upper half into a register and inserts it (two instructions);
/// its intrinsics fold the load into vinsertf128. Not always_inline (an always_inline function
/// cannot carry a target the generic templates calling it lack): the kernels that reach it
/// (history_avx2, history_avx512) are `flatten`, so it is inlined there.
#define DEM_HK_AVX2 __attribute__((target("avx2"))) inline
/// Doubles 0-3 of rows r0 .. r3 as the columns a b c d.
DEM_HK_AVX2 void rows4(const double* r0, const double* r1, const double* r2, const double* r3, lanes::L4& a,
                       lanes::L4& b, lanes::L4& c, lanes::L4& d) {
  const __m256d t0 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r0)), _mm_loadu_pd(r2), 1);
  const __m256d t1 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r1)), _mm_loadu_pd(r3), 1);
  const __m256d t2 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r0 + 2)), _mm_loadu_pd(r2 + 2), 1);
  const __m256d t3 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r1 + 2)), _mm_loadu_pd(r3 + 2), 1);
  a = (lanes::L4)_mm256_unpacklo_pd(t0, t1);   // r0[0] r1[0] r2[0] r3[0]
  b = (lanes::L4)_mm256_unpackhi_pd(t0, t1);
  c = (lanes::L4)_mm256_unpacklo_pd(t2, t3);
  d = (lanes::L4)_mm256_unpackhi_pd(t2, t3);
}
/// Doubles 0-2 of rows r0 .. r3 (Vec3: no fourth double to read) as the columns a b c.
DEM_HK_AVX2 void rows4_3(const double* r0, const double* r1, const double* r2, const double* r3, lanes::L4& a,
                         lanes::L4& b, lanes::L4& c) {
  const __m256d t0 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r0)), _mm_loadu_pd(r2), 1);
  const __m256d t1 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(r1)), _mm_loadu_pd(r3), 1);
  const __m128d lo = _mm_loadh_pd(_mm_load_sd(r0 + 2), r1 + 2), hi = _mm_loadh_pd(_mm_load_sd(r2 + 2), r3 + 2);
  a = (lanes::L4)_mm256_unpacklo_pd(t0, t1);
  b = (lanes::L4)_mm256_unpackhi_pd(t0, t1);
  c = (lanes::L4)_mm256_insertf128_pd(_mm256_castpd128_pd256(lo), hi, 1);
}

/// Four consecutive doubles of each lane's row (row[l], l < W) as four lane values a b c d
/// (column 0 .. 3): two-double halves transposed (as the frictionless AVX2 kernel's load4): 4
/// lanes by rows4, 2 lanes with GCC's vector shuffles; 8 lanes are two groups of 4 joined.
template <class T, class Rows> DEM_HK void load_block(const Rows& row, T& a, T& b, T& c, T& d) {
  if constexpr (lanes::width<T> == 8) {
    V4 a0, b0, c0, d0, a1, b1, c1, d1;
    load_block<V4>(row, a0, b0, c0, d0);
    load_block<V4>(Shifted<Rows>{row, 4}, a1, b1, c1, d1);
    a = __builtin_shufflevector(a0, a1, 0, 1, 2, 3, 4, 5, 6, 7);
    b = __builtin_shufflevector(b0, b1, 0, 1, 2, 3, 4, 5, 6, 7);
    c = __builtin_shufflevector(c0, c1, 0, 1, 2, 3, 4, 5, 6, 7);
    d = __builtin_shufflevector(d0, d1, 0, 1, 2, 3, 4, 5, 6, 7);
  } else if constexpr (lanes::width<T> == 4) {
    rows4(row[0], row[1], row[2], row[3], a, b, c, d);
  } else {
    static_assert(lanes::width<T> == 2);
    for (int half = 0; half < 2; ++half) {
      const V2 h0 = load_unaligned<V2>(row[0] + 2 * half), h1 = load_unaligned<V2>(row[1] + 2 * half);
      (half ? c : a) = __builtin_shufflevector(h0, h1, 0, 2);
      (half ? d : b) = __builtin_shufflevector(h0, h1, 1, 3);
    }
  }
}

/// load_block's inverse: columns a b c d back to four consecutive doubles of each lane's row.
template <class T, class Rows> DEM_HK void store_block(const Rows& row, T a, T b, T c, T d) {
  if constexpr (lanes::width<T> == 8) {
    store_block<V4>(row, __builtin_shufflevector(a, a, 0, 1, 2, 3), __builtin_shufflevector(b, b, 0, 1, 2, 3),
                    __builtin_shufflevector(c, c, 0, 1, 2, 3), __builtin_shufflevector(d, d, 0, 1, 2, 3));
    store_block<V4>(Shifted<Rows>{row, 4}, __builtin_shufflevector(a, a, 4, 5, 6, 7), __builtin_shufflevector(b, b, 4, 5, 6, 7),
                    __builtin_shufflevector(c, c, 4, 5, 6, 7), __builtin_shufflevector(d, d, 4, 5, 6, 7));
  } else if constexpr (lanes::width<T> == 4) {
    const T t0 = __builtin_shufflevector(a, b, 0, 4, 2, 6);   // a0 b0 a2 b2
    const T t1 = __builtin_shufflevector(a, b, 1, 5, 3, 7);   // a1 b1 a3 b3
    const T t2 = __builtin_shufflevector(c, d, 0, 4, 2, 6);   // c0 d0 c2 d2
    const T t3 = __builtin_shufflevector(c, d, 1, 5, 3, 7);   // c1 d1 c3 d3
    store_unaligned(row[0], __builtin_shufflevector(t0, t2, 0, 1, 4, 5));
    store_unaligned(row[1], __builtin_shufflevector(t1, t3, 0, 1, 4, 5));
    store_unaligned(row[2], __builtin_shufflevector(t0, t2, 2, 3, 6, 7));
    store_unaligned(row[3], __builtin_shufflevector(t1, t3, 2, 3, 6, 7));
  } else {
    static_assert(lanes::width<T> == 2);
    store_unaligned(row[0], V2{a[0], b[0]});
    store_unaligned(row[0] + 2, V2{c[0], d[0]});
    store_unaligned(row[1], V2{a[1], b[1]});
    store_unaligned(row[1] + 2, V2{c[1], d[1]});
  }
}

/// Entries 0-2 of each lane's row (the angular velocities, Vec3: no fourth entry to read):
/// entries 0-1 as two-double halves, transposed, entry 2 lane by lane.
template <class T, class Rows> DEM_HK void load_block3(const Rows& row, T& a, T& b, T& c) {
  if constexpr (lanes::width<T> == 8) {
    V4 a0, b0, c0, a1, b1, c1;
    load_block3<V4>(row, a0, b0, c0);
    load_block3<V4>(Shifted<Rows>{row, 4}, a1, b1, c1);
    a = __builtin_shufflevector(a0, a1, 0, 1, 2, 3, 4, 5, 6, 7);
    b = __builtin_shufflevector(b0, b1, 0, 1, 2, 3, 4, 5, 6, 7);
    c = __builtin_shufflevector(c0, c1, 0, 1, 2, 3, 4, 5, 6, 7);
  } else if constexpr (lanes::width<T> == 4) {
    rows4_3(row[0], row[1], row[2], row[3], a, b, c);
  } else {
    const V2 h0 = load_unaligned<V2>(row[0]), h1 = load_unaligned<V2>(row[1]);
    a = __builtin_shufflevector(h0, h1, 0, 2);
    b = __builtin_shufflevector(h0, h1, 1, 3);
    c = T{row[0][2], row[1][2]};
  }
}

/// The history of W consecutive pairs (rows of CM::history doubles from H) into lanes h[k], and
/// back: blocks of four columns transposed (a width that is not a multiple of 4 ends with a
/// block overlapping the one before it: its shared columns are loaded and stored twice, with
/// the same values); fewer than four columns lane by lane.
template <class T, int kw> DEM_HK void load_history(const double* H, T* h) {
  constexpr int W = lanes::width<T>;
  if constexpr (kw >= 4) {
    for (int k0 = 0; k0 < kw; k0 += 4) {
      const int k = k0 + 4 <= kw ? k0 : kw - 4;
      load_block(Consecutive{const_cast<double*>(H) + k, kw}, h[k], h[k + 1], h[k + 2], h[k + 3]);
    }
  } else {
    for (int k = 0; k < kw; ++k)
      for (int l = 0; l < W; ++l) h[k][l] = H[kw * l + k];
  }
}
template <class T, int kw> DEM_HK void store_history(double* H, const T* h) {
  constexpr int W = lanes::width<T>;
  if constexpr (kw >= 4) {
    for (int k0 = 0; k0 < kw; k0 += 4) {
      const int k = k0 + 4 <= kw ? k0 : kw - 4;
      store_block(Consecutive{H + k, kw}, h[k], h[k + 1], h[k + 2], h[k + 3]);
    }
  } else {
    for (int k = 0; k < kw; ++k)
      for (int l = 0; l < W; ++l) H[kw * l + k] = h[k][l];
  }
}

/// One group of W pairs (indices I, J, images C; their history rows at H, CM::history doubles
/// each), results at out[q .. q+W).
template <class T, bool Sheared, class CM, class Image>
DEM_HK void history_group(const HistoryInputs<CM>& in, const CM& model, const contact::RateLanes<T>& rate, T dt,
                          const std::int32_t* I, const std::int32_t* J, const Image* C, double* H,
                          HistoryChunk& out, int q) {
  using lanes::select;
  constexpr int W = lanes::width<T>, kw = CM::history;
  const T mz = lanes::splat<T>(-0.0), zero = lanes::splat<T>(0.0);
  const double* P = in.packed;
  T xi, yi, zi, ri, xj, yj, zj, rj, ox, oy, oz, pad;
  load_block(Indexed<std::int32_t>{P, I, 8}, xi, yi, zi, ri);
  load_block(Indexed<std::int32_t>{P, J, 8}, xj, yj, zj, rj);
  load_block(Indexed<Image>{in.off, C, 4}, ox, oy, oz, pad);
  contact::Separation<T> sep = contact::separation(xi, yi, zi, ri, xj + ox, yj + oy, zj + oz, rj);
  const auto touch = contact::touching(sep);
  if (!lanes::any(touch)) {   // no contact in the group: nothing to add, the springs end
    for (double* a : {out.fx, out.fy, out.fz, out.tix, out.tiy, out.tiz, out.tjx, out.tjy, out.tjz, out.d})
      store(a + q, mz);
    std::fill(H, H + kw * W, 0.0);
    return;
  }
  // (Loading the velocities and angular velocities with the positions, without this exit,
  // runs fewer instructions, 854.9 against 873.9 per frictional particle-step, but timed
  // slower: the angular velocities stay live through the normal law and are spilled;
  // docs/benchmarks.md, "Friction on the vector kernels, the loads".)
  T h[kw > 0 ? kw : 1];
  load_history<T, kw>(H, h);
  contact::V3<T> wi{zero, zero, zero}, wj{zero, zero, zero};
  if constexpr (CM::rotations) {
    load_block3(Indexed<std::int32_t>{&in.w[0].x, I, 3}, wi.x, wi.y, wi.z);
    load_block3(Indexed<std::int32_t>{&in.w[0].x, J, 3}, wj.x, wj.y, wj.z);
  }
  T vxi, vyi, vzi, vxj, vyj, vzj, mi, mj;   // velocities and masses: entries 4-7 of the records
  load_block(Indexed<std::int32_t>{P + 4, I, 8}, vxi, vyi, vzi, mi);
  load_block(Indexed<std::int32_t>{P + 4, J, 8}, vxj, vyj, vzj, mj);
  // (the masses are read only by a sub-model of the pair, per_pair: Hertz; they came lane by lane
  // from State::mass before: the Hertz-Mindlin kernel 546.2 -> 523.3 instructions per
  // particle-step, docs/benchmarks.md)
  contact::PairForces<T> c =
      model.template advance<Sheared>(sep, ri, rj, mi, mj, vxj - vxi, vyj - vyi, vzj - vzi, wi, wj, rate, dt, h);
  store(out.fx + q, select(touch, c.fj.x, mz));
  store(out.fy + q, select(touch, c.fj.y, mz));
  store(out.fz + q, select(touch, c.fj.z, mz));
  store(out.tix + q, select(touch, c.ti.x, mz));
  store(out.tiy + q, select(touch, c.ti.y, mz));
  store(out.tiz + q, select(touch, c.ti.z, mz));
  store(out.tjx + q, select(touch, c.tj.x, mz));
  store(out.tjy + q, select(touch, c.tj.y, mz));
  store(out.tjz + q, select(touch, c.tj.z, mz));
  store(out.d + q, select(touch, c.dissipated, mz));
  for (int k = 0; k < kw; ++k) h[k] = select(touch, h[k], zero);   // out of contact: the springs end
  store_history<T, kw>(H, h);
}

/// Pass 1 of a chunk for lanes of T: pairs p0 .. p0+n-1. Whole groups of W pairs read their
/// indices and history in place; a short last group runs on copies padded with its last pair
/// (only its own pairs' history is written back: the pairs after it belong to the next chunk
/// or to another block's thread).
template <class T, bool Sheared, class CM>
DEM_HK void history_body(const HistoryInputs<CM>& given, long p0, int n, HistoryChunk& out) {
  constexpr int W = lanes::width<T>, kw = CM::history;
  // A local copy (not const: GCC keeps const aggregates in memory): through the reference GCC
  // reloaded every pointer of the inputs after each group's stores (the history's and the
  // chunk's may alias `given` for all it knows); a local whose address does not escape they
  // cannot.
  HistoryInputs<CM> in = given;
  contact::RateLanes<T> rate = contact::rate_lanes<T>(in.rate);   // not const: GCC keeps const aggregates in memory
  const T dt = lanes::splat<T>(in.dt);
  const CM model = in.model;   // a local copy: its constants (k, -1/k, ...) leave the loop
  const int whole = n / W * W;
  for (int q = 0; q < whole; q += W) {
    const long p = p0 + q;
    history_group<T, Sheared>(in, model, rate, dt, in.pair_i + p, in.partner + p, in.image + p, in.history + kw * p,
                              out, q);
  }
  if (whole == n) return;
  const int valid = n - whole;
  std::int32_t I[W], J[W];
  std::uint8_t C[W];
  alignas(64) double H[W * (kw > 0 ? kw : 1)];
  for (int l = 0; l < W; ++l) {
    const long p = p0 + whole + std::min(l, valid - 1);
    I[l] = in.pair_i[p]; J[l] = in.partner[p]; C[l] = in.image[p];
    std::copy(in.history + kw * p, in.history + kw * (p + 1), H + kw * l);
  }
  history_group<T, Sheared>(in, model, rate, dt, I, J, C, H, out, whole);
  std::copy(H, H + kw * valid, in.history + kw * (p0 + whole));
}
#undef DEM_HK
#undef DEM_HK_AVX2

template <class CM>
using HistoryKernelFn = void (*)(const HistoryInputs<CM>&, long p0, int n, HistoryChunk& out);

// One kernel per instruction set: the same body on 2, 4 or 8 lanes.
template <bool Sheared, class CM>
void history_generic(const HistoryInputs<CM>& in, long p0, int n, HistoryChunk& out) {
  history_body<lanes::L2, Sheared>(in, p0, n, out);
}
template <bool Sheared, class CM>
__attribute__((target("avx2"), flatten)) void history_avx2(const HistoryInputs<CM>& in, long p0, int n, HistoryChunk& out) {
  history_body<lanes::L4, Sheared>(in, p0, n, out);
}
template <bool Sheared, class CM>
__attribute__((target("avx512f,avx512vl,avx512dq"), flatten)) void history_avx512(const HistoryInputs<CM>& in, long p0, int n,
                                                                            HistoryChunk& out) {
  history_body<lanes::L8, Sheared>(in, p0, n, out);
}

/// The history kernel of `kernel` (not reference).
template <bool Sheared, class CM>
HistoryKernelFn<CM> history_kernel_of(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::avx512: return history_avx512<Sheared, CM>;
    case PairKernel::avx2: return history_avx2<Sheared, CM>;
    default: return history_generic<Sheared, CM>;
  }
}

}  // namespace dem::kernels
