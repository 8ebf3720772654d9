// What starts a cycle and what the loop's timeline is: the one place where real time and
// lock-step differ. ControlLoop holds one Pacing, chosen by LoopSettings::lockstep:
//
//   RealTimePacing  cycles on CLOCK_MONOTONIC (a fake in tests): the fixed-rate grid at
//                   rate_hz (trigger clock) or a state's arrival (trigger state); a cycle
//                   that ends past its deadline is a miss and the grid re-anchors.
//   LockStepPacing  one cycle per simulator tick, on the simulator's clock: the plant stands
//                   still while the controller computes, so there is no deadline, and a
//                   command acts exactly when the cycle expected it to (the run repeats).
//
// Loop thread only; allocates nothing.
#pragma once

#include <atomic>
#include <cstdint>

#include "mppi/daemon/loop_counters.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/deadline_monitor.hpp"
#include "mppi/rt/schedule.hpp"
#include "mppi/transport/inbox.hpp"

namespace mppi::daemon {

// When a cycle starts, its deadline, and "now" on the timeline the states are placed on.
struct CycleTimes {
  std::int64_t start_ns = 0;
  std::int64_t deadline_ns = INT64_MAX;
  std::int64_t now_state_ns = 0;
};

// How the state's sample time is placed on the loop's timeline (LatencySettings' fields).
struct StateTimeSettings {
  bool use_sample_time = true;
  std::int64_t future_tolerance_ns = 2'000'000;
};

class Pacing {
 public:
  // What wait() found: a cycle to run; stop; a lock-step tick answered already whose answer
  // is sent again (kResend) or dropped (kDrop).
  enum class Wait { kCycle, kStopped, kResend, kDrop };

  virtual ~Pacing() = default;
  // The first release at now_ns (real time); after it started() is true.
  virtual void start(std::int64_t now_ns) = 0;
  bool started() const { return started_; }
  // Sleeps until the next cycle's start (or stop) and says when it is.
  virtual Wait wait(const std::atomic<bool>& stop, CycleTimes* t) = 0;
  // When the cycle's compute time starts counting (the command's compute_us).
  virtual std::int64_t compute_start(std::int64_t start_ns) = 0;
  // The state's sample time on the loop's timeline; *future: further ahead than the tolerance.
  virtual std::int64_t state_time_ns(const transport::StateSample& x, bool* future) const = 0;
  // When a fresh command acts, for the command history: `expected` (the cycle's t_act) or
  // `measured` (from when it was sent).
  virtual std::int64_t command_acts_ns(std::int64_t expected_ns, std::int64_t measured_ns) const = 0;
  // The cycle ended at end_ns (clock time; compute counted from t0): its timing into the
  // monitor. Returns the heartbeat (the watchdog's time of the last completed cycle).
  virtual std::int64_t finish(std::int64_t start_ns, std::int64_t t0, std::int64_t end_ns) = 0;
  // Periods lost to overruns (real time).
  virtual std::int64_t skipped_periods() const { return 0; }

 protected:
  bool started_ = false;
};

// The loop's shared pieces the pacing reads and records into.
struct PacingContext {
  rt::Clock* clock;
  transport::Inbox* inbox;
  rt::DeadlineMonitor* monitor;
  LoopCounters* counters;
  StateTimeSettings state_time;
};

class RealTimePacing final : public Pacing {
 public:
  // state_trigger: cycles start on states (min_gap and grace in periods); else on the grid.
  RealTimePacing(const PacingContext& ctx, std::int64_t period_ns, bool state_trigger, double min_gap, double grace);

  void start(std::int64_t now_ns) override;
  Wait wait(const std::atomic<bool>& stop, CycleTimes* t) override;
  std::int64_t compute_start(std::int64_t start_ns) override { return start_ns; }
  std::int64_t state_time_ns(const transport::StateSample& x, bool* future) const override;
  std::int64_t command_acts_ns(std::int64_t, std::int64_t measured_ns) const override { return measured_ns; }
  std::int64_t finish(std::int64_t start_ns, std::int64_t t0, std::int64_t end_ns) override;
  std::int64_t skipped_periods() const override { return schedule_.skipped_periods(); }

 private:
  Wait wait_for_grid(const std::atomic<bool>& stop, CycleTimes* t);
  Wait wait_for_state(const std::atomic<bool>& stop, CycleTimes* t);
  void begin(std::int64_t now_ns, CycleTimes* t) const;

  PacingContext ctx_;
  rt::PeriodicSchedule schedule_;
  bool state_trigger_;
  double min_gap_, grace_;
  std::int64_t trigger_recv_ns_ = INT64_MIN;  // recv_ns of the state that started the last cycle
  bool grace_started_ = false;                // trigger state: the last cycle started without a state
};

class LockStepPacing final : public Pacing {
 public:
  // poll_ns: how often a wait for a tick checks stop.
  LockStepPacing(const PacingContext& ctx, std::int64_t poll_ns) : ctx_(ctx), poll_ns_(poll_ns) {}

  void start(std::int64_t) override { started_ = true; }
  Wait wait(const std::atomic<bool>& stop, CycleTimes* t) override;
  std::int64_t compute_start(std::int64_t) override { return ctx_.clock->now_ns(); }
  std::int64_t state_time_ns(const transport::StateSample& x, bool* future) const override;
  std::int64_t command_acts_ns(std::int64_t expected_ns, std::int64_t) const override { return expected_ns; }
  std::int64_t finish(std::int64_t start_ns, std::int64_t t0, std::int64_t end_ns) override;

 private:
  PacingContext ctx_;
  std::int64_t poll_ns_;
  std::int64_t last_tick_seq_ = -1;
};

}  // namespace mppi::daemon
