#pragma once
// A straight line r_i = x0 + x1 t_i - y_i fitted by hand (the normal equations and (A^T A)^-1 in closed form): chi^2
// is exactly quadratic in (x0, x1), the oracle of the error-scale and profile-interval tests.
#include <ceres/ceres.h>

#include <vector>

namespace demfit_test {

struct Line {
  double t, y;
  template <class T>
  bool operator()(const T* x, T* r) const {
    r[0] = x[0] + x[1] * T(t) - T(y);
    return true;
  }
};

struct LineFit {
  static constexpr int n = 5;
  const double ts[n] = {0.0, 0.5, 1.0, 2.0, 3.5}, ys[n] = {0.1, 0.9, 1.7, 4.2, 6.8};
  double S1 = 0, St = 0, Stt = 0;
  std::vector<double> x;     ///< the least-squares optimum
  std::vector<double> cov;   ///< (A^T A)^-1, row-major
  ceres::Problem problem;
  LineFit() {
    double Sy = 0, Sty = 0;
    for (int i = 0; i < n; ++i) { S1 += 1; St += ts[i]; Stt += ts[i] * ts[i]; Sy += ys[i]; Sty += ts[i] * ys[i]; }
    const double det = S1 * Stt - St * St;
    x = {(Stt * Sy - St * Sty) / det, (S1 * Sty - St * Sy) / det};
    cov = {Stt / det, -St / det, -St / det, S1 / det};
    for (int i = 0; i < n; ++i)
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<Line, 1, 2>(new Line{ts[i], ys[i]}), nullptr, x.data());
  }
};

}  // namespace demfit_test
