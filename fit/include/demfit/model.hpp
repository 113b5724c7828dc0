// The incremental anisotropic constitutive model (Magnanimo & Luding 2011; Imole et al. 2013;
// Kumar, Luding & Magnanimo 2014), in the scalar form of the biaxial/axisymmetric frame:
// pressure p, stress ratio s = sigma_dev/p and deviatoric fabric F (both signed along the
// loading direction), volume fraction nu. Equations and the source of every term: docs/model.md.
//
// Units: pressures are dimensionless p* = 2<r> p / k (as the curves' p_star column); strains
// are true (log) strains; eps_vol is the full volumetric strain tr(E) = 3 eps_v (extension
// positive), eps_d the deviatoric magnitude of docs/definitions.md, signed by the loading
// direction. Everything here is templated on the scalar so that Ceres can differentiate it.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace demfit::model {

/// Layout of the isotropic parameter block (the laws of Goncu et al. 2010 for the unloading branch).
enum IsoIndex {
  kP0 = 0,     ///< p0 [-] (p* units): prefactor of the pressure law
  kNuC,        ///< nu_c [-]: jamming volume fraction of the pressure law
  kGammaP,     ///< gamma_p [-]: non-linearity of the pressure law
  kC0,         ///< C0 [-]: coordination number at jamming
  kC1,         ///< C1 [-]: amplitude of the coordination power law
  kNuCC,       ///< nu_cC [-]: jamming volume fraction of the coordination law
  kAlpha,      ///< alpha [-]: exponent of the coordination law
  kNumIso
};

/// Layout of the shear parameter block: six quantities, each a law of nu with two
/// coefficients, q(nu) = a + b (nu - nu_ref) (rates through their logarithm, so they stay > 0).
enum ShearIndex {
  kSmaxA = 0, kSmaxB,      ///< s_max(nu) [-]: critical-state stress ratio
  kLnBetaSA, kLnBetaSB,    ///< ln beta_s(nu), beta_s [-] (per unit eps_d): rate of the stress ratio
  kFmaxA, kFmaxB,          ///< F_max(nu) [-]: critical-state deviatoric fabric
  kLnBetaFA, kLnBetaFB,    ///< ln beta_F(nu), beta_F [-]: rate of the fabric
  kAnisoA, kAnisoB,        ///< a_A(nu) [-]: anisotropy modulus A = a_A B F
  kLnBetaPA, kLnBetaPB,    ///< ln beta_p(nu), beta_p [-]: relaxation rate of the anisotropic excess pressure
  kNumShear
};

/// Layout of the extension block of the frictional family (docs/model.md, "The frictional
/// extension"). Every term is neutral at zero: with all seven at 0 (and no Lode surface) the
/// right-hand side is the group model's, bit for bit (x * 1.0, pow(r, 0.0) = 1, + B * 0.0).
enum ExtIndex {
  kNFA = 0, kNFB,          ///< n_F(nu) [-]: exponent of the mobilisation r^n_F that gates the fabric rate
  kKappaA, kKappaB,        ///< kappa_s(nu) [-]: shape of the stress-ratio law, rate x (1 + kappa_s r)
  kDilA, kDilB,            ///< d_D(nu) [-]: plastic dilatancy per unit eps_d, d_D (r - chi_D)(1 - F/F_max)
  kChiD,                   ///< chi_D [-]: mobilisation at which the dilatancy changes sign (phase transformation)
  /// n_psi(nu) [-] (issue 31, fifth round; only with Ext::state_limit, else never read): the stress-ratio
  /// limit's state dependence, s_lim (p_ref/p)^n_psi = s_lim exp(-n_psi psi_p), psi_p = ln(p/p_ref) the
  /// state parameter in pressure form (docs/model.md, "The state-dependent limit").
  kNPsiA, kNPsiB,
  /// The `Weighted` fabric rule's Lode weight (issue 31, sixth round; only with FabricLode::Weighted, else never
  /// read): w = 1/(1 + (delta_w/delta)^n_w) in [0, 1], delta = delta/d the mean contact overlap; ln delta_w [-]
  /// the overlap at which w = 1/2, n_w [-] the switch's steepness (docs/model.md, "The Lode weight").
  kLnDeltaW, kNW,
  /// lambda_psi [-] (issue 31, eighth round; only with Ext::state_lode, else never read): the state exponent's
  /// Lode dependence, n_psi (c_3(b_ref)/c_3(b))^lambda_psi, c_3 the minor principal fraction of a unit strain
  /// deviator (1.73^lambda_psi in axisymmetric compression against D2; docs/model.md, "The state exponent at
  /// another Lode angle").
  kLambdaPsi,
  /// The volume-form state parameter (issue 31, tenth round; only with Ext::state_volume, else never read):
  /// psi = nu - nu_cs(p), nu_cs(p) = nu_cs + lambda_cs ln(p/kPCsRef) + c_cs (p - kPCsRef) the critical-state line
/// in the volume fraction, one of the two terms held at 0 (`--csl log|linear`)
  /// (positive psi: denser than critical). The stress-ratio target s_lim exp(n_b psi) (a peak when dense, Manzari &
  /// Dafalias 1997's M exp(-n_b psi_e)), and the dilatancy d_D (r - chi_D exp(-n_d psi)) (Li & Dafalias 2000's
  /// phase transformation M exp(m psi_e)): the volume is driven to nu_cs(p) whatever the preparation
  /// (docs/model.md, "The volume-form state parameter").
  kNuCs,       ///< nu_cs [-]: the critical-state volume fraction at p* = kPCsRef
  kLambdaCs,   ///< lambda_cs [-]: d nu_cs / d ln p* (positive: soft spheres pack denser at higher pressure)
  kNB,         ///< n_b [-] (written n_peak): the peak's state exponent
  kND,         ///< n_d [-] (written n_dil): the phase transformation's state exponent
  /// c_cs [-]: d nu_cs / d p*, the line's linear term (eleventh round, `--csl linear`: nu_cs(p) = nu_cs + c_cs (p* -
  /// kPCsRef), the rigid-grain critical state nu_cs - c_cs kPCsRef compressed by the contacts' compliance; 0 in the
  /// logarithmic form and in files written before it)
  kCCs,
  /// n_rate [-]: the exponent of the rates' elastic scaling ((B/p)/(B/p)_ref)^n_rate (twelfth round, rate_scale):
  /// 1 in files written before it (the eleventh round's scaling), 0 unscaled; fitted with --state-limit volume
  kNRate,
  /// m_peak [-]: the peak's state exponent at pressure p, n_peak (p*/kPCsRef)^m_peak (twelfth round: at the same psi
  /// the dense peak rises with the pressure from p* = 1e-3 to 5e-2; 0 in files written before it; fitted with
  /// --state-limit volume from two start pressures on)
  kMPeak,
  kNumExt
};

/// The drained triaxial control (Control::Triaxial) solves (B - A/3) d eps_vol = ... for the volume change: it has a
/// pole where the anisotropy modulus A = a_A B F reaches 3B (a_A F = 3): the volume change per unit shear diverges and no
/// constant side stress can be held. Within kTriaxialMargin of it (B - A/3 at most 0.1 B, B > 0: the volume rate
/// amplified tenfold or more, where RK4's fixed steps throw the stress ratio far off before they reach the pole) a state
/// is lost (State::lost, every entry NaN): the path is not continued, and a fit's step that leads there is rejected
/// (twentieth round; docs/model.md, "Where the drained triaxial control is lost").
constexpr double kTriaxialMargin = 0.1;
/// Reference pressure of the critical-state line nu_cs(p) of the volume-form state parameter [p* units].
constexpr double kPCsRef = 1e-3;
/// With the volume-form state parameter the stress ratio's shape 1 + kappa_s r is floored here (eleventh round): a
/// psi-law of kappa_s extrapolated past -1/r would turn it negative and drive the stress ratio away from its target
/// (the loose calibration's constant-p runaway, docs/model.md). Without the flag the shape is not floored.
constexpr double kShapeFloor = 0.05;

/// Number of extension coefficients without the state-dependent limit (the block Ceres sees when it is off).
constexpr int kNumExtBase = kNPsiA;
/// Size of the extension block: kNumExtBase, kNumExtBase + 2 with the state-dependent limit (n_psi), kLambdaPsi
/// with the `Weighted` rule's two coefficients (its n_psi entries then held at 0 when the limit is off), kNumExt
/// with the Lode-dependent state exponent (the `Weighted` entries then held when the rule is another).
/// The volume-form state parameter's block is the whole layout (kNumExt; the entries it does not read held).
inline int ext_size(bool state_limit, bool weighted = false, bool state_lode = false, bool state_volume = false) {
  if (state_volume) return kNumExt;
  return state_lode ? kNuCs : weighted ? kLambdaPsi : state_limit ? kNumExtBase + 2 : kNumExtBase;
}

/// Lode-angle dependence of the stress-ratio limit: s_max is the limit at the calibration
/// test's intermediate-stress ratio b_ref; at another b the limit lies on the same
/// Matsuoka-Nakai (I1 I2/I3 = const) or Lade-Duncan (I1^3/I3 = const) surface.
enum class Surface { None = 0, MatsuokaNakai, LadeDuncan };

/// b = (sigma_2 - sigma_3)/(sigma_1 - sigma_3) the model assumes for a test: 0 for axisymmetric
/// compression (D3 = diag(1/2, 1/2, -1) strain, the triaxial path), 1/2 for D2 = diag(1, 0, -1)
/// (coaxial stress and strain: the stress Lode angle of the strain's; an assumption, the stored
/// curves carry no intermediate stress). docs/model.md.
constexpr double kLodeBD2 = 0.5;

/// Lode-angle dependence of the fabric limit: `Norm`, the deviatoric norm F_dev saturates at
/// F_max whatever the Lode angle; `Principal`, the largest principal deviatoric fabric
/// max_i |F_i - tr F/3| saturates at the same value at every Lode angle (a hexagonal, Tresca-like
/// limit in the deviatoric plane), so the norm's limit is F_max c(b_ref)/c(b), c(b) the largest
/// |principal component| of a unit deviator at b (fabric_lode_factor). docs/model.md.
///
/// `Opening`: the limit as `Principal`, and the fabric's gate r^n_F driven by the minor principal
/// deviatoric stress ratio |sigma_3 - p|/p (contacts opening along the extension directions)
/// over its value at the D2 limit, instead of by s/s_lim: the same at b_ref, slower in
/// axisymmetric compression, where the minor deviator is s/3 against D2's s/sqrt(3).
///
/// `Overlap` (issue 31, third round): the limit as `Principal`; the gate is the fraction of contacts
/// opened along the extension directions, r_F = 1 - exp(-e_3/delta), e_3 = c_3(b) l the minor
/// (extension) principal strain since the loading start or the last reversal (l: |eps_d| accumulated
/// since then), delta = pi p* / (C(nu) nu) the mean contact overlap over the diameter of the packing
/// (Hookean contacts, from p = C nu k delta/(pi d^2)), so that a contact of overlap delta_c opens at
/// e_3 = delta_c/d and, with exponentially distributed forces, a fraction 1 - exp(-e_3/delta) has
/// opened. No parameter; D2 changes too (its gate is no longer the mobilisation). docs/model.md.
///
/// `Extension` (issue 31, fourth round): the gate and the limit as `Overlap`, and the fabric's rate per
/// unit extension (minor principal) strain instead of per unit |eps_d|: beta_F c_3(b)/c_3(b_ref), so
/// 1/sqrt(3) of D2's in axisymmetric compression. Identity at b_ref (D2 is `Overlap`'s, bit for bit).
/// No parameter. docs/model.md, "The fabric's rate".
///
/// `Weighted` (issue 31, sixth round): the limit and the opened-fraction gate as `Overlap`, with the Lode
/// dependence of the onset and of the rate both raised to a weight w in [0, 1]: the gate's extension strain
/// c_3(b_ref) (c_3(b)/c_3(b_ref))^w l and the rate beta_F (c_3(b)/c_3(b_ref))^w. w = 1 is `Extension`; w = 0
/// a fabric blind to the Lode angle but for its limit. w rises with the mean contact overlap (lode_weight):
/// two coefficients that only a second Lode angle in the calibration identifies (identity at b_ref).
/// docs/model.md, "The Lode weight".
enum class FabricLode { Norm = 0, Principal, Opening, Overlap, Extension, Weighted };

/// Named view of all parameters (double), with units; `iso()`/`shear()` give the Ceres blocks.
struct Parameters {
  double p0 = 0.04;        ///< [-] p* prefactor of the isotropic pressure law
  double nu_c = 0.664;     ///< [-] jamming volume fraction of the pressure law
  double gamma_p = 0.0;    ///< [-] non-linearity of the pressure law
  double C0 = 5.6;         ///< [-] coordination number at jamming
  double C1 = 8.3;         ///< [-] coordination power-law amplitude
  double nu_cC = 0.667;    ///< [-] jamming volume fraction of the coordination law
  double alpha = 0.5;      ///< [-] coordination power-law exponent
  double shear[kNumShear] = {0.16, -0.5, std::log(50.0), -5.0, 0.11, -0.8, std::log(40.0), -8.0,
                             0.3, -5.0, std::log(20.0), 0.0};
  /// frictional extension (all 0, the group model, but n_rate 1: the eleventh round's rate scaling)
  double ext[kNumExt] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0};
  static_assert(kNumExt == 19 && kNRate == 17, "the default of ext: n_rate 1, every other entry 0");
  bool extended = false;   ///< the frictional family (ext fitted, Lode surface `surface`)
  bool state_limit = false;   ///< the frictional family's state-dependent stress-ratio limit (n_psi fitted)
  bool state_lode = false;    ///< ... with the exponent's Lode dependence (lambda_psi fitted; needs state_limit)
  bool state_volume = false;  ///< the volume-form state parameter psi = nu - nu_cs(p) (n_b, n_d fitted; the line held)
  Surface surface = Surface::None;   ///< Lode-angle surface of the extended family
  FabricLode fabric = FabricLode::Norm;   ///< Lode rule of the extended family's fabric limit
  double nu_ref = 0.74;    ///< [-] volume fraction the nu-laws are centred on
  /// [-] the stress Lode parameter b of D2 and of paths made of D2 (lode_b_of): kLodeBD2, the strain's, until issue
  /// 31's thirteenth round; the constant-volume D2 of data/geotech/constant_volume carries b = 0.32-0.39 at its
  /// critical state (`dem model --d2-lode`). s_max stays the limit at kLodeBD2.
  double b_d2 = kLodeBD2;
  /// [-] with the volume-form state parameter, the range of psi its laws are read in (Ext::psi_lo, psi_hi): the
  /// calibration's own states (psi_range); rows psi_min, psi_max of parameters.csv. Infinite: no clamp (files before
  /// the thirteenth round).
  double psi_lo = -std::numeric_limits<double>::infinity();
  double psi_hi = std::numeric_limits<double>::infinity();
  /// With state_volume: the anisotropy's pressure relaxes as an excess over the isotropic law (Ext::excess_relaxes;
  /// row anisotropy_excess of parameters.csv, absent: false).
  bool excess_relaxes = false;
  /// With excess_relaxes: the excess bounded within (-p, p) (Ext::excess_bounded; row anisotropy_excess = 2).
  bool excess_bounded = false;
  /// The start's deviators unaligned with the loading (Ext::start_unaligned; row start_anisotropy = 1 of
  /// parameters.csv, absent: false).
  bool start_unaligned = false;
  /// The plastic dilatancy gated by the mobilisation (Ext::dilatancy_gated; row dilatancy_gate = 1, absent: false).
  bool dilatancy_gated = false;
  /// With state_limit: the fabric's limit follows the state as the stress ratio's does (Ext::fabric_state; row
  /// fabric_limit = 1, absent: false).
  bool fabric_state = false;
  /// sigma_dev scales with p_ref under a volume change (Ext::deviator_reference; row deviator_volume = 1, absent: false).
  bool deviator_reference = false;
  std::vector<double> iso() const { return {p0, nu_c, gamma_p, C0, C1, nu_cC, alpha}; }
  void set_iso(const double* v) { p0 = v[0]; nu_c = v[1]; gamma_p = v[2]; C0 = v[3]; C1 = v[4]; nu_cC = v[5]; alpha = v[6]; }
};

/// The `Weighted` rule's start: w = 1/2 at a mean overlap delta/d of 0.03 (the friction study's packings
/// span about 0.01-0.06), n_w = 4.
constexpr double kDeltaWStart = 0.03;

/// Names of the shear coefficients as written in tables.
inline const char* shear_name(int i) {
  static const char* n[kNumShear] = {"s_max_a", "s_max_b", "ln_beta_s_a", "ln_beta_s_b", "F_max_a", "F_max_b",
                                     "ln_beta_F_a", "ln_beta_F_b", "a_A_a", "a_A_b", "ln_beta_p_a", "ln_beta_p_b"};
  return n[i];
}
inline const char* ext_name(int i) {
  static const char* n[kNumExt] = {"n_F_a", "n_F_b", "kappa_s_a", "kappa_s_b", "d_D_a", "d_D_b", "chi_D",
                                   "n_psi_a", "n_psi_b", "ln_delta_w", "n_w", "lambda_psi", "nu_cs", "lambda_cs",
                                   "n_peak", "n_dil", "c_cs", "n_rate", "m_peak"};
  return n[i];
}
inline const char* iso_name(int i) {
  static const char* n[kNumIso] = {"p0", "nu_c", "gamma_p", "C0", "C1", "nu_cC", "alpha"};
  return n[i];
}

/// The coordination law's jamming fraction: nu_cC, or the pressure law's nu_c where nu_cC <= 0 (one jamming
/// fraction for both laws, `dem model --jamming shared`: the stiffness B is then bounded at every nu, docs/model.md
/// "One jamming fraction"). A calibration writes the tied value as nu_c's, the same law.
template <class T>
T coordination_jamming(const T* iso) {
  return iso[kNuCC] > T(0.0) ? iso[kNuCC] : iso[kNuC];
}

/// C(nu) = C0 + C1 (nu/nu_cC - 1)^alpha [-] (Goncu et al. 2010), C0 below nu_cC.
template <class T>
T coordination(const T* iso, const T& nu) {
  using std::pow;
  const T base = nu / coordination_jamming(iso) - T(1.0);
  if (!(base > T(0.0))) return iso[kC0];
  return iso[kC0] + iso[kC1] * pow(base, iso[kAlpha]);
}

/// Isotropic pressure p*(nu) = p0 (nu C(nu)/nu_c) x (1 + gamma_p x), x = ln(nu/nu_c) [-]
/// (Goncu et al. 2010, with -eps_v = ln(nu/nu_c) the full volumetric strain from jamming).
template <class T>
T isotropic_pressure(const T* iso, const T& nu) {
  using std::log;
  const T x = log(nu / iso[kNuC]);
  return iso[kP0] * (nu * coordination(iso, nu) / iso[kNuC]) * x * (T(1.0) + iso[kGammaP] * x);
}

/// Bulk modulus B = dp*/d ln(nu) [-] of the isotropic law (so that isotropic compression,
/// d ln nu = -d eps_vol, integrates exactly to p*(nu)). Closed-form derivative.
template <class T>
T bulk_modulus(const T* iso, const T& nu) {
  using std::log;
  using std::pow;
  const T x = log(nu / iso[kNuC]);
  const T C = coordination(iso, nu);
  const T nu_j = coordination_jamming(iso);
  const T base = nu / nu_j - T(1.0);
  T dC = T(0.0);   // nu dC/dnu
  if (base > T(0.0)) dC = iso[kC1] * iso[kAlpha] * pow(base, iso[kAlpha] - T(1.0)) * nu / nu_j;
  const T g = x * (T(1.0) + iso[kGammaP] * x);            // x (1 + gamma x)
  const T dg = T(1.0) + T(2.0) * iso[kGammaP] * x;        // d g / d ln nu
  return iso[kP0] / iso[kNuC] * (nu * C * g + nu * dC * g + nu * C * dg);
}

/// The shear laws evaluated at nu.
template <class T>
struct Local {
  T s_max, beta_s, F_max, beta_F, a_A, beta_p;
};
template <class T>
Local<T> local(const T* shear, const T& nu, double nu_ref) {
  using std::exp;
  const T d = nu - T(nu_ref);
  return {shear[kSmaxA] + shear[kSmaxB] * d, exp(shear[kLnBetaSA] + shear[kLnBetaSB] * d),
          shear[kFmaxA] + shear[kFmaxB] * d, exp(shear[kLnBetaFA] + shear[kLnBetaFB] * d),
          shear[kAnisoA] + shear[kAnisoB] * d, exp(shear[kLnBetaPA] + shear[kLnBetaPB] * d)};
}

/// The extension's laws at nu (neutral when ext is null).
template <class T>
struct LocalExt {
  T n_F, kappa_s, d_D, chi_D;
};
template <class T>
LocalExt<T> local_ext(const T* ext, const T& nu, double nu_ref) {
  if (ext == nullptr) return {T(0.0), T(0.0), T(0.0), T(0.0)};
  const T d = nu - T(nu_ref);
  return {ext[kNFA] + ext[kNFB] * d, ext[kKappaA] + ext[kKappaB] * d, ext[kDilA] + ext[kDilB] * d, ext[kChiD]};
}

/// The surface's invariant at mean stress 1, stress ratio s = q/p and intermediate-stress ratio
/// b: principal stresses 1 + s c_i, c = ((2 - b), (2b - 1), -(1 + b))/(3 sqrt(1 - b + b^2)), so
/// that q = sqrt(((s1-s2)^2 + (s2-s3)^2 + (s3-s1)^2)/2) = s. Returns the invariant and d/ds.
template <class T>
void surface_invariant(Surface f, const T& s, double b, T* value, T* deriv) {
  const double k = 1.0 / std::sqrt(1.0 - b + b * b);
  const double c[3] = {(2.0 - b) / 3.0 * k, (2.0 * b - 1.0) / 3.0 * k, -(1.0 + b) / 3.0 * k};
  const T s1 = T(1.0) + s * T(c[0]), s2 = T(1.0) + s * T(c[1]), s3 = T(1.0) + s * T(c[2]);
  const T I3 = s1 * s2 * s3;
  const T dI3 = T(c[0]) * s2 * s3 + s1 * T(c[1]) * s3 + s1 * s2 * T(c[2]);
  if (f == Surface::LadeDuncan) {   // I1^3 / I3, I1 = 3
    *value = T(27.0) / I3;
    *deriv = -T(27.0) * dI3 / (I3 * I3);
    return;
  }
  const T I2 = s1 * s2 + s2 * s3 + s3 * s1;   // Matsuoka-Nakai: I1 I2 / I3
  const T dI2 = T(c[0]) * (s2 + s3) + T(c[1]) * (s1 + s3) + T(c[2]) * (s1 + s2);
  *value = T(3.0) * I2 / I3;
  *deriv = T(3.0) * (dI2 * I3 - I2 * dI3) / (I3 * I3);
}

/// The stress-ratio limit at intermediate-stress ratio b on the surface through (s_ref, b_ref):
/// s_ref itself when there is no surface or b == b_ref; else Newton's method on the invariant
/// from s_ref (12 steps, converged to rounding for s < 2; differentiable for Ceres).
template <class T>
T lode_limit(const T& s_ref, double b, Surface f, double b_ref = kLodeBD2) {
  if (f == Surface::None || b == b_ref) return s_ref;
  T target, dummy;
  surface_invariant(f, s_ref, b_ref, &target, &dummy);
  T s = s_ref;
  for (int it = 0; it < 12; ++it) {
    T v, dv;
    surface_invariant(f, s, b, &v, &dv);
    s = s - (v - target) / dv;
  }
  return s;
}


/// The plane-strain Lode parameter of a surface (issue 31, thirteenth round): the b at which the surface through
/// (s_ref, kLodeBD2) has a deviatoric normal with no intermediate component, so that a plastic flow normal to it in the
/// deviatoric plane (SANISAND's direction n) keeps the intermediate strain at zero, as D2 does. There the trace's
/// (sigma_1 - sigma_3)/p = s(b)/sqrt(1 - b + b^2) is largest (the tangent is normal to pure shear); golden-section
/// search over b in [0, 1], to 1e-9. 1/2 without a surface (a circle); below it for Lade-Duncan and Matsuoka-Nakai,
/// falling as s_ref grows.
inline double plane_strain_lode_b(Surface f, double s_ref) {
  if (f == Surface::None) return kLodeBD2;
  const auto width = [&](double b) { return lode_limit(s_ref, b, f) / std::sqrt(1.0 - b + b * b); };
  const double g = (std::sqrt(5.0) - 1.0) / 2.0;
  double a = 0.0, c = 1.0;
  double x1 = c - g * (c - a), x2 = a + g * (c - a), f1 = width(x1), f2 = width(x2);
  while (c - a > 1e-9) {
    if (f1 < f2) { a = x1; x1 = x2; f1 = f2; x2 = a + g * (c - a); f2 = width(x2); }
    else { c = x2; x2 = x1; f2 = f1; x1 = c - g * (c - a); f1 = width(x1); }
  }
  return 0.5 * (a + c);
}

/// Largest |principal component| of a deviator of unit magnitude (sigma_dev convention of
/// docs/definitions.md) with intermediate ratio b: max(2 - b, 1 + b) / (3 sqrt(1 - b + b^2));
/// 2/3 at b = 0 and 1, 1/sqrt(3) at b = 1/2.
inline double principal_fraction(double b) {
  return std::max(2.0 - b, 1.0 + b) / (3.0 * std::sqrt(1.0 - b + b * b));
}

/// Size of the minor (most negative) principal component of a unit deviator at b:
/// (1 + b) / (3 sqrt(1 - b + b^2)); 1/3 at b = 0, 1/sqrt(3) at b = 1/2, 2/3 at b = 1.
inline double minor_fraction(double b) { return (1.0 + b) / (3.0 * std::sqrt(1.0 - b + b * b)); }

/// The fabric limit at b over the one at b_ref: 1 for `Norm`, c(b_ref)/c(b) for `Principal`
/// (sqrt(3)/2 for axisymmetric compression against D2).
inline double fabric_lode_factor(FabricLode f, double b, double b_ref = kLodeBD2) {
  if (f == FabricLode::Norm || b == b_ref) return 1.0;
  return principal_fraction(b_ref) / principal_fraction(b);
}

/// The fabric's rate at b over the one at b_ref: c_3(b)/c_3(b_ref) for `Extension` (the rate per unit
/// extension strain; 1/sqrt(3) in axisymmetric compression against D2), 1 otherwise and at b_ref.
inline double fabric_rate_factor(FabricLode f, double b, double b_ref = kLodeBD2) {
  if (f != FabricLode::Extension || b == b_ref) return 1.0;
  return minor_fraction(b) / minor_fraction(b_ref);
}

/// Mean contact overlap over the particle diameter, delta/d = pi p* / (C nu) [-]: Hookean contacts
/// f = k delta, branch vectors of length d, p = (1/3V) sum f d = C nu k delta / (pi d^2) with
/// N C/2 contacts in V = N pi d^3/(6 nu), and p* = d p / k (docs/definitions.md). C from the
/// coordination law. Polydispersity and the spread of branch lengths are neglected.
template <class T>
T mean_overlap(const T* iso, const T& nu, const T& p) {
  return T(3.14159265358979323846) * p / (coordination(iso, nu) * nu);
}

/// The gate variable at mean overlap delta after the extension strain e3: 1 - exp(-e3/delta),
/// floored at 1e-6 like the mobilisation; 1 where the overlap is not positive.
template <class T>
T opened_fraction_at(const T& delta, const T& e3) {
  using std::exp;
  if (!(delta > T(0.0))) return T(1.0);
  T f = T(1.0) - exp(-e3 / delta);
  if (!(f > T(1e-6))) f = T(1e-6);
  return f;
}

/// The `Overlap` rule's gate variable: the fraction of contacts opened along the extension
/// directions, 1 - exp(-e_3/delta), e_3 = minor_fraction(b) l the extension principal strain
/// after |eps_d| = l since the loading start (D2: l/sqrt(3); axisymmetric compression: l/3) and
/// delta = mean_overlap (exponential force distribution, Radjai et al. 1996).
template <class T>
T opened_fraction(const T* iso, const T& nu, const T& p, const T& l, double b) {
  return opened_fraction_at(mean_overlap(iso, nu, p), T(minor_fraction(b)) * l);
}

/// The `Weighted` rule's Lode weight w = 1/(1 + (delta_w/delta)^n_w) = 1/(1 + exp(n_w (ln delta_w -
/// ln delta))), delta = mean_overlap: 0 for loosely held contacts (the fabric ignores the Lode angle but
/// for its limit), 1 for deeply overlapped ones (it follows the extension strain), 1/2 at delta_w. 0
/// where the overlap is not positive.
template <class T>
T lode_weight(const T* ext, const T& delta) {
  using std::exp;
  using std::log;
  if (!(delta > T(0.0))) return T(0.0);
  return T(1.0) / (T(1.0) + exp(ext[kNW] * (ext[kLnDeltaW] - log(delta))));
}

/// What the frictional family adds to a run: its parameter block (null: the group model), the
/// test's intermediate-stress ratio b, the Lode surface of the stress ratio, the Lode rule of
/// the fabric limit, and whether the block carries the state-dependent limit's n_psi (kNPsiA,
/// kNPsiB; off: the block has kNumExtBase entries and they are never read).
template <class T>
struct Ext {
  const T* p = nullptr;
  double b = kLodeBD2;
  Surface surface = Surface::None;
  FabricLode fabric = FabricLode::Norm;
  bool state_limit = false;
  bool state_lode = false;   ///< n_psi scaled by (c_3(b_ref)/c_3(b))^lambda_psi (the block carries kLambdaPsi)
  bool state_volume = false;   ///< the volume-form state parameter (the block carries kNuCs..kCCs)
  /// The stress's Lode parameter where it is not the strain's b (D2: Parameters::b_d2, thirteenth round): the
  /// stress-ratio limit on the surface, the rate's s_max/s_lim and the Opening gate read it; the fabric rules keep b
  /// (the DEM's D2 fabric is not at the stress's b; docs/model.md). Negative: b.
  double b_stress = -1.0;
  /// With the volume-form state parameter (thirteenth round): the range of psi the laws are read in. The laws of psi
  /// (the nu-laws at nu_ref + psi, the peak's e^{n_peak psi}) hold their edge values outside it, so that a
  /// prediction that leaves the calibration's states does not extrapolate linear laws without bound; the dilatancy's
  /// e^{-n_dil psi} keeps the state itself (it drives psi back to 0). Infinite (the default): no clamp.
  double psi_lo = -std::numeric_limits<double>::infinity();
  double psi_hi = std::numeric_limits<double>::infinity();
  /// If set (plain double runs only): [min, max] of psi over every evaluation of the right-hand side, RK4's
  /// intermediate stages included (psi_range), so that the range covers every state a calibration's fit evaluated.
  double* psi_seen = nullptr;
  /// With the volume-form state parameter (eighteenth round, `--anisotropy-pressure relaxing`): the anisotropy's
  /// pressure A sigma d eps_d is an excess over the isotropic law at the elastic state, which relaxes at beta_p, not a
  /// change of the elastic state. The elastic volume fraction then follows p_ref = p - q (q the excess, dq = A sigma -
  /// beta_p q), so at the critical state the volume is steady where the dilatancy is 0 (psi = 0), whatever a_A F.
  /// False (the default, the tenth to seventeenth rounds): d ln nu_el = dp/B, q = 0, beta_p never acts.
  bool excess_relaxes = false;
  /// With excess_relaxes (nineteenth round, `--anisotropy-pressure bounded`): the excess's source A sigma is gated by
  /// 1 - (q/p)^2, dq = A sigma (1 - (q/p)^2) - beta_p q, so that q stays within (-p, p) and the elastic state's pressure
  /// p - q above 0 (the relaxing excess alone reaches q > p: an elastic state below jamming; docs/model.md).
  bool excess_bounded = false;
  /// The start's deviators are unaligned (twenty-eighth round, `--start-anisotropy unaligned`): s and F integrate the
  /// part aligned with the loading, from 0; the measured start values s0, F0 (the random deviators of a finite
  /// isotropic packing) are orthogonal to it, so the DEM's magnitude is observed(s, s0) = sqrt(s^2 + s0^2) (signed as
  /// s). False (the default, every stored calibration): the start values are taken as aligned and integrated from.
  bool start_unaligned = false;
  /// The plastic dilatancy gated by the mobilisation (twenty-eighth round, `--dilatancy-gate mobilisation`): d_D r (r -
  /// chi_D)(1 - F/F_lim), so that it starts at 0 with the loading, as the DEM's volume under constant pressure does,
  /// instead of at its largest contraction d_D chi_D. Without the volume-form state parameter only. False (the
  /// default, every stored calibration): ungated.
  bool dilatancy_gated = false;
  /// With state_limit (thirtieth round, `--fabric-limit state`): the fabric is driven to F_lim times the stress ratio's
  /// state factor (p_ref/p)^n_psi, so that it softens with the stress ratio where the pressure rises above the
  /// isotropic reference at constant volume, or the reference falls below the pressure as the packing dilates at
  /// constant pressure. The dilatancy's fabric gate keeps F_lim (as the mobilisation keeps s_lim). No coefficient is
  /// added. False (the default, every stored calibration): the fabric's limit F_lim whatever the state.
  bool fabric_state = false;
  /// Under a volume change the deviatoric stress scales with the isotropic reference pressure p_ref(nu) (thirtieth
  /// round, `--deviator-volume reference`): d sigma_dev = sigma_dev d p_ref / p_ref besides -A d eps_vol, so that the
  /// stress ratio's volumetric term is -(A - s B + s B p/p_ref)/p d eps_vol (deviator_volume_term). The DEM's friction
  /// study after the peak: at constant volume sigma_dev stays where it is while p rises, at constant p it falls with
  /// p_iso(nu) as the packing dilates (docs/model.md, "The deviatoric stress under a volume change"). A constant-volume
  /// curve does not see it (its fits are unchanged); no coefficient is added. Without the volume-form state parameter.
  /// False (the default, every stored calibration): sigma_dev does not change with the volume but through A.
  bool deviator_reference = false;
};

/// The number of members of the aggregate A: the most initialisers `A{...}` takes (a value that converts to anything
/// stands for each), counted up from 0 (at most 64). with_block's guard: a member it does not copy changes the count.
struct AnyMember {
  template <class X>
  constexpr operator X() const;   // declared only: used in unevaluated braces
};
template <class A, class... M>
constexpr std::size_t brace_count(long) {   // A{M...} does not compile: one initialiser too many
  return sizeof...(M) - 1;
}
template <class A, class... M>
constexpr auto brace_count(int) -> decltype(A{std::declval<M>()...}, std::size_t()) {
  if constexpr (sizeof...(M) < 64) return brace_count<A, M..., AnyMember>(0);
  return sizeof...(M);
}
template <class A>
constexpr std::size_t member_count() { return brace_count<A>(0); }

/// The options of O (every member of Ext but its block and psi_seen) with the block P of another scalar type: the
/// residual functors keep one Ext<double> of options (calibration_ext) and bind their block of Jets to it at each
/// evaluation, so that a new option is a member here and one line below, not a flag in every functor.
template <class T, class U>
Ext<T> with_block(const Ext<U>& o, const T* p) {
  static_assert(member_count<Ext<double>>() == 17,
                "Ext has a new member: copy it in with_block, then update this count");
  Ext<T> e{p, o.b, o.surface, o.fabric, o.state_limit, o.state_lode, o.state_volume, o.b_stress, o.psi_lo, o.psi_hi};
  e.excess_relaxes = o.excess_relaxes;
  e.excess_bounded = o.excess_bounded;
  e.start_unaligned = o.start_unaligned;
  e.dilatancy_gated = o.dilatancy_gated;
  e.fabric_state = o.fabric_state;
  e.deviator_reference = o.deviator_reference;
  return e;
}

/// The magnitude a packing shows for the aligned deviator part x [-] with an unaligned start part x0 [-]
/// (Ext::start_unaligned): sign(x) sqrt(x^2 + x0^2), + at x = 0 (the first loading direction). x itself where the
/// start is aligned or x0 = 0.
template <class T>
T observed(const T& x, double x0, bool unaligned) {
  using std::sqrt;
  if (!unaligned || x0 == 0.0) return x;
  const T m = sqrt(x * x + T(x0 * x0));
  return x < T(0.0) ? -m : m;
}

/// The volume-form state parameter psi = nu - nu_cs(p), nu_cs(p) = nu_cs + lambda_cs ln(p/kPCsRef) (tenth round)
/// + c_cs (p - kPCsRef) (eleventh round; one of the two held at 0):
/// positive denser than the critical-state line. p floored at 1e-12 (a path that unloads to zero pressure).
template <class T>
T state_psi(const T* ext, const T& nu, const T& p) {
  using std::log;
  T pp = p;
  if (!(pp > T(1e-12))) pp = T(1e-12);
  return nu - (ext[kNuCs] + ext[kLambdaCs] * log(pp / T(kPCsRef)) + ext[kCCs] * (pp - T(kPCsRef)));
}

/// The state-dependent stress-ratio limit (issue 31, fifth round): the limit the stress ratio is
/// driven to, s_lim exp(-n_psi psi_p) = s_lim (p_ref/p)^n_psi, with psi_p = ln(p/p_ref) the state
/// parameter in pressure form: the pressure against the isotropic reference p_ref = k p_iso(nu) at the
/// current volume fraction (the reference of the pressure relaxation). A packing below its
/// reference pressure (psi_p < 0, "denser than the reference at this pressure") has a limit above
/// s_lim, one above it a lower one; psi_p = 0 gives s_lim. As Manzari & Dafalias (1997)'s peak
/// ratio M exp(-n_b psi), with the volume-form psi = e - e_cs(p) of Been & Jefferies (1985) replaced
/// by the pressure form (the state pressure index of Wang et al. 2002). p_ref/p floored at 1e-6
/// (p_ref <= 0 below the isotropic law's jamming fraction). n_psi(nu) = a + b (nu - nu_ref).
/// With `lode` (eighth round) the exponent is n_psi (c_3(b_ref)/c_3(b))^lambda_psi at the test's b: at b_ref
/// (D2) n_psi itself; lambda_psi = 0 the exponent of every Lode angle alike.
template <class T>
T state_limit_factor(const T* ext, const T& nu, double nu_ref, const T& p, const T& p_ref, double b = kLodeBD2,
                     bool lode = false) {
  using std::exp;
  using std::log;
  T n_psi = ext[kNPsiA] + ext[kNPsiB] * (nu - T(nu_ref));
  if (lode && b != kLodeBD2)
    n_psi = n_psi * exp(ext[kLambdaPsi] * T(std::log(minor_fraction(kLodeBD2) / minor_fraction(b))));
  T ratio = p_ref / p;
  if (!(ratio > T(1e-6))) ratio = T(1e-6);
  return exp(n_psi * log(ratio));
}

/// State of the material point.
template <class T>
struct State {
  T ln_nu;   ///< ln(volume fraction)
  T p;       ///< pressure p* [-]
  T s;       ///< stress ratio sigma_dev/p [-], signed along the first loading direction
  T F;       ///< deviatoric fabric [-], signed likewise
  T l = T(0.0);   ///< |eps_d| accumulated since the loading start or the last reversal [-] (FabricLode::Overlap)
  /// Plastic volumetric strain [-] (extension positive; integrated, read with the volume-form state parameter only):
  /// every volume change but the elastic -dp/B, so that ln nu + e_pl = ln nu_el, the elastic volume fraction, follows
  /// the pressure along the isotropic law (d ln nu_el = dp/B). The law's B and p_ref are evaluated at nu_el: a dense
  /// packing dilating to its critical state below the isotropic law's jamming fraction keeps its stiffness, and the
  /// relaxation towards k p_iso(nu_el) = p vanishes (docs/model.md, "The volume-form state parameter").
  T e_pl = T(0.0);
  /// The drained triaxial control was lost on the way here (kTriaxialMargin): every entry is then NaN.
  bool lost = false;
};

/// How the volume is controlled during a segment.
enum class Control {
  Volume,     ///< prescribed d eps_vol = volume_rate * |d eps_d| (0: constant volume, D2/D3)
  Isobaric,   ///< d p = 0: d eps_vol solved from the pressure equation (mixed control)
  Triaxial    ///< d sigma_r = 0, sigma_r = p (1 - s/3) the side stress of an axisymmetric state
              ///< (compression positive, s = (sigma_a - sigma_r)/p signed): d eps_vol solved from
              ///< (1 - s/3) dp - (p/3) ds = 0 (constant-side-stress test; docs/model.md)
};

/// Side (radial) stress of the axisymmetric state in p* units: sigma_a = p + 2 q/3,
/// sigma_r = p - q/3 with q = s p = sigma_a - sigma_r (sigma_dev = |sigma_a - sigma_r| for
/// axisymmetric stress, docs/definitions.md).
template <class T>
T side_stress(const State<T>& y) {
  return y.p * (T(1.0) - y.s / T(3.0));
}

/// One monotone piece of a strain path.
struct Segment {
  double eps_d = 0.1;          ///< signed deviatoric strain of the segment [-] (negative: reversed)
  Control control = Control::Volume;
  double volume_rate = 0.0;    ///< d eps_vol / |d eps_d| [-] for Control::Volume
  double eps_vol = 0.0;        ///< pure volumetric segment (eps_d = 0): full volumetric strain [-]
  int outputs = 50;            ///< points written along the segment (its end included)
  double max_step = 5e-4;      ///< largest RK4 step in |eps_d| (or |eps_vol|) [-]
};

/// One output point of a path.
template <class T>
struct Point {
  double eps_d_acc;   ///< accumulated |eps_d| since the path start [-]
  double eps_d;       ///< signed deviatoric strain since the path start [-]
  T eps_vol;          ///< full volumetric strain since the path start [-]
  State<T> state;
};

/// Material functions that the right-hand side needs, with the packing's isotropic scale k:
/// p_ref(nu) = k p_iso(nu), B(nu) = k dp_iso/dln nu (k = p(0)/p_iso(nu0): the state's own
/// offset from the fitted law; docs/model.md).
template <class T>
struct Material {
  const T* iso;
  const T* shear;
  double nu_ref;
  T k;
  Ext<T> ext = {};
  /// With the volume-form state parameter: B/p on the isotropic law at p* = kPCsRef, so that the rates scaled by the
  /// elastic stiffness B/p (rate_scale) keep their values at that pressure (1: unscaled)
  T bp_ref = T(1.0);
};

/// The peak's state exponent at pressure p* (volume-form state parameter): n_peak (p*/kPCsRef)^m_peak.
template <class T>
T peak_exponent(const T* ext, const T& p) {
  T pp = p;
  if (!(pp > T(1e-12))) pp = T(1e-12);
  return ext[kNB] * exp(ext[kMPeak] * log(pp / T(kPCsRef)));
}

/// The psi the laws of psi read (thirteenth round): psi within [ext.psi_lo, ext.psi_hi]; a double run also records
/// psi itself in ext.psi_seen when set (psi_range).
template <class T>
T law_psi(const Ext<T>& ext, const T& psi) {
  if constexpr (std::is_same<T, double>::value) {
    if (ext.psi_seen) {
      ext.psi_seen[0] = std::min(ext.psi_seen[0], psi);
      ext.psi_seen[1] = std::max(ext.psi_seen[1], psi);
    }
  }
  if (psi < T(ext.psi_lo)) return T(ext.psi_lo);
  if (psi > T(ext.psi_hi)) return T(ext.psi_hi);
  return psi;
}

/// The rates' elastic scaling with the volume-form state parameter: ((B/p)/(B/p)_ref)^n_rate; at n_rate = 1 the shear
/// modulus is a fixed fraction of the bulk modulus (a constant Poisson ratio, as SANISAND's G and K; the eleventh
/// round), n_rate < 1 a rise to the peak that slows less with the pressure than the stiffness falls (the twelfth
/// round's p* = 5e-2 tests; docs/model.md): 1 otherwise.
template <class T>
T rate_scale(const Material<T>& m, const T& B, const T& p) {
  if (!(m.ext.p && m.ext.state_volume)) return T(1.0);
  T pp = p;
  if (!(pp > T(1e-12))) pp = T(1e-12);
  const T ratio = B / pp / m.bp_ref;
  if (!(ratio > T(1e-12))) return T(0.0);
  return exp(m.ext.p[kNRate] * log(ratio));
}

/// The stress ratio's shape 1 + kappa_s r at the mobilisation r (stress ratio: linear for longer). With the
/// volume-form state parameter (`capped`) a stress ratio above its target's mobilisation r_t relaxes at least as fast
/// as at the target: the shape is max(1 + kappa_s r, 1 + kappa_s r_t) there (fourteenth round: a psi-law kappa_s < 0
/// otherwise slows the return of an overshoot to the floor's 5 %, and the volumetric term keeps carrying s away;
/// docs/model.md); then floored at kShapeFloor. Without the flag: 1 + kappa_s r, unbounded.
template <class T>
T stress_shape(const T& kappa_s, const T& r, const T& r_t, bool capped) {
  T shape = T(1.0) + kappa_s * r;
  if (!capped) return shape;
  if (r > r_t && T(1.0) + kappa_s * r_t > shape) shape = T(1.0) + kappa_s * r_t;
  return shape < T(kShapeFloor) ? T(kShapeFloor) : shape;
}

/// The source of the anisotropic excess q per unit |d eps_d|: A sigma, or with the bounded excess (Ext::excess_bounded,
/// nineteenth round) A sigma (1 - (q/p)^2), zero at q = +-p.
template <class T>
T excess_source(const Ext<T>& ext, const T& a_sigma, const T& q, const T& p) {
  if (!ext.excess_bounded) return a_sigma;
  const T x = q / p;
  return a_sigma * (T(1.0) - x * x);
}

/// A lost state (State::lost): every entry NaN, so that the path's later rows and a fit's residuals on them are not
/// numbers (Ceres rejects a step that leads there).
template <class T>
State<T> lost_state(const State<T>& y) {
  const T nan = y.p * T(std::numeric_limits<double>::quiet_NaN());
  State<T> d{nan, nan, nan, nan, nan, nan};
  d.lost = true;
  return d;
}

/// The extra volumetric coupling of the stress ratio with Ext::deviator_reference: s B p/p_ref [K], so that d s = ... -
/// (A - s B + this)/p d eps_vol (sigma_dev scaling with p_ref under a volume change); 0 without the option. p_ref/p
/// floored at 1e-6 as in the state factor (p_ref <= 0 below the isotropic law's jamming fraction).
template <class T>
T deviator_volume_term(const Ext<T>& e, const State<T>& y, const T& B, const T& p_ref) {
  if (!e.deviator_reference || e.state_volume) return T(0.0);
  T ratio = p_ref / y.p;
  if (!(ratio > T(1e-6))) ratio = T(1e-6);
  return y.s * B / ratio;
}

/// The pure volumetric segment: d eps_vol = +1 per unit l (its sign carried by seg.eps_vol); the elastic state moves
/// with the volume (e_pl unchanged), and an anisotropic excess stays what it was. E_dev: deviator_volume_term.
template <class T>
State<T> volumetric_rhs(const State<T>& y, const T& A, const T& B, const T& E_dev, const Segment& seg) {
  const T dev = T(seg.eps_vol > 0 ? 1.0 : -1.0);
  State<T> d;
  d.ln_nu = -dev;
  d.p = -B * dev;
  d.s = -(A - y.s * B + E_dev) / y.p * dev;
  d.F = T(0.0);
  d.l = T(0.0);
  d.e_pl = T(0.0);
  return d;
}

/// The pressure-form state factor (p_ref/p)^n_psi of the stress ratio's limit (and with Ext::fabric_state the fabric's)
/// at the stress's Lode parameter b_s; 1 without the pressure-form state limit.
template <class T>
T pressure_state_factor(const Material<T>& m, const T& nu, const T& p, const T& p_ref, double b_s) {
  if (!m.ext.p || !m.ext.state_limit) return T(1.0);
  return state_limit_factor(m.ext.p, nu, m.nu_ref, p, p_ref, b_s, m.ext.state_lode);
}

/// The fabric's law as a relaxation, dF/dl = kappa (target - F) with kappa >= 0 (rhs reports it where asked): the
/// gated rate kappa = beta_F g_s rate_F r_F^n_F and the target sigma F_lim (the state's on Ext::fabric_state). 0 and
/// F itself on a volumetric segment and where the state is lost.
template <class T>
struct FabricRelaxation {
  T kappa, target;
};

/// Derivatives per unit |d eps_d| along a segment with direction sigma (+1/-1), or per unit
/// eps_vol for a pure volumetric segment (sigma = 0). Returns d/dl of (ln nu, p, s, F).
/// The excess pressure's relaxation in rhs, beta_p (p - p_ref) per unit |d eps_d|: the law's (Law), none (Off), or the
/// unit (Unit; relax_pressure reads from it the direction in which the relaxation moves the state). rhs reports beta_p,
/// the excess p - p_ref and B = dp_ref/dln nu_el where asked (PressureRelaxation).
enum class Excess { Law, Off, Unit };
template <class T>
struct PressureRelaxation {
  T beta_p, excess, B;
};

/// The fabric gate and the Lode factor of the fabric's rate (rhs): the gate is r_F^n_F with r_F the mobilisation r, or
/// under the `Opening` rule the minor principal deviatoric stress ratio over its value at the D2 limit (r itself at
/// b_ref), or under the opening rules the opened fraction; 1 and the rule's rate factor without the extension.
template <class T>
struct FabricGate {
  T gate, rate;
};
template <class T>
FabricGate<T> fabric_gate(const Material<T>& m, const State<T>& y, const T& nu_el, const T& r, const T& s_lim,
                          const T& s_max, const T& n_F, double b_s) {
  using std::exp;
  using std::pow;
  T r_F = r;
  if (m.ext.fabric == FabricLode::Opening && b_s != kLodeBD2)
    r_F = r * s_lim * T(minor_fraction(b_s) / minor_fraction(kLodeBD2)) / s_max;
  const bool weighted = m.ext.p && m.ext.fabric == FabricLode::Weighted && m.ext.b != kLodeBD2;
  const bool opened = m.ext.fabric == FabricLode::Overlap || m.ext.fabric == FabricLode::Extension ||
                      m.ext.fabric == FabricLode::Weighted;
  // The `Weighted` rule: the Lode factor c_3(b)/c_3(b_ref) of the onset and the rate raised to w.
  T lode_w = T(1.0);
  if (weighted) {
    const T delta = mean_overlap(m.iso, nu_el, y.p);
    lode_w = exp(lode_weight(m.ext.p, delta) * T(std::log(minor_fraction(m.ext.b) / minor_fraction(kLodeBD2))));
    r_F = opened_fraction_at(delta, T(minor_fraction(kLodeBD2)) * lode_w * y.l);
  } else if (opened) {
    r_F = opened_fraction(m.iso, nu_el, y.p, y.l, m.ext.b);
  }
  const T rate = weighted ? lode_w : m.ext.p ? T(fabric_rate_factor(m.ext.fabric, m.ext.b)) : T(1.0);   // the group model ignores the rule
  return {m.ext.p ? pow(r_F, n_F) : T(1.0), rate};   // the fabric follows the mobilisation
}

template <class T>
State<T> rhs(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg,
             FabricRelaxation<T>* relax_F = nullptr, Excess excess = Excess::Law,
             PressureRelaxation<T>* relax_p = nullptr) {
  using std::exp;
  const T nu = exp(y.ln_nu);
  const bool vol_state = m.ext.p && m.ext.state_volume;
  const T nu_el = vol_state ? exp(y.ln_nu + y.e_pl) : nu;   // the elastic volume fraction (nu itself otherwise)
  const T B = m.k * bulk_modulus(m.iso, nu_el);
  const T p_ref = m.k * isotropic_pressure(m.iso, nu_el);
  // With the volume-form state parameter every law is a law of psi (q = a + b psi: the critical state's a at psi = 0,
  // whatever the preparation), not of nu - nu_ref.
  const T psi = vol_state ? state_psi(m.ext.p, nu, y.p) : T(0.0);
  const T psi_law = vol_state ? law_psi(m.ext, psi) : T(0.0);   // within [psi_lo, psi_hi]
  const T nu_law = vol_state ? T(m.nu_ref) + psi_law : nu;
  const Local<T> L = local(m.shear, nu_law, m.nu_ref);
  const T A = L.a_A * B * y.F;                       // anisotropy modulus [K]
  const T E_dev = deviator_volume_term(m.ext, y, B, p_ref);   // 0 unless Ext::deviator_reference
  if (relax_p) *relax_p = {L.beta_p, y.p - p_ref, B};
  State<T> d;
  if (sigma == 0.0) return volumetric_rhs(y, A, B, E_dev, seg);
  // The frictional extension (docs/model.md): r the mobilised stress ratio on the test's Lode
  // surface; neutral (the group model's numbers exactly) when m.ext.p is null or all zero.
  const LocalExt<T> X = local_ext(m.ext.p, nu_law, m.nu_ref);
  const double b_s = m.ext.b_stress >= 0.0 ? m.ext.b_stress : m.ext.b;   // the stress's Lode parameter
  const T s_lim = lode_limit(L.s_max, b_s, m.ext.surface);
  T r = T(sigma) * y.s / s_lim;
  if (!(r > T(1e-6))) r = T(1e-6);
  const FabricGate<T> G = fabric_gate(m, y, nu_el, r, s_lim, L.s_max, X.n_F, b_s);
  // The fabric limit at the test's Lode angle (F_max itself at b_ref, or without the rule).
  const T F_lim = m.ext.p ? L.F_max * T(fabric_lode_factor(m.ext.fabric, m.ext.b)) : L.F_max;
  // Plastic dilatancy: gated by the fabric (1 - F/F_lim) (and by r with Ext::dilatancy_gated), or with the volume-form
  // state parameter driven by psi (tenth round): d_D (r - chi_D e^{-n_d psi}), no fabric gate, so the volume moves until
  // psi = 0.
  const T gate_D = m.ext.dilatancy_gated ? r : T(1.0);
  const T dil = vol_state ? X.d_D * (r - X.chi_D * exp(-m.ext.p[kND] * psi))
                : m.ext.p ? X.d_D * (r - X.chi_D) * (T(1.0) - T(sigma) * y.F / F_lim) * gate_D : T(0.0);
  // The excess pressure relaxing with |d eps_d| (relax_pressure: none, or the unit)
  const T relax = excess == Excess::Law ? L.beta_p * (y.p - p_ref) : T(excess == Excess::Unit ? 1.0 : 0.0);
  const T src = excess_source(m.ext, A * T(sigma), y.p - p_ref, y.p);   // the excess's source A sigma (gated: bounded)
  T dvol;                                            // d eps_vol per |d eps_d|
  // The deviatoric source of ds. The rate is scaled by s_max/s_lim so that the initial shear
  // stiffness G/p = beta_s s_max does not depend on the Lode angle (only the limit does): the
  // DEM's D2 and D3 stress ratios rise together at first. 1 without a surface or at b_ref.
  const bool lode = m.ext.surface != Surface::None && b_s != kLodeBD2;
  // The state-dependent limit (fifth round; off: s_lim itself, untouched): the target of the stress
  // ratio only; the mobilisation r, the rate scaling and the dilatancy keep s_lim (psi_p = 0).
  // The volume-form state parameter (tenth round) likewise: s_lim e^{n_b psi}.
  const T state = vol_state ? T(1.0) : pressure_state_factor(m, nu, y.p, p_ref, b_s);
  const T s_target = vol_state ? s_lim * exp(peak_exponent(m.ext.p, y.p) * psi_law) : s_lim * state;
  const T shape_s = stress_shape(X.kappa_s, r, s_target / s_lim, vol_state);
  const T g_s = rate_scale(m, B, y.p);
  const T shear = L.beta_s * g_s * (lode ? L.s_max / s_lim : T(1.0)) * (T(sigma) * s_target - y.s) * shape_s;
  if (seg.control == Control::Isobaric) {
    dvol = (src - relax + B * dil) / B;
  } else if (seg.control == Control::Triaxial && B > T(0.0) && !(B - (A + E_dev) / T(3.0) > T(kTriaxialMargin) * B)) {
    return lost_state(y);   // the side stress cannot be held (kTriaxialMargin)
  } else if (seg.control == Control::Triaxial && vol_state) {
    // The same with the elastic split: ds = shear - (A - s B)/p (dvol - dil), so (B - A/3)(dvol - dil) remains.
    dvol = dil + ((T(1.0) - y.s / T(3.0)) * (src - relax) - y.p / T(3.0) * shear) / (B - A / T(3.0));
  } else if (seg.control == Control::Triaxial) {
    // (1 - s/3) dp - (p/3) ds = 0 with dp = -B dvol + A sigma - relax + B dil and
    // ds = shear - (A - s B + E_dev)/p dvol: the B s/3 terms cancel, leaving (B - (A + E_dev)/3) dvol.
    dvol = ((T(1.0) - y.s / T(3.0)) * (A * T(sigma) - relax + B * dil) - y.p / T(3.0) * shear) /
           (B - (A + E_dev) / T(3.0));
  } else {
    dvol = T(seg.volume_rate);
  }
  d.ln_nu = -dvol;
  d.p = -B * dvol + src - relax + B * dil;
  const T F_target = T(sigma) * (m.ext.fabric_state ? F_lim * state : F_lim);   // Ext::fabric_state: the state's limit
  d.F = L.beta_F * g_s * G.rate * (F_target - y.F) * G.gate;
  if (relax_F) *relax_F = {L.beta_F * g_s * G.rate * G.gate, F_target};
  d.l = T(1.0);
  // The elastic volume fraction follows the pressure on the isotropic law (d ln nu_el = dp/B), or with a relaxing
  // excess the pressure less its anisotropic excess: d ln nu_el = (dp - A sigma + relax)/B, so that the excess q = p -
  // p_ref obeys dq = A sigma - beta_p q.
  const T dp_el = m.ext.excess_relaxes ? d.p - src + relax : d.p;
  d.e_pl = vol_state ? dp_el / B + dvol : T(0.0);
  // The volumetric term of the stress ratio: the elastic stress response to the volume change. With the volume-form
  // state parameter only the elastic part dvol - dil acts (the plastic dilatancy moves the volume, not the stress);
  // otherwise the whole dvol (the constant-volume law `shear` carries the plastic part; docs/model.md).
  const T dvol_stress = vol_state ? dvol - dil : dvol;
  d.s = shear - (A - y.s * B + E_dev) / y.p * dvol_stress;
  return d;
}

/// The volume fraction at which rhs reads the nu-laws in the state y: nu_ref + the bounded psi (law_psi) with the
/// volume-form state parameter, nu itself otherwise. Read quietly, for the diagnostics (pole_ratio, gate_exponent):
/// psi is not recorded (ext.psi_seen), so that a prediction's psi_range does not move.
template <class T>
T quiet_law_volume(const Material<T>& m, const State<T>& y) {
  using std::exp;
  const T nu = exp(y.ln_nu);
  if (!m.ext.p || !m.ext.state_volume) return nu;
  Ext<T> quiet = m.ext;
  quiet.psi_seen = nullptr;
  return T(m.nu_ref) + law_psi(quiet, state_psi(m.ext.p, nu, y.p));
}

/// A/(3B) = a_A F/3 at the state y (with Ext::deviator_reference (A + E_dev)/(3B)), a_A read as rhs reads it
/// (quiet_law_volume): the drained triaxial control's pole is where it reaches 1, and rhs gives the control up from
/// 1 - kTriaxialMargin on (B > 0).
template <class T>
T pole_ratio(const Material<T>& m, const State<T>& y) {
  using std::exp;
  const T a = local(m.shear, quiet_law_volume(m, y), m.nu_ref).a_A * y.F / T(3.0);
  if (!m.ext.deviator_reference || m.ext.state_volume) return a;
  // With Ext::deviator_reference the pole is where (A + E_dev)/(3B) reaches 1: E_dev/(3B) = s p/(3 p_ref).
  const T nu = exp(y.ln_nu);
  const T B = m.k * bulk_modulus(m.iso, nu);
  return a + deviator_volume_term(m.ext, y, B, m.k * isotropic_pressure(m.iso, nu)) / (T(3.0) * B);
}

template <class T>
State<T> axpy(const State<T>& y, const State<T>& d, double h) {
  return {y.ln_nu + T(h) * d.ln_nu, y.p + T(h) * d.p, y.s + T(h) * d.s, y.F + T(h) * d.F, y.l + T(h) * d.l,
          y.e_pl + T(h) * d.e_pl, y.lost || d.lost};
}

/// a A + b B entry by entry (l included; lost where either is).
template <class T>
State<T> lincomb(const State<T>& A, const T& a, const State<T>& B, const T& b) {
  return {a * A.ln_nu + b * B.ln_nu, a * A.p + b * B.p, a * A.s + b * B.s,         a * A.F + b * B.F,
          a * A.l + b * B.l,         a * A.e_pl + b * B.e_pl, A.lost || B.lost};
}

/// The value of a scalar: itself, or a Ceres Jet's value part (its member a), recursively.
inline double scalar_value(double x) { return x; }
template <class J>
double scalar_value(const J& j) { return scalar_value(j.a); }

/// h times the local Lipschitz constant of rhs between RK4's third and fourth stages, Y3 = y + h/2 k2 and Y4 = y + h k3:
/// h |k4 - k3| / |Y4 - Y3| (Shampine's stiffness estimate, free from the stages), in the norm of relative pressure and
/// absolute ln nu, s, F and e_pl. RK4 is stable on the negative real axis to h lambda = 2.785 and damps an error by a
/// third at 2 (model::advance's kStiffLimit).
template <class T>
double stage_stiffness(const State<T>& k2, const State<T>& k3, const State<T>& k4, const State<T>& y) {
  auto v = [](const T& x) { return scalar_value(x); };
  const double p = std::fabs(v(y.p)) > 0 ? std::fabs(v(y.p)) : 1.0;
  const double dk[5] = {v(k4.ln_nu) - v(k3.ln_nu), (v(k4.p) - v(k3.p)) / p, v(k4.s) - v(k3.s), v(k4.F) - v(k3.F),
                        v(k4.e_pl) - v(k3.e_pl)};
  const double dy[5] = {v(k3.ln_nu) - v(k2.ln_nu) / 2, (v(k3.p) - v(k2.p) / 2) / p, v(k3.s) - v(k2.s) / 2,
                        v(k3.F) - v(k2.F) / 2, v(k3.e_pl) - v(k2.e_pl) / 2};   // (Y4 - Y3)/h
  double nk = 0, ny = 0;
  for (int i = 0; i < 5; ++i) { nk += dk[i] * dk[i]; ny += dy[i] * dy[i]; }
  return ny > 0 ? std::sqrt(nk / ny) : 0.0;   // h |k4 - k3| / (h |(Y4 - Y3)/h|): h cancels
}

/// What a split step (split_step) takes exactly, apart from RK4: nothing, the fabric's relaxation (relax_fabric), or the
/// excess pressure's (relax_pressure).
enum class Split { None, Fabric, Excess };

/// One classical RK4 step of length h (in |eps_d|, or |eps_vol| for a volumetric segment). STIFF (if given): the
/// step's stage_stiffness. HOLD: the part split_step takes exactly is left out (the fabric's rate taken as 0, or rhs
/// without the excess pressure's relaxation and less SHIFT, the balancing constant of split_step).
template <class T>
State<T> rk4_step(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double h,
                  double* stiff = nullptr, Split hold = Split::None, const State<T>* shift = nullptr) {
  auto f = [&](const State<T>& x) {
    State<T> k = rhs<T>(m, x, sigma, seg, nullptr, hold == Split::Excess ? Excess::Off : Excess::Law);
    if (hold == Split::Fabric) k.F = T(0.0);
    return shift ? lincomb(k, T(1.0), *shift, T(-1.0)) : k;
  };
  const State<T> k1 = f(y);
  const State<T> k2 = f(axpy(y, k1, h / 2));
  const State<T> k3 = f(axpy(y, k2, h / 2));
  const State<T> k4 = f(axpy(y, k3, h));
  if (stiff) *stiff = stage_stiffness(k2, k3, k4, y);
  State<T> out = y;
  out.ln_nu += T(h / 6) * (k1.ln_nu + T(2) * k2.ln_nu + T(2) * k3.ln_nu + k4.ln_nu);
  out.p += T(h / 6) * (k1.p + T(2) * k2.p + T(2) * k3.p + k4.p);
  out.s += T(h / 6) * (k1.s + T(2) * k2.s + T(2) * k3.s + k4.s);
  out.F += T(h / 6) * (k1.F + T(2) * k2.F + T(2) * k3.F + k4.F);
  out.l += T(h / 6) * (k1.l + T(2) * k2.l + T(2) * k3.l + k4.l);
  out.e_pl += T(h / 6) * (k1.e_pl + T(2) * k2.e_pl + T(2) * k3.e_pl + k4.e_pl);
  out.lost = y.lost || k1.lost || k2.lost || k3.lost || k4.lost;
  return out;
}

/// The fabric relaxed exactly over h with its law's coefficients frozen at y (FabricRelaxation): F -> target + (F -
/// target) e^{-kappa h}, whatever kappa h is (a lost state keeps its F).
template <class T>
State<T> relax_fabric(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double h) {
  using std::exp;
  FabricRelaxation<T> r{T(0.0), y.F};
  rhs(m, y, sigma, seg, &r);
  State<T> z = y;
  // Beyond e^-700 (and for a rate that is not a number or infinite) the fabric is at its target, derivatives included:
  // an infinite rate's e^{-kappa h} would carry 0 x inf into a Jet's derivatives.
  z.F = scalar_value(r.kappa) * h < 700.0 ? r.target + (y.F - r.target) * exp(-r.kappa * T(h)) : r.target;
  return z;
}

/// int_0^h e^{-kappa l} dl = (1 - e^{-kappa h})/kappa (PHI) and int_0^h (1 - e^{-kappa l})/kappa dl = (h - PHI)/kappa
/// (PSI): series for |kappa h| < 1e-3, 1/kappa for PHI beyond e^-700 (so that a Jet does not carry 0 x inf).
template <class T>
void relaxed_lengths(const T& kappa, double h, T& phi, T& psi) {
  using std::exp;
  const double x = scalar_value(kappa) * h;
  if (std::fabs(x) < 1e-3) {
    const T kh = kappa * T(h);
    phi = T(h) * (T(1.0) - kh / T(2.0) + kh * kh / T(6.0) - kh * kh * kh / T(24.0));
    psi = T(h * h) * (T(0.5) - kh / T(6.0) + kh * kh / T(24.0));
    return;
  }
  phi = x > 700.0 ? T(1.0) / kappa : (T(1.0) - exp(-kappa * T(h))) / kappa;
  psi = (T(h) - phi) / kappa;
}

/// The excess pressure's relaxation R = beta_p q, q = p - p_ref, at y (thirty-eighth round). rhs is linear in R: dy/dl =
/// OFF(y) + R W(y), W read as rhs's difference between the unit and no relaxation (Excess). Along a derivative v the
/// excess moves by dq(v) = v_p - B (v_ln_nu + v_e_pl) (e_pl with the volume-form state parameter only: p_ref is read at
/// nu_el), so that q decays at KAPPA = -beta_p dq(W): at constant volume kappa = beta_p; under the isobaric control the
/// volume moves until p_ref reaches p, again at beta_p.
template <class T>
struct ExcessRelaxation {
  State<T> off, w;
  T beta_p, excess, B, kappa;
  bool vol_state;
  T dq(const State<T>& v) const { return v.p - B * (v.ln_nu + (vol_state ? v.e_pl : T(0.0))); }
};
template <class T>
ExcessRelaxation<T> excess_relaxation(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg) {
  PressureRelaxation<T> r{T(0.0), T(0.0), T(0.0)};
  ExcessRelaxation<T> e;
  e.off = rhs<T>(m, y, sigma, seg, nullptr, Excess::Off);
  e.w = lincomb(rhs<T>(m, y, sigma, seg, nullptr, Excess::Unit, &r), T(1.0), e.off, T(-1.0));
  e.beta_p = r.beta_p, e.excess = r.excess, e.B = r.B;
  e.vol_state = m.ext.p && m.ext.state_volume;
  e.kappa = -e.beta_p * e.dq(e.w);
  return e;
}

/// The split's relaxation over h from y (after Speth, Green, MacNamara & Strang 2013, "Balanced splitting and
/// rebalanced splitting", SIAM J. Numer. Anal. 51: a constant C moved between the two parts, so that a state where both
/// balance stays put): dy/dl = R W + C with W, kappa and beta_p frozen at y (E), which is linear. The excess q -> q0
/// e^{-kappa l} + dq(C) (1 - e^{-kappa l})/kappa, and the state moves by W int R dl + C h.
template <class T>
State<T> relax_pressure(const ExcessRelaxation<T>& E, const State<T>& y, const State<T>& c, double h) {
  if (E.off.lost || E.w.lost) return lost_state(y);
  T phi, psi;
  relaxed_lengths(E.kappa, h, phi, psi);
  const T moved = E.beta_p * (E.excess * phi + E.dq(c) * psi);   // int_0^h R dl
  State<T> z = lincomb(lincomb(y, T(1.0), E.w, moved), T(1.0), c, T(h));
  return z;
}

/// One step of h with the excess pressure's relaxation split off (a rebalanced Strang split): at y the constant C =
/// gamma W along the relaxation's direction with gamma = dq(OFF)/dq(W), so that the relaxation part carries the excess's
/// whole source (dq(R W + C) = dq(OFF) - kappa q) and the RK4 part none of it (dq(OFF - C) = 0 at y); the relaxation
/// plus C over h/2 exactly (relax_pressure), RK4 over h on OFF - C, the relaxation plus C over h/2 again. A quasi-steady
/// excess q = dq(OFF)/kappa (the stiff case) is then the relaxation part's own fixed point, which the plain split loses
/// (it takes q to 0 at kappa h >> 1). C moves nothing the relaxation does not move (at constant volume only p), so that
/// the other laws keep RK4's accuracy. Below kappa h = 1e-3 no constant is moved (dq(W) may be round-off there). Tried
/// and dropped (thirty-eighth round): Speth et al.'s half-and-half constant, gamma = (dq(OFF)/dq(W) - R)/2, which
/// carries R = beta_p q itself; the mu = 0.5 group fit then stopped after 7 iterations on invalid steps.
template <class T>
State<T> excess_split_step(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double h,
                           double* stiff) {
  const ExcessRelaxation<T> E = excess_relaxation(m, y, sigma, seg);
  const T dq_w = E.dq(E.w);
  const bool balanced = scalar_value(E.kappa) * h > 1e-3;   // below, dq_w may be round-off (kappa = 0 in the law)
  const T gamma = balanced ? E.dq(E.off) / dq_w : T(0.0);
  const State<T> c = lincomb(E.w, gamma, E.w, T(0.0));
  const State<T> mid = rk4_step(m, relax_pressure(E, y, c, h / 2), sigma, seg, h, stiff, Split::Excess, &c);
  return relax_pressure(excess_relaxation(m, mid, sigma, seg), mid, c, h / 2);
}

/// One step of h split (Strang) into the fabric's relaxation taken exactly over h/2 (relax_fabric), RK4 over h on the
/// rest of rhs, and the relaxation over h/2 again: second order, and stable however stiff the fabric's gate is
/// (thirty-seventh round; advance uses it where a loading start's gate is not integrable, n_F < -1); or with WHAT
/// Split::Excess the excess pressure's (excess_split_step; thirty-eighth round: first_held_try's second try at each step
/// where RK4's does not hold; the group fits at mu >= 0.3 relax their excess at beta_p up to 4e5). STIFF: the RK4
/// part's stage_stiffness, which does not see the relaxation.
template <class T>
State<T> split_step(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double h, double* stiff,
                    Split what) {
  if (what == Split::Excess) return excess_split_step(m, y, sigma, seg, h, stiff);
  const State<T> half = relax_fabric(m, y, sigma, seg, h / 2);
  return relax_fabric(m, rk4_step(m, half, sigma, seg, h, stiff, Split::Fabric), sigma, seg, h / 2);
}

/// RK4's step control (issue 31, thirty-sixth round). Where the stress ratio's law is stiff (a large beta_s at low
/// pressure, and under the triaxial extension control amplified by about (3 - s)/3) a fixed step of 5e-4 lies outside
/// RK4's stability region: the mu = 1 joint calibration's TE_s3_dense at p* = 1e-3 had h lambda = 3.9 there, moved its
/// side stress by 14 % in one output interval and was not a number in the next. An output interval is integrated again
/// from its start with the step halved, up to kMaxHalvings times, where any of its steps has a stage_stiffness above
/// kStiffLimit, where it moves the quantity a drained segment holds exactly in the equations (p under
/// Control::Isobaric, the side stress p (1 - s/3) under Control::Triaxial) by more than kHeldDrift of itself, or where
/// its finite start ends not a number (or lost, State::lost). The joint calibrations' paths at mu <= 0.5 stay below
/// h lambda = 0.5 (mu = 1: 0.94 on its other paths), so the fixed step is kept there bit for bit.
constexpr double kHeldDrift = 1e-4;
constexpr double kStiffLimit = 2.0;
constexpr int kMaxHalvings = 6;

/// The quantity the segment holds at the state y (NaN at constant volume and on a volumetric segment, sigma = 0).
template <class T>
double held_quantity(const State<T>& y, double sigma, const Segment& seg) {
  if (sigma == 0.0 || seg.control == Control::Volume) return std::numeric_limits<double>::quiet_NaN();
  const double p = scalar_value(y.p);
  return seg.control == Control::Isobaric ? p : p * (1.0 - scalar_value(y.s) / 3.0);
}

template <class T>
bool finite_state(const State<T>& y) {
  return !y.lost && std::isfinite(scalar_value(y.ln_nu)) && std::isfinite(scalar_value(y.p)) &&
         std::isfinite(scalar_value(y.s)) && std::isfinite(scalar_value(y.F)) && std::isfinite(scalar_value(y.e_pl));
}

/// Whether an interval from y to y1 holds its control: a finite start ends finite, and the held quantity (if any) moved
/// by at most kHeldDrift of itself. A start already not a number has nothing to refine.
template <class T>
bool step_held(const State<T>& y, const State<T>& y1, double sigma, const Segment& seg) {
  if (!finite_state(y)) return true;
  if (!finite_state(y1)) return false;
  const double h0 = held_quantity(y, sigma, seg);
  return std::isnan(h0) || std::fabs(held_quantity(y1, sigma, seg) - h0) <= kHeldDrift * std::fabs(h0);
}

/// One try of advance_interval: SUB RK4 steps of dl/SUB from y, the volumetric strain accumulated into EV and the
/// largest finite stage_stiffness into STIFF; SPLIT: split_step's steps instead of RK4's. With MAY_STOP the try stops
/// at the first step whose stiffness exceeds kStiffLimit (it cannot hold then, whatever follows) and returns false; a
/// try run to its end returns true.
template <class T>
bool interval_try(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double dl, int sub,
                  bool may_stop, Split split, State<T>& z, T& ev, double& stiff) {
  z = y;
  stiff = 0;
  for (int j = 0; j < sub; ++j) {
    double hl = 0;
    const State<T> z1 = split != Split::None ? split_step(m, z, sigma, seg, dl / sub, &hl, split)
                                             : rk4_step(m, z, sigma, seg, dl / sub, &hl);
    ev += z.ln_nu - z1.ln_nu;
    z = z1;
    if (std::isfinite(hl)) stiff = std::max(stiff, hl);
    if (may_stop && stiff > kStiffLimit) return false;
  }
  return true;
}

/// How advance reached the end of an interval: HALVINGS how often the kept try's step was halved (-1: no try held; 0 the
/// fixed step); GRADED from a singular_start on the graded pieces; SPLIT with the fabric's relaxation taken exactly
/// (a gate that is not integrable); RELAXED with the excess pressure's taken exactly on some step (split_step).
struct StepReport {
  int halvings = 0;
  bool graded = false, split = false, relaxed = false;
};

/// Whether the excess pressure's relaxation at y is stiff at the step h: kappa h at least kStiffLimit/2 (excess_relaxation).
template <class T>
bool stiff_excess(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double h) {
  return sigma != 0.0 && scalar_value(excess_relaxation(m, y, sigma, seg).kappa) * h >= kStiffLimit / 2;
}

/// The first of the tries of advance_interval that holds (stage_stiffness at most kStiffLimit, step_held), with the
/// step halved up to kMaxHalvings times: true, Z and EV set and K its halvings. Every try but the last stops at its
/// first step too stiff to hold; the last runs to its end (Z and EV then hold it where none held). With SPLIT none, a try
/// of RK4 that is too stiff where the excess pressure's relaxation is stiff (stiff_excess) is followed at the same step
/// by split_step with that relaxation taken exactly (thirty-eighth round; RELAXED then set where that one holds): where
/// only that relaxation is stiff it holds at the fixed step, where RK4 needed up to 64 times the steps. A try that
/// failed only on step_held is not followed by the split: the split holds a drained control by construction, so that
/// step_held would not judge it. The group model only (no extension block): in the frictional family's fits the split
/// made the mu = 0.5 weighted-rule fit twice as slow, from a start whose cost it put 2e4 times higher (not understood).
template <class T>
bool first_held_try(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double dl, int sub0,
                    Split split, State<T>& z, T& ev, int& k, bool& relaxed) {
  const T ev0 = ev;
  double stiff = 0;
  auto held = [&](Split how, bool may_stop) {
    ev = ev0;
    return interval_try(m, y, sigma, seg, dl, sub0 << k, may_stop, how, z, ev, stiff) && stiff <= kStiffLimit &&
           step_held(y, z, sigma, seg);
  };
  for (k = 0; k <= kMaxHalvings; ++k) {
    if (held(split, k < kMaxHalvings)) return true;
    if (split != Split::None || k == kMaxHalvings || !(stiff > kStiffLimit)) continue;
    if (!m.ext.p && stiff_excess(m, y, sigma, seg, dl / (sub0 << k)) && held(Split::Excess, true)) return relaxed = true;
  }
  return false;
}

/// The state after |d eps_d| = dl (|eps_vol| on a volumetric segment) from y: ceil(dl/max_step) RK4 steps, the full
/// volumetric strain tr(E) accumulated step by step into EPS_VOL. Where a step's stage_stiffness exceeds kStiffLimit or
/// step_held fails the interval is integrated again (with the excess pressure's relaxation taken exactly, then with the
/// step halved, up to kMaxHalvings times), and the first try that holds is kept (first_held_try). A try stops at its
/// first step too stiff to hold (thirty-seventh round: a try that failed ran to its end before, so that a path needing
/// 1/64 of the step cost 127 fixed-step intervals instead of 64 and a few steps). Where none holds, the finest finite
/// RK4 try is kept (the tries that had stopped early are run to their end for it), or where none is finite the fixed
/// step's (its NaN or lost state, as before the thirty-sixth round: a path that fails at every step fails as it did).
/// REPORT (if given): its halvings and relaxed; halvings 0 and not relaxed is the fixed step, bit for bit as before.
/// SPLIT: every try with split_step instead of RK4's steps (advance, where a loading start's gate is not integrable).
template <class T>
State<T> advance_interval(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double dl,
                          double max_step, T& eps_vol, StepReport* report = nullptr, Split split = Split::None) {
  const int sub0 = std::max(1, static_cast<int>(std::ceil(dl / max_step)));
  State<T> z;
  T ev = eps_vol;
  int k = 0;
  bool relaxed = false;
  if (first_held_try(m, y, sigma, seg, dl, sub0, split, z, ev, k, relaxed)) {
    if (report) report->halvings = k, report->relaxed = relaxed;
    eps_vol = ev;
    return z;
  }
  if (report) report->halvings = -1, report->relaxed = false;
  // None held: the finest finite try (z, the last, ran to its end), else the fixed step's.
  for (k = kMaxHalvings - 1; k >= 0 && !finite_state(z); --k) {
    double stiff = 0;
    ev = eps_vol;
    interval_try(m, y, sigma, seg, dl, sub0 << k, false, split, z, ev, stiff);
  }
  eps_vol = ev;
  return z;
}

/// The fabric gate's exponent n_F at the state y, read as rhs reads it (quiet_law_volume); 0 for the group model.
template <class T>
double gate_exponent(const Material<T>& m, const State<T>& y) {
  if (!m.ext.p) return 0.0;
  return scalar_value(local_ext(m.ext.p, quiet_law_volume(m, y), m.nu_ref).n_F);
}

/// A loading start (l = 0) whose fabric gate's exponent is negative: the gate r_F^n_F is unbounded where nothing has
/// opened yet (r_F -> 0, floored at 1e-6), an integrable singularity l^n_F for n_F > -1 that a fixed step cannot
/// resolve: its first RK4 stage reads the floor, and the fabric jumps towards its limit in one step (thirty-sixth
/// round: the stored lab_dense calibration, n_F = -0.53 at its dense start, F 0.03 -> 0.49 in the first output
/// interval at the fixed step, 0.057 converged).
template <class T>
bool singular_start(const Material<T>& m, const State<T>& y, double sigma) {
  return sigma != 0.0 && scalar_value(y.l) == 0.0 && finite_state(y) && gate_exponent(m, y) < 0.0;
}

/// The pieces of kGradedPieces + 1 on which a singular start's first interval is integrated: [0, dl 2^-G], then
/// [dl 2^-(j+1), dl 2^-j] for j = G - 1 ... 0, so that the gate varies by at most 2^|n_F| across a piece, each in at
/// least kGradedSteps RK4 steps (one step on l^-1/2 over [a, 2a] is off by 3e-3 of its integral, eight by 1e-5).
constexpr int kGradedPieces = 40;
constexpr int kGradedSteps = 8;

/// The gate exponent below which a singular_start's gate is not integrable: beta_F int_0^l r_F^n_F is infinite in the
/// law, so the fabric reaches its limit at once, and on the gate's floor (1e6)^|n_F| is beyond any RK4 step.
constexpr double kIntegrableGate = -1.0;

/// advance_interval from y, or where y is a singular_start the interval on the graded pieces (each advance_interval,
/// halvings the most of any piece, relaxed if any was; REPORT's graded says so). Where the start's gate is not
/// integrable (n_F below kIntegrableGate; thirty-seventh round: the mu = 0 joint calibration's leave-one-out refits, n_F
/// about -2.8 at D3 nu = 0.8, were not a number at their start) the graded pieces are integrated with split_step, the
/// fabric's relaxation taken exactly; REPORT's split says so.
template <class T>
State<T> advance(const Material<T>& m, const State<T>& y, double sigma, const Segment& seg, double dl, double max_step,
                 T& eps_vol, StepReport* report = nullptr) {
  StepReport r;
  r.graded = singular_start(m, y, sigma);
  r.split = r.graded && gate_exponent(m, y) < kIntegrableGate;
  if (!r.graded) {
    const State<T> z = advance_interval(m, y, sigma, seg, dl, max_step, eps_vol, &r);
    if (report) *report = r;
    return z;
  }
  StepReport piece_r;
  auto piece = [&](const State<T>& from, double length) {
    const State<T> z = advance_interval(m, from, sigma, seg, length, std::min(max_step, length / kGradedSteps), eps_vol,
                                        &piece_r, r.split ? Split::Fabric : Split::None);
    r.halvings = (piece_r.halvings < 0 || r.halvings < 0) ? -1 : std::max(r.halvings, piece_r.halvings);
    r.relaxed = r.relaxed || piece_r.relaxed;
    return z;
  };
  State<T> z = piece(y, std::ldexp(dl, -kGradedPieces));
  for (int j = kGradedPieces - 1; j >= 0; --j) z = piece(z, std::ldexp(dl, -(j + 1)));
  if (report) *report = r;
  return z;
}

/// Where p_iso first reaches p on a grid of kRisingGrid steps from nu_c to 1: [lo, hi] around that crossing, the
/// rising branch from jamming. false if the law stays below p on the whole grid (p above its reach).
constexpr int kRisingGrid = 256;
inline bool rising_bracket(const double* iso, double p, double& lo, double& hi) {
  const double nu_c = iso[kNuC];
  for (int i = 1; i <= kRisingGrid; ++i) {
    const double nu = nu_c + (1.0 - nu_c) * i / kRisingGrid;
    if (isotropic_pressure(iso, nu) >= p) {
      lo = nu_c + (1.0 - nu_c) * (i - 1) / kRisingGrid;
      hi = nu;
      return true;
    }
  }
  return false;
}

/// The highest pressure p* the isotropic law reaches on [nu_c, 1] (p_iso at 1, or the grid's maximum of rising_bracket
/// for a law that falls again): isotropic_volume is a number exactly up to it. With the volume-form state parameter a
/// path whose start pressure lies above it has no elastic volume fraction (start_state), and is lost. AT: where.
inline double isotropic_reach(const double* iso, double* at = nullptr) {
  double reach = isotropic_pressure(iso, 1.0), where = 1.0;
  const double nu_c = iso[kNuC];
  for (int i = 1; i <= kRisingGrid; ++i) {
    const double nu = nu_c + (1.0 - nu_c) * i / kRisingGrid, p = isotropic_pressure(iso, nu);
    if (p > reach) { reach = p; where = nu; }
  }
  if (at) *at = where;
  return reach;
}

/// The isotropic law's volume fraction at pressure p* [-]: p_iso(nu) = p, bracketed between nu_c and 1 by bisection
/// in double, then two Newton steps in T (d p_iso / d nu = B/nu), so that Ceres differentiates it through the law's
/// parameters. nu_c itself where p <= 0. A law that falls again below 1 (a coordination law with C1 < 0) and ends
/// below p at 1 is bracketed on its rising branch (rising_bracket; twenty-second round: the bracket [nu_c, 1] then
/// returned 1, so that a last digit of a coefficient moved a start state from the rising branch to nu = 1); NaN where
/// the law never reaches p (the path's state is then not a number: lost to a fit, `inf` in a prediction).
template <class T>
T isotropic_volume(const T* iso, double p) {
  auto val = [](const T& x) { return model::scalar_value(x); };
  const double nu_c = val(iso[kNuC]);
  double lo = nu_c, hi = 1.0;
  std::vector<double> isod(kNumIso);
  for (int i = 0; i < kNumIso; ++i) isod[i] = val(iso[i]);
  if (!(p > 0)) return iso[kNuC];
  if (isotropic_pressure(isod.data(), hi) < p && !rising_bracket(isod.data(), p, lo, hi))
    return iso[kNuC] * T(std::numeric_limits<double>::quiet_NaN());
  for (int it = 0; it < 60; ++it) {
    const double mid = 0.5 * (lo + hi);
    (isotropic_pressure(isod.data(), mid) < p ? lo : hi) = mid;
  }
  T nu = T(0.5 * (lo + hi));
  for (int it = 0; it < 2; ++it) nu = nu - (isotropic_pressure(iso, nu) - T(p)) * nu / bulk_modulus(iso, nu);
  return nu;
}

/// The material of a path from (nu0, p0): the scale k = p0/p_iso(nu0), the state's own offset from the isotropic law;
/// with the volume-form state parameter k = 1 (the elastic state is the law's at p0, start_state) and the rates'
/// reference stiffness B/p at p* = kPCsRef on the law (rate_scale).
template <class T>
Material<T> start_material(const T* iso, const T* shear, double nu_ref, double nu0, double p0, const Ext<T>& ext) {
  if (ext.p && ext.state_volume) {
    const T nu_ref_cs = isotropic_volume(iso, kPCsRef);
    Material<T> m{iso, shear, nu_ref, T(1.0), ext};
    m.bp_ref = bulk_modulus(iso, nu_ref_cs) / T(kPCsRef);
    return m;
  }
  return Material<T>{iso, shear, nu_ref, T(p0) / isotropic_pressure(iso, T(nu0)), ext};
}

/// The start state; with the volume-form state parameter the plastic strain e_pl = ln(nu_iso(p0)/nu0), so that the
/// elastic volume fraction starts on the isotropic law at p0 whatever the preparation (a loose packing below the law's
/// jamming fraction included): the elastic stiffness a function of the pressure alone, as SANISAND's K(p).
/// With Ext::start_unaligned s and F start at 0 (the aligned parts; s0 and F0 are then only observed, `observed`).
template <class T>
State<T> start_state(const Material<T>& m, double nu0, double p0, double s0, double F0) {
  State<T> y{T(std::log(nu0)), T(p0), T(m.ext.start_unaligned ? 0.0 : s0), T(m.ext.start_unaligned ? 0.0 : F0)};
  using std::log;
  if (m.ext.p && m.ext.state_volume) y.e_pl = log(isotropic_volume(m.iso, p0)) - T(std::log(nu0));
  return y;
}

/// Integrates the model along `path` from the state (nu0, p0, s0, F0) (p0 in p* units).
/// Returns the initial point and `outputs` points per segment. The isotropic scale k is
/// p0 / p_iso(nu0). Throws std::invalid_argument for an empty path or a non-positive state.
template <class T>
std::vector<Point<T>> integrate(const T* iso, const T* shear, double nu_ref, double nu0, double p0, double s0,
                                double F0, const std::vector<Segment>& path, const Ext<T>& ext = {}) {
  using std::log;
  if (path.empty()) throw std::invalid_argument("model path: no segments");
  if (!(nu0 > 0 && p0 > 0)) throw std::invalid_argument("model path: initial nu and p must be positive");
  Material<T> m = start_material(iso, shear, nu_ref, nu0, p0, ext);
  State<T> y = start_state(m, nu0, p0, s0, F0);
  T eps_vol = T(0.0);
  double acc = 0, eps_d = 0, last_sigma = 1.0;
  std::vector<Point<T>> out{{0.0, 0.0, eps_vol, y}};
  for (const Segment& seg : path) {
    const bool vol = seg.eps_d == 0.0;
    if (vol && seg.eps_vol == 0.0) throw std::invalid_argument("model path: a segment with no strain");
    if (seg.outputs < 1) throw std::invalid_argument("model path: a segment needs at least one output point");
    const double sigma = vol ? 0.0 : (seg.eps_d > 0 ? 1.0 : -1.0);
    const double length = vol ? std::fabs(seg.eps_vol) : std::fabs(seg.eps_d);
    const double dl = length / seg.outputs;
    if (sigma != 0.0 && sigma != last_sigma) y.l = T(0.0);   // a reversal: the opening restarts
    if (sigma != 0.0) last_sigma = sigma;
    for (int o = 0; o < seg.outputs; ++o) {
      y = advance(m, y, sigma, seg, dl, seg.max_step, eps_vol);
      if (!vol) { acc += dl; eps_d += sigma * dl; }
      out.push_back({acc, eps_d, eps_vol, y});
    }
  }
  return out;
}

/// A path given row by row, as the DEM path curves are sampled: row i is reached from row i-1
/// by |d eps_d| = acc[i] - acc[i-1] [-] in the direction direction[i] (+1 the first loading
/// direction, -1 reversed; 0: no deviatoric strain, the row repeats the state), at constant
/// volume (isobaric[i] == 0), at constant pressure (isobaric[i] == 1) or at constant side
/// stress (isobaric[i] == 2: the triaxial test, Control::Triaxial; the axial strain of the row
/// is then (eps_vol - 2 eps_d)/3, axial_strain()). Segment ends (reversal
/// points) must be rows, so that every interval is monotone. Returns the state and the full
/// volumetric strain tr(E) since row 0 at every row (row 0: the start state (nu0, p0, s0, F0)).
/// Throws std::invalid_argument for mismatched sizes, decreasing acc or a non-positive start.
template <class T>
struct RowState {
  State<T> state;
  T eps_vol;   ///< full volumetric strain tr(E) since row 0 [-] (extension positive)
  /// pole_ratio a_A F/3 at the row's state where the row was reached under the drained triaxial control (NaN
  /// elsewhere, and in jet runs: a diagnostic of predictions)
  double pole = std::numeric_limits<double>::quiet_NaN();
  int halvings = 0;   ///< how often RK4's step was halved to reach this row from the last (advance; -1: no step held)
  bool graded = false;   ///< reached from a singular_start on the graded pieces (advance)
  bool split = false;    ///< reached from a start whose gate is not integrable, with split_step (advance)
  bool relaxed = false;  ///< reached with the excess pressure's relaxation taken exactly on some step (advance)
};
template <class T>
std::vector<RowState<T>> integrate_rows(const T* iso, const T* shear, double nu_ref, double nu0, double p0, double s0,
                                        double F0, const std::vector<double>& acc, const std::vector<int>& direction,
                                        const std::vector<int>& isobaric, double max_step = 5e-4,
                                        const Ext<T>& ext = {}) {
  if (acc.empty() || direction.size() != acc.size() || isobaric.size() != acc.size())
    throw std::invalid_argument("model path rows: acc, direction and isobaric must have the same, non-zero length");
  if (!(nu0 > 0 && p0 > 0)) throw std::invalid_argument("model path rows: initial nu and p must be positive");
  Material<T> m = start_material(iso, shear, nu_ref, nu0, p0, ext);
  State<T> y = start_state(m, nu0, p0, s0, F0);
  T eps_vol = T(0.0);
  double last_sigma = 1.0;
  StepReport report;
  std::vector<RowState<T>> out;
  out.reserve(acc.size());
  out.push_back({y, eps_vol});
  for (std::size_t i = 1; i < acc.size(); ++i) {
    const double dl = acc[i] - acc[i - 1];
    if (dl < 0) throw std::invalid_argument("model path rows: accumulated strain decreases at row " + std::to_string(i));
    if (dl > 0 && direction[i] != 0) {
      Segment seg;
      seg.control = isobaric[i] == 2 ? Control::Triaxial : isobaric[i] ? Control::Isobaric : Control::Volume;
      const double sigma = direction[i] > 0 ? 1.0 : -1.0;
      if (sigma != last_sigma) y.l = T(0.0);   // a reversal: the opening restarts
      last_sigma = sigma;
      y = advance(m, y, sigma, seg, dl, max_step, eps_vol, &report);
    }
    out.push_back({y, eps_vol});
    out.back().halvings = report.halvings;
    out.back().graded = report.graded;
    out.back().split = report.split;
    out.back().relaxed = report.relaxed;
    report = StepReport{};
    if constexpr (std::is_same<T, double>::value)
      if (isobaric[i] == 2 && !y.lost) out.back().pole = pole_ratio(m, y);
  }
  return out;
}

/// Axial strain of an axisymmetric strain state diag(e_r, e_r, e_a) from its full volumetric
/// strain eps_vol = 2 e_r + e_a and its deviatoric strain eps_d = e_r - e_a (the magnitude of
/// docs/definitions.md, |e_a - e_r|, signed positive for axial compression): e_a = (eps_vol - 2 eps_d)/3.
inline double axial_strain(double eps_vol, double eps_d) { return (eps_vol - 2.0 * eps_d) / 3.0; }

/// Monotone constant-volume shear from the state (nu0, p0, s0, F0), evaluated at the given
/// strains (increasing, >= 0): the path on which the model is calibrated (D2, D3). REPORTS (if given): how each point
/// was reached from the one before (advance's StepReport; the first point's is empty).
template <class T>
std::vector<State<T>> monotone_shear(const T* iso, const T* shear, double nu_ref, double nu0, double p0, double s0,
                                     double F0, const std::vector<double>& eps, double max_step = 5e-4,
                                     const Ext<T>& ext = {}, std::vector<StepReport>* reports = nullptr) {
  using std::exp;
  Material<T> m = start_material(iso, shear, nu_ref, nu0, p0, ext);
  State<T> y = start_state(m, nu0, p0, s0, F0);
  Segment seg;   // constant volume, forward
  std::vector<State<T>> out;
  out.reserve(eps.size());
  if (reports) reports->clear();
  double at = 0;
  for (double e : eps) {
    if (e < at) throw std::invalid_argument("monotone_shear: strains must increase");
    const double dl = e - at;
    T unused = T(0.0);
    StepReport r;
    if (dl > 0) y = advance(m, y, 1.0, seg, dl, max_step, unused, &r);
    at = e;
    out.push_back(y);
    if (reports) reports->push_back(r);
  }
  return out;
}

}  // namespace demfit::model
