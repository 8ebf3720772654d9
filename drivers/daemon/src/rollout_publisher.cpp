#include "mppi/daemon/rollout_publisher.hpp"

#include <algorithm>
#include <cmath>

#include "mppi/rt/clock.hpp"

namespace mppi::daemon {

RolloutPublisher::RolloutPublisher(const FanSettings& s, double rate_hz, int vehicles, int horizon) : s_(s) {
  if (s.hz <= 0.0 || s.top + s.random <= 0) return;
  every_ = std::max<std::int64_t>(1, std::llround(rate_hz / s.hz));
  fan_.reserve(s.top + s.random, vehicles, horizon);
}

void RolloutPublisher::after_cycle(Controller& c, transport::Transport& tx, std::int64_t cycle_index,
                                   std::int64_t state_seq, bool fresh) {
  if (!enabled()) return;
  if (asked_ && fresh && c.fan(s_.top, s_.random, &fan_)) {
    transport::RolloutsView v;
    v.utime = rt::wall_utime();
    v.seq = published_ + 1;
    v.state_seq = state_seq;
    v.cycle = fan_.cycle;
    v.total = fan_.total;
    v.vehicles = fan_.vehicles;
    v.steps = fan_.steps;
    v.dt = c.dt();
    v.lambda = fan_.lambda;
    v.count = fan_.count;
    v.top = fan_.top;
    v.index = fan_.index.data();
    v.cost = fan_.cost.data();
    v.weight = fan_.weight.data();
    v.crashed = fan_.crashed.data();
    v.xyz = fan_.xyz.data();
    if (tx.publish_rollouts(v)) ++published_;
  }
  // Keep the rollouts of the next cycle when it starts a new period of the fan's rate (and
  // until one is published: a cycle that held its plan has none to show).
  const bool published_this = asked_ && fresh;
  asked_ = (cycle_index + 1) % every_ == 0 || (asked_ && !published_this);
  if (asked_) c.keep_rollouts();
}

}  // namespace mppi::daemon
