// The contact model: sub-models composed at compile time in a fixed order,
//   normal -> damping -> (no-tension clamp) -> tangential -> rolling (and twisting),
// over one geometry per pair (geometry.hpp), the way MercuryDPM's Species mixins and LAMMPS'
// GranularModel sub-models are organised. An empty sub-model (NoTangential) costs nothing: the
// frictionless model is exactly the old linear spring-dashpot, bit for bit, and keeps 3 degrees
// of freedom per particle. `with_contact_model` turns the scene's ContactLaw into the concrete
// type once per pair loop (or measurement), so the loops are compiled for each model.
//
// Where a new sub-model goes (ARCHITECTURE.md): a struct in its own header beside these, with
// its force (templated on the lane type if it should run in the vector kernels), `history`,
// `name`, `from(law, k_ref)` and `info()` (its keys, text, oscillators, counterparts:
// submodel.hpp); with history, `update` on lanes and `lane_body = true` let the vector kernels
// run it (else the scalar loop does); then one entry in its slot's list below and one in registry.cpp. The scene
// loader, checks, physics record, `dem info`, curve preambles and VTK read the descriptions.
#pragma once
#include <array>
#include <type_traits>
#include <utility>

#include "dem/contact/geometry.hpp"
#include "dem/contact/normal_hertz.hpp"
#include "dem/contact/normal_linear.hpp"
#include "dem/contact/normal_luding.hpp"
#include "dem/contact/rolling.hpp"
#include "dem/contact/tangential.hpp"
#include "dem/contact/tangential_mindlin.hpp"
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
/// Whether a sub-model reads its pair beyond the geometry (`per_pair = true`: its body takes a
/// PairLanes<T>, the overlap, a12 and the reduced mass; Hertz's damping, Mindlin's stiffness).
template <class S, class = void> struct PerPairOf { static constexpr bool value = false; };
template <class S> struct PerPairOf<S, std::void_t<decltype(S::per_pair)>> { static constexpr bool value = S::per_pair; };

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
  /// A sub-model reads the pair beyond its geometry (PairLanes: the pair loops pass the masses).
  static constexpr bool per_pair_normal = PerPairOf<Normal>::value;
  static constexpr bool per_pair = per_pair_normal || PerPairOf<Tangential>::value;
  /// Runs on the loops of the models with history (pair_loop_history and the history kernels,
  /// which call `advance`): it has history, or a sub-model reads its pair (Hertz alone).
  static constexpr bool history_loop = history > 0 || per_pair;
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
  /// The normal force of one pair [N] (a12 = r_i r_j/(r_i + r_j) [m], h the contact's history,
  /// m_r the pair's reduced mass [kg], read by a per-pair normal law): `advance` updates a history
  /// normal's state (the pair loop), otherwise it is only read.
  __attribute__((always_inline)) double normal_force(const NormalGeometry<double>& g, double a12 = 0,
                                                     double* h = nullptr, bool advance = false,
                                                     double m_r = 0) const {
    if constexpr (normal_history > 0) {
      (void)m_r;
      const double f = advance ? normal.update(g.delta, a12, h) : normal.force(g.delta, a12, h);
      return f + damping.template bind<double>().force(g);
    } else if constexpr (per_pair_normal) {
      (void)h; (void)advance;
      return clamp(normal.force(g, PairLanes<double>{g.delta, a12, m_r}));
    } else {
      (void)a12; (void)h; (void)advance; (void)m_r;
      return bind<double>().normal_force(g);
    }
  }
  /// The no-tension clamp of a per-pair normal law's force (as Bound::normal_force's).
  template <class T> __attribute__((always_inline)) T clamp(T f) const {
    const T zero = lanes::splat<T>(0.0);
    return lanes::select(lanes::greater(f, zero) | lanes::mask_of<T>(attractive), f, zero);
  }
  /// One step of one pair of a model with history, in lanes of T (double: the reference loop):
  /// the separation `sep` of the radii ri, rj [m], the masses mi, mj [kg] (read only by a
  /// per-pair sub-model: others may pass zeros), the velocity difference v_j - v_i [m/s], the
  /// angular velocities [1/s], the rate [1/s] and dt [s]; h (CM::history entries) is advanced.
  /// The contact is assumed (the caller discards pairs out of contact). Every sub-model's body
  /// is called here in the fixed order normal -> damping -> tangential -> rolling.
  template <bool Sheared, class T>
  __attribute__((always_inline)) PairForces<T> advance(const Separation<T>& sep, T ri, T rj, T mi, T mj, T dvx, T dvy,
                                                       T dvz,
                                                       const V3<T>& wi, const V3<T>& wj, const RateLanes<T>& rate,
                                                       T dt, T* h) const {
    using lanes::splat;
    T vx, vy, vz;
    relative_velocity<Sheared>(sep, dvx, dvy, dvz, rate, vx, vy, vz);
    NormalGeometry<T> g = normal_geometry(sep, vx, vy, vz);
    PairLanes<T> pair{g.delta, splat<T>(0.0), splat<T>(0.0)};
    if constexpr (normal_history > 0 || per_pair) pair.a12 = ri * rj / (ri + rj);
    if constexpr (per_pair) pair.m_r = mi * mj / (mi + mj);
    else { (void)mi; (void)mj; }
    T fn;
    if constexpr (normal_history > 0)
      fn = normal.update(g.delta, pair.a12, h) + damping.template bind<T>().force(g);
    else if constexpr (per_pair_normal)
      fn = clamp(normal.force(g, pair));
    else
      fn = bind<T>().normal_force(g);
    V3<T> n{g.nx, g.ny, g.nz};
    PairForces<T> out{n * fn, {}, {}, splat<T>(0.0)};
    if constexpr (rotations) {
      const T half = splat<T>(0.5), zero = splat<T>(0.0);
      const T ai = ri - half * g.delta, aj = rj - half * g.delta;   // lever arms to the overlap's middle
      V3<T> v_contact = V3<T>{vx, vy, vz} - cross(wi * ai + wj * aj, n);
      T fn_plus = lanes::select(lanes::less(fn, zero), zero, fn);   // std::max(fn, 0.0)
      // Lanes out of contact (the kernels discard them) get an infinite Coulomb limit, so that
      // they never send their group down the sliders' rare sliding branch (one pair, T = double,
      // is always in contact here).
      if constexpr (lanes::is_lanes<T>)
        fn_plus = lanes::select(touching(sep), fn_plus, splat<T>(__builtin_inf()));
      V3<T> ft;
      if constexpr (PerPairOf<Tangential>::value)
        ft = tangential.update(n, v_contact, fn_plus, dt, h + tangential_offset, out.dissipated, pair);
      else
        ft = tangential.update(n, v_contact, fn_plus, dt, h + tangential_offset, out.dissipated);
      V3<T> nxf = cross(n, ft);
      out.fj = out.fj + ft;
      out.ti = nxf * (-ai);   // (a_i n) x (-f_j)
      out.tj = nxf * (-aj);   // (-a_j n) x f_j
      if constexpr (Rolling::history > 0) {   // a couple: torques only
        V3<T> tr =
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
    if constexpr (normal_history > 0 || per_pair_normal) return normal.energy(delta, a12, h);
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
using Model3 = ContactModel<Normal, typename Normal::Damping, Tangential, Rolling>;
using Frictionless = Model3<LinearSpring, NoTangential>;
using Frictional = Model3<LinearSpring, CundallStrack>;
using FrictionalRolling = Model3<LinearSpring, CundallStrack, RollingSpring>;

/// The sub-models the composition is generated from, slot by slot (the registry, registry.hpp,
/// lists their descriptions in the same order). A new sub-model is one entry here.
template <class... T> struct TypeList { static constexpr int size = sizeof...(T); };
using NormalModels = TypeList<LinearSpring, LudingNormal, HertzNormal>;
using TangentialModels = TypeList<NoTangential, CundallStrack, MindlinTangential, MindlinForceTangential>;
using RollingSlotModels = TypeList<NoRolling, RollingSpring, RollingTwisting>;

namespace detail {
template <class L, int I> struct At;
template <class H, class... T> struct At<TypeList<H, T...>, 0> { using type = H; };
template <class H, class... T, int I> struct At<TypeList<H, T...>, I> { using type = typename At<TypeList<T...>, I - 1>::type; };

/// Calls f(type tag of entry i of L) for a runtime index i.
template <class L, int I = 0, class F>
decltype(auto) visit_index(int i, F&& f) {
  using T = typename At<L, I>::type;
  if constexpr (I + 1 < L::size) {
    if (i != I) return visit_index<L, I + 1>(i, std::forward<F>(f));
  }
  return f(static_cast<T*>(nullptr));
}

/// A composition that can run: rolling and twisting need the tangential model's rotations.
template <class N, class T, class R>
inline constexpr bool valid_composition = T::rotations || R::history == 0;

template <class N, class T, class R>
ContactModel<N, typename N::Damping, T, R> compose_model(const ContactLaw& law) {
  const double k_ref = law.reference_stiffness();
  return {N::from(law, k_ref), N::Damping::from(law, k_ref), T::from(law, k_ref),
          N::history == 0 && law.allow_attractive(), R::from(law, k_ref)};
}
}  // namespace detail

/// Which entry of each slot list the law chose: normal and tangential by name, the rolling slot
/// by the first type that accepts the law. Throws std::logic_error for a name no list has.
std::array<int, 3> composition_index(const ContactLaw& law);

/// Calls f(model) with the concrete contact model of the scene's law, generated from the slot
/// lists above (every valid product). The composed model is taken from the law's cache when the
/// cache matches the law (contact::compose fills it; the loader calls it), else built here.
template <class F>
decltype(auto) with_contact_model(const ContactLaw& law, F&& f) {
  const ContactLaw::Cache& cache = law.cache();
  const bool cached = cache.model && cache.stamp == law.stamp();
  const std::array<int, 3> idx = cached ? cache.index : composition_index(law);
  return detail::visit_index<NormalModels>(idx[0], [&](auto* n) -> decltype(auto) {
    return detail::visit_index<TangentialModels>(idx[1], [&](auto* t) -> decltype(auto) {
      return detail::visit_index<RollingSlotModels>(idx[2], [&](auto* r) -> decltype(auto) {
        using N = std::remove_pointer_t<decltype(n)>;
        using T = std::remove_pointer_t<decltype(t)>;
        using R = std::remove_pointer_t<decltype(r)>;
        if constexpr (detail::valid_composition<N, T, R>) {
          using CM = ContactModel<N, typename N::Damping, T, R>;
          if (cached) return f(*static_cast<const CM*>(cache.model.get()));
          const CM cm = detail::compose_model<N, T, R>(law);
          return f(cm);
        } else {
          // composition_index never names it (rolling needs rotations): the frictionless model
          return f(detail::compose_model<LinearSpring, NoTangential, NoRolling>(law));
        }
      });
    });
  });
}

/// The frictionless linear spring-dashpot of a law (the vector kernels' model).
inline Frictionless frictionless(const ContactLaw& law) {
  return detail::compose_model<LinearSpring, NoTangential, NoRolling>(law);
}

/// Builds the law's composed model once and keeps it in the law's cache (call after the last
/// change of the law, before the pair loops run on several threads).
void compose(const ContactLaw& law);

/// Doubles of per-contact history of the scene's model (0: none), and which of them change
/// sign when the pair's particles swap roles (bit k: entry k).
int history_width(const ContactLaw& law);
unsigned history_odd_mask(const ContactLaw& law);

/// Gives the state what the model needs and nothing more: angular velocities and torques
/// (zero) for a frictional model, none for a frictionless one; a history of the model's width
/// (a history of another width is dropped).
void prepare_state(const ContactLaw& law, State& state);

}  // namespace dem::contact
