#include "dem/forces.hpp"
#include "dem/parallel.hpp"

#include <algorithm>
#include <cmath>
#include <immintrin.h>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace dem {

namespace {

// One pair: the contact force on j [N] (minus it on i); false if the spheres do not touch.
template <bool Sheared, class Law>
inline bool contact_force(const Law& law, const Vec3& xi, const Vec3& xj_image, const Vec3& vi,
                          const Vec3& vj, double ri, double rj, const VelGrad& rate, Vec3& f_on_j) {
  const Vec3 d = xj_image - xi;
  const double r2 = dot(d, d);
  const double reach = ri + rj;
  if (r2 >= reach * reach) return false;
  const double r = std::sqrt(r2);
  const double inv_r = 1.0 / r;
  const Vec3 n = d * inv_r;                          // unit normal from i to j
  // fluctuation + affine relative velocity (L d; a diagonal L: the component-wise product)
  const Vec3 v_rel = (vj - vi) + (Sheared ? rate.apply(d) : hadamard(rate.diag, d));
  const double fn = law(reach - r, -dot(v_rel, n));
  f_on_j = n * fn;
  return true;
}

// The reference pair loop (the simple form of the kernels below, PairKernel::reference):
// pairs of particles [begin, end), forces on j >= end go to spill[block_of[j]].
template <bool Sheared, class Law>
void pair_loop_reference(const Law& law, const State& s, const NeighborList& list, const VelGrad& rate,
                         int begin, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                         const std::uint16_t* block_of) {
  Vec3 off[27];
  image_offsets(s.box, off);
  const Vec3* x = s.position.data();
  const Vec3* v = s.velocity.data();
  const double* rad = s.radius.data();
  const std::int32_t* first = list.first.data();
  const std::int32_t* partner = list.partner.data();
  const std::uint8_t* image = list.image.data();
  for (int i = begin; i < end; ++i) {
    Vec3 fi{0, 0, 0};
    const Vec3 xi = x[i], vi = v[i];
    const double ri = rad[i];
    for (int p = first[i]; p < first[i + 1]; ++p) {
      const int j = partner[p];
      Vec3 fj;
      if (!contact_force<Sheared>(law, xi, x[j] + off[image[p]], vi, v[j], ri, rad[j], rate, fj)) continue;
      if (j < end) f[j] += fj; else spill[block_of[j]].push_back({j, fj});
      fi -= fj;
    }
    f[i] += fi;
  }
}

// ---- The vectorised pair loop -------------------------------------------------------------
// Two passes over chunks of kChunk listed pairs. (1) The kernel computes the force on j of
// every pair of the chunk, without branches, into three small arrays (L1-resident): the same
// IEEE operations in the same order as contact_force (no FMA contraction: this file is
// compiled with -ffp-contract=off), so every lane gives the bits of the scalar code; a pair
// out of contact gets -0.0, which added to anything leaves it unchanged. (2) A scalar pass
// adds them in list order exactly as pair_loop_reference does. So every kernel (reference,
// generic, avx2, avx512) gives the same bits, whatever the CPU.
constexpr int kChunk = 256;
constexpr int kPrefetch = 64;   // pairs

struct KernelInputs {
  const double* packed;       ///< per particle: x y z r vx vy vz 0 (ForceScratch::packed) [m, m/s]
  const std::int32_t* pair_i; ///< i of each pair
  const std::int32_t* partner;
  const std::uint8_t* image;
  const double* off;          ///< 27 image offsets, x y z 0 each [m]
  double k, gamma;            ///< contact law [N/m], [kg/s]
  bool attractive;
  VelGrad rate;               ///< [1/s]
  const Vec3* force;          ///< the forces pass 2 adds to (prefetched by the AVX2 kernel)
  long p_end;                 ///< end of the block's pairs (no prefetch past it)
};

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

using KernelFn = void (*)(const KernelInputs&, long, int, double*, double*, double*);

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
KernelFn kernel_of(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::avx512: return kernel_avx512<Sheared>;
    case PairKernel::avx2: return kernel_avx2<Sheared>;
    default: return kernel_generic<Sheared>;
  }
}

// Pass 2 of a chunk: the forces in list order, as pair_loop_reference adds them. `fi` and
// `current` carry the running sum of the pairs of particle `current` across chunks.
inline void add_chunk(const std::int32_t* pi, const std::int32_t* pj, int n, const double* fx, const double* fy,
                      const double* fz, int end, Vec3* f, std::vector<std::vector<SpilledForce>>& spill,
                      const std::uint16_t* block_of, int& current, Vec3& fi) {
  for (int q = 0; q < n; ++q) {
    const int i = pi[q], j = pj[q];
    if (i != current) {   // f[i] += 0 (a particle without pairs) would change nothing: skipped
      f[current] += fi;
      fi = Vec3{0, 0, 0};
      current = i;
    }
    const Vec3 fj{fx[q], fy[q], fz[q]};
    if (j < end) f[j] += fj;
    else if (fj.x != 0.0 || fj.y != 0.0 || fj.z != 0.0) spill[block_of[j]].push_back({j, fj});   // +-0: no-op
    fi -= fj;
  }
}

template <bool Sheared>
void pair_loop_vector(PairKernel kernel, const ContactLaw& law, const State& s, const NeighborList& list,
                      const double* packed, const std::int32_t* pair_i, const VelGrad& rate, int begin, int end, Vec3* f,
                      std::vector<std::vector<SpilledForce>>& spill, const std::uint16_t* block_of) {
  Vec3 off3[27];
  image_offsets(s.box, off3);
  alignas(64) double off[27 * 4];
  for (int c = 0; c < 27; ++c) {
    off[4 * c] = off3[c].x; off[4 * c + 1] = off3[c].y; off[4 * c + 2] = off3[c].z; off[4 * c + 3] = 0.0;
  }
  const long p_begin = list.first[begin], p_end = list.first[end];
  const KernelInputs in{packed, pair_i, list.partner.data(), list.image.data(), off,
                        law.stiffness, law.damping, law.allow_attractive, rate, f, p_end};
  const KernelFn run = kernel_of<Sheared>(kernel);
  alignas(64) double fx[kChunk], fy[kChunk], fz[kChunk];
  int current = p_begin < p_end ? pair_i[p_begin] : begin;
  Vec3 fi{0, 0, 0};
  for (long p0 = p_begin; p0 < p_end; p0 += kChunk) {
    const int n = static_cast<int>(std::min<long>(kChunk, p_end - p0));
    run(in, p0, n, fx, fy, fz);
    add_chunk(pair_i + p0, list.partner.data() + p0, n, fx, fy, fz, end, f, spill, block_of, current, fi);
  }
  if (p_begin < p_end) f[current] += fi;
}

void add_background_damping(const Model& m, State& s) {
  const double gb = m.background_damping;
  if (gb == 0.0) return;
  for (int i = 0; i < s.count(); ++i) s.force[i] -= s.velocity[i] * gb;
}

}  // namespace

void partition_pairs(const NeighborList& list, int blocks, ForceScratch& scratch) {
  blocks = std::max(1, blocks);
  if (scratch.list_builds == list.builds && scratch.blocks() == blocks) return;
  const int n = static_cast<int>(list.first.size()) - 1;
  const long total = list.first[n];
  scratch.bounds.assign(blocks + 1, n);
  scratch.bounds[0] = 0;
  for (int b = 1; b < blocks; ++b) {
    const long target = total * b / blocks;
    scratch.bounds[b] = static_cast<int>(
        std::lower_bound(list.first.begin(), list.first.end() - 1, target) - list.first.begin());
  }
  scratch.block_of.resize(n);
  for (int b = 0; b < blocks; ++b)
    std::fill(scratch.block_of.begin() + scratch.bounds[b], scratch.block_of.begin() + scratch.bounds[b + 1],
              static_cast<std::uint16_t>(b));
  scratch.spill.assign(blocks, std::vector<std::vector<SpilledForce>>(blocks));
  scratch.pair_i.resize(list.partner.size());
  scratch.packed.resize(8 * static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i)
    std::fill(scratch.pair_i.begin() + list.first[i], scratch.pair_i.begin() + list.first[i + 1], i);
  scratch.list_builds = list.builds;
}

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
    // machines measured (docs/benchmarks.md); avx512 stays selectable by name.
    return pair_kernel_supported(PairKernel::avx2) ? PairKernel::avx2 : PairKernel::generic;
  }();
  return best;
}

// Four blocks by default: 1, 2, 3 and 4 threads sum every force in the same order.
constexpr int kDefaultBlocks = 4;

int block_count(int blocks_setting, int threads) {
  return std::clamp(blocks_setting > 0 ? blocks_setting : std::max(kDefaultBlocks, threads), 1, 65535);
}

void accumulate_pair_forces(const Model& model, const State& state, const NeighborList& list,
                            const VelGrad& rate, int b, ForceScratch& scratch, Vec3* force) {
  for (auto& to : scratch.spill[b]) to.clear();
  const int begin = scratch.bounds[b], end = scratch.bounds[b + 1];
  auto& spill = scratch.spill[b];
  const std::uint16_t* block_of = scratch.block_of.data();
  if (scratch.kernel == PairKernel::reference) {
    const LinearSpringDashpot law(model.contact);
    if (rate.sheared()) pair_loop_reference<true>(law, state, list, rate, begin, end, force, spill, block_of);
    else pair_loop_reference<false>(law, state, list, rate, begin, end, force, spill, block_of);
    return;
  }
  const std::int32_t* pair_i = scratch.pair_i.data();
  if (rate.sheared())
    pair_loop_vector<true>(scratch.kernel, model.contact, state, list, scratch.packed.data(), pair_i, rate, begin, end, force, spill, block_of);
  else
    pair_loop_vector<false>(scratch.kernel, model.contact, state, list, scratch.packed.data(), pair_i, rate, begin, end, force, spill, block_of);
}

void apply_spilled_forces(int b, const ForceScratch& scratch, Vec3* force) {
  for (int from = 0; from < b; ++from)
    for (const SpilledForce& s : scratch.spill[from][b]) force[s.j] += s.f;
}

void pack_particles(const State& s, int begin, int end, ForceScratch& scratch) {
  if (scratch.packed.size() != 8 * static_cast<std::size_t>(s.count())) return;   // sized by partition_pairs
  double* P = scratch.packed.data();
  for (int i = begin; i < end; ++i) pack_particle(s.position[i], s.radius[i], s.velocity[i], P + 8L * i);
}

void compute_forces(const Model& model, State& s, const NeighborList& list,
                    const VelGrad& rate, int threads, int blocks, ForceScratch& scratch) {
  s.force.assign(s.count(), Vec3{0, 0, 0});
  partition_pairs(list, blocks, scratch);
  pack_particles(s, 0, s.count(), scratch);
  Vec3* f = s.force.data();
  if (threads <= 1) {
    for (int b = 0; b < blocks; ++b) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
    for (int b = 1; b < blocks; ++b) apply_spilled_forces(b, scratch, f);
  } else {
#pragma omp parallel num_threads(threads)
    {
      const ThreadRank rank = this_thread_rank();
      const int t = rank.index, nt = rank.count;
      for (int b = t; b < blocks; b += nt) accumulate_pair_forces(model, s, list, rate, b, scratch, f);
#pragma omp barrier
      for (int b = t; b < blocks; b += nt) apply_spilled_forces(b, scratch, f);
    }
  }
  add_background_damping(model, s);
}

Vec3 minimum_image(const Box& box, const Vec3& xi, const Vec3& xj) {
  Vec3 d = xj - xi;
  if (!box.tilted()) {
    const Vec3 L = box.length;
    for (int k = 0; k < 3; ++k) d[k] -= L[k] * std::round(d[k] / L[k]);
    return d;
  }
  d -= box.lattice(0, 0, std::round(d.z / box.length.z));
  d -= box.lattice(0, std::round(d.y / box.length.y), 0);
  d -= box.lattice(std::round(d.x / box.length.x), 0, 0);
  return d;
}

void compute_forces_all_pairs(const Model& model, State& s, const VelGrad& rate) {
  const int n = s.count();
  const LinearSpringDashpot law(model.contact);
  s.force.assign(n, Vec3{0, 0, 0});
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const Vec3 d = minimum_image(s.box, s.position[i], s.position[j]);
      Vec3 fj;
      const bool touch = rate.sheared() ? contact_force<true>(law, s.position[i], s.position[i] + d, s.velocity[i],
                                                              s.velocity[j], s.radius[i], s.radius[j], rate, fj)
                                        : contact_force<false>(law, s.position[i], s.position[i] + d, s.velocity[i],
                                                               s.velocity[j], s.radius[i], s.radius[j], rate, fj);
      if (!touch) continue;
      s.force[j] += fj;
      s.force[i] -= fj;
    }
  add_background_damping(model, s);
}

}  // namespace dem
