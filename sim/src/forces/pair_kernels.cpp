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

// The kernel as plain C++ (auto-vectorised by GCC for each target below): the force on j of
// pairs p0 .. p0+n-1 into fx, fy, fz [N].
template <bool Sheared>
__attribute__((always_inline)) inline void kernel_body(const KernelInputs& in, long p0, int n,
                                                        double* __restrict fx, double* __restrict fy,
                                                        double* __restrict fz) {
  const double* __restrict P = in.packed;
  const double* __restrict off = in.off;
  const std::int32_t* __restrict pi = in.pair_i + p0;
  const std::int32_t* __restrict pj = in.partner + p0;
  const std::uint8_t* __restrict img = in.image + p0;
  const double k = in.k, gamma = in.gamma;
  const bool attractive = in.attractive;
  const double Lxx = in.rate.diag.x, Lyy = in.rate.diag.y, Lzz = in.rate.diag.z;
  const double Lxy = in.rate.shear.x, Lxz = in.rate.shear.y, Lyz = in.rate.shear.z;
#pragma omp simd
  for (int q = 0; q < n; ++q) {
    const long i8 = 8L * pi[q], j8 = 8L * pj[q], c4 = 4L * img[q];
    const double dx = (P[j8] + off[c4]) - P[i8];
    const double dy = (P[j8 + 1] + off[c4 + 1]) - P[i8 + 1];
    const double dz = (P[j8 + 2] + off[c4 + 2]) - P[i8 + 2];
    const double r2 = dx * dx + dy * dy + dz * dz;
    const double reach = P[i8 + 3] + P[j8 + 3];
    const bool touch = r2 < reach * reach;
    const double r = std::sqrt(r2);
    const double inv_r = 1.0 / r;
    const double nx = dx * inv_r, ny = dy * inv_r, nz = dz * inv_r;
    double ax, ay, az;   // L d
    if (Sheared) {
      ax = Lxx * dx + Lxy * dy + Lxz * dz;
      ay = Lyy * dy + Lyz * dz;
      az = Lzz * dz;
    } else {
      ax = Lxx * dx; ay = Lyy * dy; az = Lzz * dz;
    }
    const double vx = (P[j8 + 4] - P[i8 + 4]) + ax;
    const double vy = (P[j8 + 5] - P[i8 + 5]) + ay;
    const double vz = (P[j8 + 6] - P[i8 + 6]) + az;
    const double ddelta = -(vx * nx + vy * ny + vz * nz);
    const double f = k * (reach - r) + gamma * ddelta;
    const bool keep = (f > 0.0) | attractive;
    const double fn = keep ? f : 0.0;
    fx[q] = touch ? nx * fn : -0.0;
    fy[q] = touch ? ny * fn : -0.0;
    fz[q] = touch ? nz * fn : -0.0;
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

template <bool Sheared>
__attribute__((target("avx2"))) void kernel_avx2(const KernelInputs& in, long p0, int n, double* fx, double* fy,
                                                   double* fz) {
  const double* P = in.packed;
  const __m256d k = _mm256_set1_pd(in.k), gamma = _mm256_set1_pd(in.gamma);
  const __m256d keep_all = _mm256_castsi256_pd(_mm256_set1_epi64x(in.attractive ? -1 : 0));
  const __m256d zero = _mm256_setzero_pd(), minus_zero = _mm256_set1_pd(-0.0), one = _mm256_set1_pd(1.0);
  const __m256d Lxx = _mm256_set1_pd(in.rate.diag.x), Lyy = _mm256_set1_pd(in.rate.diag.y),
                Lzz = _mm256_set1_pd(in.rate.diag.z);
  const __m256d Lxy = _mm256_set1_pd(in.rate.shear.x), Lxz = _mm256_set1_pd(in.rate.shear.y),
                Lyz = _mm256_set1_pd(in.rate.shear.z);
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
    const __m256d dx = _mm256_sub_pd(_mm256_add_pd(xj, ox), xi);
    const __m256d dy = _mm256_sub_pd(_mm256_add_pd(yj, oy), yi);
    const __m256d dz = _mm256_sub_pd(_mm256_add_pd(zj, oz), zi);
    const __m256d r2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
    const __m256d reach = _mm256_add_pd(ri, rj);
    const __m256d touch = _mm256_cmp_pd(r2, _mm256_mul_pd(reach, reach), _CMP_LT_OQ);
    if (_mm256_movemask_pd(touch) == 0) {
      _mm256_store_pd(fx + q, minus_zero); _mm256_store_pd(fy + q, minus_zero); _mm256_store_pd(fz + q, minus_zero);
      continue;
    }
    load4(P + 4, I, 8, vxi, vyi, vzi, pad);
    load4(P + 4, J, 8, vxj, vyj, vzj, pad);
    const __m256d r = _mm256_sqrt_pd(r2);
    const __m256d inv_r = _mm256_div_pd(one, r);
    const __m256d nx = _mm256_mul_pd(dx, inv_r), ny = _mm256_mul_pd(dy, inv_r), nz = _mm256_mul_pd(dz, inv_r);
    __m256d ax, ay, az;
    if (Sheared) {
      ax = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(Lxx, dx), _mm256_mul_pd(Lxy, dy)), _mm256_mul_pd(Lxz, dz));
      ay = _mm256_add_pd(_mm256_mul_pd(Lyy, dy), _mm256_mul_pd(Lyz, dz));
      az = _mm256_mul_pd(Lzz, dz);
    } else {
      ax = _mm256_mul_pd(Lxx, dx); ay = _mm256_mul_pd(Lyy, dy); az = _mm256_mul_pd(Lzz, dz);
    }
    const __m256d vx = _mm256_add_pd(_mm256_sub_pd(vxj, vxi), ax);
    const __m256d vy = _mm256_add_pd(_mm256_sub_pd(vyj, vyi), ay);
    const __m256d vz = _mm256_add_pd(_mm256_sub_pd(vzj, vzi), az);
    const __m256d dot = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(vx, nx), _mm256_mul_pd(vy, ny)), _mm256_mul_pd(vz, nz));
    const __m256d ddelta = _mm256_xor_pd(dot, minus_zero);   // -dot, exactly
    const __m256d f = _mm256_add_pd(_mm256_mul_pd(k, _mm256_sub_pd(reach, r)), _mm256_mul_pd(gamma, ddelta));
    const __m256d keep = _mm256_or_pd(_mm256_cmp_pd(f, zero, _CMP_GT_OQ), keep_all);
    const __m256d fn = _mm256_blendv_pd(zero, f, keep);
    _mm256_store_pd(fx + q, _mm256_blendv_pd(minus_zero, _mm256_mul_pd(nx, fn), touch));
    _mm256_store_pd(fy + q, _mm256_blendv_pd(minus_zero, _mm256_mul_pd(ny, fn), touch));
    _mm256_store_pd(fz + q, _mm256_blendv_pd(minus_zero, _mm256_mul_pd(nz, fn), touch));
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
