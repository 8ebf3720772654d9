// The plant of an offline closed loop: the task's vehicle model integrated with RK4 (core's,
// as the simulator's plants) at a finer step than the controller's Euler rollouts.
#pragma once

#include "mppi/rk4.hpp"

namespace mppi::offline {

template <class Vehicle>
void rk4_step(const typename Vehicle::Params& p, float* x, const float* u, float h) {
  rk4_model<Vehicle>(p, x, u, h);
  Vehicle::project(x);
}

}  // namespace mppi::offline
