// Macroscopic measurements of a state: stress, fabric, coordination, energies, strains.
// Definitions follow Imole et al. (KONA 2013) and Goncu et al. (2010); see docs/definitions.md.
#pragma once
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/core/state.hpp"

namespace dem {

struct Measurement {
  std::int64_t step = 0;
  double time = 0;                ///< [s]
  Vec3 strain;                    ///< true box strains ln(L/L0), extension positive
  double eps_v = 0;               ///< (eps_xx + eps_yy + eps_zz) / 3
  double eps_d = 0;               ///< deviatoric magnitude of the strain diagonal (sheared cell: eps_d_eig)
  double nu = 0;                  ///< volume fraction
  Sym3 stress;                    ///< [Pa], compression positive, contact + kinetic parts
  Sym3 stress_kinetic;            ///< the kinetic part alone [Pa]
  double p = 0;                   ///< tr(stress)/3 [Pa]
  double p_star = 0;              ///< 2 <r> p / k
  double sigma_dev = 0;           ///< deviatoric magnitude of the stress diagonal [Pa] (sheared cell: sigma_dev_eig)
  double s_dev = 0;               ///< sigma_dev / |p| (a packing in tension too; 0 when p = 0)
  Sym3 fabric;                    ///< (1/V) sum_p V_p sum_c n n
  double F_dev = 0;               ///< deviatoric magnitude of the fabric diagonal (sheared cell: F_dev_eig)
  double C = 0;                   ///< 2 * contacts / N
  double C_nonrattler = 0;        ///< 2 * contacts among non-rattlers / N_non-rattlers
  double rattler_fraction = 0;    ///< rattlers / N (fewer than 4 contacts, removed recursively)
  double E_kin = 0;               ///< [J], fluctuation velocities
  double E_pot = 0;               ///< [J], elastic energy of contacts
  double overlap_max_rel = 0;     ///< max delta / min(r_i, r_j)
  double overlap_mean_rel = 0;    ///< mean delta / min(r_i, r_j) over contacts
  double inertial_number = 0;     ///< |eps_dot|_max * 2<r> * sqrt(rho / |p|)   (0 when p = 0)
  long contacts = 0;
  // With friction (friction_columns(), after the usual columns):
  bool frictional = false;
  double sliding_fraction = 0;    ///< contacts at the Coulomb limit / contacts
  /// Coordination of the particles with at least 2 contacts, removed recursively: the rattler rule of frictional
  /// packings (one contact cannot balance a particle, two can with friction; docs/friction.md, "Isostaticity")
  double C_nonrattler_2 = 0;
  double E_rot = 0;               ///< rotational kinetic energy sum I w^2/2 [J]
  double omega_mean = 0;          ///< mean |w| [rad/s]
  double E_t = 0;                 ///< elastic energy of the tangential springs [J] (part of E_pot)
  double W_friction = 0;          ///< energy dissipated by Coulomb sliding since the state began [J]
  Vec3 stress_antisym;            ///< antisymmetric part of the contact stress (xy, xz, yz) [Pa]
  // Objective (frame-independent) measures, from eigenvalues (docs/simple_shear.md). For a
  // diagonal deformation the strain ones equal the diagonal forms above to round-off; the stress
  // and fabric ones differ from them only by the off-diagonal parts of the tensors.
  Sym3 strain_tensor;             ///< logarithmic strain 0.5 ln(F F^T) since the stage start
  double eps_d_eig = 0;           ///< deviatoric magnitude of the eigenvalues of strain_tensor
  double sigma_dev_eig = 0;       ///< ... of the stress [Pa]
  double s_dev_eig = 0;           ///< sigma_dev_eig / |p|
  double F_dev_eig = 0;           ///< ... of the fabric
  /// Angles [deg, 0..90] between principal directions: the major (most compressive) stress
  /// direction, the major fabric direction, and the most compressive direction of the strain
  /// rate D = sym(L). NaN where a direction is undefined (isotropic D, e.g. no rate).
  double angle_sigma_F = NAN, angle_sigma_D = NAN, angle_F_D = NAN;
};

/// Eigenvalues (ascending) and unit eigenvectors of a symmetric tensor (Eigen's
/// SelfAdjointEigenSolver, iterative: exact for a diagonal tensor).
void principal(const Sym3& t, double value[3], Vec3 vector[3]);
/// deviatoric_magnitude() of the eigenvalues: sqrt(3 J2), invariant under rotations.
double deviatoric_magnitude_eig(const Sym3& t);
/// The logarithmic (Hencky) strain 0.5 ln(F F^T) of the box since strains were zeroed,
/// F = Box::deformation_gradient(); for an untilted box exactly diag(ln(L/L0)) (true_strain()).
Sym3 log_strain_tensor(const Box& box);
/// Angle [deg] between the axes of two unit vectors (0..90: directions, not orientations).
double axis_angle_deg(const Vec3& a, const Vec3& b);

/// The rattler rule of measure(): a particle with fewer than `min_contacts` contacts (4, d + 1: frictionless
/// spheres; 2 for frictional ones, C_nonrattler_2) is a rattler, removed with its contacts, recursively. `pairs` are
/// the contacts (i, j) of n particles; 1 = rattler.
std::vector<char> rattler_flags(int n, const std::vector<std::pair<int, int>>& pairs, int min_contacts = 4);

/// Measures a state. `list` must be current for the state (it is after every Engine step).
/// `rate` [1/s] enters the dashpot forces, the inertial number (max |L_ij|) and the
/// non-coaxiality angles. Strain columns: ln(L/L0) for an untilted box (diagonal modes, as
/// always), the components of the log strain tensor in a sheared one.
Measurement measure(const Model& model, const State& state, const NeighborList& list,
                    const VelGrad& rate);

/// Which curves have a column: every curve, curves of a model with rotations (a tangential
/// sub-model: its SubModelInfo::curve_columns names this group), loading-path curves, and
/// path curves with a shear stage.
enum class ColumnGroup { Every, Rotations, Path, PathSheared };

/// One curve column, defined once: the CSV header, `dem info --columns [--json]`, the docs'
/// column list (docs/curve_columns.md, generated), demtk's measure() and yade_ref/run_mode.py
/// read this table.
struct CurveColumn {
  const char* name;      ///< header name; its suffix names the unit (_Pa, _J, _s, _1_s, _deg, _rad_s)
  const char* unit;      ///< "1" (dimensionless), "Pa", "J", "s", "1/s", "deg", "rad/s", "count"
  const char* meaning;   ///< one line
  ColumnGroup group;
  /// Its value in a Measurement (nullptr for path columns: the path runner writes them, path.cpp).
  double (*value)(const Measurement&);
  bool integer = false;  ///< written as an integer (step, contacts)
};

/// Every column, in file order (every, rotations, path, path with shear; `stage` last, not listed).
const std::vector<CurveColumn>& column_table();
/// The group's name in text and JSON ("every", "rotations", "path", "path_sheared").
const char* group_name(ColumnGroup g);
/// The names of one group's columns, in order.
std::vector<std::string> columns_of(ColumnGroup g);

/// Column names of the curve CSV every curve has, in order (the Every group).
const std::vector<std::string>& curve_columns();

/// One CSV row (no newline) of the Every columns and, when m.frictional, the Rotations ones;
/// `stage` is appended last by the curve file.
std::string curve_row(const Measurement& m);

/// The columns a frictional curve adds after curve_columns() (the Rotations group).
const std::vector<std::string>& friction_columns();

}  // namespace dem
