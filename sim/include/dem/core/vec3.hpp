// Minimal 3-vector for the hot loops (plain struct, no expression templates).
#pragma once
#include <cmath>

namespace dem {

struct Vec3 {
  double x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  constexpr double operator[](int k) const { return k == 0 ? x : (k == 1 ? y : z); }
  double& operator[](int k) { return k == 0 ? x : (k == 1 ? y : z); }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
  Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
  Vec3& operator*=(double s) { x *= s; y *= s; z *= s; return *this; }
};

constexpr double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
/// Component-wise product (diagonal matrix times vector).
constexpr Vec3 hadamard(const Vec3& a, const Vec3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }

/// A velocity gradient L [1/s] (v_affine = L x) with no entry below the diagonal: the diagonal
/// (xx, yy, zz) and the upper entries `shear` = (L_xy, L_xz, L_yz), e.g. simple shear
/// v_x = gdot z is shear.y = gdot. Upper triangular because the cell is (LAMMPS' convention,
/// docs/simple_shear.md). A diagonal rate converts implicitly: every diagonal caller is unchanged.
struct VelGrad {
  Vec3 diag{0, 0, 0};
  Vec3 shear{0, 0, 0};   ///< (L_xy, L_xz, L_yz)
  constexpr VelGrad() = default;
  constexpr VelGrad(const Vec3& d) : diag(d) {}   // NOLINT: implicit on purpose
  constexpr VelGrad(const Vec3& d, const Vec3& s) : diag(d), shear(s) {}
  constexpr bool sheared() const { return shear.x != 0 || shear.y != 0 || shear.z != 0; }
  constexpr bool zero() const { return !sheared() && diag.x == 0 && diag.y == 0 && diag.z == 0; }
  constexpr VelGrad operator*(double s) const { return {diag * s, shear * s}; }
  /// L d: the affine relative velocity across a branch vector d. The diagonal case is the
  /// component-wise product (the same bits as before the shear existed).
  constexpr Vec3 apply(const Vec3& d) const {
    return sheared() ? Vec3{diag.x * d.x + shear.x * d.y + shear.y * d.z, diag.y * d.y + shear.z * d.z, diag.z * d.z}
                     : hadamard(diag, d);
  }
  /// Entry (i, j) of L (0 below the diagonal).
  constexpr double at(int i, int j) const {
    return i == j ? diag[i] : (i > j ? 0.0 : (i == 0 ? (j == 1 ? shear.x : shear.y) : shear.z));
  }
};

/// Symmetric 3x3 tensor stored as xx, yy, zz, xy, xz, yz.
struct Sym3 {
  double xx = 0, yy = 0, zz = 0, xy = 0, xz = 0, yz = 0;
  double trace() const { return xx + yy + zz; }
  void add_outer(const Vec3& a, const Vec3& b, double w) {
    xx += w * a.x * b.x; yy += w * a.y * b.y; zz += w * a.z * b.z;
    xy += w * 0.5 * (a.x * b.y + a.y * b.x);
    xz += w * 0.5 * (a.x * b.z + a.z * b.x);
    yz += w * 0.5 * (a.y * b.z + a.z * b.y);
  }
  Sym3& operator+=(const Sym3& o) {
    xx += o.xx; yy += o.yy; zz += o.zz; xy += o.xy; xz += o.xz; yz += o.yz; return *this;
  }
  Sym3 operator*(double s) const { return {xx * s, yy * s, zz * s, xy * s, xz * s, yz * s}; }
};

/// Deviatoric magnitude of the diagonal of a tensor:
///   sqrt(((a_xx-a_yy)^2 + (a_yy-a_zz)^2 + (a_zz-a_xx)^2) / 2)
/// (the /2 inside the root, as in Imole et al. 2013; gives eps_d = sqrt(3)*eps for D2).
inline double deviatoric_magnitude(double a, double b, double c) {
  return std::sqrt(((a - b) * (a - b) + (b - c) * (b - c) + (c - a) * (c - a)) / 2.0);
}

}  // namespace dem
