// The deadline guard on its own, on a fake clock it shares with the test: the test moves
// time to each deadline and waits for the guard's answer, so each claim (what it publishes,
// when, in which mode, and when it stays quiet) is checked exactly on any machine, however
// loaded. Table-style: one row per stall.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <vector>

#include "fakes.hpp"
#include "mppi/daemon/deadline_guard.hpp"

using namespace mppi;
using mppi::test::eventually;
using mppi::test::RecordingTransport;
using mppi::test::SharedFakeClock;
using transport::Mode;

namespace {

constexpr std::int64_t kMs = rt::kNsPerMs;
constexpr std::int64_t kPeriod = 20 * kMs;
constexpr float kFailsafe = 1500.0f, kInit = 3000.0f;

// Held step i is 100 * (i + 1) on every channel; `bad` (>= 0): that step is past u_max.
HeldPlan held_plan(int bad = -1) {
  HeldPlan h(5, {kInit, kInit, kInit, kInit});
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 4; ++j) h.data()[i * 4 + j] = i == bad ? 9000.0f : 100.0f * static_cast<float>(i + 1);
  return h;
}

struct Rig {
  explicit Rig(daemon::GuardSettings s, int bad = -1)
      : out(&tx, &counters, {0, 0, 0, 0}, {6000, 6000, 6000, 6000}, 4, 1),
        held(held_plan(bad)),
        guard(s, &clock, &out, &counters, held, {kFailsafe, kFailsafe, kFailsafe, kFailsafe}) {
    guard.start();
  }
  long answered() const { return counters.guard_commands.load() + counters.commands_blocked.load(); }
  // A cycle whose optimizer returns `stall` after its start (now); the deadline is a period
  // after it. Each publish the stall spans is awaited before time moves on.
  int cycle(std::int64_t seq, std::int64_t stall) {
    const std::int64_t start = clock.now_ns(), deadline = start + kPeriod;
    guard.arm(deadline, seq, held);
    for (std::int64_t t = deadline; t < start + stall; t += kPeriod) {
      const long before = answered();
      clock.set(t);
      EXPECT_TRUE(eventually([&] { return answered() == before + 1; })) << "no answer at " << (t - start) / kMs << " ms";
    }
    clock.set(start + stall);
    const int steps = guard.disarm();
    clock.set(deadline + kPeriod * (stall / kPeriod + 1));  // past the next publish it would have made
    return steps;
  }

  SharedFakeClock clock;
  RecordingTransport tx;
  daemon::LoopCounters counters;
  daemon::CommandOut out;
  HeldPlan held;
  daemon::DeadlineGuard guard;  // last: its thread stops first
};

daemon::GuardSettings settings(std::int64_t failsafe_timeout_ns = 500 * kMs, std::int64_t anytime_ns = 0) {
  daemon::GuardSettings s;
  s.period_ns = kPeriod;
  s.failsafe_timeout_ns = failsafe_timeout_ns;
  s.anytime_margin_ns = anytime_ns;
  return s;
}

struct Row {
  const char* what;
  std::int64_t stall_ns;
  std::int64_t failsafe_timeout_ns;
  int bad_step;
  std::vector<Mode> modes;  // what the guard published, in order
  std::vector<float> u0;    // and their first channel
};

const Mode H = Mode::kHoldPlan, F = Mode::kFailsafe;

const Row kRows[] = {
    {"on time: quiet", 15 * kMs, 500 * kMs, -1, {}, {}},
    {"one step", 25 * kMs, 500 * kMs, -1, {H}, {100}},
    {"three steps, one per period", 75 * kMs, 500 * kMs, -1, {H, H, H}, {100, 200, 300}},
    {"past the plan's end: u_init", 155 * kMs, 500 * kMs, -1, {H, H, H, H, H, H, H},
     {100, 200, 300, 400, 500, kInit, kInit}},
    {"past the failsafe timeout: failsafe", 95 * kMs, 30 * kMs, -1, {H, H, F, F}, {100, 200, kFailsafe, kFailsafe}},
    {"a held step the gate refuses: failsafe for it", 75 * kMs, 500 * kMs, 1, {H, F, H}, {100, kFailsafe, 300}},
};

}  // namespace

TEST(DeadlineGuard, PublishesTheHeldPlanOnePeriodApartFromTheDeadline) {
  for (const Row& row : kRows) {
    SCOPED_TRACE(row.what);
    Rig r(settings(row.failsafe_timeout_ns), row.bad_step);
    const int steps = r.cycle(7, row.stall_ns);
    EXPECT_EQ(steps, static_cast<int>(row.modes.size()));
    EXPECT_EQ(r.counters.guard_takeovers.load(), row.modes.empty() ? 0 : 1);
    // A stall of one step after it: the guard has moved on, and sent nothing more for cycle 7.
    ASSERT_EQ(r.cycle(8, 25 * kMs), 1);
    ASSERT_EQ(r.tx.commands.size(), row.modes.size() + 1);
    for (std::size_t i = 0; i < row.modes.size(); ++i) {
      EXPECT_EQ(r.tx.commands[i].state_seq, 7);
      EXPECT_EQ(r.tx.commands[i].mode, row.modes[i]) << "publish " << i;
      EXPECT_FLOAT_EQ(r.tx.commands[i].u[0], row.u0[i]) << "publish " << i;
      EXPECT_FLOAT_EQ(r.guard.step(static_cast<int>(i))[0], i < 5 ? r.held.step(static_cast<int>(i))[0] : kInit);
    }
    EXPECT_EQ(r.tx.commands.back().state_seq, 8);
    for (std::size_t i = 1; i < r.tx.commands.size(); ++i) EXPECT_EQ(r.tx.commands[i].seq, r.tx.commands[i - 1].seq + 1);
  }
}

// The failsafe timeout is the guard's own copy: the loop hands a new one over between cycles.
TEST(DeadlineGuard, TakesTheFailsafeTimeoutHandedOver) {
  Rig r(settings(500 * kMs));
  ASSERT_EQ(r.cycle(1, 55 * kMs), 2);
  r.guard.set_failsafe_timeout(10 * kMs);
  ASSERT_EQ(r.cycle(2, 55 * kMs), 2);
  ASSERT_EQ(r.tx.commands.size(), 4u);
  EXPECT_EQ(r.tx.commands[1].mode, Mode::kHoldPlan);  // cycle 1, a period past its deadline (timeout 500 ms)
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kHoldPlan);  // cycle 2 at its deadline
  EXPECT_EQ(r.tx.commands[3].mode, Mode::kFailsafe);  // a period past it: 20 ms > 10 ms
}

// Anytime: the stop flag goes up `margin` before the deadline while the cycle is armed, and
// never for a cycle that ended before it.
TEST(DeadlineGuard, RaisesTheStopFlagTheMarginBeforeTheDeadline) {
  Rig r(settings(500 * kMs, 5 * kMs));
  ASSERT_TRUE(r.guard.anytime());
  // Cycle 1 ends 10 ms in, before its margin.
  std::atomic<bool>* first = r.guard.next_stop_flag();
  EXPECT_EQ(r.cycle(1, 10 * kMs), 0);
  // Cycle 2 works until told to stop (15 ms in), then returns before its deadline.
  std::atomic<bool>* second = r.guard.next_stop_flag();
  EXPECT_NE(first, second);
  EXPECT_FALSE(second->load());
  const std::int64_t start = r.clock.now_ns();
  r.guard.arm(start + kPeriod, 2, r.held);
  r.clock.set(start + kPeriod - 5 * kMs);
  ASSERT_TRUE(eventually([&] { return second->load(); }));
  EXPECT_EQ(r.guard.disarm(), 0);
  EXPECT_FALSE(first->load()) << "cycle 1 ended before its margin";
  EXPECT_EQ(r.counters.guard_takeovers.load(), 0);
  // The flags take turns: cycle 3 has cycle 1's.
  EXPECT_EQ(r.guard.next_stop_flag(), first);
  EXPECT_TRUE(r.tx.commands.empty());
}
