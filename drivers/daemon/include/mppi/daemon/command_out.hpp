// The way out for commands, shared by the loop thread and the deadline guard's thread: the
// command gate (finite, inside the limits), one sequence counter for both, the transport, and
// the counts by mode. Each thread fills its own message buffer.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "mppi/daemon/loop_counters.hpp"
#include "mppi/rt/command_gate.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::daemon {

class CommandOut {
 public:
  CommandOut(transport::Transport* tx, LoopCounters* counters, std::vector<float> u_min, std::vector<float> u_max,
             int nu, std::int8_t kind)
      : tx_(tx), counters_(counters), gate_(std::move(u_min), std::move(u_max)), nu_(nu), kind_(kind) {}

  bool passes(const float* u) const { return gate_.pass(u, nu_); }
  // Fills `msg`, sends it and counts it by mode. The caller has passed u through the gate.
  void send(transport::Command* msg, transport::Mode mode, const float* u, std::int64_t state_seq);
  // `msg` again as it was (a lock-step answer lost on the way).
  void resend(const transport::Command& msg);
  int nu() const { return nu_; }
  std::int8_t kind() const { return kind_; }

 private:
  transport::Transport* tx_;
  LoopCounters* counters_;
  rt::CommandGate gate_;
  int nu_;
  std::int8_t kind_;
  std::atomic<std::int64_t> seq_{0};
};

}  // namespace mppi::daemon
