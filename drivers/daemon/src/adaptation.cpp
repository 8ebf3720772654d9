// Estimators: what a new state teaches the loop, and forgetting it. The disturbance
// observer (the external acceleration and the mass) and the actuation delay estimate.
#include "mppi/daemon/adaptation.hpp"

namespace mppi::daemon {

Estimators::Estimators(const DisturbanceSettings& disturbance, const DelayEstimateSettings& delay, Controller& c,
                       std::vector<int> actuator_states)
    : observer_(disturbance, c.vehicles(), c.nx() / c.vehicles(), c.mass()),
      delays_(delay, c.nx(), std::move(actuator_states)) {
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  observe_ = disturbance.estimate && c.set_external_accel(zero);
}

bool Estimators::learn(Controller& c, const CommandHistory& h, const float* x, std::int64_t t_state_ns,
                       std::int64_t delay_ns) {
  // The disturbance observer compares the state with the last one predicted.
  if (observe_ && observer_.update(c, h, x, t_state_ns)) observer_.apply(c);
  return delays_.active() && delays_.update(c, h, x, t_state_ns, delay_ns);
}

void Estimators::forget(Controller& c) {
  if (observe_) {
    observer_.reset();
    observer_.apply(c);
  }
  delays_.reset();
}

void Estimators::set_nominal_mass(Controller& c, float kg) {
  if (!observer_.estimates_mass()) return;
  observer_.set_nominal_mass(kg);
  observer_.apply(c);
}

}  // namespace mppi::daemon
