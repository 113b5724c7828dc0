#include "dem/io/preparation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <set>

#include "dem/io/checks.hpp"
#include "dem/core/errors.hpp"
#include "io/preparation_toml.hpp"

namespace dem {

namespace {

bool stress_controlled(const PrepStage& s) {
  return s.kind == PrepStage::Kind::Pressure || s.kind == PrepStage::Kind::Uniaxial;
}

std::string g(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

bool file_safe(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  });
}

const char* kind_name(PrepStage::Kind k) {
  switch (k) {
    case PrepStage::Kind::Compress: return "compress";
    case PrepStage::Kind::Expand: return "expand";
    case PrepStage::Kind::Relax: return "relax";
    case PrepStage::Kind::Pressure: return "pressure";
    case PrepStage::Kind::Uniaxial: return "uniaxial";
  }
  return "?";
}

// The one number of `table.key` (absent: `fallback`); anything but a finite number is refused.
double number(const toml::table& t, const char* key, double fallback, const std::function<void(std::string)>& fail) {
  const toml::node* n = t.get(key);
  if (!n) return fallback;
  auto v = n->value<double>();
  if (!v || !std::isfinite(*v)) fail(std::string(key) + " must be a finite number");
  return *v;
}

// A stress-controlled stage: a servo drives p (pressure) or sigma_zz with x, y fixed (uniaxial) to
// target_Pa at most at rate_tc, then holds it until relaxed (until.ke_ratio) or max_time_tc.
PrepStage parse_stress_stage(const toml::table& t, PrepStage s, const toml::table* until, double t_c,
                             const std::function<void(std::string)>& fail) {
  if (t.contains("checkpoints"))
    fail("a stress-controlled stage ends at a volume fraction it finds, so it has no checkpoints list: its end state "
         "is the checkpoint of series checkpoint_name (named by the volume fraction reached)");
  if (!t.contains("target_Pa")) fail("target_Pa (the stress to compress to and hold, in Pa) is missing");
  s.target = number(t, "target_Pa", 0, fail);
  if (!t.contains("rate_tc")) fail("rate_tc (the servo's largest strain rate x t_c, e.g. 1e-4) is missing");
  s.rate = number(t, "rate_tc", 0, fail) / t_c;
  if (until && (until->size() != 1 || !until->contains("ke_ratio")))
    fail("a stress-controlled stage stops when relaxed at its target: until = { ke_ratio = R } (E_kin < R * E_pot, "
         "default 1e-6), or after max_time_tc");
  s.ke_ratio = until ? number(*until, "ke_ratio", 1e-6, fail) : 1e-6;
  s.max_time = number(t, "max_time_tc", 2e5, fail) * t_c;
  if (const toml::node* n = t.get("checkpoint_name")) {
    auto v = n->value_exact<std::string>();
    if (!v) fail("checkpoint_name must be a string");
    s.checkpoint_name = *v;
  }
  return s;
}

PrepStage parse_stage(const toml::table& t, double t_c, const std::string& where) {
  auto fail = [&](const std::string& what) { throw SceneError(where + ": " + what); };
  static const std::set<std::string> keys = {"name", "kind", "rate_tc", "until", "max_time_tc", "checkpoint_name",
                                             "checkpoints", "target_Pa"};
  for (auto&& [k, v] : t)
    if (!keys.count(std::string(k.str())))
      fail("unknown key '" + std::string(k.str()) + "'; a preparation stage has name, kind (compress, expand, "
           "relax, pressure or uniaxial), rate_tc, until, max_time_tc (relax, pressure, uniaxial), target_Pa "
           "(pressure, uniaxial), checkpoint_name, checkpoints");
  PrepStage s;
  auto name = t["name"].value_exact<std::string>();
  if (!name) fail("name must be given as a string (the file stem of the stage's curve, e.g. name = \"compress\")");
  s.name = *name;
  auto kind = t["kind"].value_exact<std::string>();
  static const std::map<std::string, PrepStage::Kind> kinds = {
      {"compress", PrepStage::Kind::Compress}, {"expand", PrepStage::Kind::Expand}, {"relax", PrepStage::Kind::Relax},
      {"pressure", PrepStage::Kind::Pressure}, {"uniaxial", PrepStage::Kind::Uniaxial}};
  if (!kind || !kinds.count(*kind))
    fail("kind must be \"compress\", \"expand\", \"relax\", \"pressure\" or \"uniaxial\"");
  s.kind = kinds.at(*kind);
  const toml::table* until = t.get("until") ? t.get("until")->as_table() : nullptr;
  if (t.contains("until") && !until) fail("until must be a table, e.g. until = { phi = 0.64 }");
  if (t.contains("target_Pa") && !stress_controlled(s))
    fail("target_Pa is the stress of a \"pressure\" or \"uniaxial\" stage; a " + *kind + " stage has none");
  if (stress_controlled(s)) return parse_stress_stage(t, s, until, t_c, fail);
  const bool relax = s.kind == PrepStage::Kind::Relax;
  if (relax) {
    for (const char* k : {"rate_tc", "checkpoint_name", "checkpoints"})
      if (t.contains(k)) fail(std::string(k) + " has no meaning for a relaxation (constant volume): remove it");
    if (until && (until->size() != 1 || !until->contains("ke_ratio")))
      fail("a relaxation stops on until = { ke_ratio = R } (E_kin < R * E_pot; default 1e-8) or after max_time_tc");
    s.ke_ratio = until ? number(*until, "ke_ratio", 1e-8, fail) : 1e-8;
    s.max_time = number(t, "max_time_tc", 2e5, fail) * t_c;
    return s;
  }
  if (t.contains("max_time_tc")) fail("max_time_tc is for relaxations; a " + *kind + " stage ends on its phi");
  if (!until || until->size() != 1 || !until->contains("phi"))
    fail("a " + *kind + " stage ends on a volume fraction: until = { phi = X }");
  s.phi = number(*until, "phi", 0, fail);
  if (!t.contains("rate_tc")) fail("rate_tc (true strain rate per axis x t_c, e.g. 1e-4) is missing");
  s.rate = number(t, "rate_tc", 0, fail) / t_c;
  s.checkpoint_name = s.name;
  if (const toml::node* n = t.get("checkpoint_name")) {
    auto v = n->value_exact<std::string>();
    if (!v) fail("checkpoint_name must be a string");
    s.checkpoint_name = *v;
  }
  if (const toml::node* n = t.get("checkpoints")) {
    const toml::array* a = n->as_array();
    if (!a) fail("checkpoints must be an array of volume fractions, e.g. checkpoints = [0.80, 0.70]");
    for (const auto& e : *a) {
      auto v = e.value<double>();
      if (!v || !std::isfinite(*v)) fail("checkpoints must be an array of finite volume fractions");
      s.checkpoints.push_back(*v);
    }
  }
  return s;
}

// Checks one compress/expand stage: rate, target, checkpoints on its side of the target.
void validate_phi_stage(const PrepStage& s, double t_c, const std::function<void(std::string)>& fail) {
  const double rate_tc = s.rate * t_c;
  if (!(rate_tc > 0) || !std::isfinite(rate_tc)) fail("rate_tc must be a positive number");
  if (rate_tc > 1e-2)
    fail("rate_tc = " + g(rate_tc) + " deforms the box by 1% per contact time: far from quasi-static; use rates "
         "below 1e-3 (typical: 1e-6 to 1e-4)");
  if (!(s.phi > 0 && s.phi < 0.9))
    fail("until.phi = " + g(s.phi) + " must be in (0, 0.9): denser, overlaps are of the order of the radius");
  const bool up = s.kind == PrepStage::Kind::Compress;
  if (!file_safe(s.checkpoint_name)) fail("checkpoint_name must be letters, digits, _ or - (a file stem)");
  for (double phi : s.checkpoints)
    if (!(phi > 0 && phi < 0.9) || (up ? phi > s.phi : phi < s.phi))
      fail("checkpoint " + g(phi) + " lies beyond the stage's target phi " + g(s.phi) + " (a " +
           (up ? std::string("compression") : std::string("expansion")) + " never gets there): remove it or move "
           "it to a stage that passes it");
}

std::string record_of(const PrepStage& s, double t_c) {
  std::string r = s.name + ":" + kind_name(s.kind);
  if (s.kind == PrepStage::Kind::Relax)
    return r + ":ke_ratio=" + physics_number(s.ke_ratio) + ":max_time_tc=" + physics_number(s.max_time / t_c);
  if (stress_controlled(s))
    return r + ":target_Pa=" + physics_number(s.target) + ":rate_tc=" + physics_number(s.rate * t_c) +
           ":ke_ratio=" + physics_number(s.ke_ratio) + ":max_time_tc=" + physics_number(s.max_time / t_c) +
           (s.checkpoint_name.empty() ? "" : ":" + s.checkpoint_name);
  r += ":rate_tc=" + physics_number(s.rate * t_c) + ":phi=" + physics_number(s.phi);
  if (!s.checkpoints.empty()) r += ":" + s.checkpoint_name + "=" + physics_list(s.checkpoints);
  return r;
}

}  // namespace

std::vector<PrepStage> default_preparation(const Protocol& p) {
  using K = PrepStage::Kind;
  PrepStage compress{"compress", K::Compress, p.compress_rate, p.target_phi, 0, 0, 0, "compress", {}};
  PrepStage relax{"relax", K::Relax, 0, 0, p.relax_ke_ratio, p.relax_max_time, 0, "", {}};
  PrepStage loading{"cycle_loading", K::Compress, p.cycle_rate, p.cycle_phi_max, 0, 0, 0, "loading",
                    p.checkpoints_loading};
  PrepStage unloading{"cycle_unloading", K::Expand, p.cycle_rate, p.target_phi, 0, 0, 0, "unloading",
                      p.checkpoints_unloading};
  return {compress, relax, loading, unloading};
}

std::vector<PrepStage> parse_preparation(const toml::array& stages, double t_c, const std::string& origin) {
  std::vector<PrepStage> out;
  for (std::size_t i = 0; i < stages.size(); ++i) {
    const std::string where = origin + ": protocol.preparation stage " + std::to_string(i + 1);
    const toml::table* t = stages[i].as_table();
    if (!t) throw SceneError(where + " must be a table, e.g. { name = \"compress\", kind = \"compress\", "
                             "rate_tc = 1e-4, until = { phi = 0.64 } }");
    out.push_back(parse_stage(*t, t_c, where));
  }
  return out;
}

void validate_preparation(const Protocol& p, double t_c, const std::string& origin) {
  if (p.preparation.empty())
    throw SceneError(origin + ": protocol.preparation lists no stage: give at least one (or remove the key for the "
                     "built-in compress / relax / cycle)");
  std::set<std::string> names, stems;
  std::size_t n_mode_checkpoints = 0;
  for (std::size_t i = 0; i < p.preparation.size(); ++i) {
    const PrepStage& s = p.preparation[i];
    const std::string where = origin + ": protocol.preparation stage " + std::to_string(i + 1) + " (" + s.name + ")";
    auto fail = [&](const std::string& what) { throw SceneError(where + ": " + what); };
    if (!file_safe(s.name)) fail("name must be letters, digits, _ or - (it is the file stem of the stage's curve)");
    if (!names.insert(s.name).second) fail("two stages are named '" + s.name + "': each needs its own name (file)");
    if (s.kind == PrepStage::Kind::Relax || stress_controlled(s)) {
      if (!(s.ke_ratio > 0) || !std::isfinite(s.ke_ratio)) fail("until.ke_ratio must be a positive number");
      if (!(s.max_time > 0) || !std::isfinite(s.max_time)) fail("max_time_tc must be a positive number");
    }
    if (s.kind == PrepStage::Kind::Relax) continue;
    if (stress_controlled(s)) {
      if (!(s.target > 0) || !std::isfinite(s.target))
        fail("target_Pa must be a positive pressure (compression; a packing cannot be held in tension by a servo)");
      if (!(s.rate > 0) || !std::isfinite(s.rate) || s.rate * t_c > 1e-2)
        fail("rate_tc must be a positive number below 1e-2 (the servo's largest strain rate x t_c; typical 1e-5 to 1e-3)");
      if (!s.checkpoint_name.empty() && !file_safe(s.checkpoint_name))
        fail("checkpoint_name must be letters, digits, _ or - (a file stem)");
      if (!s.checkpoint_name.empty() && s.checkpoint_name == p.modes_from) ++n_mode_checkpoints;
      continue;
    }
    validate_phi_stage(s, t_c, fail);
    for (double phi : s.checkpoints)
      if (!stems.insert(checkpoint_stem(s.checkpoint_name, phi)).second)
        fail("checkpoint " + checkpoint_stem(s.checkpoint_name, phi) + " is listed twice (or two volume fractions "
             "round to that file name, 3 decimals): keep one, or give the stages different checkpoint_name");
    if (s.checkpoint_name == p.modes_from) n_mode_checkpoints += s.checkpoints.size();
  }
  if (!p.modes.empty() && n_mode_checkpoints == 0)
    throw SceneError(origin + ": protocol.modes_from = \"" + p.modes_from + "\" names no checkpoints of the "
                     "preparation, so the modes would have nothing to start from: give a stage checkpoint_name = \"" +
                     p.modes_from + "\" and checkpoints, or set modes_from to a series that has them");
}

std::vector<double> mode_checkpoints(const Protocol& p) {
  std::vector<double> phis;
  for (const auto& s : p.preparation)
    if ((s.kind == PrepStage::Kind::Compress || s.kind == PrepStage::Kind::Expand) && s.checkpoint_name == p.modes_from)
      phis.insert(phis.end(), s.checkpoints.begin(), s.checkpoints.end());
  std::sort(phis.begin(), phis.end(), std::greater<double>());
  return phis;
}

std::string checkpoint_stem(const std::string& series, double phi) { return series + "_" + fmt_phi(phi); }

std::string preparation_record(const Protocol& p, double t_c) {
  std::string r;
  for (const auto& s : p.preparation) r += (r.empty() ? "" : "/") + record_of(s, t_c);   // not modes_from: modes only
  return r;
}

double preparation_particle_steps(const Model& m) {
  double phi = m.protocol.initial_phi, steps = 0;
  for (const auto& s : m.protocol.preparation) {
    if (s.kind == PrepStage::Kind::Relax || stress_controlled(s)) continue;
    // ln(phi) moves by 3 rate dt per step under isotropic deformation.
    const bool runs = s.kind == PrepStage::Kind::Compress ? s.phi > phi : s.phi < phi;
    if (runs) steps += std::fabs(std::log(s.phi / phi)) / (3 * s.rate * m.dt);
    phi = s.phi;
  }
  return steps * m.count;
}

std::string describe(const PrepStage& s, double t_c) {
  if (s.kind == PrepStage::Kind::Relax)
    return "relax until E_kin < " + g(s.ke_ratio) + " E_pot (at most " + g(s.max_time / t_c) + " t_c)";
  if (stress_controlled(s))
    return std::string(s.kind == PrepStage::Kind::Pressure ? "to pressure " : "uniaxially (x, y fixed) to sigma_zz ") +
           g(s.target) + " Pa (servo, at most " + g(s.rate * t_c) + "/t_c), held until E_kin < " + g(s.ke_ratio) +
           " E_pot (at most " + g(s.max_time / t_c) + " t_c)" +
           (s.checkpoint_name.empty() ? "" : ", checkpoint " + s.checkpoint_name + " at the volume fraction reached");
  std::string d = std::string(kind_name(s.kind)) + " to phi " + g(s.phi) + " at " + g(s.rate * t_c) + "/t_c";
  if (!s.checkpoints.empty()) {
    d += ", checkpoints " + s.checkpoint_name + " at";
    for (double phi : s.checkpoints) d += " " + g(phi);
  }
  return d;
}

}  // namespace dem
