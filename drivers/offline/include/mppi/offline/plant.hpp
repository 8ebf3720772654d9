// The plant of an offline closed loop: the task's vehicle model integrated with RK4 at a
// finer step than the controller's Euler rollouts, with its own parameters.
#pragma once

namespace mppi::offline {

template <class Vehicle>
void rk4_step(const typename Vehicle::Params& p, float* x, const float* u, float h) {
  constexpr int n = Vehicle::kNx;
  float k1[n], k2[n], k3[n], k4[n], tmp[n];
  Vehicle::derivative(p, x, u, k1);
  for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5f * h * k1[i];
  Vehicle::derivative(p, tmp, u, k2);
  for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5f * h * k2[i];
  Vehicle::derivative(p, tmp, u, k3);
  for (int i = 0; i < n; ++i) tmp[i] = x[i] + h * k3[i];
  Vehicle::derivative(p, tmp, u, k4);
  for (int i = 0; i < n; ++i) x[i] += h / 6.0f * (k1[i] + 2.0f * k2[i] + 2.0f * k3[i] + k4[i]);
  Vehicle::project(x);
}

}  // namespace mppi::offline
