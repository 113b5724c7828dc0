// The immutable description of a simulation: physics parameters, protocol and outputs.
// Loaded from a TOML scene file (see scene.hpp), validated once, then only read.
// All quantities are SI: metres, kilograms, seconds, newtons, pascals.
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "dem/core/vec3.hpp"

namespace dem {

/// Which time integrator advances the particles.
enum class Integrator {
  VelocityVerlet,     ///< kick-drift-kick, forces at the half-step velocity (default)
  SymplecticEuler,    ///< v += a dt; x += v dt  (what YADE's NewtonIntegrator does)
};

/// The slots of the contact model, in the order a contact's force is composed
/// (contact/contact_model.hpp); each holds one sub-model, chosen by name.
enum class ContactSlot { Normal = 0, Tangential = 1, Rolling = 2, Twisting = 3 };
inline constexpr int kContactSlots = 4;

/// The contact model as the scene chose it ([contact]): a sub-model name per slot and the values
/// of the chosen sub-models' keys. What the names mean, which keys each sub-model has (units,
/// defaults, bounds) and how they become forces is declared by the sub-models themselves and
/// collected in one registry (contact/registry.hpp); this struct only carries the choice, so a
/// new sub-model adds nothing here. Filled by the scene loader (`contact::read_contact`).
class ContactLaw {
 public:
  /// The sub-model in a slot: "linear" / "luding" (normal), "none" / "cundall_strack"
  /// (tangential), "none" / "sds" (rolling, twisting), or whatever the registry holds.
  const std::string& model(ContactSlot s) const { return models_[static_cast<int>(s)]; }
  /// A key's value (a scene key of a chosen sub-model, without "contact."): throws
  /// std::logic_error naming the key when the chosen sub-models have no such key.
  double get(const std::string& key) const;
  /// A key's value, or `fallback` when the chosen sub-models have no such key.
  double get_or(const std::string& key, double fallback) const;
  bool has(const std::string& key) const { return values_.count(key) != 0; }
  const std::map<std::string, double>& values() const { return values_; }
  void select(ContactSlot s, const std::string& name) { models_[static_cast<int>(s)] = name; ++stamp_; }
  void set(const std::string& key, double v) { values_[key] = v; ++stamp_; }
  void clear_values() { values_.clear(); ++stamp_; }

  /// If false (default) the normal force is clamped at zero when the dashpot outweighs the spring
  /// on separation (no sticking; physical for dry grains), which is also what YADE 2023.02a's
  /// Law2_ScGeom_ViscElPhys_Basic does (docs/yade.md). If true the force may turn attractive.
  bool allow_attractive() const { return attractive_; }
  void set_allow_attractive(bool a) { attractive_ = a; ++stamp_; }

  /// The model needs angular velocities, torques and per-contact history (a tangential sub-model).
  bool frictional() const { return model(ContactSlot::Tangential) != "none"; }
  bool rolling() const { return frictional() && model(ContactSlot::Rolling) != "none"; }
  bool twisting() const { return frictional() && model(ContactSlot::Twisting) != "none"; }
  /// The normal sub-model's stiffness for t_c and dt [N/m] (its fastest branch): set by the
  /// registry from the normal sub-model's declaration when the law is composed.
  double time_step_stiffness() const { return time_step_stiffness_; }
  /// The normal sub-model's dashpot for t_c and e [kg/s] (constant viscosity).
  double time_step_damping() const { return time_step_damping_; }
  void set_time_step(double k, double gamma) { time_step_stiffness_ = k; time_step_damping_ = gamma; }
  /// The normal sub-model's reference stiffness [N/m] for p* = 2<r>p/k (k, or k1 for Luding's law).
  double reference_stiffness() const { return reference_stiffness_; }
  void set_reference_stiffness(double k) { reference_stiffness_ = k; }
  /// The smallest particle's radius [m] and the particles' density [kg/m^3], for a normal law
  /// whose time scale needs them (Hertz's Rayleigh time): the scene loader sets them before the
  /// contact keys are read.
  double scale_radius() const { return scale_radius_; }
  double scale_density() const { return scale_density_; }
  void set_scale(double radius_min, double density) { scale_radius_ = radius_min; scale_density_ = density; ++stamp_; }

  /// Changes with every change of the choice or a value: the composed model cached for the pair
  /// loops (contact::compose) is used only while it matches.
  std::uint64_t stamp() const { return stamp_; }
  struct Cache {
    std::shared_ptr<const void> model;   ///< the composed model, of the type the indices name
    std::array<int, 3> index{};          ///< its normal, tangential and rolling-slot type
    std::uint64_t stamp = ~0ULL;
  };
  const Cache& cache() const { return cache_; }
  void set_cache(Cache c) const { cache_ = std::move(c); }

 private:
  std::array<std::string, kContactSlots> models_{"linear", "none", "none", "none"};
  std::map<std::string, double> values_;
  bool attractive_ = false;
  double time_step_stiffness_ = 0, time_step_damping_ = 0, reference_stiffness_ = 0;
  double scale_radius_ = 0, scale_density_ = 0;
  std::uint64_t stamp_ = 0;
  mutable Cache cache_;
};

/// What ends a stage of a loading path (PathStage::stop).
enum class PathStop {
  EpsD,       ///< eps_d of the box strain gained in this stage reaches `until` (an increment, > 0)
  Time,       ///< the stage has lasted `until` seconds
  EpsV,       ///< eps_v since the path start crosses `until` (a value, reached from either side)
  EpsXX, EpsYY, EpsZZ,   ///< that true strain component since the path start crosses `until`
  Pressure,   ///< p crosses `until` [Pa]
  SDev,       ///< s_dev crosses `until`
  Phi,        ///< the volume fraction crosses `until`
  TauXY, TauXZ, TauYZ,   ///< the shear stress tau_ij = -sigma_ij [Pa] crosses `until` (forward SS_ij: tau > 0)
  Relaxed,    ///< at a sampled row: E_kin < `until` * max(E_pot, E_floor) and every servo target held within 1 %
};

/// One stage of a loading path (strain reversal, cyclic shear, mixed control). Each axis is
/// either strain-rate controlled (its entry of `shape`, times protocol.deviatoric_rate) or
/// stress controlled (a finite `sigma` entry: a servo drives sigma_ii to it). Alternatively
/// `pressure` holds the mean pressure at a target with the prescribed rate as the deviatoric
/// direction (isobaric shear). Targets are in pascals after the path start has resolved
/// multiples of p0 (the pressure at the path start; PathStage::relative).
struct PathStage {
  std::string name;                     ///< label in the curve's `stage` column
  /// The prescribed velocity-gradient shape [-] (times protocol.deviatoric_rate: L [1/s]): its
  /// diagonal the strain-rate shape, its upper entries (L_xy, L_xz, L_yz) simple shear in a
  /// sheared cell (docs/simple_shear.md), always strain controlled; a servo acts on the diagonal.
  VelGrad shape;
  Vec3 sigma{NAN, NAN, NAN};            ///< normal-stress target per axis (NaN: strain controlled), compression > 0
  double pressure = NAN;                ///< mean-pressure target (NaN: none)
  /// With `pressure` and one compressed axis k (the only non-zero `shape.diag` entry, sigma_1):
  /// the true-triaxial test at constant p and fixed b = (sigma_2 - sigma_3)/(sigma_1 - sigma_3),
  /// sigma_3 on axis k+1, sigma_2 on axis k+2 (cyclic; z compressed: sigma_3 = x, sigma_2 = y),
  /// both servo controlled (NaN: none). b = 0 is triaxial compression, 1 extension, at constant p.
  double lode_b = NAN;
  bool relative = true;                 ///< sigma, pressure (and a Pressure stop) in multiples of p0, else [Pa]
  bool constant_volume = false;         ///< asserts tr(rate) = 0 and no servo (checked)
  PathStop stop = PathStop::EpsD;
  double until = 0;                     ///< stop value (see PathStop); a Pressure or Tau stop in Pa once resolved
  bool until_relative = false;          ///< a Pressure or Tau stop given in multiples of p0
  double max_time = 0;                  ///< a Relaxed stop ends (with a warning) after this [s]; 0: no limit but the path's
  bool sheared() const { return shape.sheared(); }
  bool has_servo() const { return std::isfinite(pressure) || std::isfinite(sigma.x) || std::isfinite(sigma.y) ||
                                  std::isfinite(sigma.z); }
};

/// A deformation applied to the periodic box from each checkpoint. A plain mode is a constant
/// velocity gradient (diagonal: a true-strain rate (box lengths follow L_k(t) = L_k(0) exp(rate_k t)) up to eps_d_max;
/// a loading path ([paths] in the scene) is a list of stages, written as one curve.
struct DeformationMode {
  std::string name;             ///< e.g. "D2", "D3", "iso", "uniaxial_z", or a [paths] name
  /// The velocity-gradient shape [-], multiplied by the mode rate (protocol.deviatoric_rate: L
  /// [1/s]): the diagonal a strain-rate direction, the upper entries (L_xy, L_xz, L_yz) simple
  /// shear (a sheared cell, docs/simple_shear.md).
  VelGrad shape;
  bool sheared() const { return shape.sheared(); }
  std::vector<PathStage> path;  ///< non-empty: a loading path (shape unused)
};

/// The stress servo of path stages (control.hpp): a PI law on the stress error with its gain
/// from the packing's affine stiffness, a time constant of `waves` elastic-wave crossings of
/// the box and a strain-rate limit.
struct ServoOptions {
  double waves = 1;             ///< servo time constant / time for an elastic wave to cross the box
  double rate_max = 0;          ///< |servo strain rate| limit [1/s] (derived: rate_max_tc / t_c)
  double rate_max_tc = 0;       ///< scene value; 0: 4 x protocol.deviatoric_rate_tc
};

/// One stage of the preparation (`protocol.preparation` in a scene, or the built-in list made
/// from the compress/relax/cycle keys, default_preparation()). Either an isotropic compression
/// or expansion at a constant true strain rate until the volume fraction reaches `phi`, or a
/// relaxation at constant volume until E_kin < ke_ratio * max(E_pot, E_floor) or `max_time`.
/// A compression (expansion) that starts at or above (below) its `phi` is skipped with a note.
/// Checkpoints: a phi strictly between the stage's start and `phi` is landed on exactly; one
/// equal to the start (end) volume fraction is saved before (after) the stage.
struct PrepStage {
  /// Pressure / Uniaxial: stress controlled (a servo, control.hpp) from wherever the packing is to
  /// `target` [Pa] (p, or sigma_zz with the x and y lengths fixed), then held there until relaxed.
  enum class Kind { Compress, Expand, Relax, Pressure, Uniaxial };
  std::string name;                  ///< file stem: prep/<name>.csv, resume point prep/after_<name>.ckpt
  Kind kind = Kind::Relax;
  double rate = 0;                   ///< compress/expand: true strain rate per axis, magnitude [1/s]
  double phi = 0;                    ///< compress/expand: target volume fraction
  double ke_ratio = 1e-8;            ///< relax: ends when E_kin < ke_ratio * max(E_pot, E_floor)
  double max_time = 0;               ///< relax, pressure, uniaxial: ends after this duration at the latest [s]
  double target = 0;                 ///< pressure / uniaxial: the stress target [Pa] (rate: the servo's rate limit)
  std::string checkpoint_name;       ///< checkpoints/<checkpoint_name>_phiX.XXX.{ckpt,txt}
  std::vector<double> checkpoints;   ///< volume fractions at which the state is saved
};

/// The protocol: preparation (compress, relax, cycle) then deviatoric modes from checkpoints.
struct Protocol {
  double initial_phi = 0.3;          ///< random placement volume fraction, (0, 0.45]
  double target_phi = 0.64;          ///< phi_t, end of first compression, below jamming
  double compress_rate = 0;          ///< isotropic true volumetric-strain rate per axis [1/s]
  double relax_ke_ratio = 1e-8;      ///< relaxation ends when E_kin < ratio * max(E_pot, E_floor)
  double relax_max_time = 0;         ///< [s] relaxation ends at this time at the latest
  double cycle_phi_max = 0.82;       ///< top of the compression/decompression cycle
  double cycle_rate = 0;             ///< isotropic strain rate during the cycle [1/s]
  std::vector<double> checkpoints_unloading;   ///< phi values for checkpoints on unloading
  std::vector<double> checkpoints_loading;     ///< phi values on loading (optional)
  /// The preparation stages in order (filled by load_scene: `protocol.preparation` or the
  /// built-in list made from the keys above).
  std::vector<PrepStage> preparation;
  bool preparation_explicit = false; ///< true: the scene lists protocol.preparation
  std::string modes_from = "unloading";        ///< the checkpoint series the modes start from
  std::vector<DeformationMode> modes;          ///< run from every checkpoint of `modes_from`
  double deviatoric_rate = 0;        ///< mode rate [1/s] (multiplies a mode's shape)
  double eps_d_max = 0.4;            ///< deviatoric runs stop at this eps_d (or |eps| for others)
  ServoOptions servo;                ///< stress control of loading-path stages
};

/// Output cadence and formats.
struct OutputOptions {
  double sample_strain = 2e-3;       ///< a curve row every this much strain change (eps_d or eps_v)
  long relax_sample_steps = 2000;    ///< a row every this many steps while relaxing
  int vtk_per_stage = -1;            ///< VTK snapshots per stage besides start and end (-1: auto_vtk_per_stage, 20 for small scenes)
  bool vtk = true;                   ///< write VTK snapshots (.vtu + .pvd)
  double progress_seconds = 2.0;     ///< wall seconds between progress lines on stderr
};

/// Everything that describes a run. Immutable once validated.
struct Model {
  // particles
  int count = 9261;                  ///< N, >= 2
  double radius_min = 0.5e-3;        ///< [m]
  double radius_max = 1.5e-3;        ///< [m]
  double density = 2000;             ///< [kg/m^3]
  unsigned long long seed = 1;       ///< seeds placement and initial velocities
  std::string packing_file;          ///< start from this YADE-format packing instead of placing

  ContactLaw contact;
  double background_damping = 0.1;   ///< gamma_b [kg/s] on the fluctuation velocity, >= 0

  // integration
  Integrator integrator = Integrator::VelocityVerlet;
  /// Fluctuation velocities in the deforming box. true (SLLOD, default): v' also feels
  /// -E_dot v' (integrated exactly as v' *= exp(-rate dt) with the box deformation), so the
  /// kinetic stress does work and E_kin + E_pot changes by -V sigma:E_dot dt (docs/control.md, "Kinematics in the deforming box").
  /// false ("plain", dem 0.1): v' is left unchanged by the deformation, which leaves the
  /// kinetic stress's work out of the energy balance.
  bool sllod = true;
  double dt_over_tc = 1.0 / 50.0;    ///< dt as a fraction of t_c of the two smallest particles
  double skin_over_rmin = 0.4;       ///< Verlet skin / radius_min (a scene's "auto": auto_skin_over_rmin)
  bool skin_auto = false;            ///< skin_over_rmin came from auto_skin_over_rmin (the scene's default)
  int threads = 0;                   ///< OpenMP threads; 0: all available
  /// Blocks of the pair loop (forces.hpp): the summation order of the forces depends on the
  /// blocks, not on the threads that run them, so one block count gives the same bits for any
  /// thread count. 0 (default): max(4, threads), i.e. 1-4 threads give identical curves (cost:
  /// 3.7 % more instructions than one block on one thread, docs/benchmarks.md).
  int blocks = 0;
  /// Run a step on one thread instead of the team when that is measured to be faster (a
  /// machine busy with other jobs); the same bits either way. false: always all threads.
  bool adaptive_threads = true;
  double max_overlap_fraction = 1.0; ///< stop if an overlap exceeds this fraction of the smaller radius (blow-up;
                                     ///< at phi = 0.82 real packings reach 0.4 (N = 9261) to 0.52 (N = 30000))
  long check_every_steps = 200;      ///< sanity-check cadence

  Protocol protocol;
  OutputOptions output;

  /// [ensemble] packings: independent packings of this scene (K >= 1). Member k is the same
  /// scene with particles.seed = member_seed(seed, k); K = 1 is a single packing.
  int ensemble_packings = 1;
  /// Rows of the scene's [sweep] table (0: none). The table itself is read by dem/io/sweep.hpp;
  /// it is not part of the resolved scene (each row's scene is an ordinary scene).
  int sweep_rows = 0;

  // Derived quantities (filled by finalize()).
  double t_contact = 0;              ///< t_c of two radius_min spheres [s]
  double restitution = 0;            ///< e of two radius_min spheres
  double dt = 0;                     ///< time step [s]

  /// Computes t_c, e, dt from the parameters. Call after changing any parameter.
  void finalize();
};

/// Contact duration [s] and restitution of a pair with reduced mass m_r [kg].
/// Throws std::invalid_argument when the pair is overdamped (gamma^2/(4 m_r^2) >= k/m_r).
struct PairCollision { double t_contact; double restitution; };
PairCollision pair_collision(double stiffness, double damping, double reduced_mass);

/// Seed of ensemble member k (k = 0 .. K-1): member 0 keeps `seed`, the others get
/// well-separated seeds (SplitMix64 of seed and k, below 2^53 so TOML and JSON keep them exact),
/// so that the ensembles of seeds 1 and 2 share no member.
unsigned long long member_seed(unsigned long long seed, int k);

/// Mass [kg] of a sphere of radius r [m] and density rho [kg/m^3].
double sphere_mass(double radius, double density);

/// File-name tag of a volume fraction: "phi0.700" (3 decimals; checkpoint and curve names).
std::string fmt_phi(double phi);

/// The neighbour skin a scene gets by default ("auto"), from its time step alone, so the same
/// scene gives the same skin (and bits) on any machine, thread count and restart:
///   skin / r_min = 0.4 (dt/t_c / 0.02)^0.4 for dt > t_c/50, else 0.4 (the default at t_c/50;
/// 1.0 at t_c/5, 1.56 at the stability limit). A thicker skin lists more pairs (each costs the pair loop every step) but is
/// rebuilt less often (each rebuild costs about 65 listed pairs' worth per particle); particles
/// move about dt further per step, so the best skin grows with dt. The constants come from the
/// measured cost model of bench/skin_scan.py (docs/skin_scan.md). The scene loader caps it for a
/// box of few particles (never below 0.4), so such a scene still fits two list cutoffs.
double auto_skin_over_rmin(double dt_over_tc);

}  // namespace dem
