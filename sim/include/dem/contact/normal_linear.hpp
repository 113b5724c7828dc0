// Normal sub-models: the linear spring (normal), the linear dashpot (damping) and the no-tension
// clamp of their sum. Luding-group defaults: k = 1e8 N/m, gamma = 1 kg/s (not mass-scaled).
#pragma once
#include "dem/contact/geometry.hpp"
#include "dem/core/model.hpp"

namespace dem::contact {

/// f = k delta [N]. Energy k delta^2 / 2 [J]; tangent stiffness k [N/m].
/// Scene key: contact.stiffness_N_m.
struct LinearSpring {
  double k;
  static constexpr int history = 0;
  /// The sub-model with its parameters in lanes (bound once, outside a kernel's loop).
  template <class T> struct Bound {
    T k;
    __attribute__((always_inline)) T force(const NormalGeometry<T>& g) const { return k * g.delta; }
  };
  template <class T> Bound<T> bind() const { return {lanes::splat<T>(k)}; }
  double energy(double delta) const { return 0.5 * k * delta * delta; }
  double stiffness() const { return k; }
};

/// f = gamma d(delta)/dt [N] (constant viscosity). Scene key: contact.damping_kg_s.
/// With the spring: t_c = pi / sqrt(k/m_r - (gamma/2m_r)^2), e = exp(-gamma t_c / 2m_r)
/// (pair_collision in model.hpp).
struct LinearDashpot {
  double gamma;
  template <class T> struct Bound {
    T gamma;
    __attribute__((always_inline)) T force(const NormalGeometry<T>& g) const { return gamma * g.ddelta; }
  };
  template <class T> Bound<T> bind() const { return {lanes::splat<T>(gamma)}; }
};

}  // namespace dem::contact
