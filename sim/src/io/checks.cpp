#include "dem/io/checks.hpp"
#include "dem/stages/preparation.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "dem/contact/registry.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/core/errors.hpp"

namespace dem {

namespace {

[[noreturn]] void bad(const std::string& origin, const std::string& what) {
  throw std::runtime_error(origin + ": " + what);
}

bool finite3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

std::string num(double v) { return physics_number(v); }

void check_ids(const State& s, const std::string& origin) {
  std::vector<char> seen(s.count(), 0);
  for (int i = 0; i < s.count(); ++i) {
    const std::int32_t id = s.id[i];
    if (id < 0 || id >= s.count())
      bad(origin, "particle id " + std::to_string(id) + " at slot " + std::to_string(i) + " is outside [0, " +
                      std::to_string(s.count()) + "): the file is corrupt; rerun the preparation");
    if (seen[id]++)
      bad(origin, "particle id " + std::to_string(id) + " appears twice: the file is corrupt; rerun the preparation");
  }
}

}  // namespace

void validate_state(const State& s, const std::string& origin) {
  const std::size_t n = s.position.size();
  if (n < 2) bad(origin, "fewer than 2 particles");
  if (s.velocity.size() != n || s.force.size() != n || s.radius.size() != n || s.mass.size() != n ||
      s.id.size() != n)
    bad(origin, "particle arrays have inconsistent sizes: the file is corrupt");
  check_ids(s, origin);
  for (int k = 0; k < 3; ++k)
    if (!(s.box.length[k] > 0) || !std::isfinite(s.box.length[k]))
      bad(origin, "box length along axis " + std::to_string(k) + " is " + num(s.box.length[k]) +
                      ": must be finite and positive (the file is corrupt)");
  if (!finite3(s.box.tilt) || !finite3(s.box.tilt0) || !finite3(s.tilt_at_build))
    bad(origin, "the cell's tilt is not finite (the file is corrupt)");
  for (int i = 0; i < s.count(); ++i) {
    const std::string who = "particle " + std::to_string(s.id[i]);
    if (!(s.radius[i] > 0) || !std::isfinite(s.radius[i])) bad(origin, who + " has radius " + num(s.radius[i]) + ": must be finite and positive");
    if (!(s.mass[i] > 0) || !std::isfinite(s.mass[i])) bad(origin, who + " has mass " + num(s.mass[i]) + ": must be finite and positive");
    if (!finite3(s.position[i]) || !finite3(s.velocity[i]) || !finite3(s.force[i]))
      bad(origin, who + " has a non-finite position, velocity or force (the file is corrupt)");
  }
}

void check_packing(const Model& m, const State& s, const std::string& origin) {
  const auto [lo, hi] = std::minmax_element(s.radius.begin(), s.radius.end());
  if (*lo < m.radius_min * (1 - 1e-9) || *hi > m.radius_max * (1 + 1e-9)) {
    const int worst = *lo < m.radius_min * (1 - 1e-9) ? static_cast<int>(lo - s.radius.begin())
                                                      : static_cast<int>(hi - s.radius.begin());
    bad(origin, "radii span [" + num(*lo) + ", " + num(*hi) + "] m (sphere " + std::to_string(s.id[worst]) +
                    "), outside the scene's [particles.radius_min_m, particles.radius_max_m] = [" + num(m.radius_min) +
                    ", " + num(m.radius_max) + "] m, from which t_c, dt and the neighbour skin are derived: set "
                    "particles.radius_min_m and particles.radius_max_m to the packing's radii (or use a packing of this scene)");
  }
  State copy = s;   // the list build sorts and wraps the particles
  NeighborList list;
  rebuild_neighbor_list(copy, list, m.skin_over_rmin * m.radius_min, true);
  double worst = 0;
  int wi = -1, wj = -1;
  for_each_contact(copy, list, [&](int i, int j, const Vec3&, double r, double delta) {
    if (r <= 1e-9 * (copy.radius[i] + copy.radius[j]))
      bad(origin, "spheres " + std::to_string(copy.id[i]) + " and " + std::to_string(copy.id[j]) +
                      " have the same centre: the packing is broken (remove one of them)");
    const double rel = delta / std::min(copy.radius[i], copy.radius[j]);
    if (rel > worst) { worst = rel; wi = i; wj = j; }
  });
  if (worst > m.max_overlap_fraction)
    bad(origin, "spheres " + std::to_string(copy.id[wi]) + " and " + std::to_string(copy.id[wj]) + " overlap by " +
                    num(worst) + " x the smaller radius, beyond integration.max_overlap_fraction = " +
                    num(m.max_overlap_fraction) + ": the packing is not a packing of these spheres (units? box?); "
                    "fix the file, or raise integration.max_overlap_fraction if such overlaps are intended");
}

// Measured: 0.33 kB per sphere at N = 9261, phi = 0.70 (max RSS of dem mode); 0.6 kB leaves room
// for denser packings (more listed pairs).
double estimated_memory_bytes(long long n) { return 600.0 * static_cast<double>(n); }

void check_memory(const Model& m) {
  if (!m.packing_file.empty()) return;   // N comes from the file, which was read already
  const double need = estimated_memory_bytes(m.count);
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return;
  const double have = static_cast<double>(pages) * static_cast<double>(page);
  if (need > 0.8 * have) {
    char b[300];
    std::snprintf(b, sizeof b, "particles.count = %d needs about %.3g GB (estimate: 0.6 kB per sphere), but this machine "
                  "has %.3g GB of memory: lower particles.count or run on a larger machine", m.count, need / 1e9, have / 1e9);
    throw SceneError(b);
  }
}

std::string physics_number(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

std::string physics_list(const std::vector<double>& v) {
  std::string s;
  for (double x : v) s += (s.empty() ? "" : ",") + physics_number(x);
  return "[" + s + "]";
}

Physics material_physics(const Model& m) {
  Physics p = {{"particles.radius_min_m", num(m.radius_min)},
               {"particles.radius_max_m", num(m.radius_max)},
               {"particles.density_kg_m3", num(m.density)}};
  // The normal keys records before the registry listed here (their hashes stay the same).
  for (const std::string& key : contact::record_base_keys())
    if (m.contact.has(key)) p.push_back({"contact." + key, num(m.contact.get(key))});
  p.insert(p.end(), {{"contact.allow_attractive", m.contact.allow_attractive() ? "true" : "false"},
                     {"contact.background_damping_kg_s", num(m.background_damping)},
                     {"integration.integrator", m.integrator == Integrator::VelocityVerlet ? "velocity_verlet" : "symplectic_euler"},
                     {"integration.dt_over_tc", num(m.dt_over_tc)},
                     {"integration.kinematics", m.sllod ? "sllod" : "plain"}});
  for (auto& kv : contact::contact_record(m.contact, num)) p.push_back(kv);   // the sub-models beyond the defaults
  return p;
}

namespace {
std::string vec(const Vec3& v) {
  return "[" + physics_number(v.x) + "," + physics_number(v.y) + "," + physics_number(v.z) + "]";
}
}  // namespace

std::string mode_definition(const Model& m, const DeformationMode& mode) {
  if (mode.path.empty())
    return "rate_shape=" + vec(mode.rate_shape) + (mode.sheared() ? ";shear_shape=" + vec(mode.shear_shape) : "") +
           ";eps_d_max=" + physics_number(m.protocol.eps_d_max);
  std::string d = "path=";
  for (const auto& s : mode.path)
    d += s.name + ":rate=" + vec(s.rate_shape) + (s.sheared() ? ":shear_shape=" + vec(s.shear_shape) : "") + ":sigma=" + vec(s.sigma) + ":pressure=" + physics_number(s.pressure) +
         (s.relative ? ":p0" : ":Pa") + (s.constant_volume ? ":constant_volume" : "") + ":stop" +
         std::to_string(static_cast<int>(s.stop)) + "=" + physics_number(s.until) + (s.until_relative ? "p0" : "") +
         (s.max_time > 0 ? ":max_time_tc=" + physics_number(s.max_time / m.t_contact) : "") + "/";
  return d + ";servo.waves=" + physics_number(m.protocol.servo.waves) +
         ";servo.rate_max_tc=" + physics_number(m.protocol.servo.rate_max_tc);
}

Physics shear_physics(const Model& m) {
  Physics p = material_physics(m);
  p.emplace_back("protocol.deviatoric_rate_tc", num(m.protocol.deviatoric_rate * m.t_contact));
  return p;
}

Physics preparation_physics(const Model& m) {
  const Protocol& q = m.protocol;
  Physics p = material_physics(m);
  p.insert(p.end(), {{"particles.count", m.packing_file.empty() ? std::to_string(m.count) : "(packing)"},
                     {"particles.seed", std::to_string(m.seed)},
                     {"particles.packing_file", m.packing_file.empty() ? "none" : m.packing_file},
                     {"protocol.initial_phi", num(q.initial_phi)},
                     {"protocol.preparation", preparation_record(q, m.t_contact)}});
  return p;
}

std::string physics_hash(const Physics& p) {
  std::uint64_t h = 14695981039346656037ULL;
  for (const auto& [k, v] : p)
    for (char c : k + "=" + v + ";") { h ^= static_cast<unsigned char>(c); h *= 1099511628211ULL; }
  char b[20];
  std::snprintf(b, sizeof b, "%016llx", static_cast<unsigned long long>(h));
  return b;
}

std::string physics_line(const Physics& p) {
  std::string s = physics_hash(p);
  for (const auto& [k, v] : p) s += " " + k + "=" + v;
  return s;
}

Physics parse_physics_line(const std::string& line) {
  Physics p;
  std::istringstream in(line);
  std::string word;
  while (in >> word) {
    const auto eq = word.find('=');
    if (eq != std::string::npos && eq > 0) p.emplace_back(word.substr(0, eq), word.substr(eq + 1));
  }
  return p;
}

std::string physics_diff(const Physics& a, const Physics& b, const std::string& a_name, const std::string& b_name) {
  std::string d;
  for (const auto& [k, va] : a)
    for (const auto& [kb, vb] : b)
      if (k == kb && va != vb)
        d += (d.empty() ? "" : "; ") + k + " = " + va + " (" + a_name + ") vs " + vb + " (" + b_name + ")";
  return d;
}

}  // namespace dem
