// Lane types for the one contact-force body (contact_model.hpp) that the scalar reference loop
// and every vectorised kernel share (HOOMD-blue's "one evaluator for every back end").
//
// A sub-model writes its force once, as a template on the lane type T:
//   T = double      one pair (the reference loop, the all-pairs oracle, GCC's auto-vectorised
//                   generic/AVX-512 kernels);
//   T = Lanes<4>    four pairs in one AVX2 register (the hand-written kernel keeps only the
//                   loads, transposes and prefetches; the arithmetic is this body);
//   T = Lanes<2|8>  two (generic x86-64) or eight (AVX-512) pairs: the kernels of the models
//                   with history (forces/history_kernels.hpp) run every width from one source.
// Lanes are GCC vector extensions, not intrinsics: their operators need no target attribute,
// so the body inlines into a `target("avx2")` kernel and compiles to 256-bit instructions there,
// while the same source gives scalar code elsewhere. Every operation is the IEEE operation of
// the scalar code (no FMA: the kernels are built with -ffp-contract=off), so every lane gives
// the scalar bits.
#pragma once
#include <cstdint>

namespace dem::lanes {

template <int W>
struct Lanes {
  typedef double V __attribute__((vector_size(8 * W)));
  typedef std::int64_t M __attribute__((vector_size(8 * W)));   ///< mask: all ones = true
  static constexpr int width = W;
  V v;
};

using L2 = Lanes<2>;   ///< SSE2 (the generic kernel of the history models)
using L4 = Lanes<4>;   ///< AVX2
using L8 = Lanes<8>;   ///< AVX-512

/// Pairs in one value of T: 1 for double.
template <class T> struct WidthOf { static constexpr int value = 1; };
template <int W> struct WidthOf<Lanes<W>> { static constexpr int value = W; };

#define DEM_LANE __attribute__((always_inline)) inline
template <int W> DEM_LANE Lanes<W> operator+(Lanes<W> a, Lanes<W> b) { return {a.v + b.v}; }
template <int W> DEM_LANE Lanes<W> operator-(Lanes<W> a, Lanes<W> b) { return {a.v - b.v}; }
template <int W> DEM_LANE Lanes<W> operator*(Lanes<W> a, Lanes<W> b) { return {a.v * b.v}; }
template <int W> DEM_LANE Lanes<W> operator/(Lanes<W> a, Lanes<W> b) { return {a.v / b.v}; }
template <int W> DEM_LANE Lanes<W> operator-(Lanes<W> a) { return {-a.v}; }   // flips the sign bit, as scalar -x

/// The mask type of a lane type: bool for one pair.
template <class T> struct MaskOf { using type = bool; };
template <int W> struct MaskOf<Lanes<W>> { using type = typename Lanes<W>::M; };
template <class T> using Mask = typename MaskOf<T>::type;

/// A constant in every lane.
template <class T> DEM_LANE T splat(double x) {
  T r;
  for (int l = 0; l < T::width; ++l) r.v[l] = x;
  return r;
}
template <> DEM_LANE double splat<double>(double x) { return x; }
template <> DEM_LANE L4 splat<L4>(double x) { return {L4::V{x, x, x, x}}; }

// Comparisons and selection.
DEM_LANE bool less(double a, double b) { return a < b; }
DEM_LANE bool greater(double a, double b) { return a > b; }
template <int W> DEM_LANE typename Lanes<W>::M less(Lanes<W> a, Lanes<W> b) { return a.v < b.v; }
template <int W> DEM_LANE typename Lanes<W>::M greater(Lanes<W> a, Lanes<W> b) { return a.v > b.v; }
DEM_LANE bool less_equal(double a, double b) { return a <= b; }
DEM_LANE bool greater_equal(double a, double b) { return a >= b; }
DEM_LANE bool equal(double a, double b) { return a == b; }
template <int W> DEM_LANE typename Lanes<W>::M less_equal(Lanes<W> a, Lanes<W> b) { return a.v <= b.v; }
template <int W> DEM_LANE typename Lanes<W>::M greater_equal(Lanes<W> a, Lanes<W> b) { return a.v >= b.v; }
template <int W> DEM_LANE typename Lanes<W>::M equal(Lanes<W> a, Lanes<W> b) { return a.v == b.v; }
/// m ? a : b, lane by lane.
DEM_LANE double select(bool m, double a, double b) { return m ? a : b; }
template <int W> DEM_LANE Lanes<W> select(typename Lanes<W>::M m, Lanes<W> a, Lanes<W> b) { return {m ? a.v : b.v}; }
/// True in any lane.
DEM_LANE bool any(bool m) { return m; }
template <class M> DEM_LANE bool any(M m) {
  bool r = false;
  for (unsigned l = 0; l < sizeof(M) / 8; ++l) r |= m[l] != 0;
  return r;
}
/// A scalar flag as a mask (true in every lane).
template <class T> DEM_LANE Mask<T> mask_of(bool b) {
  const Mask<T> none{};
  return b ? ~none : none;
}
template <> DEM_LANE bool mask_of<double>(bool b) { return b; }

/// Correctly rounded square root in every lane (GCC turns the lane loop into vsqrtpd).
DEM_LANE double sqrt(double a) { return __builtin_sqrt(a); }
template <int W> DEM_LANE Lanes<W> sqrt(Lanes<W> a) {
  Lanes<W> r;
  for (int l = 0; l < W; ++l) r.v[l] = __builtin_sqrt(a.v[l]);
  return r;
}
#undef DEM_LANE

}  // namespace dem::lanes
