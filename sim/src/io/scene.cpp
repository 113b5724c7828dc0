#include "dem/io/scene.hpp"

#include "dem/contact/contact_model.hpp"
#include "dem/contact/registry.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/control.hpp"
#include "dem/io/work.hpp"
#include "dem/io/preparation.hpp"
#include "io/preparation_toml.hpp"
#include "io/scene_modes.hpp"
#include "io/scene_text.hpp"
#include "io/sweep_toml.hpp"
#include "dem/io/toml_write.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

namespace dem {

namespace {

// Reads typed keys from a table and remembers which keys were consumed.
class KeyReader {
 public:
  KeyReader(toml::table& root, std::string origin) : root_(root), origin_(std::move(origin)) {}

  template <class T>
  void get(const std::string& section, const std::string& key, T& out) {
    known_[section].insert(key);
    toml::table* sec = section_table(section);
    toml::node* node = sec ? sec->get(key) : nullptr;
    const std::string name = section + "." + key;
    if (!node) { set_default(section, key, out); return; }
    if constexpr (std::is_same_v<T, bool>) {
      if (auto v = node->value_exact<bool>()) out = *v; else type_error(name, "true or false");
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (auto v = node->value_exact<std::string>()) out = *v; else type_error(name, "a string");
    } else if constexpr (std::is_integral_v<T>) {
      auto v = node->value_exact<int64_t>();
      if (!v) type_error(name, "an integer");
      const bool fits = std::is_signed_v<T>
                            ? *v >= static_cast<int64_t>(std::numeric_limits<T>::min()) &&
                                  *v <= static_cast<int64_t>(std::numeric_limits<T>::max())
                            : *v >= 0;
      if (!fits)
        throw SceneError(origin_ + ": key '" + name + "' = " + std::to_string(*v) + " is out of range [" +
                         std::to_string(std::is_signed_v<T> ? std::numeric_limits<T>::min() : 0) + ", " +
                         std::to_string(std::is_signed_v<T> ? std::numeric_limits<T>::max()
                                                            : std::numeric_limits<int64_t>::max()) + "]");
      out = static_cast<T>(*v);
    } else if constexpr (std::is_same_v<T, double>) {
      if (auto v = node->value<double>()) out = *v; else type_error(name, "a number");
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
      auto* arr = node->as_array();
      if (!arr) type_error(name, "an array of numbers");
      out.clear();
      for (auto& e : *arr) {
        auto v = e.value<double>();
        if (!v) type_error(name, "an array of numbers");
        out.push_back(*v);
      }
    } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
      auto* arr = node->as_array();
      if (!arr) type_error(name, "an array of strings");
      out.clear();
      for (auto& e : *arr) {
        auto v = e.value<std::string>();
        if (!v) type_error(name, "an array of strings");
        out.push_back(*v);
      }
    }
  }

  // A number, or the string "auto" (also when absent: the resolved scene then says "auto").
  // Returns true for "auto" (out unchanged).
  bool get_number_or_auto(const std::string& section, const std::string& key, double& out) {
    known_[section].insert(key);
    toml::table* sec = section_table(section);
    toml::node* node = sec ? sec->get(key) : nullptr;
    if (!node) { set_default(section, key, std::string("auto")); return true; }
    if (auto v = node->value_exact<std::string>(); v && *v == "auto") return true;
    if (auto v = node->value<double>(); v && !node->is_string()) { out = *v; return false; }
    type_error(section + "." + key, "a number or \"auto\"");
    return false;
  }

  // A key read elsewhere (not through get): known, never given a default.
  void known(const std::string& section, const std::string& key) { known_[section].insert(key); }

  // A key that keeps its value when absent and gets no default in the resolved scene.
  template <class T>
  void get_if_present(const std::string& section, const std::string& key, T& out) {
    toml::table* sec = section_table(section);
    if (sec && sec->get(key)) get(section, key, out);
    else known(section, key);
  }

  // Sections whose keys are free (user-defined modes).
  void allow_any(const std::string& section) { free_sections_.insert(section); known_[section]; }

  void reject_unknown() {
    for (auto&& [k, v] : root_) {
      const std::string sec(k.str());
      if (!known_.count(sec))
        throw SceneError(origin_ + ": unknown section [" + sec + "]; known sections: " + list_sections());
      if (free_sections_.count(sec)) continue;
      auto* t = v.as_table();
      if (!t) throw SceneError(origin_ + ": '" + sec + "' must be a section [" + sec + "]");
      for (auto&& [kk, vv] : *t) {
        const std::string key(kk.str());
        if (!known_[sec].count(key)) {
          std::string keys;
          for (auto& kn : known_[sec]) keys += (keys.empty() ? "" : ", ") + kn;
          throw SceneError(origin_ + ": unknown key '" + sec + "." + key + "'; known keys of [" +
                           sec + "]: " + keys);
        }
      }
    }
  }

 private:
  toml::table* section_table(const std::string& section) {
    toml::node* n = root_.get(section);
    return n ? n->as_table() : nullptr;
  }
  template <class T>
  void set_default(const std::string& section, const std::string& key, const T& value) {
    // Record defaults so the resolved scene lists every key.
    if (!root_.get(section)) root_.insert(section, toml::table{});
    toml::table& t = *root_.get(section)->as_table();
    if constexpr (std::is_same_v<T, std::vector<double>> || std::is_same_v<T, std::vector<std::string>>) {
      toml::array a;
      for (auto& e : value) a.push_back(e);
      t.insert(key, a);
    } else if constexpr (std::is_same_v<T, unsigned long long>) {
      t.insert(key, static_cast<int64_t>(value));
    } else if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
      t.insert(key, static_cast<int64_t>(value));
    } else {
      t.insert(key, value);
    }
  }
  [[noreturn]] void type_error(const std::string& name, const std::string& what) {
    throw SceneError(origin_ + ": key '" + name + "' must be " + what);
  }
  std::string list_sections() const {
    std::string s;
    for (auto& [k, v] : known_) s += (s.empty() ? "" : ", ") + k;
    return s;
  }

  toml::table& root_;
  std::string origin_;
  std::map<std::string, std::set<std::string>> known_;
  std::set<std::string> free_sections_;
};

// End of a string starting at i (at its opening quote), or npos if it does not end.
std::size_t string_end(const std::string& t, std::size_t i) {
  const char q = t[i];
  const bool multi = t.compare(i, 3, std::string(3, q)) == 0;
  for (std::size_t k = i + (multi ? 3 : 1); k < t.size(); ++k) {
    if (q == '"' && t[k] == '\\') { ++k; continue; }
    if (!multi && t[k] == '\n') return std::string::npos;
    if (multi ? t.compare(k, 3, std::string(3, q)) == 0 : t[k] == q) return k + (multi ? 2 : 0);
  }
  return std::string::npos;
}

// The scene text as toml++ gets it: pure ASCII. toml++ 3.3.0 reaches __builtin_unreachable
// (undefined behaviour) on non-ASCII characters in several places, also in strings after a
// syntax error and in its error paths (three findings of tests/fuzz/fuzz_scene). So non-ASCII
// bytes in comments become '?' (comments carry no values), and anywhere else, strings
// included, they are refused, as are control characters and unclosed strings.
std::string ascii_scene(std::string t, const std::string& origin) {
  int line = 1;
  auto fail = [&](const std::string& what) {
    throw SceneError(origin + ":" + std::to_string(line) + ": TOML syntax error: " + what);
  };
  for (std::size_t i = 0; i < t.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(t[i]);
    if ((c < 0x20 && c != '\t' && c != '\n' && c != '\r') || c == 0x7f)
      fail("a control character (byte " + std::to_string(c) + "): is this a text file?");
    if (c == '\n') ++line;
  }
  line = 1;
  for (std::size_t i = 0; i < t.size(); ++i) {
    const char c = t[i];
    if (c == '\n') {
      ++line;
    } else if (c == '#') {
      for (; i + 1 < t.size() && t[i + 1] != '\n'; ++i)
        if (static_cast<unsigned char>(t[i + 1]) >= 0x80) t[i + 1] = '?';
    } else if (c == '"' || c == '\'') {
      const std::size_t end = string_end(t, i);
      if (end == std::string::npos) fail("a string is not closed");
      for (std::size_t k = i; k <= end; ++k)
        if (static_cast<unsigned char>(t[k]) >= 0x80)
          fail("a non-ASCII character in a string (scene values are ASCII: rename the file or folder, or link it)");
      line += static_cast<int>(std::count(t.begin() + i, t.begin() + end, '\n'));
      i = end;
    } else if (static_cast<unsigned char>(c) >= 0x80) {
      fail("a non-ASCII character outside a comment (keys and values are ASCII; write e.g. nu, sigma)");
    }
  }
  return t;
}

// What a TOML node is, in words, for messages that say what was found instead.
std::string node_kind(const toml::node& n) {
  if (n.is_table()) return "a table";
  if (n.is_array_of_tables()) return "an array of tables ([[...]])";
  if (n.is_array()) return "an array";
  if (n.is_string()) return "a string";
  if (n.is_boolean()) return "a boolean";
  if (n.is_number()) return "a number";
  return "a date or time";
}

// Every top-level entry of a scene is a section: [name] with keys under it. `particles = 5`,
// `[[contact]]` or `modes = [...]` are refused here, once, before any reader looks inside.
void check_sections(const toml::table& root, const std::string& origin) {
  for (auto&& [k, v] : root) {
    if (v.is_table()) continue;
    const std::string sec(k.str());
    throw SceneError(origin + ": '" + sec + "' must be a section, [" + sec + "] on its own line followed by its key = "
                     "value lines, but it is " + node_kind(v) +
                     (v.is_array_of_tables() ? ": write [" + sec + "] once, not [[" + sec + "]]" : ""));
  }
}

bool blank(const std::string& s) {
  return std::all_of(s.begin(), s.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); });
}

// --set section.key=value: the key path is read by TOML itself (quoted names, spaces around
// the dots), and must be exactly two non-blank names; the value replaces the key's.
void apply_override(toml::table& root, const std::string& ov) {
  const std::string shape = ": give section.key=value, e.g. contact.damping_kg_s=0.5 (a string value may be bare)";
  const auto eq = ov.find('=');
  if (eq == std::string::npos || eq == 0) throw SceneError("override '" + ov + "' must look like section.key=value" + shape.substr(shape.find(',')));
  const std::string key = ov.substr(0, eq);
  std::string value = ov.substr(eq + 1);
  ascii_scene(key + " = " + value, "override '" + ov + "'");
  if (key.find('.') == std::string::npos)
    throw SceneError("override '" + ov + "': name the section, e.g. contact.damping_kg_s=0");
  toml::table parsed;
  try {
    parsed = toml::parse(key + " = " + value);
  } catch (const toml::parse_error&) {
    try {
      parsed = toml::parse(key + " = \"" + value + "\"");
    } catch (const toml::parse_error& e) {
      throw SceneError("override '" + ov + "' is not valid (" + std::string(e.description()) + ")" + shape);
    }
  }
  toml::table* sec_in = parsed.size() == 1 ? parsed.begin()->second.as_table() : nullptr;
  if (!sec_in || sec_in->is_inline() || sec_in->size() != 1)
    throw SceneError("override '" + ov + "' must set one key of one section" + shape);
  const std::string section(parsed.begin()->first.str());
  const std::string leaf(sec_in->begin()->first.str());
  toml::node& val = sec_in->begin()->second;
  if (blank(section) || blank(leaf))
    throw SceneError("override '" + ov + "': the key path '" + key + "' has a blank name (section '" + section +
                     "', key '" + leaf + "')" + shape);
  if (val.is_table() && !val.as_table()->is_inline())
    throw SceneError("override '" + ov + "': nested keys (" + key + ") are not supported" + shape);
  // Merge: replace the leaf, create the section as needed.
  if (!root.get(section)) root.insert(section, toml::table{});
  toml::table* sec = root.get(section)->as_table();
  if (!sec) throw SceneError("override '" + ov + "': '" + section + "' is not a section" + shape);
  sec->insert_or_assign(leaf, val);
}


// protocol.preparation if the scene lists it (then the keys of the built-in preparation are refused).
const toml::array* explicit_preparation(toml::table& root, const std::string& origin) {
  const toml::table* proto = root.get("protocol") ? root.get("protocol")->as_table() : nullptr;
  const toml::node* n = proto ? proto->get("preparation") : nullptr;
  if (!n) return nullptr;
  const toml::array* a = n->as_array();
  if (!a)
    throw SceneError(origin + ": protocol.preparation must be an array of stage tables, e.g. [{ name = \"compress\", "
                     "kind = \"compress\", rate_tc = 1e-4, until = { phi = 0.64 } }, ...] (docs/protocol.md)");
  for (const char* key : {"target_phi", "compress_rate_tc", "relax_ke_ratio", "relax_max_time_tc", "cycle_phi_max",
                          "cycle_rate_tc", "checkpoints_unloading", "checkpoints_loading"})
    if (proto->contains(key))
      throw SceneError(origin + ": protocol." + key + " belongs to the built-in preparation, but protocol.preparation "
                       "lists the stages: remove protocol." + key + " and give its value in the stage it belongs to");
  return a;
}

}  // namespace

std::string scene_text_for_toml(const std::string& text, const std::string& origin) {
  return ascii_scene(text, origin);
}

// [contact]: the sub-models and their keys, as the registry's descriptions say (contact/registry.hpp).
static void read_contact_section(KeyReader& r, ContactLaw& c, const std::string& origin, toml::table& root) {
  auto node = [&root](const std::string& key) -> toml::node* {
    toml::node* sec = root.get("contact");
    return sec && sec->as_table() ? sec->as_table()->get(key) : nullptr;
  };
  contact::ContactKeys keys;
  keys.present = [&](const std::string& key) { return node(key) != nullptr; };
  keys.get_number = [&](const std::string& key, double& v) { r.get("contact", key, v); };
  keys.peek_number = [&](const std::string& key, double& v) { r.get_if_present("contact", key, v); };
  keys.get_string = [&](const std::string& key, std::string& v) { r.get("contact", key, v); };
  keys.peek_string = [&](const std::string& key, std::string& v) { r.get_if_present("contact", key, v); };
  for (const contact::SubModelInfo* m : contact::submodels())
    for (const contact::KeySpec& k : m->keys) r.known("contact", k.name);
  r.known("contact", "normal");
  r.known("contact", "tangential");
  contact::read_contact(keys, c, origin);
}

// The auto skin of a scene with few particles: at most what lets the box at the preparation's
// densest volume fraction, its shortest edge shrunk by the modes' strain (exp(-eps_d_max)), hold
// two list cutoffs (2 r_max + skin) with 10 % to spare, but never below the old 0.4 r_min (a box
// too small for that was too small before too). Packings from a file keep the rule (their count
// is not known here).
static void cap_auto_skin(Model& m) {
  if (!m.packing_file.empty()) return;
  double phi = std::max(m.protocol.cycle_phi_max, m.protocol.target_phi);
  for (const PrepStage& st : m.protocol.preparation) phi = std::max(phi, st.phi);
  const double a = m.radius_min, b = m.radius_max;
  const double mean_r3 = b > a ? (b * b * b * b - a * a * a * a) / (4 * (b - a)) : a * a * a;
  const double edge = std::cbrt(m.count * 4.0 / 3.0 * M_PI * mean_r3 / phi) * std::exp(-m.protocol.eps_d_max);
  const double cap = (0.9 * edge / 2 - 2 * b) / a;
  m.skin_over_rmin = std::min(m.skin_over_rmin, std::max(0.4, cap));
}

// A stress target in pascals the spheres cannot carry: at p* = 2 r_min p / k equal to
// integration.max_overlap_fraction their overlaps reach that fraction of the radius, where the
// run stops as a blow-up (blamed on dt). Relative targets are checked when p0 is known (path.cpp).
static void check_stress_targets(const Model& m, const std::string& origin) {
  const double limit = stress_target_limit(m);
  for (const auto& mode : m.protocol.modes)
    for (const auto& st : mode.path) {
      if (st.relative) continue;
      for (double t : {st.sigma.x, st.sigma.y, st.sigma.z, st.pressure})
        if (std::isfinite(t) && t > limit) {
          char b[700];
          std::snprintf(b, sizeof b, "%s: paths.%s stage '%s': a stress target of %g Pa is beyond what these spheres "
                        "carry: at integration.max_overlap_fraction x contact.stiffness_N_m / (2 particles.radius_min_m) "
                        "= %g Pa their overlaps reach max_overlap_fraction of the radius; give a target far below that "
                        "(elastic element tests stay near 1e-3 of it), or in multiples of the start pressure (sigma_p0, "
                        "pressure_p0)", origin.c_str(), mode.name.c_str(), st.name.c_str(), t, limit);
          throw SceneError(b);
        }
    }
}

// [particles], [contact] and [integration].
static void read_physics(KeyReader& r, Model& m, const std::string& origin, toml::table& root) {
  r.get("particles", "count", m.count);
  r.get("particles", "radius_min_m", m.radius_min);
  r.get("particles", "radius_max_m", m.radius_max);
  r.get("particles", "density_kg_m3", m.density);
  r.get("particles", "seed", m.seed);
  r.get("particles", "packing_file", m.packing_file);
  bool attractive = false;
  r.get("contact", "allow_attractive", attractive);
  m.contact.set_allow_attractive(attractive);
  r.get("contact", "background_damping_kg_s", m.background_damping);
  m.contact.set_scale(m.radius_min, m.density);   // for a law's time scale (Hertz's Rayleigh time)
  read_contact_section(r, m.contact, origin, root);
  std::string integrator = "velocity_verlet";
  r.get("integration", "integrator", integrator);
  if (integrator == "velocity_verlet") m.integrator = Integrator::VelocityVerlet;
  else if (integrator == "symplectic_euler") m.integrator = Integrator::SymplecticEuler;
  else throw SceneError(origin + ": integration.integrator = '" + integrator +
                        "' is unknown; use \"velocity_verlet\" or \"symplectic_euler\"");
  std::string kinematics = "sllod";
  r.get("integration", "kinematics", kinematics);
  if (kinematics == "sllod" || kinematics == "plain") m.sllod = kinematics == "sllod";
  else throw SceneError(origin + ": integration.kinematics = '" + kinematics +
                        "' is unknown; use \"sllod\" (default: the kinetic stress does work in a deforming box) or "
                        "\"plain\" (the scheme of dem 0.1)");
  r.get("integration", "dt_over_tc", m.dt_over_tc);
  m.skin_auto = r.get_number_or_auto("integration", "skin_over_rmin", m.skin_over_rmin);
  if (m.skin_auto) m.skin_over_rmin = auto_skin_over_rmin(m.dt_over_tc);
  r.get("integration", "threads", m.threads);
  r.get_if_present("integration", "blocks", m.blocks);
  r.get_if_present("integration", "adaptive_threads", m.adaptive_threads);
  r.get("integration", "max_overlap_fraction", m.max_overlap_fraction);
  r.get("integration", "check_every_steps", m.check_every_steps);
}

// The protocol's rates as the scene gives them, in units of 1/t_c (t_c is known only later).
struct ProtocolRates {
  double compress_tc = 1e-4, cycle_tc = 2e-5, dev_tc = 5e-6, relax_max_tc = 2e5;
};

// The rates checked (positive, quasi-static; the modes' and paths' entries too) and turned into
// 1/s and seconds with the scene's t_c; the servo's rate limit and time constant checked; path
// stages' times in seconds.
static void set_protocol_rates(Model& m, const ProtocolRates& r, const std::string& origin) {
  Protocol& p = m.protocol;
  auto positive = [&](double v, const char* key) {
    if (!(v > 0) || !std::isfinite(v))
      throw SceneError(origin + ": protocol." + key + " must be a positive number");
  };
  positive(r.compress_tc, "compress_rate_tc");
  positive(r.cycle_tc, "cycle_rate_tc");
  positive(r.dev_tc, "deviatoric_rate_tc");
  positive(r.relax_max_tc, "relax_max_time_tc");
  for (auto [rate_tc, key] : {std::pair{r.compress_tc, "compress_rate_tc"}, {r.cycle_tc, "cycle_rate_tc"},
                              {r.dev_tc, "deviatoric_rate_tc"}})
    if (rate_tc > 1e-2) {
      char b[300];
      std::snprintf(b, sizeof b, "%s: protocol.%s = %g deforms the box by %.3g%% per contact time: far from "
                    "quasi-static; use rates below 1e-3 (typical: 1e-6 to 1e-4)", origin.c_str(), key, rate_tc,
                    100 * rate_tc);
      throw SceneError(b);
    }
  check_mode_rates(p.modes, r.dev_tc, origin);
  check_stress_targets(m, origin);
  p.compress_rate = r.compress_tc / m.t_contact;
  p.cycle_rate = r.cycle_tc / m.t_contact;
  p.deviatoric_rate = r.dev_tc / m.t_contact;
  p.relax_max_time = r.relax_max_tc * m.t_contact;
  if (p.servo.rate_max_tc == 0) p.servo.rate_max_tc = 4 * r.dev_tc;
  if (!(p.servo.rate_max_tc > 0) || !std::isfinite(p.servo.rate_max_tc))
    throw SceneError(origin + ": servo.rate_max_tc must be a positive number (0: 4 x protocol.deviatoric_rate_tc)");
  if (!(p.servo.waves >= 0.1) || !std::isfinite(p.servo.waves))
    throw SceneError(origin + ": servo.waves must be >= 0.1 (the servo time in elastic-wave crossings of the box; "
                     "shorter makes the servo fight the packing's own dynamics)");
  p.servo.rate_max = p.servo.rate_max_tc / m.t_contact;
  for (auto& mode : p.modes)
    for (auto& st : mode.path)
      if (st.stop == PathStop::Time) st.until *= m.t_contact;   // time_tc -> seconds
      else if (st.stop == PathStop::Relaxed) st.max_time *= m.t_contact;
}

Model load_scene(const std::string& text, const std::vector<std::string>& overrides,
                 std::string* resolved, const std::string& origin) {
  toml::table root;
  try {
    root = toml::parse(ascii_scene(text, origin), origin);
  } catch (const toml::parse_error& e) {
    std::ostringstream m;
    m << origin << ":" << e.source().begin.line << ": TOML syntax error: " << e.description();
    throw SceneError(m.str());
  }
  check_sections(root, origin);
  for (auto& ov : overrides) apply_override(root, ov);

  Model m;
  // [sweep]: checked here (so `dem info` and `dem run` refuse a bad one), then left out of the
  // resolved scene: the rows' scenes are ordinary scenes (dem/io/sweep.hpp).
  m.sweep_rows = static_cast<int>(parse_scene_sweep(root, origin).rows.size());
  root.erase("sweep");
  KeyReader r(root, origin);
  read_physics(r, m, origin, root);

  Protocol& p = m.protocol;
  ProtocolRates rates;
  p.checkpoints_unloading = {0.80, 0.75, 0.70, 0.68};
  std::vector<std::string> modes = {"D2", "D3"};
  r.get("protocol", "initial_phi", p.initial_phi);
  const toml::array* preparation = explicit_preparation(root, origin);
  p.preparation_explicit = preparation != nullptr;
  r.known("protocol", "preparation");
  if (p.preparation_explicit) {
    r.get("protocol", "modes_from", p.modes_from);
  } else {
    r.get_if_present("protocol", "modes_from", p.modes_from);
    r.get("protocol", "target_phi", p.target_phi);
    r.get("protocol", "compress_rate_tc", rates.compress_tc);
    r.get("protocol", "relax_ke_ratio", p.relax_ke_ratio);
    r.get("protocol", "relax_max_time_tc", rates.relax_max_tc);
    r.get("protocol", "cycle_phi_max", p.cycle_phi_max);
    r.get("protocol", "cycle_rate_tc", rates.cycle_tc);
    r.get("protocol", "checkpoints_unloading", p.checkpoints_unloading);
    r.get("protocol", "checkpoints_loading", p.checkpoints_loading);
  }
  r.get("protocol", "modes", modes);
  r.get("protocol", "deviatoric_rate_tc", rates.dev_tc);
  r.get("protocol", "eps_d_max", p.eps_d_max);

  r.get("output", "sample_strain", m.output.sample_strain);
  r.get("output", "relax_sample_steps", m.output.relax_sample_steps);
  r.get("output", "vtk", m.output.vtk);
  r.get("output", "vtk_per_stage", m.output.vtk_per_stage);
  r.get("output", "progress_seconds", m.output.progress_seconds);
  r.get("ensemble", "packings", m.ensemble_packings);

  // User-defined modes: [modes] name = [rx, ry, rz] (diagonal) or a 3x3 velocity gradient
  // [[Lxx, Lxy, Lxz], [Lyx, Lyy, Lyz], [Lzx, Lzy, Lzz]] with nothing below the diagonal.
  r.allow_any("modes");
  const CustomModes custom = read_custom_modes(root, origin);
  r.allow_any("paths");
  const auto paths = parse_paths(root, origin, custom);
  r.get("servo", "waves", p.servo.waves);
  r.get("servo", "rate_max_tc", p.servo.rate_max_tc);
  r.reject_unknown();

  p.modes = resolve_modes(modes, custom, paths, origin);

  // Rates are given as rate * t_c; t_c needs the contact parameters, so validate those first.
  validate(m);
  try {
    m.finalize();
  } catch (const std::invalid_argument& e) {
    throw SceneError(origin + ": " + e.what());
  }
  // Every sub-model's oscillators must be integrable at this dt (contact/registry.hpp).
  const std::string unstable =
      contact::stability_problem(m.contact, contact::pair_scale(m.contact, m.radius_min, m.density), m.dt);
  if (!unstable.empty()) throw SceneError(origin + ": " + unstable);
  contact::compose(m.contact);
  set_protocol_rates(m, rates, origin);
  p.preparation = preparation ? parse_preparation(*preparation, m.t_contact, origin) : default_preparation(p);
  validate_preparation(p, m.t_contact, origin);
  if (m.skin_auto) cap_auto_skin(m);
  check_work(m, origin);
  if (resolved) {
    *resolved = toml_write(root);   // toml++'s bytes without its writer's undefined behaviour
  }
  return m;
}

Model load_scene_file(const std::string& path, const std::vector<std::string>& overrides,
                      std::string* resolved) {
  std::stringstream ss;
  try {
    ss << read_regular_file(path, "scene file", std::size_t(1) << 24);
  } catch (const std::runtime_error& e) {
    throw SceneError(e.what());
  }
  toml::table parsed;
  try {
    parsed = toml::parse(ascii_scene(ss.str(), path), path);
  } catch (const toml::parse_error&) {
    return load_scene(ss.str(), overrides, resolved, path);   // reports the syntax error
  }
  const bool no_keys = std::all_of(parsed.begin(), parsed.end(), [](const auto& kv) {
    const toml::table* t = kv.second.as_table();
    return t && t->empty();
  });
  if (no_keys)
    throw SceneError(path + ": the scene file is empty (no keys): it would silently run the built-in N = 9261 paper "
                     "scene for hours; start from a scene in data/scenes/ (quickstart.toml, paper_n9261.toml) "
                     "and change what you need");
  return load_scene(ss.str(), overrides, resolved, path);
}

namespace {

[[noreturn]] void fail(const std::string& msg) { throw SceneError(msg); }
bool finite_positive(double v) { return v > 0 && std::isfinite(v); }
std::string g(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

void validate_particles_and_contact(const Model& m) {
  if (m.count < 2) fail("particles.count must be at least 2");
  if (!finite_positive(m.radius_min)) fail("particles.radius_min_m must be positive and finite");
  if (!(m.radius_max >= m.radius_min) || !std::isfinite(m.radius_max))
    fail("particles.radius_max_m must be at least particles.radius_min_m, and finite");
  if (!finite_positive(m.density)) fail("particles.density_kg_m3 must be positive and finite");
  if (!(m.background_damping >= 0) || !std::isfinite(m.background_damping))
    fail("contact.background_damping_kg_s must be zero or positive and finite");
  contact::validate_contact(m.contact);
}

void validate_integration(const Model& m) {
  // Linear spring: both integrators are stable for omega_0 dt < 2, i.e. dt/t_c < 2/pi.
  const double dt_limit = 2.0 / M_PI;
  if (!finite_positive(m.dt_over_tc)) fail("integration.dt_over_tc must be positive");
  if (m.dt_over_tc >= dt_limit)
    fail("integration.dt_over_tc = " + std::to_string(m.dt_over_tc) + " is beyond the stability "
         "limit 2/pi = 0.637 of the integrator for a single contact (omega_0 dt < 2); "
         "dense packings need far less: use 0.02 (t_c/50)");
  if (!(m.skin_over_rmin > 0 && m.skin_over_rmin <= 4)) fail("integration.skin_over_rmin must be in (0, 4]");
  if (m.threads < 0) fail("integration.threads must be >= 0 (0 = all cores)");
  if (m.blocks < 0 || m.blocks > 4096)
    fail("integration.blocks must be in [0, 4096] (0: max(4, threads); N: the same results for any thread count)");
  if (!(m.max_overlap_fraction > 0 && m.max_overlap_fraction <= 2))
    fail("integration.max_overlap_fraction must be in (0, 2]");
  if (m.check_every_steps < 1) fail("integration.check_every_steps must be >= 1");
}

// Checkpoint lists: inside [target_phi, cycle_phi_max], no NaN, no two with the same file name.
void validate_checkpoints(const Protocol& p, const std::vector<double>& phis, const std::string& key) {
  std::set<std::string> names;
  for (double phi : phis) {
    if (!(phi >= p.target_phi && phi <= p.cycle_phi_max))
      fail("protocol." + key + " value " + g(phi) + " lies outside [target_phi, cycle_phi_max] = [" +
           g(p.target_phi) + ", " + g(p.cycle_phi_max) + "]");
    if (!names.insert(fmt_phi(phi)).second)
      fail("protocol." + key + " lists " + g(phi) + " twice, or two values that round to the same file name " +
           fmt_phi(phi) + " (3 decimals): keep one of them");
  }
}

void validate_modes_and_strain(const Protocol& p) {
  std::set<std::string> modes;
  for (const auto& mode : p.modes)
    if (!modes.insert(mode.name).second) fail("protocol.modes lists '" + mode.name + "' twice: keep one");
  if (!(p.eps_d_max > 0 && p.eps_d_max <= 2)) fail("protocol.eps_d_max must be in (0, 2]");
}

void validate_protocol(const Model& m) {
  const Protocol& p = m.protocol;
  if (!(p.initial_phi > 0 && p.initial_phi <= 0.45))
    fail("protocol.initial_phi must be in (0, 0.45]: random placement cannot go denser");
  if (p.preparation_explicit) {   // its stages are checked by validate_preparation
    validate_modes_and_strain(p);
    return;
  }
  // Soft spheres can be pushed past jamming, but at phi near 1 overlaps are of the order of
  // the radius and the linear contact law is meaningless.
  const double phi_limit = 0.9;
  for (double phi : {p.target_phi, p.cycle_phi_max})
    if (!(phi > 0 && phi < phi_limit))
      fail("volume fraction " + g(phi) + " in [protocol] is beyond what these soft "
           "spheres can pack without overlaps of the order of their radius; keep phi below 0.9");
  if (!(p.target_phi > p.initial_phi)) fail("protocol.target_phi must exceed protocol.initial_phi");
  if (!(p.cycle_phi_max >= p.target_phi)) fail("protocol.cycle_phi_max must be >= protocol.target_phi");
  validate_checkpoints(p, p.checkpoints_unloading, "checkpoints_unloading");
  validate_checkpoints(p, p.checkpoints_loading, "checkpoints_loading");
  if (!finite_positive(p.relax_ke_ratio)) fail("protocol.relax_ke_ratio must be positive and finite");
  validate_modes_and_strain(p);
}

void validate_output(const Model& m) {
  if (!finite_positive(m.output.sample_strain)) fail("output.sample_strain must be positive and finite");
  if (m.output.relax_sample_steps < 1) fail("output.relax_sample_steps must be >= 1");
  if (m.output.vtk_per_stage < -1)
    fail("output.vtk_per_stage must be >= 0, or -1 (auto: 20 snapshots per stage up to 2000 particles, fewer above)");
  if (!(m.output.progress_seconds >= 0) || !std::isfinite(m.output.progress_seconds))
    fail("output.progress_seconds must be zero or positive and finite (use --quiet for no progress lines)");
}

}  // namespace

void validate(const Model& m) {
  validate_particles_and_contact(m);
  validate_integration(m);
  validate_protocol(m);
  validate_output(m);
  if (m.ensemble_packings < 1 || m.ensemble_packings > 10000)
    fail("ensemble.packings must be in [1, 10000] (independent packings of the scene)");
  if (m.ensemble_packings > 1 && !m.packing_file.empty())
    fail("ensemble.packings = " + std::to_string(m.ensemble_packings) + " with particles.packing_file: every "
         "member would start from the same packing; an ensemble needs random placements (packing_file = \"\")");
}

}  // namespace dem
