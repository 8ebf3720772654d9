// Disturbance observer: what the model does not know (a heavier vehicle, weaker motors,
// wind through drag) shows as a steady difference between the velocity the model predicts
// from the last state through the commands sent and the velocity then measured. Its
// low-passed integral is an external acceleration (world frame) that the model adds to
// every vehicle (Controller::set_external_accel), so the optimizer plans with it: integral
// action, without which a mismatched quadrotor sinks at a steady rate. Fixed buffers.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/state_predictor.hpp"

namespace mppi::daemon {

struct DisturbanceSettings {
  bool estimate = true;
  double time_constant_s = 0.5;            // of the low-pass on the residual acceleration
  float limit = 4.0f;                      // |estimate| per axis, m/s^2
  std::int64_t max_gap_ns = 100'000'000;   // states further apart restart the comparison
};

class DisturbanceObserver {
 public:
  // nx states per vehicle, velocity at [vel, vel + 3) of each (the quadrotor models: 3).
  DisturbanceObserver(const DisturbanceSettings& s, int vehicles, int vehicle_nx, int vel = 3);

  // A new state x (all vehicles), sampled at t_ns on the loop's timeline. Compares it with
  // the previous state predicted to t_ns through the commands in `h`, with the model as it
  // is now (its current estimate included): the residual moves the estimate. Returns true
  // when the estimate changed.
  bool update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns);
  void reset();
  const float* estimate() const { return est_; }
  std::int64_t updates() const { return updates_; }

 private:
  DisturbanceSettings s_;
  int vehicles_, vnx_, vel_;
  std::vector<float> prev_, pred_;
  std::int64_t t_prev_ = 0;
  bool have_prev_ = false;
  float est_[3] = {0.0f, 0.0f, 0.0f};
  std::int64_t updates_ = 0;
};

}  // namespace mppi::daemon
