// Latency compensation: each fresh cycle optimises from the state predicted to the time its
// command will act, t_act = cycle start + expected latency + transport + actuation delay,
// through the commands already sent (they act meanwhile). ActTime owns what that takes: the
// latency estimator (cycle start -> command out), the command history, the actuation delay
// flown with (the settings', or the estimate's: Estimators), the predicted state and the
// estimate-lag catch-up. Loop thread only (the published latency estimate is an atomic);
// allocates nothing after construction.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/delay_estimator.hpp"
#include "mppi/daemon/pacing.hpp"
#include "mppi/daemon/state_predictor.hpp"
#include "mppi/rt/latency_estimator.hpp"
#include "mppi/transport/inbox.hpp"

namespace mppi::daemon {

struct LatencySettings {
  bool compensate = true;
  rt::LatencyEstimatorSettings estimator;   // expected cycle start -> command sent
  std::int64_t transport_ns = 200'000;      // command sent -> the plant has it
  std::int64_t actuation_delay_ns = 0;      // the plant has it -> it acts (ESCs, autopilot)
  // How far the autopilot's position and velocity estimate trails the vehicle (its EKF's
  // delay; the vehicle file's estimate_lag): they are predicted from that much before the
  // sample time, the attitude and rates (the gyro's, current) from the sample time. Quadrotor
  // states only (position, velocity first).
  std::int64_t estimate_lag_ns = 0;
  // The state's age from its sample_utime, stamped on this host's wall clock (the
  // simulator and the MAVLink bridge do); false: from its receipt (a publisher whose clock
  // is not ours; the transport delay is then not seen).
  bool use_sample_time = true;
  std::int64_t future_tolerance_ns = 2'000'000;  // a sample time further ahead is refused
  // The actuation delay estimated in flight (delay_estimator.hpp): replaces actuation_delay_ns.
  DelayEstimateSettings delay_estimate;
};

// What a cycle knows of the newest state, on the loop's timeline (now_state_ns's).
struct CycleState {
  const transport::StateSample* x = nullptr;
  bool have = false;           // a state has arrived
  bool future = false;         // stamped further ahead than the tolerance
  bool new_sample = false;     // not the one the last fresh cycle optimised from
  std::int64_t seq = -1;
  std::int64_t now_ns = 0;      // the cycle's start
  std::int64_t t_state_ns = 0;  // the sample time
  std::int64_t age_ns = 0;
  std::int64_t t_act_ns = 0;    // when this cycle's command acts
  std::int64_t lead_ns = 0;     // t_act - sample time, with latency compensation; else 0
};

class ActTime {
 public:
  ActTime(const LatencySettings& s, const Controller& c);

  // The newest state of `in` on the pacing's timeline at now_ns, and when this cycle's
  // command acts; `last_seq_used`: the state the last fresh cycle optimised from.
  CycleState read(const transport::Inbox& in, const Pacing& pacing, std::int64_t now_ns,
                  std::int64_t last_seq_used) const;
  // The state of `s` as it will be at s.t_act_ns, through the commands already sent (its
  // position and velocity first caught up over the estimate lag).
  const float* predict(const Controller& c, const CycleState& s);

  // When a command sent at sent_ns acts (transport, then the actuation delay).
  std::int64_t acts_after_sent(std::int64_t sent_ns) const {
    return sent_ns + s_.transport_ns + actuation_delay_ns_;
  }
  // What went out: u acts from acts_ns on (the command history).
  void record(std::int64_t acts_ns, const float* u) { history_.add(acts_ns, u); }
  void remember_sent(std::int64_t sent_ns, const float* u) { record(acts_after_sent(sent_ns), u); }
  // A cycle took cycle_ns from its start to its command out. False: the estimator refused it.
  bool learn(std::int64_t cycle_ns);
  // The commands sent so far were not flown (failsafe, restart): u_init acts from now on.
  void forget_commands() { history_.reset(); }

  bool compensate() const { return s_.compensate; }
  const CommandHistory& history() const { return history_; }
  std::int64_t actuation_delay_ns() const { return actuation_delay_ns_; }
  void set_actuation_delay_ns(std::int64_t ns) { actuation_delay_ns_ = ns; }
  std::int64_t configured_actuation_delay_ns() const { return s_.actuation_delay_ns; }
  std::int64_t estimate_ns() const { return latency_.estimate_ns(); }
  // The estimate for other threads.
  std::int64_t published_estimate_ns() const { return published_ns_.load(std::memory_order_relaxed); }
  // Replay: the next cycles' expected latency (ns) instead of the estimator's; < 0: the estimator's.
  void set_expected_latency(std::int64_t ns) { expected_override_ns_ = ns; }

 private:
  void catch_up_estimate(const Controller& c, std::int64_t t_state_ns);

  LatencySettings s_;
  rt::LatencyEstimator latency_;
  CommandHistory history_;
  std::vector<float> x_pred_;
  std::vector<float> x_lag_;  // the estimate's position and velocity caught up (estimate_lag_ns)
  std::int64_t actuation_delay_ns_;
  std::int64_t expected_override_ns_ = -1;
  std::atomic<std::int64_t> published_ns_{0};
};

}  // namespace mppi::daemon
