// The spring-dashpot-slider: one body for the tangential spring (Cundall-Strack), the rolling
// spring and the twisting spring (tangential.hpp, rolling.hpp), templated on the lane type T
// (double: one pair, the reference loop; lanes::Lanes<W>: W pairs, the vector kernels) and on
// the spring's type V (V3<T> for the tangential and rolling springs, T for the twisting one).
// Branch-free: both outcomes are computed and one is picked per lane, with the IEEE operations of
// the scalar code in its order, so every lane gives the bits of T = double.
#pragma once
#include "dem/contact/geometry.hpp"
#include "dem/contact/lanes.hpp"

namespace dem::contact {

/// What one step of a slider gives: the force (spring + dashpot, capped), the spring after the
/// step, the energy lost at the cap (zero while sticking) and where it slid.
template <class T, class V>
struct SliderStep {
  V force;        ///< [N] on j (tangential) or the rolling/twisting "force"
  V spring;       ///< displacement after the step [m]
  T dissipated;   ///< [J]
  lanes::Mask<T> sliding;
};

/// One step of a spring of stiffness k [N/m] and a dashpot gamma [kg/s] in series with a slider
/// of force limit `limit` [N] (mu fn), the spring starting at `start` [m] (already rotated into
/// the current tangent plane by the caller) and driven by the velocity v [m/s] over dt [s]:
/// xi = start + v dt, trial force f* = -k xi - gamma v; if |f*| > limit the force is f* scaled
/// to the limit and the spring is reset to the cone, xi = -(f + gamma v)/k (Luding 2008, eqs.
/// 17-21). The dissipated energy is the work the motion did on the spring over the step
/// (trapezoid of the spring force along v dt) minus the change of the spring's energy.
template <class T, class V>
__attribute__((always_inline)) inline SliderStep<T, V> slider_step(const V& start, const V& v, T dt, T k, T gamma,
                                                                 T limit) {
  V step = v * dt;
  V xi = start + step;
  V f = xi * (-k) - v * gamma;
  const T f2 = dot(f, f);
  const auto slip = lanes::greater(f2, limit * limit);
  SliderStep<T, V> out{f, xi, lanes::splat<T>(0.0), slip};   // all stick: what the picks give
  if (lanes::any(slip)) {   // rare: the sliding outcome, picked lane by lane (one return: no aggregate merge)
    V fs = f * (limit / lanes::sqrt(f2));
    V xs = (fs + v * gamma) * (lanes::splat<T>(-1.0) / k);
    const T e = lanes::splat<T>(0.5) * k * (dot(start + xs, step) - dot(xs, xs) + dot(start, start));
    out.force = pick(slip, fs, f);
    out.spring = pick(slip, xs, xi);
    out.dissipated = pick(slip, e, out.dissipated);
  }
  return out;
}

}  // namespace dem::contact
