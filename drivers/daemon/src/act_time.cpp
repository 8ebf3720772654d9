// ControlLoop: when this cycle's command acts, and the state predicted to then (latency
// compensation): the state's time on the loop's timeline, its age, the expected latency.
#include <algorithm>
#include <cstdint>

#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

ControlLoop::CycleState ControlLoop::read_state(std::int64_t now_state_ns) const {
  CycleState s;
  s.x = &in_->state.front();
  s.have = in_->state.writes() > 0;
  s.now_ns = now_state_ns;
  // Staleness from the state's sample time (on the pacing's timeline): a state older than the
  // timeouts, or stamped in the future, is not predicted from.
  s.t_state_ns = s.have ? pacing_->state_time_ns(*s.x, &s.future) : 0;
  s.age_ns = s.have ? std::max<std::int64_t>(0, now_state_ns - s.t_state_ns) : INT64_MAX;
  s.seq = s.have ? s.x->seq : -1;
  s.new_sample = s.seq != last_state_seq_used_;
  // Expected latency of this cycle (start -> command out), then when its command acts. In
  // whole microseconds: command_t's lead_us then gives t_act exactly (replay).
  const LatencySettings& ls = s_.latency;
  const std::int64_t expected =
      (expected_override_ns_ >= 0 ? expected_override_ns_ : latency_.estimate_ns()) / rt::kNsPerUs * rt::kNsPerUs;
  s.t_act_ns = now_state_ns + expected + ls.transport_ns + ls.actuation_delay_ns;
  s.lead_ns = ls.compensate ? s.t_act_ns - s.t_state_ns : 0;
  return s;
}

// The state to optimise from. A new sample first teaches the loop what the last prediction
// missed (adapt_to). Latency compensation: the state as it will be when this command acts,
// predicted through the commands already sent.
const float* ControlLoop::predict_to_act(const CycleState& s) {
  if (s.new_sample) adapt_to(s.x->x, s.t_state_ns);
  if (!s_.latency.compensate) {
    plan_.detach();
    return s.x->x;
  }
  counters_.plan_skips.fetch_add(plan_.align(s.t_act_ns), std::memory_order_relaxed);
  std::copy_n(s.x->x, x_pred_.size(), x_pred_.data());
  catch_up_estimate(s.t_state_ns);
  history_.predict(*c_, x_pred_.data(), s.t_state_ns, s.t_act_ns);
  monitor_.record_lead(s.lead_ns);
  // A moving reference is compared with the predicted state at the predicted state's time:
  // the reference at t_act, not at the sample time (else a lag of `lead` at its speed).
  if (have_reference_ && inputs_.reference.kind != Reference::kHold) {
    inputs_.reference_time = static_cast<float>(static_cast<double>(s.x->sample_utime - reference_t0_utime_) * 1e-6 +
                                                static_cast<double>(s.lead_ns) * 1e-9);
    c_->set_inputs(inputs_);
  }
  return x_pred_.data();
}

// The autopilot's position and velocity describe the vehicle estimate_lag before the sample
// time (its EKF fuses GPS late), its attitude and rates the sample time: the state is rolled
// forward over the lag through the commands that acted then, and only its position and
// velocity are taken (the first six states of the quadrotor models; settings refuse the lag
// for others).
void ControlLoop::catch_up_estimate(std::int64_t t_state_ns) {
  const std::int64_t lag = s_.latency.estimate_lag_ns;
  if (lag <= 0 || x_pred_.size() < 6) return;
  std::copy(x_pred_.begin(), x_pred_.end(), x_lag_.begin());
  history_.predict(*c_, x_lag_.data(), t_state_ns - lag, t_state_ns);
  std::copy_n(x_lag_.begin(), 6, x_pred_.begin());
}

}  // namespace mppi::daemon
