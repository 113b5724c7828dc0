// The geometry of one pair, computed once and read by every sub-model (contact_model.hpp).
#pragma once
#include "dem/contact/lanes.hpp"
#include "dem/core/vec3.hpp"

namespace dem::contact {

/// A 3-vector of lanes (T = double: one pair), with Vec3's operations in Vec3's order, so that
/// the lane bodies of the history sub-models give Vec3's bits.
template <class T>
struct V3 {
  T x, y, z;
};
#define DEM_V3 __attribute__((always_inline)) inline
template <class T> DEM_V3 V3<T> operator+(const V3<T>& a, const V3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class T> DEM_V3 V3<T> operator-(const V3<T>& a, const V3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class T> DEM_V3 V3<T> operator*(const V3<T>& a, T s) { return {a.x * s, a.y * s, a.z * s}; }
template <class T> DEM_V3 T dot(const V3<T>& a, const V3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T> DEM_V3 V3<T> cross(const V3<T>& a, const V3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
/// m ? a : b, lane by lane, for lanes and 3-vectors of lanes.
template <class M, class T> DEM_V3 T pick(M m, T a, T b) { return lanes::select(m, a, b); }
template <class M, class T> DEM_V3 V3<T> pick(M m, const V3<T>& a, const V3<T>& b) {
  return {lanes::select(m, a.x, b.x), lanes::select(m, a.y, b.y), lanes::select(m, a.z, b.z)};
}
/// The one-dimensional springs (twisting) use the same slider: dot of scalars is their product.
DEM_V3 double dot(double a, double b) { return a * b; }
template <class T, class = std::enable_if_t<lanes::is_lanes<T>>> DEM_V3 T dot(T a, T b) { return a * b; }
inline V3<double> v3(const Vec3& a) { return {a.x, a.y, a.z}; }
inline Vec3 vec3(const V3<double>& a) { return {a.x, a.y, a.z}; }
#undef DEM_V3

/// Where j's image is relative to i: the branch vector d = x_j + image - x_i [m], |d|^2 and
/// the reach r_i + r_j [m]. In contact when |d|^2 < reach^2 (`touching`).
template <class T>
struct Separation {
  T dx, dy, dz, r2, reach;
};

template <class T>
__attribute__((always_inline)) inline Separation<T> separation(T xi, T yi, T zi, T ri, T xj, T yj, T zj, T rj) {
  const T dx = xj - xi, dy = yj - yi, dz = zj - zi;
  return {dx, dy, dz, dx * dx + dy * dy + dz * dz, ri + rj};
}

template <class T>
__attribute__((always_inline)) inline lanes::Mask<T> touching(const Separation<T>& s) {
  return lanes::less(s.r2, s.reach * s.reach);
}

/// The normal part of a contact: unit normal n from i to j, distance r [m], overlap
/// delta = r_i + r_j - r [m] (> 0 in contact), overlap rate ddelta = -(v_rel . n) [m/s]
/// (> 0 approaching), with v_rel the full relative velocity of the centres (fluctuation plus
/// the affine flow L d of the deforming cell).
template <class T>
struct NormalGeometry {
  T r, nx, ny, nz, delta, ddelta;
  T vx, vy, vz;   ///< v_rel [m/s]
};

/// What a sub-model that declares `per_pair = true` reads of its pair beyond the geometry
/// (Hertz's damping, Mindlin's stiffness): the overlap delta [m] (as NormalGeometry's, not
/// clamped), a12 = r_i r_j/(r_i + r_j) [m] and the reduced mass m_r = m_i m_j/(m_i + m_j) [kg].
template <class T>
struct PairLanes {
  T delta, a12, m_r;
};

/// The velocity gradient L [1/s] in lanes (bound once, outside a kernel's loop).
template <class T>
struct RateLanes {
  T xx, yy, zz, xy, xz, yz;
};
template <class T> RateLanes<T> rate_lanes(const VelGrad& L) {
  using lanes::splat;
  return {splat<T>(L.diag.x), splat<T>(L.diag.y), splat<T>(L.diag.z),
          splat<T>(L.shear.x), splat<T>(L.shear.y), splat<T>(L.shear.z)};
}

/// Relative velocity of the centres: (v_j - v_i) + L d, with L upper triangular (`Sheared`) or
/// diagonal (L d is then the component-wise product).
template <bool Sheared, class T>
__attribute__((always_inline)) inline void relative_velocity(const Separation<T>& s, T dvx, T dvy, T dvz,
                                                             const RateLanes<T>& L, T& vx, T& vy, T& vz) {
  T ax, ay, az;
  if (Sheared) {
    ax = L.xx * s.dx + L.xy * s.dy + L.xz * s.dz;
    ay = L.yy * s.dy + L.yz * s.dz;
    az = L.zz * s.dz;
  } else {
    ax = L.xx * s.dx;
    ay = L.yy * s.dy;
    az = L.zz * s.dz;
  }
  vx = dvx + ax; vy = dvy + ay; vz = dvz + az;
}

template <class T>
__attribute__((always_inline)) inline NormalGeometry<T> normal_geometry(const Separation<T>& s, T vx, T vy, T vz) {
  NormalGeometry<T> g;
  g.r = lanes::sqrt(s.r2);
  const T inv_r = lanes::splat<T>(1.0) / g.r;
  g.nx = s.dx * inv_r; g.ny = s.dy * inv_r; g.nz = s.dz * inv_r;
  g.delta = s.reach - g.r;
  g.ddelta = -(vx * g.nx + vy * g.ny + vz * g.nz);
  g.vx = vx; g.vy = vy; g.vz = vz;
  return g;
}

}  // namespace dem::contact
