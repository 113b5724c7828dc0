// Stress control of loading-path stages: the packing's stress and affine stiffness along the
// box axes, and the servo that turns stress errors into box strain rates.
//
// Sign conventions: stress compression positive [Pa]; strain rate extension positive [1/s].
// Compressing an axis raises its stress, so d sigma_ii = -sum_j M_ij d eps_j.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/core/state.hpp"

namespace dem {

/// The stress of a state and its affine stiffness along the box axes, from one pass over contacts.
struct AxisResponse {
  Sym3 stress;               ///< contact + kinetic stress [Pa], as measure() computes it
  double M[3][3] = {};       ///< affine stiffness M_ij = (1/V) sum_c k l_c^2 n_i^2 n_j^2 [Pa]: the
                             ///< stress change of axis i per unit compressive strain of axis j if
                             ///< every contact followed the box (an upper bound of the true one)
  double S[3][3] = {};       ///< the same for the shear entries: S_im = (1/V) sum_c k l_c^2 n_i^2 n_a n_b
                             ///< with m = (xy, xz, yz) = (a, b) [Pa]: the affine rate of sigma_ii is
                             ///< -sum_j M_ij L_jj - sum_m S_im L_m (zero for an isotropic fabric)
  double p() const { return stress.trace() / 3.0; }
};

/// Stress and affine stiffness of `state` (list current, any tilted cell: branch vectors from
/// the cell's images, V = det H); `rate` [1/s] (its L d) enters the dashpot term.
AxisResponse axis_response(const Model& model, const State& state, const NeighborList& list, const VelGrad& rate);

/// The servo of one path stage: each controlled quantity y (a normal stress sigma_ii, or the mean
/// pressure p) has an actuator direction b (the axis, or (1,1,1)) and a target y*. A true-triaxial
/// stage (PathStage::lode_b) with a compressed axis (sigma_1) controls p by the sigma_3 axis and
/// sigma_2 - sigma_3 - b (sigma_1 - sigma_3) = 0 by the sigma_2 axis; with an extended axis
/// (sigma_3) p by the other two together and the b row by their difference; its relative error is
/// measured against p. With
/// e = y - y* (positive: too compressed) and G = C M B the affine gain matrix, the servo rate is
///     u = G^-1 (e + I / T_i) / tau,    I = integral of e dt,    T_i = 4 tau,
/// updated every update_steps() steps (about t_loop / 40, t_loop = options.waves x the time an
/// elastic wave crosses the longest box edge, at the stage start), with tau = that interval: a
/// dead-beat law on the affine response (the box deforms affinely, so that response is immediate;
/// the slower non-affine relaxation is corrected at the next updates), but at least the time in
/// which an error of 0.5 % of the target drives the servo at its rate limit (the packing's stress
/// noise must not set the box rate). |B u| is limited to
/// options.rate_max; the integral is frozen while limited
/// (anti-windup). The box rate is prescribed + B u. The prescribed part may carry shear entries
/// (L_xy, L_xz, L_yz: simple shear at constant normal stress); they are strain controlled, the
/// servo acts on the diagonal only, and their affine stress rate (AxisResponse::S) enters the
/// feed-forward.
class Servo {
 public:
  /// `stage` targets already in Pa; `prescribed` is the strain-controlled part [1/s].
  Servo(const PathStage& stage, const VelGrad& prescribed, const ServoOptions& options);

  bool active() const { return !rows_.empty(); }
  /// Starts the stage: fixes tau from the packing's stiffness, density and box.
  void start(const AxisResponse& r, const Model& model, const State& state);
  /// New box strain rate [1/s] from the current response, `elapsed` [s] after the last update.
  VelGrad update(const AxisResponse& r, double elapsed);
  /// Servo time constant tau [s] (0 before start()).
  double tau() const { return tau_; }
  /// Steps between control updates (1 before start()).
  std::int64_t update_steps() const { return every_; }
  /// Target normal stress per axis [Pa] (NaN where the axis is not stress controlled) and the
  /// mean-pressure target (NaN: none).
  Vec3 sigma_target() const { return sigma_target_; }
  double pressure_target() const { return pressure_target_; }
  /// Largest |y - y*| / y* over the controlled quantities of a stress [Pa] (0 without a servo).
  double relative_error(const Sym3& stress) const;
  /// The same per controlled quantity, named as in the curve summary: sigma_xx, sigma_yy, sigma_zz
  /// (relative to their targets), p (to its target), b (the lode_b row, relative to the p target).
  std::vector<std::pair<std::string, double>> component_errors(const Sym3& stress) const;

 private:
  // scale: the denominator of the relative error (0: the target itself; the b row's target is 0)
  struct Row { Vec3 c; Vec3 b; double target; double integral = 0; double scale = 0; const char* name = ""; };
  static double output(const Row& row, const Sym3& stress);
  std::vector<Row> rows_;
  VelGrad prescribed_;
  Vec3 sigma_target_{NAN, NAN, NAN};
  double pressure_target_ = NAN;
  ServoOptions options_;
  double tau_ = 0;
  double t_i_ = 0;
  std::int64_t every_ = 1;
};

/// Checks a loading path before anything runs; throws SceneError naming the stage, the problem
/// and the fix (over-constrained axes, negative targets, stops that can never trigger).
void validate_path(const std::string& path_name, const std::vector<PathStage>& path);

}  // namespace dem
