// How a contact sub-model describes itself (after LAMMPS' `gran_sub_mod*`, which declare their
// coefficients, mixing and history, and MercuryDPM's Species mixins): its scene keys with units,
// defaults, bounds and meaning; its text for `dem info`, the curve preamble and the physics
// record; the oscillators the time step must integrate (its stability bound); its history; the
// curve columns and VTK fields it adds; its YADE and LAMMPS counterparts. Each sub-model
// declares this in its own header (`static const SubModelInfo& info()`), next to its force; the
// registry (registry.hpp) lists the sub-models once and everything else reads it.
#pragma once
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "dem/core/model.hpp"

namespace dem::contact {

/// One scene key of a sub-model: `[contact] name = value`.
struct KeySpec {
  std::string name;          ///< the key under [contact], e.g. "friction"
  std::string unit;          ///< "N/m", "kg/s", "Pa", or "1" (dimensionless)
  double fallback = 0;       ///< the default value (times the value of `fallback_times`, if named)
  std::string fallback_times;   ///< non-empty: the default is fallback x this key's value (Luding's kp = 5 k1)
  double lo = 0, hi = 0;     ///< bounds (lo_open: lo excluded; hi <= lo: no upper bound)
  bool lo_open = false;
  std::string meaning;       ///< one line: what it is, with an example value
};

/// A mass on a spring and dashpot that the time integrator must resolve for one contact of the
/// smallest pair: m_eff x'' = -k x - gamma x'. Explicit central differences (velocity Verlet)
/// are stable for dt < (2/omega)(sqrt(1 + zeta^2) - zeta), omega = sqrt(k/m_eff),
/// zeta = gamma/(2 m_eff omega) (Belytschko, Liu, Moran, Nonlinear Finite Elements, sec. 6.3).
struct Oscillator {
  std::string what;          ///< e.g. "the tangential spring of the contact point"
  double m_eff;              ///< [kg]
  double k;                  ///< [N/m]
  double gamma;              ///< [kg/s]
  std::string stiffness_key; ///< the key that sets k (k = value x k_per_key), "" if none
  double k_per_key = 1;
  std::string damping_key;   ///< the key that sets gamma (gamma = value), "" if none
};

/// Smallest-pair scales the description functions get.
struct PairScale {
  double m_r;    ///< reduced mass of two radius_min spheres [kg]
  double r;      ///< radius_min [m]
  double k_ref;  ///< the normal sub-model's reference stiffness [N/m] (ratios such as k_t/k multiply it)
};

using Slot = ContactSlot;

/// printf-style %g of a number (for the description texts).
std::string g_num(double v);
/// A number as the shortest text that reads back as the same double, for input decks of other codes.
std::string exact_num(double v);

struct SubModelInfo {
  Slot slot;
  std::string name;          ///< the slot's value in a scene ("linear", "cundall_strack", ...)
  std::string title;         ///< one line for people
  std::string reference;     ///< where the law comes from
  std::vector<KeySpec> keys; ///< its scene keys ([contact] name)
  /// The key whose non-zero value switches the sub-model on (rolling, twisting), "" if the slot's
  /// selector (contact.normal, contact.tangential) names it.
  std::string switch_key;
  /// A key whose non-zero value selects this sub-model when the slot's selector is absent
  /// (contact.friction > 0 alone selects cundall_strack); "" for none.
  std::string implied_by;
  int history = 0;           ///< doubles of per-contact history
  std::string history_text;  ///< what they are and how they change when i and j swap
  bool rotations = false;    ///< needs angular velocities and torques (6 degrees of freedom)
  std::string yade;          ///< the YADE counterpart (classes), or "none"
  std::string lammps;        ///< the LAMMPS `pair granular` counterpart, or "none"
  /// Its words in a LAMMPS `pair granular` `pair_coeff` line with this law's values (a normal
  /// sub-model: its normal model; the others: their keyword and coefficients; "" for a slot left
  /// empty), SI units; null: no counterpart (`lammps` says why). `lammps_pair_coeff` joins them.
  std::function<std::string(const ContactLaw&)> lammps_words;
  /// A normal sub-model's words after every other slot's (its damping model, limit_damping).
  std::function<std::string(const ContactLaw&)> lammps_tail;
  /// Its YADE counterpart as options of yade_ref/run_mode.py (`dem info SCENE --yade`): the
  /// `--law` values (run_mode.py's YADE law families) it works with for this law's values, in
  /// order of preference (empty: any), and its options with this law's values ("" for none);
  /// `yade_words` null: no counterpart (`yade` says why). `yade_run_mode_options` joins them.
  std::function<std::vector<std::string>(const ContactLaw&)> yade_laws;
  std::function<std::string(const ContactLaw&)> yade_words;
  /// Its LIGGGHTS `pair_style gran` counterpart: its words there ("model hooke/stiffness",
  /// "tangential history"; "" for a slot left empty), a normal sub-model's keywords after every
  /// slot's (`liggghts_tail`: "absolute_damping on limitForce on"), and the global properties it
  /// reads, "NAME VALUE" each (a `fix property/global NAME peratomtypepair 1 VALUE`), SI units;
  /// `liggghts_words` null: no counterpart declared (`liggghts` says why). `liggghts_pair_style` joins them.
  std::string liggghts = "none declared";
  std::function<std::string(const ContactLaw&)> liggghts_words;
  std::function<std::string(const ContactLaw&)> liggghts_tail;
  std::function<std::vector<std::string>(const ContactLaw&)> liggghts_properties;
  /// Groups of curve columns it adds (the column table's groups, measure.hpp: "rotations").
  std::vector<std::string> column_groups;
  std::vector<std::string> vtk_fields;      ///< contact-network fields it adds
  /// Its `dem info` line and curve-preamble text for a law and pair scale.
  std::function<std::string(const ContactLaw&, const PairScale&)> describe;
  /// The normal sub-model's stiffness for t_c and dt [N/m] (its fastest branch); null for the rest.
  std::function<double(const ContactLaw&)> time_step_stiffness;
  /// The normal sub-model's dashpot for t_c and e [kg/s]; null for the rest.
  std::function<double(const ContactLaw&)> time_step_damping;
  /// The normal sub-model's reference stiffness for p* [N/m]; null for the rest.
  std::function<double(const ContactLaw&)> reference_stiffness;
  /// The oscillators its parameters make (empty: none beyond the normal contact's t_c).
  std::function<std::vector<Oscillator>(const ContactLaw&, const PairScale&)> oscillators;
  /// Checks between its keys beyond their bounds (e.g. kp > k1); returns the problem or "".
  std::function<std::string(const ContactLaw&)> check;
};

}  // namespace dem::contact
