#pragma once
// A dynamic autodiff cost function whose cost-only evaluations are made in the jets' arithmetic (model_fit.cpp's
// path residuals use it; tests/cpp/test_model.cpp holds it to that).

#include <ceres/ceres.h>

#include <memory>
#include <vector>

namespace demfit {

// A path's residuals without their derivatives, computed in the jets' arithmetic (derivative parts 0) rather than in
// double, so that Ceres' cost at a point and its Jacobian there come from the same numbers (twentieth round). The
// two differ in the last bits (a jet divides by multiplying with the inverse), and where a path passes within a
// rounding error of the drained triaxial control's margin (kTriaxialMargin) one of them is lost and the other not:
// Ceres then accepts a step whose Jacobian it cannot evaluate and stops ("Residual and Jacobian evaluation failed").
template <class F, int kStride>
class JetValuedCost : public ceres::CostFunction {
 public:
  JetValuedCost(const F* f, ceres::DynamicAutoDiffCostFunction<F, kStride>* autodiff) : f_(f), autodiff_(autodiff) {
    *mutable_parameter_block_sizes() = autodiff->parameter_block_sizes();
    set_num_residuals(autodiff->num_residuals());
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    if (jacobians) return autodiff_->Evaluate(parameters, residuals, jacobians);
    using Jet = ceres::Jet<double, kStride>;
    const auto& sizes = parameter_block_sizes();
    std::vector<std::vector<Jet>> values(sizes.size());
    std::vector<const Jet*> blocks;
    for (std::size_t b = 0; b < sizes.size(); ++b) {
      for (int k = 0; k < sizes[b]; ++k) values[b].push_back(Jet(parameters[b][k]));
      blocks.push_back(values[b].data());
    }
    std::vector<Jet> r(num_residuals());
    if (!(*f_)(blocks.data(), r.data())) return false;
    for (int i = 0; i < num_residuals(); ++i) residuals[i] = r[i].a;
    return true;
  }

 private:
  const F* f_;   // owned by autodiff_
  std::unique_ptr<ceres::DynamicAutoDiffCostFunction<F, kStride>> autodiff_;
};

}  // namespace demfit
