// Publishes, at a low rate, a display sample of the optimizer's rollouts (core's RolloutFan:
// the lowest-cost ones and a random subsample, with weights and positions) as rollouts_t
// for tools/view. Off by default (daemon.rollouts.hz: 0). The loop calls after_cycle() once,
// at the end of every cycle: it publishes the fan of a cycle that kept its rollouts and
// flew the optimizer's command, then asks the controller to keep the next cycle's when one
// is due. The cycle itself pays only the copies Controller::keep_rollouts makes; the fan is
// rebuilt after the command is out. Buffers are sized here, once: nothing allocates later.
#pragma once

#include <cstdint>

#include "mppi/controller.hpp"
#include "mppi/rollout_fan.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::daemon {

struct FanSettings {
  static constexpr int kMaxRollouts = 256;
  double hz = 0.0;   // fans a second; 0: off
  int top = 16;      // the lowest-cost rollouts
  int random = 16;   // ... and this many others, one from each stratum of the sample index
};

class RolloutPublisher {
 public:
  // For a controller of `vehicles` vehicles and `horizon` steps, in a loop at rate_hz.
  RolloutPublisher(const FanSettings& s, double rate_hz, int vehicles, int horizon);

  bool enabled() const { return every_ > 0; }
  // End of a cycle (cycle_index counts from 0). fresh: the command that went out was this
  // cycle's optimizer update.
  void after_cycle(Controller& c, transport::Transport& tx, std::int64_t cycle_index, std::int64_t state_seq,
                   bool fresh);
  std::int64_t published() const { return published_; }

 private:
  FanSettings s_;
  std::int64_t every_ = 0;  // cycles between fans
  bool asked_ = false;      // the controller was asked to keep this cycle's rollouts
  RolloutFan fan_;
  std::int64_t published_ = 0;
};

}  // namespace mppi::daemon
