// The pair kernels: the force of each listed pair, vectorised for generic x86-64, AVX2 (by
// hand, with intrinsics) and AVX-512 (GCC's vectorisation of the plain C++ body), and the
// choice among them at run time. Built with -ffp-contract=off -fno-math-errno
// -fno-trapping-math (sim/CMakeLists.txt): no fused multiply-add, so every lane computes the
// reference loop's bits; sqrt stays IEEE (correctly rounded), only errno and trap semantics go.
#include "forces/pair_kernels.hpp"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace dem {
namespace kernels {
namespace {

constexpr int kPrefetch = 64;   // pairs ahead whose records the AVX2 kernel prefetches

using contact::NormalGeometry;
using contact::Separation;
using lanes::L4;

// The kernel as plain C++ (auto-vectorised by GCC for each target below): the force on j of
// pairs p0 .. p0+n-1 into fx, fy, fz [N]. The arithmetic is the contact model's body.
template <bool Sheared>
__attribute__((always_inline)) inline void kernel_body(const KernelInputs& in, long p0, int n,
                                                        double* __restrict fx, double* __restrict fy,
                                                        double* __restrict fz) {
  const double* __restrict P = in.packed;
  const double* __restrict off = in.off;
  const std::int32_t* __restrict pi = in.pair_i + p0;
  const std::int32_t* __restrict pj = in.partner + p0;
  const std::uint8_t* __restrict img = in.image + p0;
  const auto model = in.model.bind<double>();
  const auto rate = contact::rate_lanes<double>(in.rate);
#pragma omp simd
  for (int q = 0; q < n; ++q) {
    const long i8 = 8L * pi[q], j8 = 8L * pj[q], c4 = 4L * img[q];
    const Separation<double> sep = contact::separation(P[i8], P[i8 + 1], P[i8 + 2], P[i8 + 3], P[j8] + off[c4],
                                                       P[j8 + 1] + off[c4 + 1], P[j8 + 2] + off[c4 + 2], P[j8 + 3]);
    const bool touch = contact::touching(sep);
    double vx, vy, vz;
    contact::relative_velocity<Sheared>(sep, P[j8 + 4] - P[i8 + 4], P[j8 + 5] - P[i8 + 5], P[j8 + 6] - P[i8 + 6], rate,
                                        vx, vy, vz);
    const NormalGeometry<double> g = contact::normal_geometry(sep, vx, vy, vz);
    const double fn = model.normal_force(g);
    fx[q] = touch ? g.nx * fn : -0.0;
    fy[q] = touch ? g.ny * fn : -0.0;
    fz[q] = touch ? g.nz * fn : -0.0;
  }
}

template <bool Sheared>
void kernel_generic(const KernelInputs& in, long p0, int n, double* fx, double* fy, double* fz) {
  kernel_body<Sheared>(in, p0, n, fx, fy, fz);
}
template <bool Sheared>
__attribute__((target("avx512f,avx512vl,avx512dq"))) void kernel_avx512(const KernelInputs& in, long p0, int n,
                                                                          double* fx, double* fy, double* fz) {
  kernel_body<Sheared>(in, p0, n, fx, fy, fz);
}

// The AVX2 kernel, by hand: four pairs at a time; each particle's record (x y z r, then
// vx vy vz 0) is one aligned 256-bit load, four records are transposed into x, y, z, r
// vectors. The arithmetic is kernel_body's, operation for operation.
#define DEM_AVX2 __attribute__((target("avx2"), always_inline)) inline
// Records r0..r3 (4 doubles each, at base + stride * idx[l]) as the columns a, b, c, d:
// two 128-bit halves per 256-bit register, then in-lane unpacks.
DEM_AVX2 void load4(const double* base, const std::int32_t* idx, int stride, __m256d& a, __m256d& b, __m256d& c,
                    __m256d& d) {
  const double* r0 = base + stride * idx[0];
  const double* r1 = base + stride * idx[1];
  const double* r2 = base + stride * idx[2];
  const double* r3 = base + stride * idx[3];
  const __m256d t0 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(r0)), _mm_load_pd(r2), 1);
  const __m256d t1 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(r1)), _mm_load_pd(r3), 1);
  const __m256d t2 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(r0 + 2)), _mm_load_pd(r2 + 2), 1);
  const __m256d t3 = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(r1 + 2)), _mm_load_pd(r3 + 2), 1);
  a = _mm256_unpacklo_pd(t0, t1);   // r0[0] r1[0] r2[0] r3[0]
  b = _mm256_unpackhi_pd(t0, t1);
  c = _mm256_unpacklo_pd(t2, t3);
  d = _mm256_unpackhi_pd(t2, t3);
}

DEM_AVX2 L4 lanes_of(__m256d v) { return (L4)v; }
DEM_AVX2 __m256d reg(L4 v) { return (__m256d)v; }

template <bool Sheared>
__attribute__((target("avx2"))) void kernel_avx2(const KernelInputs& in, long p0, int n, double* fx, double* fy,
                                                   double* fz) {
  const double* P = in.packed;
  const __m256d minus_zero = _mm256_set1_pd(-0.0);
  const L4 lane_minus_zero = lanes_of(minus_zero);
  const auto model = in.model.bind<L4>();                   // parameters in lanes, once
  const auto rate = contact::rate_lanes<L4>(in.rate);
  for (int q = 0; q < n; q += 4) {
    std::int32_t tail[3][4];
    const std::int32_t *I = in.pair_i + p0 + q, *J = in.partner + p0 + q, *C;
    if (q + 4 <= n) {
      for (int l = 0; l < 4; ++l) tail[2][l] = in.image[p0 + q + l];
    } else {   // a short last group repeats its last pair (its forces are not read back)
      for (int l = 0; l < 4; ++l) {
        const long p = p0 + std::min(q + l, n - 1);
        tail[0][l] = in.pair_i[p]; tail[1][l] = in.partner[p]; tail[2][l] = in.image[p];
      }
      I = tail[0]; J = tail[1];
    }
    C = tail[2];
    // Prefetch the records of the pairs kPrefetch ahead and the forces pass 2 will add to:
    // beyond the caches (N >~ 10^5) the loop otherwise waits on memory.
    if (p0 + q + kPrefetch + 4 <= in.p_end)
      for (int l = 0; l < 4; ++l) {
        _mm_prefetch(reinterpret_cast<const char*>(P + 8L * in.partner[p0 + q + kPrefetch + l]), _MM_HINT_T0);
        _mm_prefetch(reinterpret_cast<const char*>(P + 8L * in.pair_i[p0 + q + kPrefetch + l]), _MM_HINT_T0);
      }
    for (int l = 0; l < 4; ++l) _mm_prefetch(reinterpret_cast<const char*>(in.force + J[l]), _MM_HINT_T0);
    __m256d xi, yi, zi, ri, vxi, vyi, vzi, xj, yj, zj, rj, vxj, vyj, vzj, ox, oy, oz, pad;
    load4(P, I, 8, xi, yi, zi, ri);
    load4(P, J, 8, xj, yj, zj, rj);
    load4(in.off, C, 4, ox, oy, oz, pad);
    // From here on the arithmetic is the model's (lanes of four pairs).
    const Separation<L4> sep = contact::separation(
        lanes_of(xi), lanes_of(yi), lanes_of(zi), lanes_of(ri), lanes_of(xj) + lanes_of(ox), lanes_of(yj) + lanes_of(oy),
        lanes_of(zj) + lanes_of(oz), lanes_of(rj));
    const auto touch = contact::touching(sep);
    if (_mm256_movemask_pd(reinterpret_cast<const __m256d&>(touch)) == 0) {
      _mm256_store_pd(fx + q, minus_zero); _mm256_store_pd(fy + q, minus_zero); _mm256_store_pd(fz + q, minus_zero);
      continue;
    }
    load4(P + 4, I, 8, vxi, vyi, vzi, pad);
    load4(P + 4, J, 8, vxj, vyj, vzj, pad);
    L4 vx, vy, vz;
    contact::relative_velocity<Sheared>(sep, lanes_of(vxj) - lanes_of(vxi), lanes_of(vyj) - lanes_of(vyi),
                                        lanes_of(vzj) - lanes_of(vzi), rate, vx, vy, vz);
    const NormalGeometry<L4> g = contact::normal_geometry(sep, vx, vy, vz);
    const L4 fn = model.normal_force(g);
    _mm256_store_pd(fx + q, reg(lanes::select(touch, g.nx * fn, lane_minus_zero)));
    _mm256_store_pd(fy + q, reg(lanes::select(touch, g.ny * fn, lane_minus_zero)));
    _mm256_store_pd(fz + q, reg(lanes::select(touch, g.nz * fn, lane_minus_zero)));
  }
}
#undef DEM_AVX2

template <bool Sheared>
KernelFn kernel_for(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::avx512: return kernel_avx512<Sheared>;
    case PairKernel::avx2: return kernel_avx2<Sheared>;
    default: return kernel_generic<Sheared>;
  }
}

}  // namespace

KernelFn kernel_of(PairKernel kernel, bool sheared) {
  return sheared ? kernel_for<true>(kernel) : kernel_for<false>(kernel);
}

}  // namespace kernels

bool pair_kernel_supported(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::avx512:
      return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
             __builtin_cpu_supports("avx512dq");
    case PairKernel::avx2: return __builtin_cpu_supports("avx2");
    default: return true;
  }
}

const char* pair_kernel_name(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::reference: return "reference";
    case PairKernel::generic: return "generic";
    case PairKernel::avx2: return "avx2";
    case PairKernel::avx512: return "avx512";
  }
  return "?";
}

std::vector<PairKernel> supported_pair_kernels() {
  std::vector<PairKernel> out;
  for (PairKernel k : {PairKernel::reference, PairKernel::generic, PairKernel::avx2, PairKernel::avx512})
    if (pair_kernel_supported(k)) out.push_back(k);
  return out;
}

PairKernel pair_kernel_from_name(const std::string& name) {
  for (PairKernel k : {PairKernel::reference, PairKernel::generic, PairKernel::avx2, PairKernel::avx512})
    if (name == pair_kernel_name(k)) {
      if (!pair_kernel_supported(k))
        throw std::runtime_error("pair kernel '" + name + "' needs CPU instructions this machine lacks; "
                                 "choose one of reference, generic, avx2, avx512 that it has, or 'auto'");
      return k;
    }
  if (name == "auto" || name.empty()) return best_pair_kernel();
  throw std::runtime_error("unknown pair kernel '" + name + "': use auto, avx512, avx2, generic or reference");
}

PairKernel best_pair_kernel() {
  static const PairKernel best = [] {
    const char* env = std::getenv("DEM_PAIR_KERNEL");
    if (env && *env && std::string(env) != "auto") {
      try {
        return pair_kernel_from_name(env);
      } catch (const std::runtime_error& e) {
        throw std::runtime_error(std::string("DEM_PAIR_KERNEL: ") + e.what());
      }
    }
    // The hand-written AVX2 kernel beats GCC's AVX-512 vectorisation of the plain one on the
    // machines measured, and the 2-lane generic build is slower than the scalar reference loop
    // (docs/benchmarks.md): avx2, else reference; the others stay selectable by name.
    return pair_kernel_supported(PairKernel::avx2) ? PairKernel::avx2 : PairKernel::reference;
  }();
  return best;
}


}  // namespace dem
