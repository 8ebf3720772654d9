// What starts a cycle: real time on the clock's grid (trigger clock) or on a state's arrival
// (trigger state), or lock-step on the simulator's ticks; and the timeline each runs on.
#include "mppi/daemon/pacing.hpp"

#include <algorithm>
#include <cstdint>

namespace mppi::daemon {

// ---- real time ------------------------------------------------------------------------

RealTimePacing::RealTimePacing(const PacingContext& ctx, std::int64_t period_ns, bool state_trigger, double min_gap,
                               double grace)
    : ctx_(ctx), schedule_(period_ns), state_trigger_(state_trigger), min_gap_(min_gap), grace_(grace) {}

void RealTimePacing::start(std::int64_t now_ns) {
  schedule_.start(now_ns);
  started_ = true;
}

Pacing::Wait RealTimePacing::wait(const std::atomic<bool>& stop, CycleTimes* t) {
  return state_trigger_ ? wait_for_state(stop, t) : wait_for_grid(stop, t);
}

void RealTimePacing::begin(std::int64_t now_ns, CycleTimes* t) const {
  t->start_ns = now_ns;
  t->deadline_ns = schedule_.deadline_ns();
  t->now_state_ns = now_ns;
}

Pacing::Wait RealTimePacing::wait_for_grid(const std::atomic<bool>& stop, CycleTimes* t) {
  // Absolute-time sleep; an early return (a signal) re-checks stop and sleeps again.
  rt::Clock& clock = *ctx_.clock;
  std::int64_t now = clock.now_ns();
  while (now < schedule_.next_release_ns()) {
    if (stop.load(std::memory_order_relaxed)) return Wait::kStopped;
    clock.sleep_until(schedule_.next_release_ns());
    now = clock.now_ns();
  }
  if (stop.load(std::memory_order_relaxed)) return Wait::kStopped;
  schedule_.begin(now);
  begin(now, t);
  return Wait::kCycle;
}

Pacing::Wait RealTimePacing::wait_for_state(const std::atomic<bool>& stop, CycleTimes* t) {
  const std::int64_t period = schedule_.period_ns(), next = schedule_.next_release_ns();
  const auto part = [&](double f) { return static_cast<std::int64_t>(f * static_cast<double>(period)); };
  // next is a period after the last cycle's start (or the end of a late cycle, or the start).
  // A new state starts a cycle at once if it came min_gap periods after the last start, or
  // after a cycle the grace started (states slower than the rate: each one is awaited); one
  // that came sooner starts it min_gap after the last start (the rate's bound, never the
  // grace: the state waits no longer than the bound needs). With none, the grace runs out:
  // after a state's cycle `grace` past the grid time, after the grace's own cycle on the grid
  // (no state: the stale path at rate_hz).
  const std::int64_t earliest = grace_started_ ? INT64_MIN : next - period + part(min_gap_);
  const std::int64_t latest = grace_started_ ? next : next + part(grace_);
  std::int64_t now = ctx_.clock->now_ns();
  for (;;) {
    if (stop.load(std::memory_order_relaxed)) return Wait::kStopped;
    const std::int64_t got = ctx_.inbox->last_state_recv_ns();
    const bool fresh = got > trigger_recv_ns_;
    if (fresh && (got >= earliest || now >= earliest)) {
      ctx_.counters->state_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;
      grace_started_ = false;
      break;
    }
    if (now >= latest) {
      ctx_.counters->clock_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;  // an older state never starts a cycle later
      grace_started_ = true;
      break;
    }
    ctx_.clock->sleep_until_or(ctx_.inbox->state_wake, fresh ? earliest : latest);  // each state (and a signal) re-checks
    now = ctx_.clock->now_ns();
  }
  if (!grace_started_) ctx_.monitor->record_wake(std::max<std::int64_t>(0, now - trigger_recv_ns_));
  schedule_.begin_at(now);
  begin(now, t);
  return Wait::kCycle;
}

std::int64_t RealTimePacing::state_time_ns(const transport::StateSample& x, bool* future) const {
  // The loop's timeline is CLOCK_MONOTONIC. The state arrived at recv_ns; it was
  // (recv_utime - sample_utime) old then, both on this host's wall clock.
  std::int64_t in_flight = 0;
  if (ctx_.state_time.use_sample_time && x.recv_utime != 0) in_flight = (x.recv_utime - x.sample_utime) * rt::kNsPerUs;
  const std::int64_t ahead = -in_flight;
  *future = ahead > ctx_.state_time.future_tolerance_ns;
  return x.recv_ns - std::max<std::int64_t>(0, in_flight);
}

std::int64_t RealTimePacing::finish(std::int64_t start_ns, std::int64_t, std::int64_t end_ns) {
  const bool missed = schedule_.finish(end_ns);
  ctx_.monitor->record(start_ns, end_ns, missed);
  return end_ns;
}

// ---- lock-step ------------------------------------------------------------------------

Pacing::Wait LockStepPacing::wait(const std::atomic<bool>& stop, CycleTimes* t) {
  transport::ClockTick tick;
  while (!ctx_.inbox->ticks.pop(&tick)) {
    if (stop.load(std::memory_order_relaxed)) return Wait::kStopped;
    ctx_.inbox->wake.wait_for(poll_ns_);
  }
  // A tick the simulator repeated (it republishes a state and its tick when no answer
  // came in time) was answered already: a second cycle on it would run the optimizer one
  // cycle ahead of the simulator and the run would no longer repeat. The answer is sent
  // again instead, in case it was the one lost. (A sequence far behind the last one is a
  // new simulator run, and is followed.)
  if (last_tick_seq_ >= 0 && tick.seq <= last_tick_seq_ && tick.seq > last_tick_seq_ - 100) {
    ctx_.counters->repeated_ticks.fetch_add(1, std::memory_order_relaxed);
    return tick.seq == last_tick_seq_ ? Wait::kResend : Wait::kDrop;
  }
  last_tick_seq_ = tick.seq;
  const std::int64_t sim_ns = tick.sim_utime * rt::kNsPerUs;
  t->start_ns = sim_ns;
  t->deadline_ns = INT64_MAX;
  t->now_state_ns = sim_ns;
  return Wait::kCycle;
}

// sample_utime is on the simulator's clock, as is the loop's timeline.
std::int64_t LockStepPacing::state_time_ns(const transport::StateSample& x, bool* future) const {
  const std::int64_t ahead = 0;
  *future = ahead > ctx_.state_time.future_tolerance_ns;
  return x.sample_utime * rt::kNsPerUs;
}

// The plant's clock stood still: the cycle took its compute time on the simulator's clock.
std::int64_t LockStepPacing::finish(std::int64_t start_ns, std::int64_t t0, std::int64_t end_ns) {
  ctx_.monitor->record(start_ns, start_ns + (end_ns - t0), false);
  return ctx_.clock->now_ns();
}

}  // namespace mppi::daemon
