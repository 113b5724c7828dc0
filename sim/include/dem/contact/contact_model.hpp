// The contact model: sub-models composed at compile time in a fixed order,
//   normal -> damping -> (no-tension clamp) -> tangential -> rolling (and twisting),
// over one geometry per pair (geometry.hpp), the way MercuryDPM's Species mixins and LAMMPS'
// GranularModel sub-models are organised. An empty sub-model (NoTangential) costs nothing: the
// frictionless model is exactly the old linear spring-dashpot, bit for bit, and keeps 3 degrees
// of freedom per particle. `with_contact_model` turns the scene's ContactLaw into the concrete
// type once per pair loop (or measurement), so the loops are compiled for each model.
//
// Where a new sub-model goes (ARCHITECTURE.md): a struct in its own header beside these
// (force templated on the lane type so that the vector kernels run it: `Bound<T>` without
// history, `update` on lanes and `lane_body = true` with it, else the scalar loop runs the
// model; `history` and `rotations` constants), a template slot or a type here, a case in with_contact_model, its
// keys in io/scene.cpp and io/checks.cpp (physics record), and its tests.
#pragma once
#include <type_traits>

#include "dem/contact/geometry.hpp"
#include "dem/contact/normal_linear.hpp"
#include "dem/contact/normal_luding.hpp"
#include "dem/contact/rolling.hpp"
#include "dem/contact/tangential.hpp"
#include "dem/core/model.hpp"
#include "dem/core/state.hpp"

namespace dem::contact {

/// History doubles of a sub-model (0 for those that declare none).
template <class S, class = void> struct HistoryOf { static constexpr int value = 0; };
template <class S> struct HistoryOf<S, std::void_t<decltype(S::history)>> { static constexpr int value = S::history; };
/// Whether a sub-model with history has a body on lanes (`lane_body = true`: its update is a
/// template on the lane type); one without history needs none (its Bound<T> is its body).
template <class S, class = void> struct LaneBodyOf { static constexpr bool value = HistoryOf<S>::value == 0; };
template <class S> struct LaneBodyOf<S, std::void_t<decltype(S::lane_body)>> { static constexpr bool value = S::lane_body; };

/// What one pair of a model with history gives, in lanes of T: the force on j [N] (on i: its
/// negative), the torques on i and j [N m], and the energy lost to the sliders this step [J].
template <class T>
struct PairForces {
  V3<T> fj, ti, tj;
  T dissipated;
};

template <class Normal, class Damping, class Tangential, class Rolling = NoRolling>
struct ContactModel {
  Normal normal;
  Damping damping;
  Tangential tangential;
  bool attractive = false;   ///< false: the normal force is clamped at zero (no tension); history normals: no clamp
  Rolling rolling{};

  using RollingModel = Rolling;
  /// History doubles per contact, in this order: the normal sub-model's, the tangential one's,
  /// the rolling one's.
  static constexpr int normal_history = HistoryOf<Normal>::value;
  static constexpr int tangential_offset = normal_history;
  static constexpr int rolling_offset = normal_history + Tangential::history;
  static constexpr int history = normal_history + Tangential::history + Rolling::history;
  static constexpr bool rotations = Tangential::rotations;
  /// Runs in the vector kernels: no history, or every sub-model with history has a body on lanes
  /// (a sub-model without one falls back to the scalar reference loop, pair_loop_history).
  static constexpr bool vectorised = history == 0 || (LaneBodyOf<Normal>::value && LaneBodyOf<Tangential>::value &&
                                                      LaneBodyOf<Rolling>::value);
  /// History entries that change sign when i and j swap (the tangential spring's).
  static constexpr unsigned odd_mask = [] {
    if constexpr (Tangential::history > 0) return Tangential::odd_mask << tangential_offset;
    else return 0u;
  }();

  /// The model with its parameters in lanes of T: a kernel binds it once before its loop.
  template <class T>
  struct Bound {
    typename Normal::template Bound<T> normal;
    typename Damping::template Bound<T> damping;
    lanes::Mask<T> attractive;
    T zero;
    /// The normal force magnitude [N], repulsion positive: spring + dashpot, clamped at zero
    /// unless `attractive`. One body for one pair (T = double) and for lanes of pairs.
    __attribute__((always_inline)) T normal_force(const NormalGeometry<T>& g) const {
      const T f = normal.force(g) + damping.force(g);
      return lanes::select(lanes::greater(f, zero) | attractive, f, zero);
    }
  };
  template <class T> Bound<T> bind() const {
    return {normal.template bind<T>(), damping.template bind<T>(), lanes::mask_of<T>(attractive), lanes::splat<T>(0.0)};
  }
  /// The normal force of one pair [N] (a12 = r_i r_j/(r_i + r_j) [m], h the contact's history):
  /// `advance` updates a history normal's state (the pair loop), otherwise it is only read.
  __attribute__((always_inline)) double normal_force(const NormalGeometry<double>& g, double a12 = 0,
                                                     double* h = nullptr, bool advance = false) const {
    if constexpr (normal_history > 0) {
      const double f = advance ? normal.update(g.delta, a12, h) : normal.force(g.delta, a12, h);
      return f + damping.template bind<double>().force(g);
    } else {
      (void)a12; (void)h; (void)advance;
      return bind<double>().normal_force(g);
    }
  }
  /// One step of one pair of a model with history, in lanes of T (double: the reference loop):
  /// the separation `sep` of the radii ri, rj [m], the velocity difference v_j - v_i [m/s], the
  /// angular velocities [1/s], the rate [1/s] and dt [s]; h (CM::history entries) is advanced.
  /// The contact is assumed (the caller discards pairs out of contact). Every sub-model's body
  /// is called here in the fixed order normal -> damping -> tangential -> rolling.
  template <bool Sheared, class T>
  __attribute__((always_inline)) PairForces<T> advance(const Separation<T>& sep, T ri, T rj, T dvx, T dvy, T dvz,
                                                       const V3<T>& wi, const V3<T>& wj, const RateLanes<T>& rate,
                                                       T dt, T* h) const {
    using lanes::splat;
    T vx, vy, vz;
    relative_velocity<Sheared>(sep, dvx, dvy, dvz, rate, vx, vy, vz);
    const NormalGeometry<T> g = normal_geometry(sep, vx, vy, vz);
    T fn;
    if constexpr (normal_history > 0)
      fn = normal.update(g.delta, ri * rj / (ri + rj), h) + damping.template bind<T>().force(g);
    else
      fn = bind<T>().normal_force(g);
    const V3<T> n{g.nx, g.ny, g.nz};
    PairForces<T> out{n * fn, {}, {}, splat<T>(0.0)};
    if constexpr (rotations) {
      const T half = splat<T>(0.5), zero = splat<T>(0.0);
      const T ai = ri - half * g.delta, aj = rj - half * g.delta;   // lever arms to the overlap's middle
      const V3<T> v_contact = V3<T>{vx, vy, vz} - cross(wi * ai + wj * aj, n);
      const T fn_plus = lanes::select(lanes::less(fn, zero), zero, fn);   // std::max(fn, 0.0)
      const V3<T> ft = tangential.update(n, v_contact, fn_plus, dt, h + tangential_offset, out.dissipated);
      const V3<T> nxf = cross(n, ft);
      out.fj = out.fj + ft;
      out.ti = nxf * (-ai);   // (a_i n) x (-f_j)
      out.tj = nxf * (-aj);   // (-a_j n) x f_j
      if constexpr (Rolling::history > 0) {   // a couple: torques only
        const V3<T> tr =
            rolling.update(RollingInput<T>{n, wi, wj, ai * aj / (ai + aj), fn_plus}, dt, h + rolling_offset, out.dissipated);
        out.ti = out.ti + tr;
        out.tj = out.tj - tr;
      }
    } else {
      (void)wi; (void)wj; (void)dt;
    }
    return out;
  }
  /// Elastic energy of the normal sub-model alone [J].
  double normal_energy(double delta, double a12, const double* h) const {
    if constexpr (normal_history > 0) return normal.energy(delta, a12, h);
    else { (void)a12; (void)h; return normal.energy(delta); }
  }
  /// Elastic energy stored in a contact of overlap delta [m] and history h [J].
  double energy(double delta, double a12, const double* h) const {
    double e = normal_energy(delta, a12, h);
    if constexpr (Tangential::history > 0) e += tangential.energy(h + tangential_offset);
    if constexpr (Rolling::history > 0) e += rolling.energy(h + rolling_offset);
    return e;
  }
  double normal_stiffness() const { return normal.stiffness(); }
};

template <class Normal, class Tangential, class Rolling = NoRolling>
using Model3 = ContactModel<Normal, LinearDashpot, Tangential, Rolling>;
using Frictionless = Model3<LinearSpring, NoTangential>;
using Frictional = Model3<LinearSpring, CundallStrack>;
using FrictionalRolling = Model3<LinearSpring, CundallStrack, RollingSpring>;

inline Frictionless frictionless(const ContactLaw& law) {
  return {LinearSpring{law.stiffness}, LinearDashpot{law.damping}, NoTangential{}, law.allow_attractive};
}
inline Frictional frictional(const ContactLaw& law) {
  return {LinearSpring{law.stiffness}, LinearDashpot{law.damping},
          CundallStrack{law.tangential_stiffness_ratio * law.stiffness, law.tangential_damping, law.friction,
                        law.objective_spring},
          law.allow_attractive};
}
inline FrictionalRolling frictional_rolling(const ContactLaw& law) {
  const Frictional base = frictional(law);
  return {base.normal, base.damping, base.tangential, base.attractive,
          RollingSpring{law.rolling_stiffness_ratio * law.stiffness, law.rolling_damping, law.rolling_friction}};
}
/// Rolling (mu_r may be 0: off) and twisting resistance.
inline RollingTwisting rolling_twisting(const ContactLaw& law) {
  return {frictional_rolling(law).rolling,
          TwistingSpring{law.twisting_stiffness_ratio * law.stiffness, law.twisting_damping, law.twisting_friction}};
}

/// Calls f(model) with the concrete contact model of the scene's law: the normal sub-model
/// (linear or Luding's), the tangential one (none or Cundall-Strack), rolling (off, on, or
/// rolling with twisting).
template <class F>
decltype(auto) with_contact_model(const ContactLaw& law, F&& f) {
  if (law.normal == NormalModel::Luding) {
    const LudingNormal n{law.stiffness, law.luding_kp, law.luding_kc, law.luding_plasticity_depth};
    const Frictional base = frictional(law);
    if (law.twisting())
      return f(Model3<LudingNormal, CundallStrack, RollingTwisting>{n, base.damping, base.tangential, false,
                                                                    rolling_twisting(law)});
    if (law.rolling())
      return f(Model3<LudingNormal, CundallStrack, RollingSpring>{n, base.damping, base.tangential, false,
                                                                  frictional_rolling(law).rolling});
    if (law.frictional()) return f(Model3<LudingNormal, CundallStrack>{n, base.damping, base.tangential, false});
    return f(Model3<LudingNormal, NoTangential>{n, base.damping, NoTangential{}, false});
  }
  if (law.twisting()) {
    const Frictional base = frictional(law);
    return f(Model3<LinearSpring, CundallStrack, RollingTwisting>{base.normal, base.damping, base.tangential,
                                                                  base.attractive, rolling_twisting(law)});
  }
  if (law.rolling()) return f(frictional_rolling(law));
  if (law.frictional()) return f(frictional(law));
  return f(frictionless(law));
}

/// Doubles of per-contact history of the scene's model (0: none), and which of them change
/// sign when the pair's particles swap roles (bit k: entry k).
int history_width(const ContactLaw& law);
unsigned history_odd_mask(const ContactLaw& law);

/// Gives the state what the model needs and nothing more: angular velocities and torques
/// (zero) for a frictional model, none for a frictionless one; a history of the model's width
/// (a history of another width is dropped).
void prepare_state(const ContactLaw& law, State& state);

}  // namespace dem::contact
