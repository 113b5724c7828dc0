#include "dem/contact/registry.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "dem/contact/contact_model.hpp"
#include "dem/core/errors.hpp"

namespace dem::contact {

std::string g_num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

std::string exact_num(double v) {
  char b[40];
  const std::to_chars_result r = std::to_chars(b, b + sizeof b, v);   // the shortest text that reads back as v
  return std::string(b, r.ptr);
}

namespace {

// The "off" entries of the rolling and twisting slots.
SubModelInfo off_info(Slot slot, const std::string& what) {
  SubModelInfo d;
  d.slot = slot;
  d.name = "none";
  d.title = "no " + what + " resistance";
  d.yade = d.lammps = "none";
  d.lammps_words = [](const ContactLaw&) { return std::string(); };   // LAMMPS: leave the keyword out
  d.yade_words = [](const ContactLaw&) { return std::string(); };     // YADE: nothing to say
  d.liggghts = "none";
  d.liggghts_words = [](const ContactLaw&) { return std::string(); };
  d.describe = [](const ContactLaw&, const PairScale&) { return std::string("off"); };
  return d;
}

constexpr Slot kSlots[] = {Slot::Normal, Slot::Tangential, Slot::Rolling, Slot::Twisting};

const KeySpec* key_of(const SubModelInfo& m, const std::string& key) {
  for (const KeySpec& k : m.keys)
    if (k.name == key) return &k;
  return nullptr;
}

std::string bounds_text(const KeySpec& k) {
  if (k.hi > k.lo) return std::string(k.lo_open ? "(" : "[") + g_num(k.lo) + ", " + g_num(k.hi) + "]";
  return k.lo_open ? "positive and finite" : "zero or positive and finite";
}

bool within(const KeySpec& k, double v) {
  if (!std::isfinite(v)) return false;
  if (k.lo_open ? !(v > k.lo) : !(v >= k.lo)) return false;
  return !(k.hi > k.lo) || v <= k.hi;
}

}  // namespace

const std::vector<const SubModelInfo*>& submodels() {
  static const SubModelInfo rolling_off = off_info(Slot::Rolling, "rolling");
  static const SubModelInfo twisting_off = off_info(Slot::Twisting, "twisting");
  // The registry: one line per sub-model, each slot's default first.
  static const std::vector<const SubModelInfo*> all = {
      &LinearSpring::info(), &LudingNormal::info(), &HertzNormal::info(),     // normal
      &NoTangential::info(), &CundallStrack::info(), &MindlinTangential::info(),
      &MindlinForceTangential::info(),                                        // tangential
      &rolling_off, &RollingSpring::info(),               // rolling
      &twisting_off, &TwistingSpring::info()};            // twisting
  return all;
}

const SubModelInfo* find_submodel(Slot slot, const std::string& name) {
  for (const SubModelInfo* m : submodels())
    if (m->slot == slot && m->name == name) return m;
  return nullptr;
}

std::string slot_selector(Slot slot) {
  return slot == Slot::Normal ? "normal" : slot == Slot::Tangential ? "tangential" : "";
}

std::string slot_name(Slot slot) {
  switch (slot) {
    case Slot::Normal: return "normal";
    case Slot::Tangential: return "tangential";
    case Slot::Rolling: return "rolling";
    case Slot::Twisting: return "twisting";
  }
  return "";
}

namespace {

const SubModelInfo& slot_default(Slot slot) {
  for (const SubModelInfo* m : submodels())
    if (m->slot == slot) return *m;
  throw std::logic_error("contact registry: slot without sub-models");
}

std::string names_of(Slot slot) {
  std::string s;
  for (const SubModelInfo* m : submodels())
    if (m->slot == slot) s += (s.empty() ? "\"" : ", \"") + m->name + "\" (" + m->title + ")";
  return s;
}

// The sub-model a switched slot (rolling, twisting) gets: the one whose switch key is non-zero.
const SubModelInfo* switched_on(Slot slot, const ContactKeys& keys) {
  for (const SubModelInfo* m : submodels()) {
    if (m->slot != slot || m->switch_key.empty()) continue;
    double v = 0;
    keys.peek_number(m->switch_key, v);
    if (v != 0) return m;
  }
  return nullptr;
}

// A selected slot's choice: the selector's name, else the sub-model whose key implies it (a
// tangential model by a non-zero contact.friction), else the slot's default.
const SubModelInfo& selected(Slot slot, const ContactKeys& keys, bool& said, const std::string& origin) {
  const std::string sel = slot_selector(slot);
  std::string name;
  keys.peek_string(sel, name);
  said = !name.empty();
  if (said) {
    if (const SubModelInfo* m = find_submodel(slot, name)) return *m;
    throw SceneError(origin + ": contact." + sel + " = '" + name + "' is unknown; use " + names_of(slot) +
                     " (docs/contact_models.md; dem info --contact-models lists every sub-model)");
  }
  for (const SubModelInfo* m : submodels()) {   // e.g. friction > 0 alone selects cundall_strack
    if (m->slot != slot || m->implied_by.empty()) continue;
    double v = 0;
    keys.peek_number(m->implied_by, v);
    if (v != 0) return *m;
  }
  return slot_default(slot);
}

// The default of a key, with its "times another key" resolved from values already read.
double default_of(const KeySpec& k, const ContactLaw& law) {
  return k.fallback_times.empty() ? k.fallback : k.fallback * law.get(k.fallback_times);
}

// A key given in the scene that no chosen sub-model reads: refused, naming the sub-model that
// reads it, unless `tolerated` (its slot was switched off outright: "none", or the switch key = 0).
void refuse_unused(const SubModelInfo& owner, const std::string& key, const ContactKeys& keys,
                   const std::set<std::string>& read, bool tolerated, const std::string& origin) {
  if (read.count(key) || tolerated || !keys.present(key)) return;
  double v = 0;
  keys.peek_number(key, v);
  if (v == 0) return;   // a zero of a key not in use changes nothing (sweeps over 0 keep their table)
  const std::string sel = slot_selector(owner.slot);
  const std::string how = !owner.switch_key.empty() && owner.switch_key != key
                              ? "set contact." + owner.switch_key + " > 0" +
                                    (owner.rotations ? " (with a tangential model)" : "")
                              : !sel.empty() ? "set contact." + sel + " = \"" + owner.name + "\""
                                             : "set a tangential model (contact.friction > 0)";
  throw SceneError(origin + ": contact." + key + " belongs to the " + slot_name(owner.slot) + " sub-model \"" +
                   owner.name + "\" (" + owner.title + "), which this scene does not use: " + how + ", or remove it");
}

}  // namespace

void read_contact(const ContactKeys& keys, ContactLaw& law, const std::string& origin) {
  law.clear_values();
  std::set<std::string> read;
  std::vector<const SubModelInfo*> chosen;
  bool tangential_said_none = false;
  for (Slot slot : kSlots) {
    bool said = false;
    const SubModelInfo* m = nullptr;
    if (slot == Slot::Normal || slot == Slot::Tangential) {
      m = &selected(slot, keys, said, origin);
      if (slot == Slot::Tangential) tangential_said_none = said && m->name == slot_default(slot).name;
    } else if (law.frictional()) {
      m = switched_on(slot, keys);
    } else if (const SubModelInfo* on = switched_on(slot, keys); on && !tangential_said_none) {
      refuse_unused(*on, on->switch_key, keys, read, false, origin);
    }
    if (!m) m = &slot_default(slot);
    law.select(slot, m->name);
    if (!slot_selector(slot).empty() && m != &slot_default(slot)) {   // listed in the resolved scene
      std::string name = m->name;
      keys.get_string(slot_selector(slot), name);
    }
    for (const KeySpec& k : m->keys) {
      double v = default_of(k, law);
      keys.get_number(k.name, v);
      law.set(k.name, v);
      read.insert(k.name);
    }
    chosen.push_back(m);
  }
  // Keys of sub-models not in use.
  for (const SubModelInfo* m : submodels()) {
    if (std::find(chosen.begin(), chosen.end(), m) != chosen.end()) continue;
    const bool off_outright =
        (m->slot == Slot::Tangential && tangential_said_none) ||
        (m->slot != Slot::Tangential && tangential_said_none) ||
        (!m->switch_key.empty() && keys.present(m->switch_key) && law.frictional());
    for (const KeySpec& k : m->keys)   // a key that implies the sub-model contradicts "none"
      refuse_unused(*m, k.name, keys, read, off_outright && k.name != m->implied_by, origin);
  }
  const SubModelInfo& normal = *chosen.front();
  law.set_time_step(normal.time_step_stiffness(law), normal.time_step_damping(law));
  law.set_reference_stiffness(normal.reference_stiffness(law));
}

void validate_contact(const ContactLaw& law) {
  for (const SubModelInfo* m : chosen_submodels(law)) {
    for (const KeySpec& k : m->keys) {
      const double v = law.get(k.name);
      if (!within(k, v))
        throw SceneError("contact." + k.name + " must be " + bounds_text(k) + " (" + k.meaning + "); the scene gives " +
                         g_num(v));
    }
    if (m->check)
      if (const std::string problem = m->check(law); !problem.empty()) throw SceneError(problem);
  }
}

std::vector<const SubModelInfo*> chosen_submodels(const ContactLaw& law) {
  std::vector<const SubModelInfo*> out;
  for (Slot slot : kSlots) {
    const SubModelInfo* m = find_submodel(slot, law.model(slot));
    if (!m) throw std::logic_error("contact law names an unknown " + slot_name(slot) + " sub-model '" + law.model(slot) + "'");
    out.push_back(m);
  }
  return out;
}

PairScale pair_scale(const ContactLaw& law, double radius_min, double density) {
  const double m = 4.0 / 3.0 * M_PI * radius_min * radius_min * radius_min * density;
  return {0.5 * m, radius_min, law.reference_stiffness()};
}

double stable_dt(const Oscillator& o) {
  if (!(o.k > 0)) return o.gamma > 0 ? 2.0 * o.m_eff / o.gamma : std::numeric_limits<double>::infinity();
  const double w = std::sqrt(o.k / o.m_eff), zeta = o.gamma / (2.0 * o.m_eff * w);
  return 2.0 / w * (std::sqrt(1.0 + zeta * zeta) - zeta);
}

namespace {

std::vector<Oscillator> oscillators_of(const ContactLaw& law, const PairScale& s) {
  std::vector<Oscillator> out;
  for (const SubModelInfo* m : chosen_submodels(law))
    if (m->oscillators) for (Oscillator& o : m->oscillators(law, s)) out.push_back(std::move(o));
  return out;
}

bool stable_with(const ContactLaw& law, const PairScale& s, double dt, const std::string& key, double v) {
  ContactLaw trial = law;
  trial.set(key, v);
  for (const Oscillator& o : oscillators_of(trial, s))
    if ((o.stiffness_key == key || o.damping_key == key) && !(dt < stable_dt(o))) return false;
  return true;
}

bool is_normal_key(const ContactLaw& law, const std::string& key) {
  const SubModelInfo* n = find_submodel(Slot::Normal, law.model(Slot::Normal));
  return n && key_of(*n, key);
}

}  // namespace

double largest_stable_value(const ContactLaw& law, const PairScale& s, double dt, const std::string& key) {
  if (!stable_with(law, s, dt, key, 0.0)) return 0.0;
  double lo = 0.0, hi = std::max(1.0, std::fabs(law.get(key)));
  while (stable_with(law, s, dt, key, hi)) {
    lo = hi;
    hi *= 2;
    if (hi > 1e300) return std::numeric_limits<double>::infinity();
  }
  for (int it = 0; it < 200 && hi - lo > 1e-12 * hi; ++it) {
    const double mid = 0.5 * (lo + hi);
    (stable_with(law, s, dt, key, mid) ? lo : hi) = mid;
  }
  return lo;
}

std::string stability_problem(const ContactLaw& law, const PairScale& s, double dt) {
  for (const Oscillator& o : oscillators_of(law, s)) {
    if (dt < stable_dt(o)) continue;
    std::string fix;
    for (const std::string& key : {o.stiffness_key, o.damping_key}) {
      if (key.empty() || is_normal_key(law, key)) continue;
      const double best = largest_stable_value(law, s, dt, key);
      fix += std::string(fix.empty() ? "" : "; or ") + "contact." + key + " = " + g_num(law.get(key)) + " -> at most " +
             g_num(best * 0.999999) + (best == 0 ? " (no value helps: lower the other key)" : "");
    }
    if (fix.empty()) fix = "lower integration.dt_over_tc";
    else fix += "; or lower integration.dt_over_tc";
    char b[200];
    std::snprintf(b, sizeof b, "dt = %.4g s is beyond the explicit integrator's stability limit %.4g s of ", dt,
                  stable_dt(o));
    return b + o.what + " (k = " + g_num(o.k) + " N/m, gamma = " + g_num(o.gamma) + " kg/s, m_eff = " +
           g_num(o.m_eff) + " kg; dt < (2/omega)(sqrt(1 + zeta^2) - zeta)): the run would blow up or give wrong "
           "stresses and a negative dissipation: " + fix;
  }
  return "";
}

std::vector<std::string> stability_lines(const ContactLaw& law, const PairScale& s, double dt) {
  std::vector<std::string> out;
  for (const Oscillator& o : oscillators_of(law, s)) {
    const double limit = stable_dt(o);
    char b[160];
    std::snprintf(b, sizeof b, "largest stable dt %.4g s (dt is %.3g of it)", limit, dt / limit);
    std::string line = o.what + ": " + b;
    for (const std::string& key : {o.stiffness_key, o.damping_key})
      if (!key.empty() && !is_normal_key(law, key))
        line += "; contact." + key + " <= " + g_num(largest_stable_value(law, s, dt, key)) + " at this dt";
    out.push_back(line);
  }
  return out;
}

const std::vector<std::string>& record_base_keys() {
  static const std::vector<std::string> keys = {"stiffness_N_m", "damping_kg_s"};
  return keys;
}

std::vector<std::pair<std::string, std::string>> contact_record(const ContactLaw& law,
                                                                  const std::function<std::string(double)>& num) {
  std::vector<std::pair<std::string, std::string>> out;
  const auto& base = record_base_keys();
  for (const SubModelInfo* m : chosen_submodels(law)) {
    if (m == &slot_default(m->slot)) continue;   // the defaults keep the records made before them
    if (!slot_selector(m->slot).empty()) out.emplace_back("contact." + slot_selector(m->slot), m->name);
    for (const KeySpec& k : m->keys)
      if (std::find(base.begin(), base.end(), k.name) == base.end())
        out.emplace_back("contact." + k.name, num(law.get(k.name)));
  }
  return out;
}

std::vector<std::pair<std::string, std::string>> record_defaults(const std::function<std::string(double)>& num) {
  std::vector<std::pair<std::string, std::string>> out;
  std::set<std::string> seen;
  for (Slot slot : kSlots)
    if (!slot_selector(slot).empty()) out.emplace_back("contact." + slot_selector(slot), slot_default(slot).name);
  for (const SubModelInfo* m : submodels())
    for (const KeySpec& k : m->keys)
      if (k.fallback_times.empty() && seen.insert(k.name).second) out.emplace_back("contact." + k.name, num(k.fallback));
  return out;
}

namespace {

// The other sub-models of m's slot that the law's other choices accept (their `check` passes
// with them selected instead of m), as "\"a\" or \"b\"": what the slot's selector
// could name instead. The slot's default ("none") is left out.
std::string accepted_alternatives(const SubModelInfo& m, const ContactLaw& law) {
  std::string out;
  for (const SubModelInfo* o : submodels()) {
    if (o->slot != m.slot || o == &m || o == &slot_default(m.slot)) continue;
    ContactLaw with = law;
    with.select(m.slot, o->name);
    if (o->check && !o->check(with).empty()) continue;
    out += (out.empty() ? "\"" : " or \"") + o->name + "\"";
  }
  return out;
}

}  // namespace

std::vector<std::string> describe_contact(const ContactLaw& law, const PairScale& s) {
  std::vector<std::string> out;
  for (const SubModelInfo* m : chosen_submodels(law)) {
    std::string name = slot_name(m->slot);
    name.resize(17, ' ');
    out.push_back("  " + name + m->name + ": " + m->describe(law, s));
    // A sub-model a key implies (friction > 0 alone selects cundall_strack): say so where the
    // other choices accept another law of the slot (e.g. Mindlin's with the Hertz normal law),
    // which the scene would have to name.
    if (m->implied_by.empty() || slot_selector(m->slot).empty()) continue;
    if (const std::string others = accepted_alternatives(*m, law); !others.empty())
      out.push_back("  " + std::string(17, ' ') + "(\"" + m->name + "\" is what contact." + m->implied_by +
                    " > 0 selects when contact." + slot_selector(m->slot) + " is not given; with the " +
                    law.model(Slot::Normal) + " normal law contact." + slot_selector(m->slot) + " may also be " +
                    others + "; dem info --contact-models describes them)");
  }
  return out;
}

namespace {

using WordsOf = std::function<std::string(const ContactLaw&)> SubModelInfo::*;

// Each chosen sub-model's words in another code's input (the member `words`), each after a space;
// SceneError naming the sub-model that has none ("has no " + what + ": " + its member `why`) or
// whose values that code cannot take (the std::invalid_argument its words throw).
std::string chosen_words(const std::vector<const SubModelInfo*>& chosen, const ContactLaw& law, WordsOf words,
                         std::string SubModelInfo::*why, const std::string& what) {
  std::string line;
  for (const SubModelInfo* m : chosen) {
    if (!(m->*words))
      throw SceneError("contact." + slot_name(m->slot) + " = \"" + m->name + "\" has no " + what + ": " + m->*why);
    std::string w;
    try {
      w = (m->*words)(law);
    } catch (const std::invalid_argument& e) {
      throw SceneError(e.what());
    }
    if (!w.empty()) line += " " + w;
  }
  return line;
}

}  // namespace

std::string lammps_pair_coeff(const ContactLaw& law) {
  const std::vector<const SubModelInfo*> chosen = chosen_submodels(law);
  std::string line = "pair_coeff * *" + chosen_words(chosen, law, &SubModelInfo::lammps_words, &SubModelInfo::lammps,
                                                     "LAMMPS pair granular counterpart");
  if (chosen.front()->lammps_tail) line += " " + chosen.front()->lammps_tail(law);
  return line;
}

namespace {

std::string join_words(const std::vector<std::string>& v) {
  std::string o;
  for (const std::string& w : v) o += (o.empty() ? "" : ", ") + w;
  return o;
}

// The run_mode.py --law every chosen sub-model accepts, the normal sub-model's preference first.
std::string common_yade_law(const std::vector<const SubModelInfo*>& chosen, const ContactLaw& law) {
  std::vector<std::string> laws = chosen.front()->yade_laws(law);
  std::string why = "contact.normal = \"" + chosen.front()->name + "\" works with --law " + join_words(laws) + " (" +
                    chosen.front()->yade + ")";
  for (const SubModelInfo* m : chosen) {
    if (!m->yade_laws || m == chosen.front()) continue;
    const std::vector<std::string> ok = m->yade_laws(law);
    if (ok.empty()) continue;
    laws.erase(std::remove_if(laws.begin(), laws.end(),
                              [&](const std::string& l) { return std::find(ok.begin(), ok.end(), l) == ok.end(); }),
               laws.end());
    why += ", contact." + slot_name(m->slot) + " = \"" + m->name + "\" with " + join_words(ok) + " (" + m->yade + ")";
  }
  if (laws.empty())
    throw SceneError("no YADE law of yade_ref/run_mode.py takes this contact law: " + why +
                     "; change the scene so that one law takes every sub-model (e.g. a dashpot FrictMat lacks set to 0)");
  return laws.front();
}

}  // namespace

std::string yade_run_mode_options(const ContactLaw& law) {
  const std::vector<const SubModelInfo*> chosen = chosen_submodels(law);
  const std::string words = chosen_words(chosen, law, &SubModelInfo::yade_words, &SubModelInfo::yade,
                                         "counterpart in yade_ref/run_mode.py");
  return "--law " + common_yade_law(chosen, law) + words;
}

std::string liggghts_pair_style(const ContactLaw& law) {
  const std::vector<const SubModelInfo*> chosen = chosen_submodels(law);
  std::string fixes, style = "pair_style gran";
  int n = 0;
  style += chosen_words(chosen, law, &SubModelInfo::liggghts_words, &SubModelInfo::liggghts,
                        "LIGGGHTS pair gran counterpart here");
  for (const SubModelInfo* m : chosen) {
    if (m->liggghts_properties)
      for (const std::string& p : m->liggghts_properties(law)) {
        const std::size_t sp = p.find(' ');
        fixes += "fix m" + std::to_string(++n) + " all property/global " + p.substr(0, sp) + " peratomtypepair 1" +
                 p.substr(sp) + "\n";
      }
  }
  if (chosen.front()->liggghts_tail) style += " " + chosen.front()->liggghts_tail(law);
  return fixes + style + "\npair_coeff * *";
}

std::string contact_preamble(const ContactLaw& law, const PairScale& s) {
  std::string o;
  for (const SubModelInfo* m : chosen_submodels(law))
    if (m != &slot_default(m->slot)) o += "# contact " + slot_name(m->slot) + ": " + m->name + ", " + m->describe(law, s) + "\n";
  return o;
}

nlohmann::json registry_json() {
  nlohmann::json all = nlohmann::json::array();
  for (const SubModelInfo* m : submodels()) {
    nlohmann::json keys = nlohmann::json::array();
    for (const KeySpec& k : m->keys)
      keys.push_back({{"key", "contact." + k.name}, {"unit", k.unit}, {"default", k.fallback},
                      {"default_times", k.fallback_times.empty() ? nlohmann::json() : nlohmann::json("contact." + k.fallback_times)},
                      {"bounds", bounds_text(k)}, {"meaning", k.meaning}});
    all.push_back({{"slot", slot_name(m->slot)}, {"name", m->name}, {"title", m->title},
                   {"selected_by", m->switch_key.empty() ? "contact." + slot_selector(m->slot) + " = \"" + m->name + "\""
                                                         : "contact." + m->switch_key + " > 0"},
                   {"reference", m->reference}, {"keys", keys}, {"history", m->history},
                   {"history_text", m->history_text}, {"rotations", m->rotations}, {"yade", m->yade},
                   {"lammps", m->lammps}, {"liggghts", m->liggghts}, {"column_groups", m->column_groups}, {"vtk_fields", m->vtk_fields}});
  }
  return all;
}

std::string registry_text() {
  std::string o;
  for (const SubModelInfo* m : submodels()) {
    o += slot_name(m->slot) + " \"" + m->name + "\": " + m->title + "\n";
    if (!m->switch_key.empty()) o += "    on when contact." + m->switch_key + " > 0\n";
    if (!m->reference.empty()) o += "    source: " + m->reference + "\n";
    for (const KeySpec& k : m->keys)
      o += "    contact." + k.name + " [" + k.unit + "] default " +
           (k.fallback_times.empty() ? g_num(k.fallback) : g_num(k.fallback) + " x contact." + k.fallback_times) + ", " +
           bounds_text(k) + ": " + k.meaning + "\n";
    if (m->history) o += "    history: " + std::to_string(m->history) + " doubles per contact (" + m->history_text + ")\n";
    if (!m->column_groups.empty()) {
      std::string c;
      for (const auto& n : m->column_groups) c += (c.empty() ? "" : ", ") + n;
      o += "    curve columns: the \"" + c + "\" group (dem info --columns)\n";
    }
    o += "    YADE: " + m->yade + "\n    LAMMPS: " + m->lammps + "\n    LIGGGHTS: " + m->liggghts + "\n";
  }
  return o;
}

namespace {
template <class... T>
int name_index(TypeList<T...>, const std::string& name) {
  const char* names[] = {T::name...};
  for (int i = 0; i < static_cast<int>(sizeof...(T)); ++i)
    if (name == names[i]) return i;
  return -1;
}
template <class... T>
int accepting_index(TypeList<T...>, const ContactLaw& law) {
  const bool ok[] = {T::accepts(law)...};
  for (int i = 0; i < static_cast<int>(sizeof...(T)); ++i)
    if (ok[i]) return i;
  return 0;
}
}  // namespace

std::array<int, 3> composition_index(const ContactLaw& law) {
  const int n = name_index(NormalModels{}, law.model(Slot::Normal));
  const int t = name_index(TangentialModels{}, law.model(Slot::Tangential));
  if (n < 0 || t < 0)
    throw std::logic_error("contact law names an unknown sub-model: normal '" + law.model(Slot::Normal) +
                           "', tangential '" + law.model(Slot::Tangential) + "'");
  return {n, t, accepting_index(RollingSlotModels{}, law)};
}

void compose(const ContactLaw& law) {
  ContactLaw::Cache c;
  c.index = composition_index(law);
  c.stamp = law.stamp();
  with_contact_model(law, [&](const auto& cm) {
    using CM = std::decay_t<decltype(cm)>;
    c.model = std::make_shared<const CM>(cm);
  });
  law.set_cache(std::move(c));
}

}  // namespace dem::contact
