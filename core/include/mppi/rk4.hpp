// Classic fourth-order Runge-Kutta, written once and generic over the model: the plants
// (the simulator's and the offline closed loop's) reuse the controller's HD derivative()
// but integrate it far more finely and accurately than the controller's Euler rollouts, so
// model mismatch comes from parameters, not from the integrator.
#pragma once

#include <cmath>

namespace mppi {

// One RK4 step of length h for x' = f(x), f called as f(const float* x, float* dx).
template <int N, class F>
void rk4_step(F&& f, float* x, float h) {
  float k1[N], k2[N], k3[N], k4[N], tmp[N];
  f(x, k1);
  for (int i = 0; i < N; ++i) tmp[i] = x[i] + 0.5f * h * k1[i];
  f(tmp, k2);
  for (int i = 0; i < N; ++i) tmp[i] = x[i] + 0.5f * h * k2[i];
  f(tmp, k3);
  for (int i = 0; i < N; ++i) tmp[i] = x[i] + h * k3[i];
  f(tmp, k4);
  for (int i = 0; i < N; ++i) x[i] += h / 6.0f * (k1[i] + 2.0f * k2[i] + 2.0f * k3[i] + k4[i]);
}

// RK4 on a core model's derivative with the control held over the step, plus an external
// acceleration on the velocity states [vel, vel + 3) (wind); vel < 0 for none.
template <class Model>
void rk4_model(const typename Model::Params& p, float* x, const float* u, float h,
               const float* accel = nullptr, int vel = -1) {
  rk4_step<Model::kNx>(
      [&](const float* s, float* ds) {
        Model::derivative(p, s, u, ds);
        if (accel != nullptr && vel >= 0)
          for (int i = 0; i < 3; ++i) ds[vel + i] += accel[i];
      },
      x, h);
}

// Every vehicle of a task advanced by `seconds` under the control u held constant, with RK4
// in steps of at most max_step and each vehicle put back on its manifold after each step:
// what the daemon uses to predict a measured state to the time its command will act.
template <class TaskT>
void rk4_task(const typename TaskT::Params& p, float* x, const float* u, float seconds, float max_step = 0.002f) {
  if (!(seconds > 0.0f) || !(max_step > 0.0f)) return;
  using V = typename TaskT::Vehicle;
  const int n = static_cast<int>(std::ceil(seconds / max_step));
  const float h = seconds / static_cast<float>(n);
  for (int j = 0; j < TaskT::kVehicles; ++j) {
    float* xj = x + j * TaskT::kVehicleNx;
    for (int s = 0; s < n; ++s) {
      rk4_model<V>(p.vehicle, xj, u + j * TaskT::kVehicleNu, h);
      V::project(xj);
    }
  }
}

}  // namespace mppi
