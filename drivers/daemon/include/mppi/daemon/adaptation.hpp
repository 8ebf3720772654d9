// What a new state teaches the loop, in one place: the disturbance observer (the external
// acceleration and, when on, the mass the model flies with) and the actuation delay estimate.
// Each compares the state with its prediction through the commands sent (ActTime's command
// history); forgetting them is one call (failsafe, daemon.restart_estimates). Loop thread
// only; allocates nothing after construction.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/delay_estimator.hpp"
#include "mppi/daemon/disturbance_observer.hpp"
#include "mppi/daemon/state_predictor.hpp"

namespace mppi::daemon {

class Estimators {
 public:
  // actuator_states: the states the delay estimate compares (empty: no delay estimate). Only
  // models with an external acceleration (the quadrotors) take the observer's estimate.
  Estimators(const DisturbanceSettings& disturbance, const DelayEstimateSettings& delay, Controller& c,
             std::vector<int> actuator_states);

  // A new state x sampled at t_state_ns; `delay_ns`: the actuation delay the history's
  // commands were stamped with. The disturbance (and mass) estimates go into the model; true
  // when the delay estimate changed (then delay_ns() is the one to fly).
  bool learn(Controller& c, const CommandHistory& h, const float* x, std::int64_t t_state_ns, std::int64_t delay_ns);
  std::int64_t delay_ns() const { return delays_.delay_ns(); }
  // What the commands sent so far taught: the disturbance and mass estimates (the model
  // back to none), the delay estimate's window (its delay stays).
  void forget(Controller& c);
  // A model.mass update: the mass estimate's new nominal (else the next estimate overwrites it).
  void set_nominal_mass(Controller& c, float kg);
  const float* disturbance() const { return observer_.estimate(); }

 private:
  DisturbanceObserver observer_;
  DelayEstimator delays_;
  bool observe_ = false;  // the model takes an external acceleration and estimation is on
};

}  // namespace mppi::daemon
