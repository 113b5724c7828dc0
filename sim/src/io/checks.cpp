#include "dem/io/checks.hpp"
#include "dem/io/preparation.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>

#include "dem/contact/registry.hpp"
#include "dem/contact/contact_model.hpp"
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

namespace {
// The contact sub-models of a scene in words: its contact.normal and contact.tangential, and
// the rolling and twisting resistances when on (record_defaults() names what is absent).
std::string contact_models(const Model& m) {
  std::string d;
  for (const char* key : {"contact.normal", "contact.tangential", "contact.rolling_friction", "contact.twisting_friction"}) {
    std::string v = record_defaults().at(key);
    for (const auto& [k, value] : material_physics(m))
      if (k == key) v = value;
    d += (d.empty() ? "" : ", ") + std::string(key) + " = " + v;
  }
  return d;
}
}  // namespace

void check_history(const Model& m, const State& s, const std::string& origin) {
  const int w = contact::history_width(m.contact);
  const auto fix = ": run it with the scene it was made with (RUN/scene.toml beside its checkpoints/; dem mode --scene "
                   "that file), or start from a state without that history (the checkpoint's text packing, "
                   "checkpoints/*.txt: positions and radii only)";
  if (!s.history.values.empty() && s.history.width != w)
    bad(origin, "carries the contact history of another contact model (" + std::to_string(s.history.ids.size() / 2) +
                    " contacts, " + std::to_string(s.history.width) + " numbers each: tangential springs and the like), "
                    "but this scene's contact model (" + contact_models(m) + ") keeps " +
                    (w ? std::to_string(w) + " per contact" : "none") + ", so they would be dropped without a word" + fix);
  if (!m.contact.frictional())
    for (std::size_t i = 0; i < s.angular_velocity.size(); ++i)
      if (s.angular_velocity[i].x != 0 || s.angular_velocity[i].y != 0 || s.angular_velocity[i].z != 0)
        bad(origin, "particle " + std::to_string(s.id[i]) + " spins (angular velocity of a frictional model), but this "
                    "scene's contact model is frictionless (" + contact_models(m) + "), so the rotations would be "
                    "dropped without a word" + fix);
}

void check_packing(const Model& m, const State& s, const std::string& origin) {
  check_history(m, s, origin);
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
    return "rate_shape=" + vec(mode.shape.diag) + (mode.sheared() ? ";shear_shape=" + vec(mode.shape.shear) : "") +
           ";eps_d_max=" + physics_number(m.protocol.eps_d_max);
  std::string d = "path=";
  for (const auto& s : mode.path)
    d += s.name + ":rate=" + vec(s.shape.diag) + (s.sheared() ? ":shear_shape=" + vec(s.shape.shear) : "") + ":sigma=" + vec(s.sigma) + ":pressure=" + physics_number(s.pressure) +
         (std::isfinite(s.lode_b) ? ":lode_b=" + physics_number(s.lode_b) : "") +
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

// What a record without a key says: dem writes a sub-model's keys only while the sub-model is on
// (a frictionless record has no contact.tangential, a linear one no contact.normal), and records
// older than a key had its value then. The contact keys come from the sub-model registry
// (contact::record_defaults: each slot's default choice and every key's default); a key absent on
// one side and not listed here is a difference as it stands.
const std::map<std::string, std::string>& record_defaults() {
  static const std::map<std::string, std::string> d = [] {
    std::map<std::string, std::string> m;
    for (const auto& [k, v] : contact::record_defaults(physics_number)) m.emplace(k, v);
    m.emplace("integration.kinematics", "plain");   // records before SLLOD (dem 0.1's scheme)
    return m;
  }();
  return d;
}

namespace {
const std::string* find_key(const Physics& p, const std::string& key) {
  for (const auto& [k, v] : p)
    if (k == key) return &v;
  return nullptr;
}

// A side's value of `key` as the diff states it: its own, the default of a record without it
// (said so), or "absent".
std::string stated_value(const Physics& p, const std::string& key, const std::string& name, std::string* value) {
  if (const std::string* v = find_key(p, key)) { *value = *v; return *v + " (" + name + ")"; }
  const auto& defaults = record_defaults();
  if (auto it = defaults.find(key); it != defaults.end()) {
    *value = it->second;
    return it->second + " (" + name + ": not in its record, read as the default of a record without it)";
  }
  *value = "";
  return "absent (" + name + ": not in its record)";
}
}  // namespace

std::string physics_diff(const Physics& a, const Physics& b, const std::string& a_name, const std::string& b_name) {
  std::vector<std::string> keys;
  for (const auto* p : {&a, &b})
    for (const auto& kv : *p)
      if (std::find(keys.begin(), keys.end(), kv.first) == keys.end()) keys.push_back(kv.first);
  std::string d;
  for (const auto& k : keys) {
    std::string va, vb;
    const std::string sa = stated_value(a, k, a_name, &va), sb = stated_value(b, k, b_name, &vb);
    const bool both_absent_or_equal = va == vb && (find_key(a, k) || record_defaults().count(k)) &&
                                      (find_key(b, k) || record_defaults().count(k));
    if (!both_absent_or_equal) d += (d.empty() ? "" : "; ") + k + " = " + sa + " vs " + sb;
  }
  return d;
}

}  // namespace dem
