// The vectorised pair kernels (internal to forces.cpp and pair_kernels.cpp).
#pragma once
#include <cstdint>

#include "dem/forces/forces.hpp"

namespace dem::kernels {

// Two passes over chunks of kChunk listed pairs. (1) The kernel computes the force on j of
// every pair of the chunk, without branches, into three small arrays (L1-resident): the same
// IEEE operations in the same order as contact_force (no FMA contraction: pair_kernels.cpp
// is compiled with -ffp-contract=off), so every lane gives the bits of the scalar code; a pair
// out of contact gets -0.0, which added to anything leaves it unchanged. The arithmetic is not
// spelled out here: every kernel calls the contact model's one body (contact/contact_model.hpp,
// templated on the lane type), and keeps only its loads, transposes and prefetches. (2) A scalar pass
// adds them in list order exactly as pair_loop_reference does. So every kernel (reference,
// generic, avx2, avx512) gives the same bits, whatever the CPU.
constexpr int kChunk = 256;

struct KernelInputs {
  const double* packed;       ///< per particle: x y z r vx vy vz m (ForceScratch::packed) [m, m/s, kg]
  const std::int32_t* pair_i; ///< i of each pair
  const std::int32_t* partner;
  const std::uint8_t* image;
  const double* off;          ///< 27 image offsets, x y z 0 each [m]
  contact::Frictionless model;   ///< the contact model (its normal_force is the body of every kernel)
  VelGrad rate;               ///< [1/s]
  const Vec3* force;          ///< the forces pass 2 adds to (prefetched by the AVX2 kernel)
  long p_end;                 ///< end of the block's pairs (no prefetch past it)
};

/// Pass 1 of a chunk: the force on j [N] of pairs p0 .. p0+n-1 into fx, fy, fz (arrays of
/// kChunk, 64-byte aligned; a pair out of contact gets -0.0 in all three).
using KernelFn = void (*)(const KernelInputs&, long p0, int n, double* fx, double* fy, double* fz);

/// The kernel of `kernel` (not reference) for sheared (tilted/off-diagonal) or diagonal rates.
KernelFn kernel_of(PairKernel kernel, bool sheared);

}  // namespace dem::kernels
