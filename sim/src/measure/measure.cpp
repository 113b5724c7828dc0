#include "dem/measure/measure.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "dem/forces/contact_forces.hpp"

namespace dem {

namespace {
Eigen::Matrix3d to_matrix(const Sym3& t) {
  Eigen::Matrix3d m;
  m << t.xx, t.xy, t.xz, t.xy, t.yy, t.yz, t.xz, t.yz, t.zz;
  return m;
}
Sym3 from_matrix(const Eigen::Matrix3d& m) {
  return {m(0, 0), m(1, 1), m(2, 2), 0.5 * (m(0, 1) + m(1, 0)), 0.5 * (m(0, 2) + m(2, 0)), 0.5 * (m(1, 2) + m(2, 1))};
}
// The eigenvector of a distinct extreme eigenvalue (largest if `major`, else smallest); false
// when it is degenerate (within 1e-9 of the tensor's scale): no direction.
bool extreme_direction(const Sym3& t, bool major, Vec3* dir) {
  double val[3];
  Vec3 vec[3];
  principal(t, val, vec);
  const double scale = std::max(std::fabs(val[0]), std::fabs(val[2]));
  const double gap = major ? val[2] - val[1] : val[1] - val[0];
  if (!(scale > 0) || !(gap > 1e-9 * scale)) return false;
  *dir = major ? vec[2] : vec[0];
  return true;
}
}  // namespace

void principal(const Sym3& t, double value[3], Vec3 vector[3]) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(to_matrix(t));
  for (int k = 0; k < 3; ++k) {
    value[k] = es.eigenvalues()(k);
    vector[k] = Vec3{es.eigenvectors()(0, k), es.eigenvectors()(1, k), es.eigenvectors()(2, k)};
  }
}

double deviatoric_magnitude_eig(const Sym3& t) {
  double val[3];
  Vec3 vec[3];
  principal(t, val, vec);
  return deviatoric_magnitude(val[0], val[1], val[2]);
}

Sym3 log_strain_tensor(const Box& box) {
  if (!box.sheared()) {
    const Vec3 e = box.true_strain();
    return {e.x, e.y, e.z, 0, 0, 0};
  }
  double F[3][3];
  box.deformation_gradient(F);
  Eigen::Matrix3d f;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) f(i, j) = F[i][j];
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(f * f.transpose());
  const Eigen::Vector3d half_log = es.eigenvalues().array().log() * 0.5;
  return from_matrix(es.eigenvectors() * half_log.asDiagonal() * es.eigenvectors().transpose());
}

double axis_angle_deg(const Vec3& a, const Vec3& b) {
  const double c = std::min(1.0, std::fabs(dot(a, b)) / (norm(a) * norm(b)));
  return std::acos(c) * 180.0 / M_PI;
}

std::vector<char> rattler_flags(int n, const std::vector<std::pair<int, int>>& pairs, int min_contacts) {
  std::vector<int> degree(n, 0);
  for (auto& pr : pairs) { ++degree[pr.first]; ++degree[pr.second]; }
  std::vector<char> rattler(n, 0);
  std::vector<int> start(n + 1, 0), adj(2 * pairs.size());
  for (auto& pr : pairs) { ++start[pr.first + 1]; ++start[pr.second + 1]; }
  for (int i = 0; i < n; ++i) start[i + 1] += start[i];
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (auto& pr : pairs) { adj[fill[pr.first]++] = pr.second; adj[fill[pr.second]++] = pr.first; }
  std::vector<int> queue;
  for (int i = 0; i < n; ++i)
    if (degree[i] < min_contacts) { rattler[i] = 1; queue.push_back(i); }
  while (!queue.empty()) {
    const int i = queue.back();
    queue.pop_back();
    for (int a = start[i]; a < start[i + 1]; ++a) {
      const int j = adj[a];
      if (!rattler[j] && --degree[j] < min_contacts) { rattler[j] = 1; queue.push_back(j); }
    }
  }
  return rattler;
}

namespace {

// The coordination of the non-rattlers of `rattler` (0 when every particle is one), and how many rattlers there are.
double nonrattler_coordination(int n, const std::vector<std::pair<int, int>>& pairs, const std::vector<char>& rattler,
                               long* n_rattlers) {
  long nr = 0, contacts_nr = 0;
  for (int i = 0; i < n; ++i) nr += rattler[i];
  for (auto& pr : pairs) contacts_nr += (!rattler[pr.first] && !rattler[pr.second]);
  *n_rattlers = nr;
  return nr < n ? 2.0 * contacts_nr / (n - nr) : 0.0;
}

// The rattlers (rattler_flags) and the coordination of the particles that carry force; with friction also under the
// frictional rule (fewer than 2 contacts).
void set_rattlers(Measurement& m, int n, const std::vector<std::pair<int, int>>& pairs) {
  long n_rattlers = 0, unused = 0;
  m.C_nonrattler = nonrattler_coordination(n, pairs, rattler_flags(n, pairs), &n_rattlers);
  m.rattler_fraction = static_cast<double>(n_rattlers) / n;
  if (m.frictional) m.C_nonrattler_2 = nonrattler_coordination(n, pairs, rattler_flags(n, pairs, 2), &unused);
}

// The objective (eigenvalue) measures and the non-coaxiality of stress, fabric and stretching; in a
// sheared cell, or under a shear rate, the curve's deviatoric measures are the objective ones.
void set_objective_measures(Measurement& m, const State& s, const VelGrad& rate) {
  m.eps_d_eig = deviatoric_magnitude_eig(m.strain_tensor);
  m.sigma_dev_eig = deviatoric_magnitude_eig(m.stress);
  m.s_dev_eig = m.p != 0 ? m.sigma_dev_eig / std::fabs(m.p) : 0.0;
  m.F_dev_eig = deviatoric_magnitude_eig(m.fabric);
  {
    const Sym3 D{rate.diag.x, rate.diag.y, rate.diag.z, 0.5 * rate.shear.x, 0.5 * rate.shear.y, 0.5 * rate.shear.z};
    Vec3 ns, nf, nd;
    const bool has_s = extreme_direction(m.stress, true, &ns);
    const bool has_f = extreme_direction(m.fabric, true, &nf);
    const bool has_d = extreme_direction(D, false, &nd);
    if (has_s && has_f) m.angle_sigma_F = axis_angle_deg(ns, nf);
    if (has_s && has_d) m.angle_sigma_D = axis_angle_deg(ns, nd);
    if (has_f && has_d) m.angle_F_D = axis_angle_deg(nf, nd);
  }

  // In a sheared cell (or under a shear rate) the diagonal forms depend on the frame: the curve's
  // eps_d, sigma_dev, s_dev, F_dev are the objective ones there, so that everything keyed to
  // them (stops, sampling, dem fit, ensembles) works for simple shear. Diagonal runs: unchanged.
  if (s.box.sheared() || rate.sheared()) {
    m.eps_d = m.eps_d_eig;
    m.sigma_dev = m.sigma_dev_eig;
    m.s_dev = m.s_dev_eig;
    m.F_dev = m.F_dev_eig;
  }
}

}  // namespace

Measurement measure(const Model& model, const State& s, const NeighborList& list,
                    const VelGrad& rate) {
  Measurement m;
  const int n = s.count();
  const double V = s.box.volume();
  m.step = s.step;
  m.time = s.time;
  m.strain_tensor = log_strain_tensor(s.box);
  m.strain = s.box.sheared() ? Vec3{m.strain_tensor.xx, m.strain_tensor.yy, m.strain_tensor.zz} : s.box.true_strain();
  m.eps_v = (m.strain.x + m.strain.y + m.strain.z) / 3.0;
  m.eps_d = deviatoric_magnitude(m.strain.x, m.strain.y, m.strain.z);
  m.nu = s.volume_fraction();

  std::vector<std::pair<int, int>> pairs;
  Sym3 contact_stress, fabric;
  double overlap_sum = 0;
  // The tangential forces' stress, kept apart: its antisymmetric part is a check (zero in
  // equilibrium: the torques balance), its symmetric part joins the stress.
  double tangential[3][3] = {};
  long sliding = 0;
  m.frictional = model.contact.frictional();
  contact::for_each_contact_force(model, s, list, rate, [&](const contact::ContactForce& c) {
    const int i = c.i, j = c.j;
    const Vec3& d = c.d;
    const Vec3& nrm = c.n;
    const double delta = c.delta;
    contact_stress.add_outer(d, nrm, c.fn);   // branch (x) force on j, repulsion positive
    if (m.frictional) {
      const double dv[3] = {d.x, d.y, d.z}, fv[3] = {c.ft.x, c.ft.y, c.ft.z};
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) tangential[a][b] += dv[a] * fv[b];   // d (x) f on j, as the normal part
      sliding += c.sliding;
      m.E_t += c.spring_energy;
    }
    const double vi = 4.0 / 3.0 * M_PI * s.radius[i] * s.radius[i] * s.radius[i];
    const double vj = 4.0 / 3.0 * M_PI * s.radius[j] * s.radius[j] * s.radius[j];
    fabric.add_outer(nrm, nrm, vi + vj);
    m.E_pot += c.energy;
    const double rel = delta / std::min(s.radius[i], s.radius[j]);
    m.overlap_max_rel = std::max(m.overlap_max_rel, rel);
    overlap_sum += rel;
    pairs.emplace_back(i, j);
  });
  m.contacts = static_cast<long>(pairs.size());
  m.overlap_mean_rel = m.contacts ? overlap_sum / m.contacts : 0.0;
  for (int i = 0; i < n; ++i) {
    m.stress_kinetic.add_outer(s.velocity[i], s.velocity[i], s.mass[i]);
    m.E_kin += 0.5 * s.mass[i] * dot(s.velocity[i], s.velocity[i]);
  }
  m.stress_kinetic = m.stress_kinetic * (1.0 / V);
  m.stress = contact_stress * (1.0 / V);
  if (m.frictional) {
    const double t = 1.0 / V;
    m.stress += Sym3{tangential[0][0] * t, tangential[1][1] * t, tangential[2][2] * t,
                     0.5 * (tangential[0][1] + tangential[1][0]) * t, 0.5 * (tangential[0][2] + tangential[2][0]) * t,
                     0.5 * (tangential[1][2] + tangential[2][1]) * t};
    m.stress_antisym = Vec3{0.5 * (tangential[0][1] - tangential[1][0]) * t, 0.5 * (tangential[0][2] - tangential[2][0]) * t,
                            0.5 * (tangential[1][2] - tangential[2][1]) * t};
    m.sliding_fraction = m.contacts ? static_cast<double>(sliding) / m.contacts : 0.0;
    m.E_rot = s.rotational_energy();
    double w_sum = 0;
    for (const Vec3& w : s.angular_velocity) w_sum += norm(w);
    m.omega_mean = n ? w_sum / n : 0.0;
    m.W_friction = s.friction_dissipated;
  }
  m.stress += m.stress_kinetic;
  m.fabric = fabric * (1.0 / V);
  m.p = m.stress.trace() / 3.0;
  double rsum = 0;
  for (double r : s.radius) rsum += r;
  m.p_star = 2.0 * (rsum / n) * m.p / model.contact.reference_stiffness();
  m.sigma_dev = deviatoric_magnitude(m.stress.xx, m.stress.yy, m.stress.zz);
  m.s_dev = m.p != 0 ? m.sigma_dev / std::fabs(m.p) : 0.0;   // |p|: a packing in tension (adhesion) too
  m.F_dev = deviatoric_magnitude(m.fabric.xx, m.fabric.yy, m.fabric.zz);
  m.C = 2.0 * m.contacts / n;

  set_rattlers(m, n, pairs);

  set_objective_measures(m, s, rate);

  const double rate_max = std::max({std::fabs(rate.diag.x), std::fabs(rate.diag.y), std::fabs(rate.diag.z),
                                    std::fabs(rate.shear.x), std::fabs(rate.shear.y), std::fabs(rate.shear.z)});
  m.inertial_number = m.p != 0 ? rate_max * 2.0 * (rsum / n) * std::sqrt(model.density / std::fabs(m.p)) : 0.0;
  return m;
}

namespace {
using G = ColumnGroup;
double antisym_rel(const Measurement& m) { return m.p > 0 ? norm(m.stress_antisym) / m.p : 0.0; }
}  // namespace

const std::vector<CurveColumn>& column_table() {
  // clang-format off
  static const std::vector<CurveColumn> t = {
    {"step", "count", "time steps since the stage (or path) start", G::Every, [](const Measurement& m) { return double(m.step); }, true},
    {"time_s", "s", "time since the stage start", G::Every, [](const Measurement& m) { return m.time; }},
    {"eps_xx", "1", "true (log) box strain ln(L/L0) along x since the stage start, extension positive", G::Every, [](const Measurement& m) { return m.strain.x; }},
    {"eps_yy", "1", "true box strain along y", G::Every, [](const Measurement& m) { return m.strain.y; }},
    {"eps_zz", "1", "true box strain along z", G::Every, [](const Measurement& m) { return m.strain.z; }},
    {"eps_v", "1", "volumetric strain (eps_xx + eps_yy + eps_zz)/3", G::Every, [](const Measurement& m) { return m.eps_v; }},
    {"eps_d", "1", "deviatoric strain magnitude sqrt(((a-b)^2+(b-c)^2+(c-a)^2)/2) of the diagonal (eigenvalues in a sheared cell)", G::Every, [](const Measurement& m) { return m.eps_d; }},
    {"nu", "1", "volume fraction", G::Every, [](const Measurement& m) { return m.nu; }},
    {"p_Pa", "Pa", "pressure tr(sigma)/3, compression positive, contact + kinetic", G::Every, [](const Measurement& m) { return m.p; }},
    {"p_star", "1", "dimensionless pressure 2<r>p/k (k: the normal sub-model's reference stiffness)", G::Every, [](const Measurement& m) { return m.p_star; }},
    {"sigma_xx_Pa", "Pa", "stress xx", G::Every, [](const Measurement& m) { return m.stress.xx; }},
    {"sigma_yy_Pa", "Pa", "stress yy", G::Every, [](const Measurement& m) { return m.stress.yy; }},
    {"sigma_zz_Pa", "Pa", "stress zz", G::Every, [](const Measurement& m) { return m.stress.zz; }},
    {"sigma_xy_Pa", "Pa", "stress xy (symmetric part)", G::Every, [](const Measurement& m) { return m.stress.xy; }},
    {"sigma_xz_Pa", "Pa", "stress xz", G::Every, [](const Measurement& m) { return m.stress.xz; }},
    {"sigma_yz_Pa", "Pa", "stress yz", G::Every, [](const Measurement& m) { return m.stress.yz; }},
    {"sigma_dev_Pa", "Pa", "deviatoric stress magnitude of the diagonal (eigenvalues in a sheared cell)", G::Every, [](const Measurement& m) { return m.sigma_dev; }},
    {"s_dev", "1", "stress ratio sigma_dev/p", G::Every, [](const Measurement& m) { return m.s_dev; }},
    {"F_xx", "1", "fabric F = (1/V) sum_p V_p sum_c n(x)n, xx", G::Every, [](const Measurement& m) { return m.fabric.xx; }},
    {"F_yy", "1", "fabric yy", G::Every, [](const Measurement& m) { return m.fabric.yy; }},
    {"F_zz", "1", "fabric zz", G::Every, [](const Measurement& m) { return m.fabric.zz; }},
    {"F_xy", "1", "fabric xy", G::Every, [](const Measurement& m) { return m.fabric.xy; }},
    {"F_xz", "1", "fabric xz", G::Every, [](const Measurement& m) { return m.fabric.xz; }},
    {"F_yz", "1", "fabric yz", G::Every, [](const Measurement& m) { return m.fabric.yz; }},
    {"F_dev", "1", "deviatoric fabric magnitude of the diagonal (eigenvalues in a sheared cell)", G::Every, [](const Measurement& m) { return m.F_dev; }},
    {"C", "1", "coordination number 2 contacts / N", G::Every, [](const Measurement& m) { return m.C; }},
    {"C_nonrattler", "1", "coordination number of the non-rattlers", G::Every, [](const Measurement& m) { return m.C_nonrattler; }},
    {"rattler_fraction", "1", "rattlers / N (fewer than 4 contacts, removed recursively)", G::Every, [](const Measurement& m) { return m.rattler_fraction; }},
    {"E_kin_J", "J", "kinetic energy of the fluctuation velocities", G::Every, [](const Measurement& m) { return m.E_kin; }},
    {"overlap_max_rel", "1", "largest overlap / smaller radius of the pair", G::Every, [](const Measurement& m) { return m.overlap_max_rel; }},
    {"overlap_mean_rel", "1", "mean overlap / smaller radius over contacts", G::Every, [](const Measurement& m) { return m.overlap_mean_rel; }},
    {"E_pot_J", "J", "elastic energy of the contacts (normal and tangential, rolling, twisting springs)", G::Every, [](const Measurement& m) { return m.E_pot; }},
    {"p_kin_Pa", "Pa", "kinetic part of the pressure", G::Every, [](const Measurement& m) { return m.stress_kinetic.trace() / 3.0; }},
    {"inertial_number", "1", "max|L_ij| 2<r> sqrt(rho/p) (0 when p <= 0)", G::Every, [](const Measurement& m) { return m.inertial_number; }},
    {"contacts", "count", "contacts (overlapping pairs)", G::Every, [](const Measurement& m) { return double(m.contacts); }, true},
    {"eps_xy", "1", "shear component xy of the log strain 0.5 ln(F F^T)", G::Every, [](const Measurement& m) { return m.strain_tensor.xy; }},
    {"eps_xz", "1", "log strain xz", G::Every, [](const Measurement& m) { return m.strain_tensor.xz; }},
    {"eps_yz", "1", "log strain yz", G::Every, [](const Measurement& m) { return m.strain_tensor.yz; }},
    {"eps_d_eig", "1", "deviatoric magnitude of the log strain's eigenvalues (objective)", G::Every, [](const Measurement& m) { return m.eps_d_eig; }},
    {"sigma_dev_eig_Pa", "Pa", "deviatoric magnitude of the stress eigenvalues (objective)", G::Every, [](const Measurement& m) { return m.sigma_dev_eig; }},
    {"s_dev_eig", "1", "sigma_dev_eig / p", G::Every, [](const Measurement& m) { return m.s_dev_eig; }},
    {"F_dev_eig", "1", "deviatoric magnitude of the fabric eigenvalues (objective)", G::Every, [](const Measurement& m) { return m.F_dev_eig; }},
    {"angle_sigma_F_deg", "deg", "angle between the major stress and major fabric directions (nan: undefined)", G::Every, [](const Measurement& m) { return m.angle_sigma_F; }},
    {"angle_sigma_D_deg", "deg", "angle between the major stress direction and the most compressive strain-rate direction", G::Every, [](const Measurement& m) { return m.angle_sigma_D; }},
    {"angle_F_D_deg", "deg", "angle between the major fabric direction and the most compressive strain-rate direction", G::Every, [](const Measurement& m) { return m.angle_F_D; }},
    {"sliding_fraction", "1", "contacts at the Coulomb limit / contacts", G::Rotations, [](const Measurement& m) { return m.sliding_fraction; }},
    {"C_nonrattler_2", "1", "coordination number of the particles with at least 2 contacts, removed recursively (the rattler rule of frictional packings)", G::Rotations, [](const Measurement& m) { return m.C_nonrattler_2; }},
    {"E_rot_J", "J", "rotational kinetic energy sum I w^2/2", G::Rotations, [](const Measurement& m) { return m.E_rot; }},
    {"omega_mean_rad_s", "rad/s", "mean |w|", G::Rotations, [](const Measurement& m) { return m.omega_mean; }},
    {"E_t_J", "J", "elastic energy of the tangential (and rolling, twisting) springs (part of E_pot_J)", G::Rotations, [](const Measurement& m) { return m.E_t; }},
    {"W_friction_J", "J", "energy lost to sliding (and rolling, twisting) since the state began", G::Rotations, [](const Measurement& m) { return m.W_friction; }},
    {"sigma_antisym_rel", "1", "|antisymmetric contact stress| / p (torque balance: small when quasi-static)", G::Rotations, antisym_rel},
    {"rate_xx_1_s", "1/s", "applied box strain rate L_xx (prescribed or the servo's)", G::Path, nullptr},
    {"rate_yy_1_s", "1/s", "applied box strain rate L_yy", G::Path, nullptr},
    {"rate_zz_1_s", "1/s", "applied box strain rate L_zz", G::Path, nullptr},
    {"target_xx_Pa", "Pa", "stress target on xx (nan: strain controlled)", G::Path, nullptr},
    {"target_yy_Pa", "Pa", "stress target on yy", G::Path, nullptr},
    {"target_zz_Pa", "Pa", "stress target on zz", G::Path, nullptr},
    {"target_p_Pa", "Pa", "mean-pressure target (nan: none)", G::Path, nullptr},
    {"control_error_rel", "1", "largest |stress - target| / target over the controlled components", G::Path, nullptr},
    {"eps_d_accumulated", "1", "eps_d travelled along the whole path (sum of |d eps_d|)", G::Path, nullptr},
    {"rate_xy_1_s", "1/s", "applied shear rate L_xy", G::PathSheared, nullptr},
    {"rate_xz_1_s", "1/s", "applied shear rate L_xz", G::PathSheared, nullptr},
    {"rate_yz_1_s", "1/s", "applied shear rate L_yz", G::PathSheared, nullptr},
  };
  // clang-format on
  return t;
}

const char* group_name(ColumnGroup g) {
  switch (g) {
    case ColumnGroup::Every: return "every";
    case ColumnGroup::Rotations: return "rotations";
    case ColumnGroup::Path: return "path";
    case ColumnGroup::PathSheared: return "path_sheared";
  }
  return "";
}

std::vector<std::string> columns_of(ColumnGroup g) {
  std::vector<std::string> out;
  for (const CurveColumn& c : column_table())
    if (c.group == g) out.push_back(c.name);
  return out;
}

const std::vector<std::string>& curve_columns() {
  static const std::vector<std::string> cols = columns_of(ColumnGroup::Every);
  return cols;
}

const std::vector<std::string>& friction_columns() {
  static const std::vector<std::string> cols = columns_of(ColumnGroup::Rotations);
  return cols;
}

std::string curve_row(const Measurement& m) {
  std::string row;
  row.reserve(1024);
  char b[40];
  for (const CurveColumn& c : column_table()) {
    if (c.group == ColumnGroup::Path || c.group == ColumnGroup::PathSheared) break;
    if (c.group == ColumnGroup::Rotations && !m.frictional) break;
    const double v = c.value(m);
    if (c.integer) std::snprintf(b, sizeof b, "%lld", static_cast<long long>(v));
    else std::snprintf(b, sizeof b, "%.10g", v);
    if (!row.empty()) row += ',';
    row += b;
  }
  return row;
}

}  // namespace dem
