#include "dem/measure.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "dem/contact_law.hpp"

namespace dem {

Measurement measure(const Model& model, const State& s, const NeighborList& list,
                    const Vec3& rate) {
  Measurement m;
  const int n = s.count();
  const double V = s.box.volume();
  const LinearSpringDashpot law(model.contact);
  m.step = s.step;
  m.time = s.time;
  m.strain = s.box.true_strain();
  m.eps_v = (m.strain.x + m.strain.y + m.strain.z) / 3.0;
  m.eps_d = deviatoric_magnitude(m.strain.x, m.strain.y, m.strain.z);
  m.nu = s.volume_fraction();

  std::vector<int> degree(n, 0);
  std::vector<std::pair<int, int>> pairs;
  Sym3 contact_stress, fabric;
  double overlap_sum = 0;
  for_each_contact(s, list, [&](int i, int j, const Vec3& d, double r, double delta) {
    const Vec3 nrm = d * (1.0 / r);
    const Vec3 v_rel = (s.velocity[j] - s.velocity[i]) + hadamard(rate, d);
    const double fn = law(delta, -dot(v_rel, nrm));
    contact_stress.add_outer(d, nrm, fn);   // branch (x) force on j, repulsion positive
    const double vi = 4.0 / 3.0 * M_PI * s.radius[i] * s.radius[i] * s.radius[i];
    const double vj = 4.0 / 3.0 * M_PI * s.radius[j] * s.radius[j] * s.radius[j];
    fabric.add_outer(nrm, nrm, vi + vj);
    m.E_pot += law.energy(delta);
    const double rel = delta / std::min(s.radius[i], s.radius[j]);
    m.overlap_max_rel = std::max(m.overlap_max_rel, rel);
    overlap_sum += rel;
    ++degree[i]; ++degree[j];
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
  m.stress += m.stress_kinetic;
  m.fabric = fabric * (1.0 / V);
  m.p = m.stress.trace() / 3.0;
  double rsum = 0;
  for (double r : s.radius) rsum += r;
  m.p_star = 2.0 * (rsum / n) * m.p / model.contact.stiffness;
  m.sigma_dev = deviatoric_magnitude(m.stress.xx, m.stress.yy, m.stress.zz);
  m.s_dev = m.p > 0 ? m.sigma_dev / m.p : 0.0;
  m.F_dev = deviatoric_magnitude(m.fabric.xx, m.fabric.yy, m.fabric.zz);
  m.C = 2.0 * m.contacts / n;

  // Rattlers: remove particles with fewer than 4 contacts, recursively.
  std::vector<char> rattler(n, 0);
  {
    std::vector<int> start(n + 1, 0), adj(2 * pairs.size());
    for (auto& pr : pairs) { ++start[pr.first + 1]; ++start[pr.second + 1]; }
    for (int i = 0; i < n; ++i) start[i + 1] += start[i];
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (auto& pr : pairs) { adj[fill[pr.first]++] = pr.second; adj[fill[pr.second]++] = pr.first; }
    std::vector<int> queue;
    for (int i = 0; i < n; ++i)
      if (degree[i] < 4) { rattler[i] = 1; queue.push_back(i); }
    while (!queue.empty()) {
      const int i = queue.back();
      queue.pop_back();
      for (int a = start[i]; a < start[i + 1]; ++a) {
        const int j = adj[a];
        if (!rattler[j] && --degree[j] < 4) { rattler[j] = 1; queue.push_back(j); }
      }
    }
  }
  long n_rattlers = 0, contacts_nr = 0;
  for (int i = 0; i < n; ++i) n_rattlers += rattler[i];
  for (auto& pr : pairs) contacts_nr += (!rattler[pr.first] && !rattler[pr.second]);
  m.rattler_fraction = static_cast<double>(n_rattlers) / n;
  m.C_nonrattler = n_rattlers < n ? 2.0 * contacts_nr / (n - n_rattlers) : 0.0;

  const double rate_max = std::max({std::fabs(rate.x), std::fabs(rate.y), std::fabs(rate.z)});
  m.inertial_number = m.p > 0 ? rate_max * 2.0 * (rsum / n) * std::sqrt(model.density / m.p) : 0.0;
  return m;
}

const std::vector<std::string>& curve_columns() {
  static const std::vector<std::string> cols = {
      "step", "time_s", "eps_xx", "eps_yy", "eps_zz", "eps_v", "eps_d", "nu", "p_Pa", "p_star",
      "sigma_xx_Pa", "sigma_yy_Pa", "sigma_zz_Pa", "sigma_xy_Pa", "sigma_xz_Pa", "sigma_yz_Pa",
      "sigma_dev_Pa", "s_dev", "F_xx", "F_yy", "F_zz", "F_xy", "F_xz", "F_yz", "F_dev", "C",
      "C_nonrattler", "rattler_fraction", "E_kin_J", "overlap_max_rel", "overlap_mean_rel",
      "E_pot_J", "p_kin_Pa", "inertial_number", "contacts"};
  return cols;
}

std::string curve_row(const Measurement& m) {
  char buf[1024];
  const auto& S = m.stress;
  const auto& F = m.fabric;
  std::snprintf(buf, sizeof buf,
                "%lld,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,"
                "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,"
                "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,"
                "%.10g,%.10g,%.10g,%ld",
                static_cast<long long>(m.step), m.time, m.strain.x, m.strain.y, m.strain.z, m.eps_v,
                m.eps_d, m.nu, m.p, m.p_star, S.xx, S.yy, S.zz, S.xy, S.xz, S.yz, m.sigma_dev,
                m.s_dev, F.xx, F.yy, F.zz, F.xy, F.xz, F.yz, m.F_dev, m.C, m.C_nonrattler,
                m.rattler_fraction, m.E_kin, m.overlap_max_rel, m.overlap_mean_rel, m.E_pot,
                m.stress_kinetic.trace() / 3.0, m.inertial_number, m.contacts);
  return buf;
}

}  // namespace dem
