// The loop's counters since start: the loop thread and the deadline guard write them,
// other threads (the daemon's reports, the watchdog, tests) read them; relaxed atomics
// (counts, not synchronisation).
#pragma once

#include <atomic>
#include <cstdint>

namespace mppi::daemon {

struct LoopCounters {
  std::atomic<std::int64_t> commands_normal{0};
  std::atomic<std::int64_t> commands_hold{0};
  std::atomic<std::int64_t> commands_failsafe{0};
  std::atomic<std::int64_t> commands_blocked{0};  // failed the gate with no safe substitute
  std::atomic<std::int64_t> optimizer_nonfinite{0};
  std::atomic<std::int64_t> optimizer_errors{0};  // exceptions
  std::atomic<std::int64_t> gate_rejects{0};      // optimizer output outside limits
  std::atomic<std::int64_t> late_holds{0};        // deadline missed: held plan published
  std::atomic<std::int64_t> stale_cycles{0};      // state older than state_timeout
  std::atomic<std::int64_t> params_applied{0};
  std::atomic<std::int64_t> params_rejected{0};
  std::atomic<std::int64_t> status_published{0};
  std::atomic<std::int64_t> plans_published{0};
  std::atomic<std::int64_t> failsafe_entries{0};
  std::atomic<std::int64_t> publish_failures{0};  // the transport could not send a command
  std::atomic<std::int64_t> guard_takeovers{0};   // stalls the deadline guard covered
  std::atomic<std::int64_t> guard_commands{0};    // held-plan commands it published
  std::atomic<std::int64_t> future_states{0};     // sample time ahead of now: handled as stale
  std::atomic<std::int64_t> plan_skips{0};        // extra control steps the plan was shifted by
  std::atomic<std::int64_t> latency_rejected{0};  // cycle durations the estimator refused
  std::atomic<std::int64_t> repeated_ticks{0};    // lock-step ticks already answered, dropped
  std::atomic<std::int64_t> partial_updates{0};   // anytime: updates from fewer than K rollouts
  std::atomic<std::int64_t> anytime_holds{0};     // anytime: below min_rollouts, held plan published
  std::atomic<std::int64_t> state_triggered{0};   // trigger state: cycles a state started
  std::atomic<std::int64_t> clock_triggered{0};   // trigger state: cycles started without one (grace ran out)
  std::atomic<std::int64_t> holds_without_goal{0};  // no goal or reference yet: held where the first state was
  std::atomic<std::int64_t> actuation_delay_ns{0};  // the actuation delay flown with (estimated, when on)
  std::atomic<std::int64_t> map_stale_cycles{0};    // cycles flown with a map older than map_timeout_ns
  std::atomic<std::int64_t> map_age_us{-1};         // the age of the map flown at the last cycle (-1: none)
};

}  // namespace mppi::daemon
