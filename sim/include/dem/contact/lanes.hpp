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
// Lanes are GCC vector types (vector_size), not intrinsics: their built-in operators need no
// target attribute, so the body inlines into a `target("avx2")` kernel and compiles to 256-bit
// instructions there, while the same source gives scalar code elsewhere. Every operation is the
// IEEE operation of the scalar code (no FMA: the kernels are built with -ffp-contract=off), so
// every lane gives the scalar bits.
//
// Lanes<W> is the vector type itself, not a struct around it: GCC (12) keeps a struct around
// a vector, and any `const` aggregate a kernel stores into, in memory (its scalar replacement
// refuses both: "V_C_E under a different handled component", "store to a read-only decl"),
// which made the history kernels copy every value through the stack. For the same reason a
// lane body declares no `const` local of a struct type (V3<T>, SliderStep, NormalGeometry, ...):
// `const T x` is fine, `const V3<T> v` is not (docs/benchmarks.md, "Friction on the vector
// kernels, faster").
#pragma once
#include <cstdint>
#include <type_traits>
#include <utility>

namespace dem::lanes {

namespace detail {
template <int W> struct LanesOf {
  typedef double type __attribute__((vector_size(8 * W)));
  typedef std::int64_t mask __attribute__((vector_size(8 * W)));
};
}  // namespace detail

/// W doubles, one pair per lane.
template <int W> using Lanes = typename detail::LanesOf<W>::type;
using L2 = Lanes<2>;   ///< SSE2 (the generic kernel of the history models)
using L4 = Lanes<4>;   ///< AVX2
using L8 = Lanes<8>;   ///< AVX-512

/// Pairs in one value of T: 1 for double; whether T is a lane type.
template <class T> struct WidthOf { static constexpr int value = 1; };
template <> struct WidthOf<L2> { static constexpr int value = 2; };
template <> struct WidthOf<L4> { static constexpr int value = 4; };
template <> struct WidthOf<L8> { static constexpr int value = 8; };
template <class T> inline constexpr int width = WidthOf<T>::value;
template <class T> inline constexpr bool is_lanes = !std::is_same_v<T, double> && WidthOf<T>::value > 1;

#define DEM_LANE __attribute__((always_inline)) inline
/// The mask type of a lane type (all ones = true): bool for one pair.
template <class T> struct MaskOf { using type = typename detail::LanesOf<WidthOf<T>::value>::mask; };
template <> struct MaskOf<double> { using type = bool; };
template <class T> using Mask = typename MaskOf<T>::type;

/// A constant in every lane.
namespace detail {
template <class T, std::size_t... L> DEM_LANE T broadcast(double x, std::index_sequence<L...>) { return T{((void)L, x)...}; }
}  // namespace detail
template <class T> DEM_LANE T splat(double x) {
  if constexpr (std::is_same_v<T, double>) return x;
  else return detail::broadcast<T>(x, std::make_index_sequence<width<T>>{});
}

// Comparisons (lanes: all-ones masks) and selection. The built-in operators of the vector types
// do the arithmetic: +, -, *, / and unary minus (which flips the sign bit, as scalar -x).
template <class T> DEM_LANE Mask<T> less(T a, T b) { return a < b; }
template <class T> DEM_LANE Mask<T> greater(T a, T b) { return a > b; }
template <class T> DEM_LANE Mask<T> less_equal(T a, T b) { return a <= b; }
template <class T> DEM_LANE Mask<T> greater_equal(T a, T b) { return a >= b; }
template <class T> DEM_LANE Mask<T> equal(T a, T b) { return a == b; }
/// m ? a : b, lane by lane.
DEM_LANE double select(bool m, double a, double b) { return m ? a : b; }
template <class M, class T, class = std::enable_if_t<is_lanes<T>>> DEM_LANE T select(M m, T a, T b) { return m ? a : b; }
/// Four lanes: one vmovmskpd (the OR of the lanes below costs GCC 12 nine instructions). Its
/// builtin needs the target attribute, and an always_inline function cannot call a function
/// whose target its callers lack: so not always_inline; the history kernels that use it are
/// `flatten` (forces/history_kernels.hpp), which inlines it there.
namespace detail {
__attribute__((target("avx"))) inline bool any4(LanesOf<4>::mask m) {
  return __builtin_ia32_movmskpd256((LanesOf<4>::type)m) != 0;
}
}  // namespace detail
/// True in any lane.
DEM_LANE bool any(bool m) { return m; }
template <class M> DEM_LANE bool any(M m) {
  if constexpr (sizeof(M) == 32) {
    return detail::any4(m);
  } else {
    bool r = false;
    for (unsigned l = 0; l < sizeof(M) / 8; ++l) r |= m[l] != 0;
    return r;
  }
}
/// A scalar flag as a mask (true in every lane).
template <class T> DEM_LANE Mask<T> mask_of(bool b) {
  if constexpr (std::is_same_v<T, double>) return b;
  else {
    const Mask<T> none{};
    return b ? ~none : none;
  }
}

/// Correctly rounded square root in every lane (GCC turns the lane loop into vsqrtpd).
DEM_LANE double sqrt(double a) { return __builtin_sqrt(a); }
template <class T, class = std::enable_if_t<is_lanes<T>>> DEM_LANE T sqrt(T a) {
  T r;
  for (int l = 0; l < width<T>; ++l) r[l] = __builtin_sqrt(a[l]);
  return r;
}
#undef DEM_LANE

}  // namespace dem::lanes
