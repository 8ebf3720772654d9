// ControlLoop: what starts a cycle. Real time on the clock's grid (trigger clock) or on a
// state's arrival (trigger state), or lock-step on the simulator's ticks.
#include <algorithm>
#include <cstdint>

#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

void ControlLoop::start() {
  prepare();
  schedule_.start(clock_->now_ns());
  heartbeat_ns_.store(clock_->now_ns(), std::memory_order_relaxed);
  started_ = true;
}

void ControlLoop::run(const std::atomic<bool>& stop, std::int64_t max_cycles) {
  if (!started_) start();
  for (std::int64_t n = 0; (max_cycles < 0 || n < max_cycles) && !stop.load(std::memory_order_relaxed);) {
    const bool ran = s_.lockstep ? step_lockstep(stop) : step_realtime(stop);
    if (ran) ++n;
  }
}

bool ControlLoop::step_realtime(const std::atomic<bool>& stop) {
  if (!started_) start();
  if (s_.trigger == Trigger::kState) return step_state_triggered(stop);
  // Absolute-time sleep; an early return (a signal) re-checks stop and sleeps again.
  std::int64_t now = clock_->now_ns();
  while (now < schedule_.next_release_ns()) {
    if (stop.load(std::memory_order_relaxed)) return false;
    clock_->sleep_until(schedule_.next_release_ns());
    now = clock_->now_ns();
  }
  if (stop.load(std::memory_order_relaxed)) return false;
  schedule_.begin(now);
  cycle(now, schedule_.deadline_ns(), now, false);
  return true;
}

bool ControlLoop::step_state_triggered(const std::atomic<bool>& stop) {
  const std::int64_t period = schedule_.period_ns(), next = schedule_.next_release_ns();
  const auto part = [&](double f) { return static_cast<std::int64_t>(f * static_cast<double>(period)); };
  // next is a period after the last cycle's start (or the end of a late cycle, or the start).
  // A new state starts a cycle at once if it came min_gap periods after the last start, or
  // after a cycle the grace started (states slower than the rate: each one is awaited); one
  // that came sooner starts it min_gap after the last start (the rate's bound, never the
  // grace: the state waits no longer than the bound needs). With none, the grace runs out:
  // after a state's cycle `grace` past the grid time, after the grace's own cycle on the grid
  // (no state: the stale path at rate_hz).
  const std::int64_t earliest = grace_started_ ? INT64_MIN : next - period + part(s_.state_trigger_min_gap);
  const std::int64_t latest = grace_started_ ? next : next + part(s_.state_trigger_grace);
  std::int64_t now = clock_->now_ns();
  for (;;) {
    if (stop.load(std::memory_order_relaxed)) return false;
    const std::int64_t got = in_->last_state_recv_ns();
    const bool fresh = got > trigger_recv_ns_;
    if (fresh && (got >= earliest || now >= earliest)) {
      counters_.state_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;
      grace_started_ = false;
      break;
    }
    if (now >= latest) {
      counters_.clock_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;  // an older state never starts a cycle later
      grace_started_ = true;
      break;
    }
    clock_->sleep_until_or(in_->state_wake, fresh ? earliest : latest);  // each state (and a signal) re-checks
    now = clock_->now_ns();
  }
  if (!grace_started_) monitor_.record_wake(std::max<std::int64_t>(0, now - trigger_recv_ns_));
  schedule_.begin_at(now);
  cycle(now, schedule_.deadline_ns(), now, false);
  return true;
}

bool ControlLoop::step_lockstep(const std::atomic<bool>& stop) {
  transport::ClockTick tick;
  while (!in_->ticks.pop(&tick)) {
    if (stop.load(std::memory_order_relaxed)) return false;
    in_->wake.wait_for(s_.lockstep_poll_ns);
  }
  // A tick the simulator repeated (it republishes a state and its tick when no answer
  // came in time) was answered already: a second cycle on it would run the optimizer one
  // cycle ahead of the simulator and the run would no longer repeat. The answer is sent
  // again instead, in case it was the one lost. (A sequence far behind the last one is a
  // new simulator run, and is followed.)
  if (last_tick_seq_ >= 0 && tick.seq <= last_tick_seq_ && tick.seq > last_tick_seq_ - 100) {
    counters_.repeated_ticks.fetch_add(1, std::memory_order_relaxed);
    if (tick.seq == last_tick_seq_ && cmd_.seq > 0) out_.resend(cmd_);
    return false;
  }
  last_tick_seq_ = tick.seq;
  const std::int64_t sim_ns = tick.sim_utime * rt::kNsPerUs;
  cycle(sim_ns, INT64_MAX, sim_ns, true);
  return true;
}

}  // namespace mppi::daemon
