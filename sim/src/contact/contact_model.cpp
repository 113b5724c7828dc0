#include "dem/contact/contact_model.hpp"

#include "dem/core/state.hpp"

namespace dem::contact {

int history_width(const ContactLaw& law) {
  return with_contact_model(law, [](const auto& cm) { return std::decay_t<decltype(cm)>::history; });
}

unsigned history_odd_mask(const ContactLaw& law) {
  return with_contact_model(law, [](const auto& cm) { return std::decay_t<decltype(cm)>::odd_mask; });
}

void prepare_state(const ContactLaw& law, State& s) {
  const int n = s.count();
  if (law.frictional()) {
    if (static_cast<int>(s.angular_velocity.size()) != n) s.angular_velocity.assign(n, Vec3{0, 0, 0});
    if (static_cast<int>(s.torque.size()) != n) s.torque.assign(n, Vec3{0, 0, 0});
  } else {
    s.angular_velocity.clear();
    s.torque.clear();
  }
  const int w = history_width(law);
  if (s.history.width != w) {   // another model's history means nothing to this one
    s.history.width = w;
    s.history.values.clear();
    s.history.ids.clear();
  }
  s.history.odd = history_odd_mask(law);
}

}  // namespace dem::contact
