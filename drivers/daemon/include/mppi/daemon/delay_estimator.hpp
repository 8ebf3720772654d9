// Actuation delay estimate: the delay between a command reaching the vehicle and its response
// (ESCs, an autopilot's rate loop) that the latency compensation predicts over
// (daemon.latency.actuation_delay_ms). A vehicle whose delay the controller is not told flies
// on a prediction that is that much early. Every `window` states the last window is predicted
// state by state through the commands sent, each taken to act D later than recorded, for D on
// a grid; the D whose predictions of the actuator states (the motors' speeds, or the rate
// loop's body rates: they answer the command first) err least is the delay. It replaces the
// current one when it errs markedly less (min_gain), and the window starts again: the history
// then stamps commands with it. Fixed buffers: nothing allocates after construction.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/state_predictor.hpp"

namespace mppi::daemon {

struct DelayEstimateSettings {
  bool estimate = false;
  double max_ms = 40.0;     // the grid of candidates: 0 .. max_ms in step_ms
  double step_ms = 2.0;
  int window = 25;          // state pairs scored per estimate (0.5 s at 50 Hz)
  double min_gain = 0.1;    // the best candidate must err this fraction less than the current
  std::int64_t max_gap_ns = 100'000'000;  // states further apart are not a pair
};

class DelayEstimator {
 public:
  // nx states (all vehicles); `actuator_states`: the indices compared (empty: off).
  DelayEstimator(const DelayEstimateSettings& s, int nx, std::vector<int> actuator_states);

  bool active() const { return s_.estimate && !idx_.empty(); }
  // A new state x at t_ns; `current_ns`: the actuation delay the history's commands were
  // stamped with. True when the estimate changed (then delay_ns() is the one to fly).
  bool update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns,
              std::int64_t current_ns);
  std::int64_t delay_ns() const { return delay_ns_; }
  std::int64_t changes() const { return changes_; }
  void reset() { count_ = 0; }

 private:
  double error(const Controller& c, const CommandHistory& h, std::int64_t later_ns);

  DelayEstimateSettings s_;
  int nx_;
  std::vector<int> idx_;
  std::vector<float> xs_, pred_;   // (window + 1) x nx states, oldest first; one prediction
  std::vector<std::int64_t> ts_;
  int count_ = 0;
  std::int64_t delay_ns_ = 0, changes_ = 0;
};

}  // namespace mppi::daemon
