// The registry of contact sub-models: every sub-model's description (submodel.hpp), slot by
// slot, in one list, and what is made from the descriptions: the scene's [contact] keys read and
// checked, the physics record, the `dem info` and curve-preamble text, the stability bounds the
// time step puts on every sub-model's parameters, and the JSON that the Python tools
// (yade_ref/run_mode.py, bench/decks.py, demtk) read. No sub-model is named outside its own
// header, the slot lists (contact_model.hpp) and registry.cpp.
#pragma once
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "dem/contact/submodel.hpp"
#include "dem/core/model.hpp"

namespace dem::contact {

/// Every sub-model, in slot order (normal, tangential, rolling, twisting; each slot's default first).
const std::vector<const SubModelInfo*>& submodels();
/// The sub-model of a slot by name, or nullptr.
const SubModelInfo* find_submodel(Slot slot, const std::string& name);
/// The scene key that selects a slot's sub-model by name ("normal", "tangential"), "" for the
/// slots switched by a key of their own (rolling, twisting).
std::string slot_selector(Slot slot);
std::string slot_name(Slot slot);
/// The sub-models a law uses, in slot order (the rolling and twisting slots only when on).
std::vector<const SubModelInfo*> chosen_submodels(const ContactLaw& law);

/// What the scene loader gives the registry to read [contact] (implemented over toml++ in
/// io/scene.cpp): typed reads that insert the default into the resolved scene (`get`) or not
/// (`get_if_present`), and whether a key is in the scene.
struct ContactKeys {
  std::function<bool(const std::string& key)> present;
  std::function<void(const std::string& key, double& value)> get_number;   ///< inserts the default
  std::function<void(const std::string& key, double& value)> peek_number;  ///< never inserts
  std::function<void(const std::string& key, std::string& value)> get_string;
  std::function<void(const std::string& key, std::string& value)> peek_string;
};
/// Reads the sub-model choice and the chosen sub-models' keys into `law` (names, values, the
/// normal sub-model's stiffnesses); refuses an unknown name and a key of a sub-model not in use,
/// naming the sub-model that would use it. Throws SceneError.
void read_contact(const ContactKeys& keys, ContactLaw& law, const std::string& origin);
/// Checks every chosen key against its bounds and the sub-models' own checks. Throws SceneError.
void validate_contact(const ContactLaw& law);

/// The smallest pair's scales for a law (radius_min, density).
PairScale pair_scale(const ContactLaw& law, double radius_min, double density);

/// One oscillator's stability at dt: the largest dt it allows [s].
double stable_dt(const Oscillator& o);
/// The largest value of `key` that an oscillator of the law allows at dt (the others fixed),
/// by bisection on the law's oscillators; +inf if no value of it limits dt.
double largest_stable_value(const ContactLaw& law, const PairScale& s, double dt, const std::string& key);
/// The sub-models' oscillators at dt: empty if all are stable, else the first problem with the
/// key and the largest value that would run (for a SceneError).
std::string stability_problem(const ContactLaw& law, const PairScale& s, double dt);
/// One line per oscillator for `dem info`: its period, the largest stable dt, its margin.
std::vector<std::string> stability_lines(const ContactLaw& law, const PairScale& s, double dt);

/// The physics-record entries of the contact model, after the base keys: for every chosen
/// sub-model other than its slot's default, its selector (if named) and its keys, in declaration
/// order, except the normal keys the base record holds (record_base_keys).
std::vector<std::pair<std::string, std::string>> contact_record(const ContactLaw& law,
                                                                  const std::function<std::string(double)>& num);
/// The normal keys the base record lists in their old place ("stiffness_N_m", "damping_kg_s"),
/// so the records (and hashes) of runs made before the registry stay the same.
const std::vector<std::string>& record_base_keys();
/// The defaults a record made before a sub-model existed stands for: "contact.KEY" -> value
/// text of every slot's default choice (the selectors) and of every key, where the key has a
/// fixed default.
std::vector<std::pair<std::string, std::string>> record_defaults(const std::function<std::string(double)>& num);

/// `dem info`'s lines of the contact model: one per slot ("normal     linear: ...").
std::vector<std::string> describe_contact(const ContactLaw& law, const PairScale& s);
/// The curve preamble's `# contact:` lines (the chosen sub-models beyond the frictionless default).
std::string contact_preamble(const ContactLaw& law, const PairScale& s);
/// Every sub-model with its keys (units, defaults, bounds, meaning), history, counterparts.
nlohmann::json registry_json();
/// The same for people (`dem info --contact-models`).
std::string registry_text();
/// The LAMMPS `pair granular` line of this law, `pair_coeff * * ...`, from the chosen sub-models'
/// `lammps_words` (normal, tangential, rolling, twisting, then the normal's `lammps_tail`), for
/// the benchmark decks (`dem info SCENE --lammps`). Throws SceneError naming the sub-model that
/// has no LAMMPS counterpart.
std::string lammps_pair_coeff(const ContactLaw& law);
/// The LIGGGHTS lines of this law: a `fix mN all property/global NAME peratomtypepair 1 VALUE` per
/// property the chosen sub-models read, then `pair_style gran ...` (each one's `liggghts_words`,
/// the normal's `liggghts_tail`) and `pair_coeff * *` (`dem info SCENE --liggghts`, bench/decks.py).
/// Throws SceneError naming the sub-model with no LIGGGHTS counterpart declared.
std::string liggghts_pair_style(const ContactLaw& law);
/// This law as options of yade_ref/run_mode.py, `--law L ...`: L the first of the normal
/// sub-model's `yade_laws` every other chosen sub-model accepts, then each one's `yade_words`
/// (`dem info SCENE --yade`). Throws SceneError naming the sub-model with no YADE counterpart, or
/// the sub-models whose YADE laws exclude each other.
std::string yade_run_mode_options(const ContactLaw& law);

}  // namespace dem::contact
