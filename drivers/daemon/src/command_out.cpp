#include "mppi/daemon/command_out.hpp"

#include <algorithm>

#include "mppi/rt/clock.hpp"

namespace mppi::daemon {

using transport::Mode;

void CommandOut::send(transport::Command* msg, Mode mode, const float* u, std::int64_t state_seq) {
  msg->utime = rt::wall_utime();
  msg->seq = seq_.fetch_add(1, std::memory_order_relaxed) + 1;
  msg->state_seq = state_seq;
  msg->mode = mode;
  msg->kind = kind_;
  msg->n = nu_;
  std::copy_n(u, nu_, msg->u);
  resend(*msg);
  switch (mode) {
    case Mode::kNormal: counters_->commands_normal.fetch_add(1, std::memory_order_relaxed); break;
    case Mode::kHoldPlan: counters_->commands_hold.fetch_add(1, std::memory_order_relaxed); break;
    case Mode::kFailsafe: counters_->commands_failsafe.fetch_add(1, std::memory_order_relaxed); break;
  }
}

void CommandOut::resend(const transport::Command& msg) {
  if (!tx_->publish_command(msg)) counters_->publish_failures.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace mppi::daemon
