// ControlLoop: what a new state teaches the loop, and forgetting it. The disturbance
// observer (the external acceleration and the mass) and the actuation delay estimate.
#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

// What the commands sent so far taught: the command history they are predicted through, the
// disturbance and mass estimates, the delay estimate's window (its delay stays).
void ControlLoop::forget_estimates() {
  history_.reset();
  if (observe_) {
    observer_.reset();
    observer_.apply(*c_);
  }
  delays_.reset();
}

// The commands sent so far were not flown (an autopilot flew its own take-off until the bridge
// engaged: it asks for this then). What the estimates learnt from them goes: the disturbance,
// the mass, the delay (back to the settings'), and the command history they predict through.
void ControlLoop::restart_estimates() {
  forget_estimates();
  s_.latency.actuation_delay_ns = configured_delay_ns_;
  counters_.actuation_delay_ns.store(configured_delay_ns_, std::memory_order_relaxed);
}

void ControlLoop::adapt_to(const float* x, std::int64_t t_state_ns) {
  // The disturbance observer compares the state with the last one predicted.
  if (observe_ && observer_.update(*c_, history_, x, t_state_ns)) observer_.apply(*c_);
  if (delays_.active() && delays_.update(*c_, history_, x, t_state_ns, s_.latency.actuation_delay_ns)) {
    s_.latency.actuation_delay_ns = delays_.delay_ns();
    counters_.actuation_delay_ns.store(s_.latency.actuation_delay_ns, std::memory_order_relaxed);
  }
}

}  // namespace mppi::daemon
