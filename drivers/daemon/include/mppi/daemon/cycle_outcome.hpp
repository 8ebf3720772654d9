// The two decisions of a control cycle, as plain functions so each is tested by a table
// (test/rt/test_cycle_outcome.cpp): what the newest state allows (failsafe, hold the plan,
// or optimise from it), and, after the optimizer ran, what the cycle publishes.
#pragma once

#include <cstdint>

namespace mppi::daemon {

enum class StateCheck {
  kFailsafe,  // no state yet, or one older than the failsafe timeout
  kHold,      // older than the state timeout, or stamped in the future: fly the held plan
  kFresh,     // optimise from it
};

inline StateCheck check_state(bool have_state, std::int64_t age_ns, bool future, std::int64_t state_timeout_ns,
                              std::int64_t failsafe_timeout_ns) {
  if (!have_state || age_ns > failsafe_timeout_ns) return StateCheck::kFailsafe;
  if (future || age_ns > state_timeout_ns) return StateCheck::kHold;
  return StateCheck::kFresh;
}

// What a cycle publishes. The first two come from the state check, the rest from the
// optimizer's update.
enum class Outcome {
  kFailsafe,      // the failsafe command (the optimizer starts over when the state returns)
  kStale,         // the held plan; the optimizer's plan shifts with it
  kGuardCovered,  // the deadline guard already published the held plan through the stall
  kBadUpdate,     // non-finite, outside the limits or an exception: the held plan, which
                  // the optimizer restarts from
  kAnytimeHold,   // anytime stop below mppi.min_rollouts, no update: as kBadUpdate, not
                  // counted as a bad update
  kLate,          // a good update after the deadline: the held plan goes out, the update
                  // becomes the held plan
  kFresh,         // the update's command
};

// The order is the precedence: a guard that took over has published already; a bad update
// is never published, nor is a late one.
inline Outcome choose_outcome(bool guard_covered, bool good_update, bool updated, bool missed_deadline) {
  if (guard_covered) return Outcome::kGuardCovered;
  if (!good_update) return Outcome::kBadUpdate;
  if (!updated) return Outcome::kAnytimeHold;
  if (missed_deadline) return Outcome::kLate;
  return Outcome::kFresh;
}

}  // namespace mppi::daemon
