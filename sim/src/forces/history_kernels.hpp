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
  const double* packed;        ///< per particle: x y z r vx vy vz 0 (ForceScratch::packed) [m, m/s]
  const std::int32_t* pair_i;  ///< i of each pair
  const std::int32_t* partner;
  const std::uint8_t* image;
  const double* off;           ///< 27 image offsets, x y z 0 each [m]
  const Vec3* w;               ///< angular velocities [1/s] (rotating models)
  CM model;
  VelGrad rate;                ///< [1/s]
  double dt;                   ///< [s]
  double* history;             ///< State::history.values (CM::history per listed pair)
  const double* mass;          ///< per particle [kg] (read when a sub-model is per_pair)
};

#define DEM_HK __attribute__((always_inline)) inline

template <class T> DEM_HK void store(double* to, T v) { std::memcpy(to, &v, sizeof(T)); }

/// Lane l of T: entry `field` of the record of index idx[l] (records of `stride` doubles).
template <class T> DEM_HK T gather(const double* base, const std::int32_t* idx, long stride, int field) {
  T r;
  for (int l = 0; l < T::width; ++l) r.v[l] = base[stride * idx[l] + field];
  return r;
}

/// Entries 0-3 of the records at base + stride * idx[l] as four lane values (a b c d), loaded as
/// two-double halves and transposed (as the frictionless AVX2 kernel's load4, written with GCC's
/// vector shuffles so that one source serves every target); lanes of 8 are gathered.
template <class T> DEM_HK void load_columns(const double* base, const std::int32_t* idx, long stride, T& a, T& b,
                                            T& c, T& d) {
  if constexpr (T::width == 4) {
    typedef double V2 __attribute__((vector_size(16)));
    const double *r0 = base + stride * idx[0], *r1 = base + stride * idx[1], *r2 = base + stride * idx[2],
                 *r3 = base + stride * idx[3];
    V2 h0, h1, h2, h3;   // entries 0-1 of records 0-3
    std::memcpy(&h0, r0, 16); std::memcpy(&h1, r1, 16); std::memcpy(&h2, r2, 16); std::memcpy(&h3, r3, 16);
    typename T::V t0 = __builtin_shufflevector(h0, h2, 0, 1, 2, 3);   // r0 r0 r2 r2
    typename T::V t1 = __builtin_shufflevector(h1, h3, 0, 1, 2, 3);   // r1 r1 r3 r3
    a.v = __builtin_shufflevector(t0, t1, 0, 4, 2, 6);
    b.v = __builtin_shufflevector(t0, t1, 1, 5, 3, 7);
    std::memcpy(&h0, r0 + 2, 16); std::memcpy(&h1, r1 + 2, 16); std::memcpy(&h2, r2 + 2, 16); std::memcpy(&h3, r3 + 2, 16);
    t0 = __builtin_shufflevector(h0, h2, 0, 1, 2, 3);
    t1 = __builtin_shufflevector(h1, h3, 0, 1, 2, 3);
    c.v = __builtin_shufflevector(t0, t1, 0, 4, 2, 6);
    d.v = __builtin_shufflevector(t0, t1, 1, 5, 3, 7);
  } else if constexpr (T::width == 2) {
    typedef double V2 __attribute__((vector_size(16)));
    const double *r0 = base + stride * idx[0], *r1 = base + stride * idx[1];
    V2 h0, h1;
    std::memcpy(&h0, r0, 16); std::memcpy(&h1, r1, 16);
    a.v = __builtin_shufflevector(h0, h1, 0, 2);
    b.v = __builtin_shufflevector(h0, h1, 1, 3);
    std::memcpy(&h0, r0 + 2, 16); std::memcpy(&h1, r1 + 2, 16);
    c.v = __builtin_shufflevector(h0, h1, 0, 2);
    d.v = __builtin_shufflevector(h0, h1, 1, 3);
  } else {
    a = gather<T>(base, idx, stride, 0);
    b = gather<T>(base, idx, stride, 1);
    c = gather<T>(base, idx, stride, 2);
    d = gather<T>(base, idx, stride, 3);
  }
}

/// Entries 0-2 of records of `stride` doubles (the angular velocities, Vec3: no fourth entry to
/// read): entries 0-1 as two-double halves, transposed, entry 2 gathered.
template <class T> DEM_HK void load_columns3(const double* base, const std::int32_t* idx, long stride, T& a, T& b,
                                             T& c) {
  if constexpr (T::width == 4) {
    typedef double V2 __attribute__((vector_size(16)));
    V2 h0, h1, h2, h3;
    std::memcpy(&h0, base + stride * idx[0], 16); std::memcpy(&h1, base + stride * idx[1], 16);
    std::memcpy(&h2, base + stride * idx[2], 16); std::memcpy(&h3, base + stride * idx[3], 16);
    const typename T::V t0 = __builtin_shufflevector(h0, h2, 0, 1, 2, 3);
    const typename T::V t1 = __builtin_shufflevector(h1, h3, 0, 1, 2, 3);
    a.v = __builtin_shufflevector(t0, t1, 0, 4, 2, 6);
    b.v = __builtin_shufflevector(t0, t1, 1, 5, 3, 7);
  } else {
    a = gather<T>(base, idx, stride, 0);
    b = gather<T>(base, idx, stride, 1);
  }
  c = gather<T>(base, idx, stride, 2);
}

/// Pass 1 of a chunk for lanes of T: pairs p0 .. p0+n-1.
template <class T, bool Sheared, class CM>
DEM_HK void history_body(const HistoryInputs<CM>& in, long p0, int n, HistoryChunk& out) {
  using lanes::select;
  using lanes::splat;
  constexpr int W = T::width, kw = CM::history;
  const auto rate = contact::rate_lanes<T>(in.rate);
  const T dt = splat<T>(in.dt), mz = splat<T>(-0.0), zero = splat<T>(0.0);
  const double* P = in.packed;
  const CM model = in.model;   // a local copy: its constants (k, -1/k, ...) leave the loop
  for (int q = 0; q < n; q += W) {
    const int valid = std::min(W, n - q);   // a short last group repeats its last pair (not written back)
    std::int32_t I[W], J[W], C[W];
    for (int l = 0; l < W; ++l) {
      const long p = p0 + q + std::min(l, valid - 1);
      I[l] = in.pair_i[p]; J[l] = in.partner[p]; C[l] = in.image[p];
    }
    double* H = in.history + kw * (p0 + q);
    T xi, yi, zi, ri, xj, yj, zj, rj, ox, oy, oz, pad;
    load_columns(P, I, 8, xi, yi, zi, ri);
    load_columns(P, J, 8, xj, yj, zj, rj);
    load_columns(in.off, C, 4, ox, oy, oz, pad);
    const contact::Separation<T> sep = contact::separation(xi, yi, zi, ri, xj + ox, yj + oy, zj + oz, rj);
    const auto touch = contact::touching(sep);
    if (!lanes::any(touch)) {   // no contact in the group: nothing to add, the springs end
      for (double* a : {out.fx, out.fy, out.fz, out.tix, out.tiy, out.tiz, out.tjx, out.tjy, out.tjz, out.d})
        store(a + q, mz);
      std::fill(H, H + kw * valid, 0.0);
      continue;
    }
    T h[kw > 0 ? kw : 1];
    std::int32_t L[W];   // the group's pairs, relative to its first
    for (int l = 0; l < W; ++l) L[l] = std::min(l, valid - 1);
    for (int k = 0; k + 4 <= kw; k += 4) load_columns(H + k, L, kw, h[k], h[k + 1], h[k + 2], h[k + 3]);
    for (int k = kw / 4 * 4; k < kw; ++k) h[k] = gather<T>(H, L, kw, k);
    contact::V3<T> wi{zero, zero, zero}, wj{zero, zero, zero};
    if constexpr (CM::rotations) {
      const double* w = &in.w[0].x;
      load_columns3(w, I, 3, wi.x, wi.y, wi.z);
      load_columns3(w, J, 3, wj.x, wj.y, wj.z);
    }
    T vxi, vyi, vzi, vxj, vyj, vzj;
    load_columns(P + 4, I, 8, vxi, vyi, vzi, pad);
    load_columns(P + 4, J, 8, vxj, vyj, vzj, pad);
    T mi = zero, mj = zero;
    if constexpr (CM::per_pair) { mi = gather<T>(in.mass, I, 1, 0); mj = gather<T>(in.mass, J, 1, 0); }
    const contact::PairForces<T> c =
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
    for (int k = 0; k < kw; ++k) {
      const T hk = select(touch, h[k], zero);
      for (int l = 0; l < valid; ++l) H[kw * l + k] = hk.v[l];
    }
  }
}
#undef DEM_HK

template <class CM>
using HistoryKernelFn = void (*)(const HistoryInputs<CM>&, long p0, int n, HistoryChunk& out);

// One kernel per instruction set: the same body on 2, 4 or 8 lanes.
template <bool Sheared, class CM>
void history_generic(const HistoryInputs<CM>& in, long p0, int n, HistoryChunk& out) {
  history_body<lanes::L2, Sheared>(in, p0, n, out);
}
template <bool Sheared, class CM>
__attribute__((target("avx2"))) void history_avx2(const HistoryInputs<CM>& in, long p0, int n, HistoryChunk& out) {
  history_body<lanes::L4, Sheared>(in, p0, n, out);
}
template <bool Sheared, class CM>
__attribute__((target("avx512f,avx512vl,avx512dq"))) void history_avx512(const HistoryInputs<CM>& in, long p0, int n,
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
