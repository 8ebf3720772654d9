// ActTime: when this cycle's command acts, and the state predicted to then (latency
// compensation): the state's time on the loop's timeline, its age, the expected latency.
#include "mppi/daemon/act_time.hpp"

#include <algorithm>
#include <cstdint>

namespace mppi::daemon {

ActTime::ActTime(const LatencySettings& s, const Controller& c)
    : s_(s),
      latency_(s.estimator),
      history_(c.nu(), c.settings().u_init),
      x_pred_(static_cast<std::size_t>(c.nx())),
      x_lag_(static_cast<std::size_t>(c.nx())),
      actuation_delay_ns_(s.actuation_delay_ns) {
  published_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
}

CycleState ActTime::read(const transport::Inbox& in, const Pacing& pacing, std::int64_t now_ns,
                         std::int64_t last_seq_used) const {
  CycleState s;
  s.x = &in.state.front();
  s.have = in.state.writes() > 0;
  s.now_ns = now_ns;
  // Staleness from the state's sample time (on the pacing's timeline): a state older than
  // the timeouts, or stamped in the future, is not predicted from.
  s.t_state_ns = s.have ? pacing.state_time_ns(*s.x, &s.future) : 0;
  s.age_ns = s.have ? std::max<std::int64_t>(0, now_ns - s.t_state_ns) : INT64_MAX;
  s.seq = s.have ? s.x->seq : -1;
  s.new_sample = s.seq != last_seq_used;
  // Expected latency of this cycle (start -> command out), then when its command acts. In
  // whole microseconds: command_t's lead_us then gives t_act exactly (replay).
  const std::int64_t expected =
      (expected_override_ns_ >= 0 ? expected_override_ns_ : latency_.estimate_ns()) / rt::kNsPerUs * rt::kNsPerUs;
  s.t_act_ns = now_ns + expected + s_.transport_ns + actuation_delay_ns_;
  s.lead_ns = s_.compensate ? s.t_act_ns - s.t_state_ns : 0;
  return s;
}

const float* ActTime::predict(const Controller& c, const CycleState& s) {
  std::copy_n(s.x->x, x_pred_.size(), x_pred_.data());
  catch_up_estimate(c, s.t_state_ns);
  history_.predict(c, x_pred_.data(), s.t_state_ns, s.t_act_ns);
  return x_pred_.data();
}

// The autopilot's position and velocity describe the vehicle estimate_lag before the sample
// time (its EKF fuses GPS late), its attitude and rates the sample time: the state is rolled
// forward over the lag through the commands that acted then, and only its position and
// velocity are taken (the first six states of the quadrotor models; settings refuse the lag
// for others).
void ActTime::catch_up_estimate(const Controller& c, std::int64_t t_state_ns) {
  const std::int64_t lag = s_.estimate_lag_ns;
  if (lag <= 0 || x_pred_.size() < 6) return;
  std::copy(x_pred_.begin(), x_pred_.end(), x_lag_.begin());
  history_.predict(c, x_lag_.data(), t_state_ns - lag, t_state_ns);
  std::copy_n(x_lag_.begin(), 6, x_pred_.begin());
}

bool ActTime::learn(std::int64_t cycle_ns) {
  const bool taken = latency_.add(cycle_ns);
  published_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
  return taken;
}

}  // namespace mppi::daemon
