// The control cycle's two decisions as tables (mppi/daemon/cycle_outcome.hpp): what the
// newest state allows, and what a cycle publishes after an update. The loop's integration
// with both is test_control_loop.cpp's.
#include <gtest/gtest.h>

#include <cstdint>

#include "mppi/daemon/cycle_outcome.hpp"

using mppi::daemon::check_state;
using mppi::daemon::choose_outcome;
using mppi::daemon::Outcome;
using mppi::daemon::StateCheck;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kStateTimeout = 100 * kMs;
constexpr std::int64_t kFailsafeTimeout = 500 * kMs;

struct StateRow {
  const char* what;
  bool have;
  std::int64_t age_ns;
  bool future;
  StateCheck expected;
};

TEST(StateCheck, FollowsTheTimeoutsAndTheFutureStamp) {
  const StateRow rows[] = {
      {"no state yet", false, 0, false, StateCheck::kFailsafe},
      {"no state yet, whatever its age reads", false, INT64_MAX, false, StateCheck::kFailsafe},
      {"a new state", true, 0, false, StateCheck::kFresh},
      {"at the state timeout", true, kStateTimeout, false, StateCheck::kFresh},
      {"just past the state timeout", true, kStateTimeout + 1, false, StateCheck::kHold},
      {"at the failsafe timeout", true, kFailsafeTimeout, false, StateCheck::kHold},
      {"just past the failsafe timeout", true, kFailsafeTimeout + 1, false, StateCheck::kFailsafe},
      {"stamped in the future", true, 0, true, StateCheck::kHold},
      {"in the future and past the failsafe timeout", true, kFailsafeTimeout + 1, true, StateCheck::kFailsafe},
  };
  for (const StateRow& r : rows)
    EXPECT_EQ(check_state(r.have, r.age_ns, r.future, kStateTimeout, kFailsafeTimeout), r.expected) << r.what;
}

struct OutcomeRow {
  const char* what;
  bool guard_covered, good, updated, missed;
  Outcome expected;
};

TEST(ChooseOutcome, GuardThenBadThenNoUpdateThenLateThenFresh) {
  const OutcomeRow rows[] = {
      {"a good update in time", false, true, true, false, Outcome::kFresh},
      {"a good update after the deadline", false, true, true, true, Outcome::kLate},
      {"an anytime stop below min_rollouts", false, true, false, false, Outcome::kAnytimeHold},
      {"an anytime stop, and late", false, true, false, true, Outcome::kAnytimeHold},
      {"a bad update", false, false, true, false, Outcome::kBadUpdate},
      {"a bad update, late", false, false, true, true, Outcome::kBadUpdate},
      {"a bad update without an update", false, false, false, false, Outcome::kBadUpdate},
      {"the guard took over, good update", true, true, true, true, Outcome::kGuardCovered},
      {"the guard took over, bad update", true, false, true, true, Outcome::kGuardCovered},
      {"the guard took over, no update", true, true, false, true, Outcome::kGuardCovered},
  };
  for (const OutcomeRow& r : rows)
    EXPECT_EQ(choose_outcome(r.guard_covered, r.good, r.updated, r.missed), r.expected) << r.what;
}

}  // namespace
