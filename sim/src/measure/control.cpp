#include "dem/measure/control.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

#include "dem/forces/contact_forces.hpp"
#include "dem/measure/measure.hpp"
#include "dem/core/errors.hpp"

namespace dem {

AxisResponse axis_response(const Model& model, const State& s, const NeighborList& list, const VelGrad& rate) {
  AxisResponse r;
  Sym3 contact;
  double M[3][3] = {}, S[3][3] = {};
  const bool sheared = rate.sheared() || s.box.sheared();
  const bool frictional = model.contact.frictional();
  contact::for_each_contact_force(model, s, list, rate, [&](const contact::ContactForce& c) {
    const Vec3& n = c.n;
    const Vec3& d = c.d;
    const double dist = c.r;
    contact.add_outer(d, n, c.fn);
    if (frictional) contact.add_outer(d, c.ft, 1.0);   // symmetric part of d (x) f_t
    const double n2[3] = {n.x * n.x, n.y * n.y, n.z * n.z};
    const double w = c.kn * dist * dist;   // the normal sub-model's tangent stiffness
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) M[a][b] += w * n2[a] * n2[b];
    if (c.kt > 0) {   // a sticking spring resists the tangential part of l (eps . n)
      const double wt = c.kt * dist * dist;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) M[a][b] += wt * ((a == b ? n2[a] : 0.0) - n2[a] * n2[b]);
    }
    if (sheared) {
      const double nn[3] = {n.x * n.y, n.x * n.z, n.y * n.z};
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) S[a][b] += w * n2[a] * nn[b];
    }
  });
  Sym3 kinetic;
  for (int i = 0; i < s.count(); ++i) kinetic.add_outer(s.velocity[i], s.velocity[i], s.mass[i]);
  const double inv_v = 1.0 / s.box.volume();
  r.stress = contact * inv_v;
  r.stress += kinetic * inv_v;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) { r.M[a][b] = M[a][b] * inv_v; r.S[a][b] = S[a][b] * inv_v; }
  return r;
}

namespace {

double component(const Vec3& v, int a) { return a == 0 ? v.x : a == 1 ? v.y : v.z; }
Vec3 axis(int a) { return {a == 0 ? 1.0 : 0.0, a == 1 ? 1.0 : 0.0, a == 2 ? 1.0 : 0.0}; }

// g = c^T M b: the change of the controlled quantity per unit compressive servo strain.
double gain(const Vec3& c, const double M[3][3], const Vec3& b) {
  double g = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) g += component(c, i) * M[i][j] * component(b, j);
  return g;
}

// c^T S g: the affine change of the controlled quantity per unit (negative) shear strain g.
double shear_gain(const Vec3& c, const double S[3][3], const Vec3& g) {
  double s = 0;
  for (int i = 0; i < 3; ++i)
    for (int m = 0; m < 3; ++m) s += component(c, i) * S[i][m] * component(g, m);
  return s;
}

}  // namespace

constexpr double kIntegralTimes = 4;   // T_i / tau
constexpr double kFullRateError = 5e-3;   // the relative error that drives the servo at its rate limit

// Steps between control updates for a loop time t_loop = waves x the wave crossing time [s]: one
// update every t_loop / 40, but not more often than every kMinUpdateSteps steps unless the old
// interval t_loop / 20 (dem <= 0.9) already was: the update's pass over the contacts costs about
// one time step (callgrind), so the halving adds at most ~10 % to a run (docs/control.md).
namespace {
constexpr std::int64_t kMinUpdateSteps = 5;
std::int64_t update_interval(double t_loop, double dt) {
  const std::int64_t old = std::max<std::int64_t>(1, std::llround(t_loop / (20 * dt)));
  const std::int64_t halved = std::max<std::int64_t>(1, std::llround(t_loop / (40 * dt)));
  return std::min(old, std::max(halved, kMinUpdateSteps));
}
}  // namespace

Servo::Servo(const PathStage& stage, const VelGrad& prescribed, const ServoOptions& options)
    : prescribed_(prescribed), options_(options) {
  if (std::isfinite(stage.lode_b)) {   // true triaxial: the one prescribed axis k (validate_path)
    const int k = stage.shape.diag.x != 0 ? 0 : stage.shape.diag.y != 0 ? 1 : 2;
    const double b = stage.lode_b;
    if (component(stage.shape.diag, k) < 0) {   // compressed: sigma_1 on k, sigma_3 next, sigma_2 after
      const int a3 = (k + 1) % 3, a2 = (k + 2) % 3;
      rows_.push_back({Vec3{1, 1, 1} * (1.0 / 3.0), axis(a3), stage.pressure, 0, stage.pressure, "p"});
      // sigma_2 - sigma_3 - b (sigma_1 - sigma_3) = 0
      rows_.push_back({axis(a2) + axis(a3) * (b - 1) - axis(k) * b, axis(a2), 0.0, 0, stage.pressure, "b"});
    } else {   // extended: sigma_3 on k, sigma_1 next, sigma_2 after; p by both, b by their difference
      const int a1 = (k + 1) % 3, a2 = (k + 2) % 3;
      rows_.push_back({Vec3{1, 1, 1} * (1.0 / 3.0), axis(a1) + axis(a2), stage.pressure, 0, stage.pressure, "p"});
      rows_.push_back({axis(a2) + axis(k) * (b - 1) - axis(a1) * b, axis(a2) - axis(a1), 0.0, 0, stage.pressure, "b"});
    }
    pressure_target_ = stage.pressure;
  } else if (std::isfinite(stage.pressure)) {
    rows_.push_back({Vec3{1, 1, 1} * (1.0 / 3.0), Vec3{1, 1, 1}, stage.pressure, 0, 0, "p"});
    pressure_target_ = stage.pressure;
  }
  for (int a = 0; a < 3; ++a)
    if (std::isfinite(component(stage.sigma, a)))
      rows_.push_back({axis(a), axis(a), component(stage.sigma, a), 0, 0, a == 0 ? "sigma_xx" : a == 1 ? "sigma_yy" : "sigma_zz"});
  sigma_target_ = stage.sigma;
}

double Servo::output(const Row& row, const Sym3& stress) {
  return row.c.x * stress.xx + row.c.y * stress.yy + row.c.z * stress.zz;
}

void Servo::start(const AxisResponse& r, const Model& model, const State& state) {
  if (!active()) return;
  double m_max = 0;
  for (const Row& row : rows_) m_max = std::max(m_max, gain(row.c, r.M, row.b) / dot(row.c, row.b));
  for (int a = 0; a < 3; ++a) m_max = std::max(m_max, r.M[a][a]);
  const double rho_bulk = model.density * state.volume_fraction();
  const double L = std::max({state.box.length.x, state.box.length.y, state.box.length.z});
  // No contacts (a dilute state): no wave speed; let the rate limit govern (an update every 25 steps).
  const double t_wave = m_max > 0 ? L / std::sqrt(m_max / rho_bulk) : 1000 * model.dt / options_.waves;
  every_ = update_interval(options_.waves * t_wave, model.dt);
  // Dead-beat (tau = the update interval), but no faster than an error of kFullRateError of the
  // target drives the servo at its rate limit: a stiff packing's own stress noise would otherwise
  // set the box rate (at N = 2000, nu = 0.80: +-4x the test rate, docs/control.md).
  tau_ = every_ * model.dt;
  for (const Row& row : rows_) {
    const double g = gain(row.c, r.M, row.b);
    const double scale = row.scale > 0 ? row.scale : row.target;
    if (g > 0) tau_ = std::max(tau_, kFullRateError * scale / (g * options_.rate_max));
  }
  t_i_ = kIntegralTimes * tau_;
  for (Row& row : rows_) row.integral = 0;
}

VelGrad Servo::update(const AxisResponse& r, double elapsed) {
  if (!active()) return prescribed_;
  const int m = static_cast<int>(rows_.size());
  const double t_i = t_i_;
  Eigen::MatrixXd G(m, m);
  Eigen::VectorXd rhs(m), err(m);
  for (int a = 0; a < m; ++a) {
    err(a) = output(rows_[a], r.stress) - rows_[a].target;
    // feedback, minus the affine stress rate the prescribed strain rate causes (feed-forward)
    // (the shear part's: zero for an isotropic fabric, first order in its anisotropy)
    rhs(a) = (err(a) + rows_[a].integral / t_i) / tau_ - gain(rows_[a].c, r.M, prescribed_.diag);
    if (prescribed_.sheared()) rhs(a) -= shear_gain(rows_[a].c, r.S, prescribed_.shear);
    for (int b = 0; b < m; ++b) G(a, b) = gain(rows_[a].c, r.M, rows_[b].b);
  }
  // A state without contacts has no stiffness: expand/compress at the limit toward the target.
  Eigen::VectorXd u(m);
  const bool stiff = G.diagonal().minCoeff() > 0;
  if (stiff) u = G.partialPivLu().solve(rhs);
  else for (int a = 0; a < m; ++a) u(a) = err(a) > 0 ? options_.rate_max : -options_.rate_max;
  Vec3 servo{0, 0, 0};
  for (int a = 0; a < m; ++a) servo += rows_[a].b * u(a);
  const double peak = std::max({std::fabs(servo.x), std::fabs(servo.y), std::fabs(servo.z)});
  const bool limited = peak > options_.rate_max;
  if (limited) servo = servo * (options_.rate_max / peak);
  if (!limited && stiff)
    for (int a = 0; a < m; ++a) rows_[a].integral += err(a) * elapsed;
  return {prescribed_.diag + servo, prescribed_.shear};
}

double Servo::relative_error(const Sym3& stress) const {
  double worst = 0;
  for (const auto& [name, e] : component_errors(stress)) worst = std::max(worst, e);
  return worst;
}

std::vector<std::pair<std::string, double>> Servo::component_errors(const Sym3& stress) const {
  std::vector<std::pair<std::string, double>> e;
  for (const Row& row : rows_)
    e.emplace_back(row.name, std::fabs(output(row, stress) - row.target) / (row.scale > 0 ? row.scale : row.target));
  return e;
}

// ---------------------------------------------------------------------------------------

namespace {

const char* stop_name(PathStop s) {
  switch (s) {
    case PathStop::EpsD: return "eps_d";
    case PathStop::Time: return "time_tc";
    case PathStop::EpsV: return "eps_v";
    case PathStop::EpsXX: return "eps_xx";
    case PathStop::EpsYY: return "eps_yy";
    case PathStop::EpsZZ: return "eps_zz";
    case PathStop::Pressure: return "p";
    case PathStop::SDev: return "s_dev";
    case PathStop::Phi: return "phi";
    case PathStop::TauXY: return "tau_xy";
    case PathStop::TauXZ: return "tau_xz";
    case PathStop::TauYZ: return "tau_yz";
    case PathStop::Relaxed: return "ke_ratio";
  }
  return "?";
}

}  // namespace

namespace {

/// A true-triaxial stage (lode_b): b in [0, 1], a pressure target, one prescribed axis (compressed:
/// sigma_1 on it; extended: sigma_3 on it).
template <class Fail> void check_lode_b(const PathStage& s, const Fail& fail) {
  const int prescribed = (s.shape.diag.x != 0) + (s.shape.diag.y != 0) + (s.shape.diag.z != 0);
  if (std::isnan(s.pressure))
    fail("lode_b holds b = (sigma_2 - sigma_3)/(sigma_1 - sigma_3) at a constant mean pressure: give pressure_p0 "
         "or pressure_Pa too");
  if (!(s.lode_b >= 0 && s.lode_b <= 1))
    fail("lode_b = " + std::to_string(s.lode_b) + ": b = (sigma_2 - sigma_3)/(sigma_1 - sigma_3) lies in [0, 1] "
         "(0: triaxial compression, 1: extension)");
  if (s.sheared() || prescribed != 1)
    fail("with lode_b the rate drives one axis only: compressed, it is the sigma_1 axis (e.g. rate = [0, 0, -1]: "
         "sigma_3 on x, sigma_2 on y); extended, the sigma_3 axis (e.g. [0, 0, 1]: sigma_1 on x, sigma_2 on y); "
         "the servo sets the other two");
}

}  // namespace

void validate_path(const std::string& path_name, const std::vector<PathStage>& path) {
  if (path.empty()) throw SceneError("paths." + path_name + " lists no stages: give at least one");
  for (std::size_t k = 0; k < path.size(); ++k) {
    const PathStage& s = path[k];
    const std::string where = "paths." + path_name + " stage " + std::to_string(k + 1) + " ('" + s.name + "')";
    auto fail = [&](const std::string& what) { throw SceneError(where + ": " + what); };
    int stressed = 0;
    for (int a = 0; a < 3; ++a) {
      const double t = component(s.sigma, a), rate = component(s.shape.diag, a);
      if (std::isnan(t)) continue;
      ++stressed;
      if (!(t > 0) || !std::isfinite(t))
        fail(std::string("the stress target of axis ") + "xyz"[a] + " must be a positive number (compression); "
             "a granular packing cannot hold tension");
      if (rate != 0)
        fail(std::string("axis ") + "xyz"[a] + " is stress controlled, so its rate must be 0 (it is " +
             std::to_string(rate) + "): an axis is either strain-rate or stress controlled");
    }
    const double trace = s.shape.diag.x + s.shape.diag.y + s.shape.diag.z;
    // The shear entries (strain controlled) add to the deviatoric rate: eps_d of D = sym L.
    const Vec3& g = s.shape.shear;
    const double dev = s.sheared() ? deviatoric_magnitude_eig(Sym3{s.shape.diag.x, s.shape.diag.y, s.shape.diag.z,
                                                                    0.5 * g.x, 0.5 * g.y, 0.5 * g.z})
                                   : deviatoric_magnitude(s.shape.diag.x, s.shape.diag.y, s.shape.diag.z);
    if (!std::isnan(s.pressure)) {
      if (!(s.pressure > 0) || !std::isfinite(s.pressure))
        fail("the pressure target must be a positive number (compression)");
      if (stressed) fail("a pressure target with per-axis stress targets over-constrains the box: use one or the other");
      if (std::isnan(s.lode_b) && std::fabs(trace) > 1e-12 * (dev + 1e-300))
        fail("under pressure control the prescribed rate is the deviatoric direction, but it has a volumetric part "
             "(rate_x + rate_y + rate_z = " + std::to_string(trace) + "): make it trace-free, e.g. [1, 0, -1]");
    }
    if (stressed == 3 && !(s.sheared() && s.stop == PathStop::EpsD) && s.stop != PathStop::Time &&
        s.stop != PathStop::Pressure && s.stop != PathStop::SDev && s.stop != PathStop::Phi &&
        s.stop != PathStop::Relaxed &&
        !(s.sheared() && (s.stop == PathStop::TauXY || s.stop == PathStop::TauXZ || s.stop == PathStop::TauYZ)))
      fail(std::string("all three axes are stress controlled, so no strain is prescribed and a stop on ") +
           stop_name(s.stop) + " may never come: stop on time_tc, p, s_dev or phi (or eps_d with a prescribed shear)");
    if (!std::isnan(s.lode_b)) check_lode_b(s, fail);
    const bool servo = s.has_servo();
    if (s.constant_volume && servo)
      fail("constant_volume fixes tr(E_dot) = 0, and the stress targets set the rates of the same axes: the box is "
           "over-constrained; drop constant_volume (the servo then sets the volume) or the stress targets");
    if (s.constant_volume && std::fabs(trace) > 1e-12 * (dev + 1e-300))
      fail("constant_volume needs a trace-free rate, but rate_x + rate_y + rate_z = " + std::to_string(trace));
    const bool moves = dev > 0 || trace != 0;
    switch (s.stop) {
      case PathStop::EpsD:
        if (!(s.until > 0)) fail("until.eps_d is the deviatoric strain this stage adds: it must be > 0");
        if (dev == 0 && !servo)
          fail("the prescribed rate has no deviatoric part, so eps_d never grows: stop on eps_v or a strain component");
        break;
      case PathStop::Time:
        if (!(s.until > 0)) fail("until.time_tc must be > 0");
        break;
      case PathStop::EpsXX: case PathStop::EpsYY: case PathStop::EpsZZ: {
        const int a = s.stop == PathStop::EpsXX ? 0 : s.stop == PathStop::EpsYY ? 1 : 2;
        if (component(s.shape.diag, a) == 0)
          fail(std::string("until.") + stop_name(s.stop) + ": axis " + "xyz"[a] + " has no prescribed rate" +
               (std::isfinite(component(s.sigma, a)) ? " (it is stress controlled)" : "") +
               ", so its strain may never reach the target: stop on a strain-controlled axis");
        if (k == 0 && (s.until - 0) * component(s.shape.diag, a) <= 0)
          fail(std::string("until.") + stop_name(s.stop) + " = " + std::to_string(s.until) +
               " lies behind the first stage's rate (the path starts at strain 0): change the sign of the target or the rate");
        break;
      }
      case PathStop::EpsV:
        if (trace == 0 && !servo) fail("the prescribed rate is volume conserving, so eps_v never changes: stop on eps_d");
        if (k == 0 && !servo && s.until * trace <= 0)
          fail("until.eps_v lies behind the first stage's rate (the path starts at eps_v = 0): change its sign");
        break;
      case PathStop::Pressure:
        if (!(s.until > 0)) fail("until.p must be a positive pressure");
        if (!moves && !servo) fail("nothing moves the box in this stage (zero rate, no servo): p would never change");
        break;
      case PathStop::SDev:
        if (!(s.until >= 0)) fail("until.s_dev must be >= 0");
        if (dev == 0 && !servo) fail("the prescribed rate has no deviatoric part: s_dev would not be driven");
        break;
      case PathStop::Phi:
        if (!(s.until > 0 && s.until < 1)) fail("until.phi must be a volume fraction in (0, 1)");
        if (trace == 0 && !servo) fail("the prescribed rate is volume conserving, so phi never changes: stop on eps_d");
        break;
      case PathStop::Relaxed:
        if (!(s.until > 0)) fail("until.ke_ratio must be > 0 (E_kin < ke_ratio * E_pot, e.g. 1e-6)");
        if (!servo || moves)
          fail("until.ke_ratio ends a stage that holds its stress targets with nothing else prescribed: give a servo "
               "target and rate = [0, 0, 0]");
        break;
      case PathStop::TauXY: case PathStop::TauXZ: case PathStop::TauYZ:
        if (!moves && !servo)
          fail(std::string("nothing moves the box in this stage (zero rate, no servo): ") + stop_name(s.stop) +
               " would never change");
        break;
    }
  }
}

}  // namespace dem
