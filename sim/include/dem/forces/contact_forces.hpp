// Contact forces for the consumers outside the pair loop (stress, energy, the servo's response,
// VTK): the same model body, evaluated at the state's current velocities, reading the history
// the pair loop stored and never changing it (LAMMPS PR #1631: a diagnostic that mutates the
// history changes trajectories).
#pragma once
#include <type_traits>

#include "dem/contact/contact_model.hpp"
#include "dem/forces/neighbor_list.hpp"

namespace dem::contact {

/// One contact as a consumer sees it.
struct ContactForce {
  long p;          ///< index in the list (and in State::history)
  int i, j;        ///< particles (j: the listed image)
  Vec3 d;          ///< branch vector i -> j [m]
  double r;        ///< |d| [m]
  double delta;    ///< overlap [m]
  Vec3 n;          ///< unit normal d / r
  double fn;       ///< normal force on j along n [N] (repulsion positive)
  Vec3 ft;         ///< tangential force on j [N] (zero without friction)
  bool sliding;    ///< at the Coulomb limit at the last step (friction)
  double energy;   ///< elastic energy of the contact [J] (normal spring + tangential and rolling springs)
  double spring_energy;   ///< the tangential and rolling springs' part of it [J]
  double fn_elastic;      ///< the normal sub-model's elastic force alone (no dashpot) [N]
  double kn;              ///< the normal sub-model's tangent stiffness at this contact [N/m] (the servo's)
  double kt;              ///< the tangential spring's stiffness while sticking [N/m] (0: none, or sliding)
  Vec3 spring_tangential{0, 0, 0};   ///< the tangential spring xi [m] (zero without friction)
  Vec3 spring_rolling{0, 0, 0};      ///< the rolling spring xi_r [m] (zero without rolling resistance)
  double spring_twisting = 0;        ///< the twisting spring xi_o [m] (zero without twisting resistance)
};

/// Calls visit(const ContactForce&) for every listed pair in contact, in list order. The
/// normal force is the model's at the current velocities (fluctuation + rate L applied to the
/// branch vector); the tangential force is that of the stored spring (plus its dashpot at the
/// current velocities), capped at the Coulomb limit as in the pair loop.
template <class Visit>
void for_each_contact_force(const Model& model, const State& s, const NeighborList& list, const VelGrad& rate,
                            Visit&& visit) {
  with_contact_model(model.contact, [&](const auto& cm) {
    using CM = std::decay_t<decltype(cm)>;
    const bool with_history = CM::history > 0 && s.history.values.size() == list.partner.size() * CM::history;
    for_each_listed_contact(s, list, [&](long p, int i, int j, const Vec3& d, double r, double delta) {
      ContactForce c{p, i, j, d, r, delta, d * (1.0 / r), 0.0, Vec3{0, 0, 0}, false, 0.0, 0.0, 0.0, 0.0, 0.0};
      const Vec3 v_rel = (s.velocity[j] - s.velocity[i]) + rate.apply(d);
      const NormalGeometry<double> g{r, c.n.x, c.n.y, c.n.z, delta, -dot(v_rel, c.n), v_rel.x, v_rel.y, v_rel.z};
      if constexpr (CM::history_loop) {
        static double kZero[CM::history + 1] = {};
        const double a12 = s.radius[i] * s.radius[j] / (s.radius[i] + s.radius[j]);
        const double m_r = CM::per_pair ? s.mass[i] * s.mass[j] / (s.mass[i] + s.mass[j]) : 0.0;
        double* h = with_history ? const_cast<double*>(s.history.values.data()) + p * CM::history : kZero;
        c.fn = cm.normal_force(g, a12, h, false, m_r);   // read only (advance = false)
        if constexpr (CM::normal_history > 0) c.fn_elastic = cm.normal.force(delta, a12, h);
        else if constexpr (CM::per_pair_normal) c.fn_elastic = cm.normal.elastic(delta, a12);
        else c.fn_elastic = cm.normal.template bind<double>().force(g);
        c.kn = cm.normal.tangent_stiffness(delta, a12, h);
        if constexpr (CM::rotations) {
          const double ai = s.radius[i] - 0.5 * delta, aj = s.radius[j] - 0.5 * delta;
          const Vec3 wi = s.rotations() ? s.angular_velocity[i] : Vec3{0, 0, 0};
          const Vec3 wj = s.rotations() ? s.angular_velocity[j] : Vec3{0, 0, 0};
          const Vec3 v_contact = v_rel - cross(wi * ai + wj * aj, c.n);
          const double* ht = h + CM::tangential_offset;
          const TangentialInput in{c.n, v_contact, std::max(c.fn, 0.0), delta, a12};
          c.ft = cm.tangential.force(in, ht);
          c.sliding = ht[3] != 0.0;
          if constexpr (PerPairOf<typename std::decay_t<decltype(cm.tangential)>>::value) {
            if (!c.sliding) c.kt = cm.tangential.stiffness(in);
          } else {
            if (!c.sliding) c.kt = cm.tangential.stiffness();
          }
          c.spring_tangential = Vec3{ht[0], ht[1], ht[2]};
          using Rolling = typename CM::RollingModel;
          const double* hr = h + CM::rolling_offset;
          if constexpr (Rolling::history >= 3) c.spring_rolling = Vec3{hr[0], hr[1], hr[2]};
          if constexpr (Rolling::history == 4) c.spring_twisting = hr[3];
          if constexpr (Rolling::history == 1) c.spring_twisting = hr[0];
        }
        c.energy = cm.energy(delta, a12, h);
        c.spring_energy = c.energy - cm.normal_energy(delta, a12, h);
      } else {
        c.fn = cm.normal_force(g);
        c.fn_elastic = cm.normal.template bind<double>().force(g);
        c.kn = cm.normal.tangent_stiffness(delta, 0.0, nullptr);
        c.energy = cm.energy(delta, 0.0, nullptr);
      }
      visit(static_cast<const ContactForce&>(c));
    });
  });
}

}  // namespace dem::contact
