// The control loop on a fake clock with a scripted controller and a recording transport:
// schedule and monitor, and every fault path (each asserts what was published, what was
// counted, and that no non-finite value was published).
#include <cstdint>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <chrono>
#include <iterator>
#include <limits>
#include <optional>
#include <thread>

#include "fakes.hpp"
#include "mppi/daemon/control_loop.hpp"

using namespace mppi;
using mppi::test::FakeClock;
using mppi::test::FakeController;
using mppi::test::RecordingTransport;
using transport::Mode;
using transport::Reject;

namespace {

constexpr std::int64_t kMs = rt::kNsPerMs;

transport::Inbox::Expect expect16() {
  transport::Inbox::Expect e;
  e.nx = 16;
  e.vehicles = 1;
  e.model = 1;
  e.restart_after_ns = 100 * kMs;
  return e;
}

// The state trigger, with the inbox posting a wake-up per accepted state (as mppid sets it).
daemon::LoopSettings state_trigger() {
  daemon::LoopSettings s;
  s.trigger = daemon::Trigger::kState;
  return s;
}
transport::Inbox::Expect expect16_waking() {
  auto e = expect16();
  e.wake_on_state = true;
  return e;
}

// A state of the shape expect16() takes (16 values, one vehicle, model 1), sequence number
// `seq`, received at `recv_ns`; its values and sample time are the caller's.
struct Rig {
  explicit Rig(daemon::LoopSettings s = {}, transport::Inbox::Expect e = expect16())
      : inbox(e), loop(&ctl, &clock, &tx, &inbox, s) {}

  Reject state(std::int64_t n, float fill = 1.0f, std::int64_t sample_us = -1) {
    auto& s = inbox.state_buffer();
    mppi::test::shape_state(s, n);
    s.recv_ns = clock.now_ns();
    s.sample_utime = sample_us >= 0 ? sample_us : clock.now_ns() / 1000;
    for (int i = 0; i < 16; ++i) s.x[i] = fill;
    return inbox.offer_state();
  }
  // One real-time cycle (the loop sleeps on the fake clock up to its release).
  void cycle() { ASSERT_TRUE(loop.step_realtime(run)); }
  // A fresh state, then a cycle.
  void fresh_cycle() {
    state(++seq);
    cycle();
  }
  const transport::Command& last() const { return tx.commands.back(); }

  FakeClock clock;
  RecordingTransport tx;
  FakeController ctl{&clock};
  transport::Inbox inbox;
  daemon::LoopSettings settings;
  daemon::ControlLoop loop;
  std::atomic<bool> run{false};
  std::int64_t seq = 0;
};

// The deadline guard's tests: the loop and the guard share one fake clock; the scripted
// optimizer moves it through a stall deadline by deadline, waiting for each of the guard's
// publishes, so every test checks its sequence exactly on any machine, however loaded.
struct GuardRig {
  static constexpr std::int64_t kPeriod = 20 * kMs;
  explicit GuardRig(daemon::LoopSettings s = {})
      : inbox(expect16()), loop(&ctl, &clock, &tx, &inbox, guarded(s), &clock) {}
  static daemon::LoopSettings guarded(daemon::LoopSettings s) {
    s.deadline_guard = true;
    return s;
  }

  // States 1..n, each received now and followed by its real-time cycle; `fill`: the states'
  // values (none: the inbox's buffers as they are, zeros).
  void cycles(int n, std::optional<float> fill = std::nullopt) {
    for (int k = 1; k <= n; ++k) {
      auto& st = inbox.state_buffer();
      mppi::test::shape_state(st, k);
      st.recv_ns = clock.now_ns();
      if (fill)
        for (int i = 0; i < 16; ++i) st.x[i] = *fill;
      inbox.offer_state();
      ASSERT_TRUE(loop.step_realtime(run));
    }
  }
  long guard_answers() const {
    return loop.counters().guard_commands.load() + loop.counters().commands_blocked.load();
  }
  // Inside the optimizer: it runs `ns` past the cycle's start (the clock stands at it). The
  // deadline is a period after the start; each publish the stall spans is awaited.
  void stall(std::int64_t ns) {
    const std::int64_t start = clock.now_ns();
    for (std::int64_t t = start + kPeriod; t < start + ns; t += kPeriod) {
      const long before = guard_answers();
      clock.set(t);
      EXPECT_TRUE(mppi::test::eventually([&] { return guard_answers() == before + 1; }))
          << "no guard publish " << (t - start) / kMs << " ms into the stall";
    }
    clock.set(start + ns);
  }

  mppi::test::SharedFakeClock clock;
  FakeClock unused;
  FakeController ctl{&unused};
  RecordingTransport tx;
  transport::Inbox inbox;
  daemon::ControlLoop loop;
  std::atomic<bool> run{false};
};

}  // namespace

TEST(ControlLoop, OnTimeCyclesSleepOnTheAbsoluteGrid) {
  Rig r;
  r.ctl.compute_ns = [](int) { return 2 * kMs; };
  const std::int64_t t0 = r.clock.now_ns();
  for (int k = 0; k < 10; ++k) r.fresh_cycle();
  ASSERT_EQ(r.tx.commands.size(), 10u);
  for (const auto& c : r.tx.commands) EXPECT_EQ(c.mode, Mode::kNormal);
  // Each wake-up is an absolute time on the grid, not "now + period".
  for (int k = 1; k < 10; ++k) EXPECT_EQ(r.clock.sleeps[static_cast<std::size_t>(k - 1)], t0 + k * 20 * kMs);
  const auto t = r.loop.timing_total();
  EXPECT_EQ(t.cycles, 10);
  EXPECT_EQ(t.misses, 0);
  EXPECT_DOUBLE_EQ(t.period.min_ms, 20.0);
  EXPECT_DOUBLE_EQ(t.period.max_ms, 20.0);
  EXPECT_DOUBLE_EQ(t.jitter.max_ms, 0.0);
  EXPECT_NEAR(t.compute.mean_ms, 2.0, 1e-9);
  EXPECT_EQ(r.last().state_seq, 10);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

// Trigger state: each state starts its cycle when it arrives, off the clock's grid, so the
// state's wait for a cycle is gone (state sampled -> command out = the compute time).
TEST(ControlLoop, StateTriggerStartsEachCycleWhenItsStateArrives) {
  Rig r(state_trigger(), expect16_waking());
  r.ctl.compute_ns = [](int) { return 2 * kMs; };
  r.loop.start();
  const std::int64_t t0 = r.clock.now_ns();
  for (int k = 0; k < 10; ++k) {
    r.clock.set(t0 + 7 * kMs + k * 20 * kMs + (k % 3) * 300'000);  // 7 ms off the grid, 0.3 ms jitter
    r.fresh_cycle();
    EXPECT_EQ(r.last().state_seq, k + 1);
  }
  ASSERT_EQ(r.tx.commands.size(), 10u);
  for (const auto& c : r.tx.commands) EXPECT_EQ(c.mode, Mode::kNormal);
  EXPECT_TRUE(r.clock.sleeps.empty()) << "a cycle waited for the clock";
  const auto t = r.loop.timing_total();
  EXPECT_EQ(t.misses, 0);
  EXPECT_NEAR(t.latency.max_ms, 2.0, 0.011);
  EXPECT_EQ(t.wake.count, 10);
  EXPECT_NEAR(t.wake.max_ms, 0.0, 0.011);
  EXPECT_EQ(t.optimize.count, 10);
  EXPECT_NEAR(t.optimize.mean_ms, 2.0, 0.011);
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 10);
  EXPECT_EQ(r.loop.counters().clock_triggered.load(), 0);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

// Where state -> command went: a state that arrived 0.4 ms before the loop's thread looked
// (the thread ran late) shows in the wake-up, not in the compute time or the optimizer's.
TEST(ControlLoop, StateTriggerReportsTheWakeUpApartFromTheOptimizer) {
  Rig r(state_trigger(), expect16_waking());
  r.ctl.compute_ns = [](int) { return 3 * kMs; };
  r.loop.start();
  const std::int64_t t0 = r.clock.now_ns();
  for (int k = 0; k < 4; ++k) {
    r.clock.set(t0 + 5 * kMs + k * 20 * kMs);
    r.state(++r.seq);
    r.clock.advance(400'000);
    r.cycle();
  }
  const auto t = r.loop.timing_total();
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 4);
  EXPECT_EQ(t.wake.count, 4);
  EXPECT_NEAR(t.wake.min_ms, 0.4, 0.011);
  EXPECT_NEAR(t.wake.max_ms, 0.4, 0.011);
  EXPECT_NEAR(t.optimize.max_ms, 3.0, 0.011);
  EXPECT_NEAR(t.compute.max_ms, 3.0, 0.011);
  EXPECT_NEAR(t.latency.max_ms, 3.4, 0.011);  // wake-up + compute
  EXPECT_FALSE(r.tx.any_nonfinite());
}

// No goal or reference yet: the loop holds every vehicle where the first state put it (the
// task's default goal is the origin, which a vehicle 2 m up would dive to), and the first
// reference that comes replaces that.
TEST(ControlLoop, BeforeAnyGoalTheVehiclesHoldWhereTheFirstStatePutThem) {
  Rig r;
  r.ctl.compute_ns = [](int) { return 1 * kMs; };
  r.state(++r.seq, 2.0f);  // x = y = z = 2
  r.cycle();
  ASSERT_GE(r.ctl.inputs_set, 1);
  for (int d = 0; d < 3; ++d) {
    EXPECT_FLOAT_EQ(r.ctl.inputs.goals[0][d], 2.0f);
    EXPECT_FLOAT_EQ(r.ctl.inputs.reference.center[d], 2.0f);
  }
  EXPECT_EQ(r.ctl.inputs.reference.kind, Reference::kHold);
  EXPECT_EQ(r.loop.counters().holds_without_goal.load(), 1);
  // Later states do not move the held goal.
  r.state(++r.seq, 3.0f);
  r.cycle();
  EXPECT_FLOAT_EQ(r.ctl.inputs.goals[0][2], 2.0f);
  // A goal arrives: it replaces the hold.
  auto& ref = r.inbox.reference_buffer();
  ref.seq = 1;
  ref.kind = 0;
  ref.vehicle_count = 1;
  ref.goals[0][0] = 30.0f;
  ref.goals[0][1] = 0.0f;
  ref.goals[0][2] = 1.5f;
  r.inbox.offer_reference();
  r.state(++r.seq, 3.0f);
  r.cycle();
  EXPECT_FLOAT_EQ(r.ctl.inputs.goals[0][0], 30.0f);
  EXPECT_FLOAT_EQ(r.ctl.inputs.goals[0][2], 1.5f);
  EXPECT_EQ(r.loop.counters().holds_without_goal.load(), 1);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

// The same script on the clock's grid: each state waits 13 ms for its cycle.
TEST(ControlLoop, ClockTriggerMakesAStateWaitForTheGrid) {
  Rig r;
  r.ctl.compute_ns = [](int) { return 2 * kMs; };
  r.loop.start();
  const std::int64_t t0 = r.clock.now_ns();
  r.cycle();  // the first release, at t0
  for (int k = 0; k < 5; ++k) {
    r.clock.set(t0 + 7 * kMs + k * 20 * kMs);
    r.fresh_cycle();
  }
  EXPECT_NEAR(r.loop.timing_total().latency.max_ms, 15.0, 0.011);  // 13 ms wait + 2 ms
}

// States faster than the rate: one sooner than min_gap after a cycle's start starts its cycle
// min_gap after that start (the rate's bound), not at the grace (it waited up to 25 ms so, the
// p99 of state -> command through ArduCopter SITL: 20 ms); with no state, a cycle starts
// `grace` after its grid time (and answers the newest state it has). After such a cycle the
// next state starts one at once (a stream slower than the rate is followed state by state),
// and with no states at all the cycles run on the grid.
TEST(ControlLoop, StateTriggerRunsAtMostAtTheRateAndFallsBackAfterTheGrace) {
  Rig r(state_trigger(), expect16_waking());
  r.ctl.compute_ns = [](int) { return 1 * kMs; };
  r.loop.start();
  const std::int64_t t0 = r.clock.now_ns();
  r.fresh_cycle();  // a state at t0: a cycle at t0
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 1);
  r.clock.set(t0 + 5 * kMs);
  r.state(++r.seq);  // 5 ms after the start: too soon (min_gap 0.75 -> 15 ms)
  r.cycle();
  // Its cycle starts at the gap, t0 + 15 ms, on the state (not at the grace, t0 + 30 ms).
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 2);
  EXPECT_EQ(r.loop.counters().clock_triggered.load(), 0);
  ASSERT_EQ(r.clock.sleeps.size(), 1u);
  EXPECT_EQ(r.clock.sleeps.back(), t0 + 15 * kMs);
  EXPECT_EQ(r.last().state_seq, 2);
  EXPECT_EQ(r.last().mode, Mode::kNormal);
  // No state after it: the grace, at its grid time + 10 ms (t0 + 15 + 20 + 10).
  r.cycle();
  EXPECT_EQ(r.loop.counters().clock_triggered.load(), 1);
  ASSERT_EQ(r.clock.sleeps.size(), 2u);
  EXPECT_EQ(r.clock.sleeps.back(), t0 + 45 * kMs);
  EXPECT_EQ(r.last().state_seq, 2);
  // A state 3 ms after that cycle (states at 30 Hz) starts one at once.
  r.clock.set(t0 + 48 * kMs);
  r.state(++r.seq);
  r.cycle();
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 3);
  EXPECT_EQ(r.clock.sleeps.size(), 2u);
  EXPECT_EQ(r.last().state_seq, 3);
  // A state 15 ms after a state's cycle starts one too.
  const std::int64_t start3 = t0 + 48 * kMs;
  r.clock.set(start3 + 15 * kMs);
  r.state(++r.seq);
  r.cycle();
  EXPECT_EQ(r.loop.counters().state_triggered.load(), 4);
  EXPECT_EQ(r.clock.sleeps.size(), 2u);
  // States stop: grace once, then cycles on the grid, holding, then the failsafe.
  const std::int64_t start4 = start3 + 15 * kMs;
  r.cycle();
  EXPECT_EQ(r.clock.sleeps.back(), start4 + 30 * kMs);
  r.cycle();
  EXPECT_EQ(r.clock.sleeps.back(), start4 + 50 * kMs);
  for (int k = 0; k < 30; ++k) r.cycle();
  EXPECT_EQ(r.clock.sleeps.back(), start4 + 30 * kMs + 31 * 20 * kMs);
  EXPECT_EQ(r.loop.counters().clock_triggered.load(), 33);
  EXPECT_EQ(r.last().mode, Mode::kFailsafe);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, MonitorStatisticsMatchTheScriptedComputeTimes) {
  Rig r;
  r.ctl.compute_ns = [](int n) { return ((n - 1) % 10 + 1) * kMs; };  // 1..10 ms
  for (int k = 0; k < 100; ++k) r.fresh_cycle();
  const auto t = r.loop.timing_total();
  EXPECT_EQ(t.cycles, 100);
  EXPECT_EQ(t.misses, 0);
  EXPECT_NEAR(t.compute.min_ms, 1.0, 1e-9);
  EXPECT_NEAR(t.compute.max_ms, 10.0, 1e-9);
  EXPECT_NEAR(t.compute.mean_ms, 5.5, 1e-9);
  EXPECT_NEAR(t.compute.p99_ms, 10.0, 0.011);  // one 10 us bin
  EXPECT_DOUBLE_EQ(t.period.mean_ms, 20.0);
  // Status at 1 Hz from a 50 Hz loop: 2 periodic + 1 on the first mode change.
  EXPECT_EQ(r.tx.statuses.size(), 3u);
  EXPECT_NEAR(r.tx.statuses.back().compute_ms_max, 10.0f, 1e-4f);
  EXPECT_EQ(r.tx.statuses.back().cycles, 100);
}

TEST(ControlLoop, OptimizerStallPublishesHeldPlanSkipsAndReanchors) {
  Rig r;
  r.ctl.compute_ns = [](int n) { return n == 3 ? 55 * kMs : 2 * kMs; };
  std::vector<std::int64_t> starts;
  for (int k = 0; k < 6; ++k) {
    r.state(++r.seq);
    r.cycle();
    starts.push_back(r.clock.now_ns());
  }
  ASSERT_EQ(r.tx.commands.size(), 6u);  // one command per cycle, no catch-up burst
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kHoldPlan);
  // The held plan is cycle 2's plan shifted: its next step is 1000 + 2*10 + 1.
  EXPECT_FLOAT_EQ(r.tx.commands[2].u[0], 1021.0f);
  EXPECT_EQ(r.tx.commands[3].mode, Mode::kNormal);
  const auto t = r.loop.timing_total();
  EXPECT_EQ(t.misses, 1);
  EXPECT_EQ(t.late_start_misses, 0);  // the optimizer's own overrun
  EXPECT_EQ(t.max_consecutive_misses, 1);
  EXPECT_EQ(t.consecutive_misses, 0);
  EXPECT_EQ(r.loop.skipped_periods(), 2);
  EXPECT_EQ(r.loop.counters().late_holds.load(), 1);
  // Cycle 4 began right where the late cycle 3 ended (re-anchored), cycle 5 one period later.
  const std::int64_t end3 = starts[2];
  EXPECT_EQ(r.clock.sleeps.back() - r.clock.sleeps[r.clock.sleeps.size() - 2], 20 * kMs);
  EXPECT_EQ(starts[3] - end3, 2 * kMs);         // cycle 4 ran immediately, took 2 ms
  EXPECT_EQ(starts[4] - starts[3], 20 * kMs);   // then back on a 20 ms grid
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, ALateWakeIsAMissTheMachineCausedNotAnOverrun) {
  Rig r;
  r.ctl.compute_ns = [](int) { return 5 * kMs; };
  for (int k = 0; k < 6; ++k) {
    if (k == 3) r.clock.oversleep_ns = 17 * kMs;  // woken 17 ms late, 5 ms of work: 2 ms past
    r.fresh_cycle();
  }
  const auto t = r.loop.timing_total();
  EXPECT_EQ(t.misses, 1);
  EXPECT_EQ(t.late_start_misses, 1);
  EXPECT_EQ(r.tx.statuses.back().misses, 1);
  EXPECT_EQ(r.tx.statuses.back().late_start_misses, 1);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, StateStreamStopsHoldsThenFailsafeThenRecovers) {
  Rig r;
  r.ctl.compute_ns = [](int) { return 1 * kMs; };
  r.fresh_cycle();  // state received at cycle 0
  for (int k = 1; k < 30; ++k) r.cycle();
  // Age at cycle k is 20k ms: fresh up to 100 ms, held to 500 ms, failsafe after.
  for (int k = 0; k < 30; ++k) {
    const Mode want = k * 20 <= 100 ? Mode::kNormal : k * 20 <= 500 ? Mode::kHoldPlan : Mode::kFailsafe;
    EXPECT_EQ(r.tx.commands[static_cast<std::size_t>(k)].mode, want) << "cycle " << k;
  }
  EXPECT_FLOAT_EQ(r.tx.commands[29].u[0], 3000.0f);  // the failsafe command: u_init
  EXPECT_EQ(r.loop.counters().stale_cycles.load(), 20);
  // Entering failsafe published a status at once, saying so and unhealthy.
  bool failsafe_status = false;
  for (const auto& s : r.tx.statuses)
    if (s.mode == Mode::kFailsafe && !s.healthy && s.rejected_stale > 0) failsafe_status = true;
  EXPECT_TRUE(failsafe_status);
  // Fresh state again: back to normal, with a status saying so.
  r.fresh_cycle();
  EXPECT_EQ(r.last().mode, Mode::kNormal);
  EXPECT_EQ(r.tx.statuses.back().mode, Mode::kNormal);
  EXPECT_TRUE(r.tx.statuses.back().healthy);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, NoStateYetMeansFailsafe) {
  Rig r;
  r.cycle();
  EXPECT_EQ(r.last().mode, Mode::kFailsafe);
  EXPECT_EQ(r.last().state_seq, -1);
  EXPECT_EQ(r.ctl.iterations, 0);
}

TEST(ControlLoop, NanAndInfStatesAreRejectedAndCounted) {
  Rig r;
  r.fresh_cycle();
  EXPECT_EQ(r.state(++r.seq, std::numeric_limits<float>::quiet_NaN()), Reject::kNan);
  EXPECT_EQ(r.state(++r.seq, std::numeric_limits<float>::infinity()), Reject::kNan);
  r.cycle();
  EXPECT_EQ(r.inbox.counters.rejected_nan.load(), 2);
  EXPECT_EQ(r.last().state_seq, 1);  // still the last valid state
  EXPECT_EQ(r.last().mode, Mode::kNormal);
  for (float v : r.ctl.last_x0) EXPECT_TRUE(std::isfinite(v));
  for (int k = 0; k < 50; ++k) r.cycle();  // status carries the count
  EXPECT_EQ(r.tx.statuses.back().rejected_nan, 2);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, DuplicateAndOutOfOrderSeqAreRejectedAndCounted) {
  Rig r;
  EXPECT_EQ(r.state(5), Reject::kNone);
  EXPECT_EQ(r.state(5), Reject::kDuplicate);
  EXPECT_EQ(r.state(4), Reject::kOutOfOrder);
  EXPECT_EQ(r.state(6), Reject::kNone);
  r.cycle();
  EXPECT_EQ(r.last().state_seq, 6);
  EXPECT_EQ(r.inbox.counters.rejected_duplicate.load(), 1);
  EXPECT_EQ(r.inbox.counters.rejected_out_of_order.load(), 1);
  for (int k = 0; k < 50; ++k) r.cycle();
  EXPECT_EQ(r.tx.statuses.back().rejected_out_of_order, 2);
  // A step back after the stream was quiet longer than the restart window is a restart.
  r.clock.advance(200 * kMs);
  EXPECT_EQ(r.state(1), Reject::kNone);
}

TEST(ControlLoop, WrongShapeOrModelIsRejected) {
  Rig r;
  auto& s = r.inbox.state_buffer();
  s.seq = 1;
  s.nx = 13;
  s.vehicle_count = 1;
  s.n = 13;
  s.model = 1;
  EXPECT_EQ(r.inbox.offer_state(), Reject::kShape);
  auto& s2 = r.inbox.state_buffer();
  s2.nx = 16;
  s2.n = 16;
  s2.model = 2;  // quadrotor_rate state for a quadrotor task
  EXPECT_EQ(r.inbox.offer_state(), Reject::kShape);
  EXPECT_EQ(r.inbox.counters.rejected_shape.load(), 2);
}

TEST(ControlLoop, NonFiniteOptimizerOutputPublishesHeldPlan) {
  Rig r;
  r.ctl.fault = [](int n, std::vector<float>* plan, UpdateStats* st) {
    if (n == 3) {
      (*plan)[0] = std::numeric_limits<float>::quiet_NaN();
      st->finite = false;
    }
    return false;
  };
  for (int k = 0; k < 5; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kHoldPlan);
  EXPECT_FLOAT_EQ(r.tx.commands[2].u[0], 1021.0f);
  EXPECT_EQ(r.tx.commands[3].mode, Mode::kNormal);
  EXPECT_EQ(r.loop.counters().optimizer_nonfinite.load(), 1);
  // The NaN plan is not kept as a warm start: the last good plan (shifted) replaces it.
  EXPECT_EQ(r.ctl.resets, 0);
  EXPECT_EQ(r.ctl.restores, 1);
  for (float v : r.ctl.plan()) EXPECT_TRUE(std::isfinite(v));
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, GateCatchesNanTheOptimizerCalledFinite) {
  Rig r;
  r.ctl.fault = [](int n, std::vector<float>* plan, UpdateStats*) {
    if (n == 2) (*plan)[1] = std::numeric_limits<float>::infinity();
    if (n == 3) (*plan)[2] = 1e9f;  // outside u_max
    return false;
  };
  for (int k = 0; k < 4; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.commands[1].mode, Mode::kHoldPlan);
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kHoldPlan);
  EXPECT_EQ(r.loop.counters().gate_rejects.load(), 2);
  EXPECT_FALSE(r.tx.any_nonfinite());
  for (const auto& c : r.tx.commands)
    for (int i = 0; i < c.n; ++i) EXPECT_LE(c.u[i], 6000.0f);
}

TEST(ControlLoop, OptimizerErrorPublishesHeldPlan) {
  Rig r;
  r.ctl.fault = [](int n, std::vector<float>*, UpdateStats*) { return n == 2; };
  for (int k = 0; k < 3; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.commands[1].mode, Mode::kHoldPlan);
  EXPECT_FLOAT_EQ(r.tx.commands[1].u[0], 1011.0f);
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kNormal);
  EXPECT_EQ(r.loop.counters().optimizer_errors.load(), 1);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, ParameterUpdatesApplyBetweenCyclesAndBadOnesAreReported) {
  Rig r;
  auto push = [&](const char* key, double v) {
    transport::ParamUpdate p;
    std::strncpy(p.key, key, sizeof(p.key) - 1);
    p.value = v;
    r.inbox.offer_param(p);
  };
  // An update arriving mid-cycle (during the optimizer) waits for the next cycle.
  r.ctl.compute_ns = [&](int n) {
    if (n == 2) push("cost.w_xy", 3.0);
    return kMs;
  };
  r.fresh_cycle();
  r.fresh_cycle();
  EXPECT_TRUE(r.ctl.params_set.empty());
  r.fresh_cycle();
  ASSERT_EQ(r.ctl.params_set.size(), 1u);
  EXPECT_EQ(r.ctl.params_set[0].second, 3.0);
  push("cost.w_xy", -1.0);                                   // out of range
  push("cost.nonexistent", 1.0);                             // unknown
  push("mppi.lambda", 2.0);                                  // fixed for a run
  push("cost.w_xy", std::numeric_limits<double>::quiet_NaN());  // not finite
  push("daemon.state_timeout_ms", 50.0);                     // loop parameter: fine
  push("daemon.failsafe_timeout_ms", 10.0);                  // below state timeout
  r.fresh_cycle();
  EXPECT_EQ(r.loop.counters().params_rejected.load(), 5);
  EXPECT_EQ(r.loop.counters().params_applied.load(), 2);
  EXPECT_EQ(r.loop.settings().state_timeout_ns, 50 * kMs);
  EXPECT_EQ(r.ctl.mid_cycle_changes, 0);
  for (int k = 0; k < 50; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.statuses.back().rejected_params, 5);
}

// An update naming a state time (param_update_t.apply_utime) waits for the first cycle whose
// state was sampled at or after it, whenever it arrived; those due together go in arrival order.
TEST(ControlLoop, ParameterUpdatesWaitForTheStateTimeTheyName) {
  Rig r;
  auto push = [&](const char* key, double v, std::int64_t at_us) {
    transport::ParamUpdate p;
    std::strncpy(p.key, key, sizeof(p.key) - 1);
    p.value = v;
    p.apply_utime = at_us;
    r.inbox.offer_param(p);
  };
  const std::int64_t t0 = 5'000'000;  // the states' sample times, on their own clock
  auto cycle_at = [&](std::int64_t sample_us) {
    r.state(++r.seq, 1.0f, sample_us);
    r.cycle();
  };
  cycle_at(t0);
  push("cost.w_xy", 3.0, t0 + 60'000);   // three periods on
  push("cost.w_xy", 4.0, t0 + 40'000);   // two periods on: first
  push("cost.w_xy", 5.0, t0 + 60'000);   // due with the first, after it
  push("cost.w_xy", 2.0, 0);             // at once
  cycle_at(t0 + 20'000);
  ASSERT_EQ(r.ctl.params_set.size(), 1u);
  EXPECT_EQ(r.ctl.params_set[0].second, 2.0);
  cycle_at(t0 + 40'000);
  ASSERT_EQ(r.ctl.params_set.size(), 2u);
  EXPECT_EQ(r.ctl.params_set[1].second, 4.0);
  cycle_at(t0 + 59'999);                 // not yet
  EXPECT_EQ(r.ctl.params_set.size(), 2u);
  cycle_at(t0 + 60'000);
  ASSERT_EQ(r.ctl.params_set.size(), 4u);
  EXPECT_EQ(r.ctl.params_set[2].second, 3.0);
  EXPECT_EQ(r.ctl.params_set[3].second, 5.0);
  EXPECT_EQ(r.loop.counters().params_applied.load(), 4);
}

// The parameter table (loop_params.cpp): every kind of key, routed to its row, answered
// with the row's message. One row per update, in order (a row may depend on the one before).
TEST(ControlLoop, ParameterTableRoutesEachKeyAndAnswersWithItsReason) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::string daemon_keys =
      ": not tunable at run time (tunable: daemon.state_timeout_ms, daemon.failsafe_timeout_ms, daemon.identify, "
      "daemon.restart_estimates)";
  const std::string below = ": must be > 0 and below daemon.failsafe_timeout_ms";
  const std::string above = ": must be above daemon.state_timeout_ms and <= 60000";
  struct Row {
    const char* key;
    double value;
    std::string reason;  // "" = applied; else the reason after the key
  };
  const Row rows[] = {
      {"cost.w_xy", 3.0, ""},
      {"cost.w_xy", -1.0, ": out of range [0, 1e6]"},  // the controller's field table
      {"model.nonexistent", 1.0, ": unknown parameter"},
      {"bogus", 1.0, ": unknown parameter"},
      {"daemonx", 1.0, ": unknown parameter"},
      {"cost.w_xy", nan, ": must be finite"},
      {"daemon.restart_estimates", nan, ": must be finite"},
      {"mppi.lambda", 2.0, ": optimizer settings are fixed for a run (restart with --set); tunable: model.*, cost.*"},
      {"daemon.rate_hz", 10.0, daemon_keys},
      {"daemon.", 1.0, daemon_keys},
      {"daemon.state_timeout_ms", 0.0, below},
      {"daemon.state_timeout_ms", 500.0, below},  // the failsafe timeout is 500 ms
      {"daemon.state_timeout_ms", 50.0, ""},
      {"daemon.failsafe_timeout_ms", 50.0, above},
      {"daemon.failsafe_timeout_ms", 60001.0, above},
      {"daemon.failsafe_timeout_ms", 400.0, ""},
      {"daemon.identify", 1.0, ": the identification manoeuvre is for the rate-controlled tasks"},
      {"daemon.restart_estimates", 1.0, ""},
  };
  Rig r;
  for (const Row& row : rows) {
    transport::ParamUpdate p;
    std::strncpy(p.key, row.key, sizeof(p.key) - 1);
    p.value = row.value;
    r.inbox.offer_param(p);
  }
  r.fresh_cycle();
  ASSERT_EQ(r.tx.param_results.size(), std::size(rows));
  for (std::size_t i = 0; i < std::size(rows); ++i) {
    const auto& got = r.tx.param_results[i];
    EXPECT_STREQ(got.key, rows[i].key);
    EXPECT_EQ(got.applied, rows[i].reason.empty()) << rows[i].key;
    EXPECT_EQ(std::string(got.reason), rows[i].reason.empty() ? "" : rows[i].key + rows[i].reason);
  }
  EXPECT_EQ(r.loop.settings().state_timeout_ns, 50 * kMs);
  EXPECT_EQ(r.loop.settings().failsafe_timeout_ns, 400 * kMs);
  ASSERT_EQ(r.ctl.params_set.size(), 1u);
  EXPECT_EQ(r.ctl.params_set[0].second, 3.0);
}

TEST(ControlLoop, LockstepAnswersEveryTickWithOneCommand) {
  daemon::LoopSettings s;
  s.lockstep = true;
  Rig r(s);
  r.ctl.compute_ns = [](int) { return 30 * kMs; };  // slower than real time: no misses in lock-step
  for (int k = 1; k <= 20; ++k) {
    r.state(k, 1.0f, k * 20000);  // sample time in sim microseconds
    transport::ClockTick t;
    t.seq = k;
    t.sim_utime = k * 20000;
    r.inbox.offer_tick(t);
    ASSERT_TRUE(r.loop.step_lockstep(r.run));
    ASSERT_EQ(r.tx.commands.size(), static_cast<std::size_t>(k));
    EXPECT_EQ(r.last().state_seq, k);
    EXPECT_EQ(r.last().mode, Mode::kNormal);
  }
  EXPECT_EQ(r.loop.timing_total().misses, 0);
  EXPECT_DOUBLE_EQ(r.loop.timing_total().period.mean_ms, 20.0);  // sim time
  // No tick, no command: a stop request ends the wait.
  std::atomic<bool> stop{true};
  EXPECT_FALSE(r.loop.step_lockstep(stop));
  EXPECT_EQ(r.tx.commands.size(), 20u);
  // Staleness in sim time: a tick 600 sim-ms after the last state is failsafe.
  transport::ClockTick late;
  late.seq = 21;
  late.sim_utime = 20 * 20000 + 600000;
  r.inbox.offer_tick(late);
  ASSERT_TRUE(r.loop.step_lockstep(r.run));
  EXPECT_EQ(r.last().mode, Mode::kFailsafe);
}

TEST(ControlLoop, KeepsTheNearestObstaclesUpToCapacity) {
  Rig r;
  auto& o = r.inbox.obstacles_buffer();
  constexpr int kCap = ObstacleSet::kCapacity;
  const int n = kCap + 100;
  o.count = n;
  for (int i = 0; i < n; ++i) o.items[i] = Cylinder{static_cast<float>(n - i), 0.0f, 0.5f, 0.0f, 0.0f};
  r.inbox.offer_obstacles();
  r.state(1, 0.0f);  // vehicle at the origin
  r.cycle();
  const ObstacleSet& kept = r.ctl.inputs.obstacles;
  ASSERT_EQ(kept.count, kCap);
  for (int i = 0; i < kept.count; ++i) EXPECT_LE(kept.items[i].x, static_cast<float>(kCap));
}

TEST(ControlLoop, ReferenceTimeIsStateTimeSinceReferenceEpoch) {
  daemon::LoopSettings s;
  s.latency.compensate = false;  // with it, the reference is taken at the actuation time (test_latency.cpp)
  Rig r(s);
  auto& ref = r.inbox.reference_buffer();
  ref.kind = 1;
  ref.radius = 2.0f;
  ref.speed = 1.0f;
  ref.t0_utime = 1'000'000;
  ref.vehicle_count = 1;
  ref.goals[0][0] = 4.0f;
  r.inbox.offer_reference();
  r.state(1, 0.0f, 3'500'000);
  r.cycle();
  EXPECT_FLOAT_EQ(r.ctl.inputs.reference_time, 2.5f);
  EXPECT_EQ(r.ctl.inputs.reference.kind, Reference::kCircle);
  EXPECT_FLOAT_EQ(r.ctl.inputs.goals[0][0], 4.0f);
  // Non-finite reference is rejected and counted.
  auto& bad = r.inbox.reference_buffer();
  bad.radius = std::numeric_limits<float>::quiet_NaN();
  r.inbox.offer_reference();
  EXPECT_EQ(r.inbox.counters.rejected_inputs.load(), 1);
}

TEST(ControlLoop, FinalStatusIsUnhealthy) {
  Rig r;
  r.fresh_cycle();
  r.loop.publish_final_status();
  EXPECT_FALSE(r.tx.statuses.back().healthy);
  EXPECT_EQ(r.tx.statuses.back().cycles, 1);
}

TEST(ControlLoop, DeadlineGuardKeepsCommandsFlowingThroughAStall) {
  // Iteration 3 stalls 75 ms: the guard publishes the held plan at the deadline (20 ms) and
  // each period after (40, 60 ms) until it returns.
  GuardRig r;
  r.ctl.compute_ns = [&r](int n) {
    if (n == 3) r.stall(75 * kMs);
    return std::int64_t{0};
  };
  ASSERT_NO_FATAL_FAILURE(r.cycles(6, 1.0f));
  EXPECT_EQ(r.loop.counters().guard_takeovers.load(), 1);
  EXPECT_EQ(r.loop.counters().guard_commands.load(), 3);
  EXPECT_EQ(r.loop.counters().late_holds.load(), 1);
  // Every cycle is covered exactly once: by its own command or by the guard's.
  ASSERT_EQ(r.tx.commands.size(), 5u + 3u);
  // The stalled cycle (state 3): held-plan steps from cycle 2's plan, one per period; its
  // late result is not published.
  std::vector<float> held;
  for (const auto& c : r.tx.commands)
    if (c.state_seq == 3) {
      EXPECT_EQ(c.mode, Mode::kHoldPlan);
      held.push_back(c.u[0]);
    }
  ASSERT_EQ(held.size(), 3u);
  for (std::size_t g = 0; g < held.size(); ++g) EXPECT_FLOAT_EQ(held[g], 1021.0f + static_cast<float>(g));
  for (const auto& c : r.tx.commands)
    if (c.state_seq != 3) {
      EXPECT_EQ(c.mode, Mode::kNormal) << "state " << c.state_seq;
    }
  for (std::size_t i = 1; i < r.tx.commands.size(); ++i) EXPECT_EQ(r.tx.commands[i].seq, r.tx.commands[i - 1].seq + 1);
  EXPECT_EQ(r.loop.timing_total().misses, 1);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, AnytimeStopsTheOptimizerBeforeTheDeadline) {
  // Iterations 3 and 5 work until the guard sets their stop flag (5 ms before the deadline),
  // then report a partial update: 3 from enough rollouts (its command goes out), 5 from too
  // few (no update: the held plan goes out). The others return at once and are never stopped.
  daemon::LoopSettings s;
  s.anytime_margin_ns = 5 * kMs;
  GuardRig r(s);
  bool stopped[8] = {};
  auto flag_up = [&r] { return r.ctl.stop_flag != nullptr && r.ctl.stop_flag->load(); };
  r.ctl.fault = [&](int n, std::vector<float>*, UpdateStats* st) {
    if (n == 3 || n == 5) {
      r.clock.set(r.clock.now_ns() + GuardRig::kPeriod - 5 * kMs);
      EXPECT_TRUE(mppi::test::eventually(flag_up)) << "iteration " << n << " was not stopped";
      st->partial = true;
      st->rollouts = 100;
      st->updated = n == 3;
    }
    stopped[n] = flag_up();
    return false;
  };
  ASSERT_NO_FATAL_FAILURE(r.cycles(7, 1.0f));
  for (int n = 1; n <= 7; ++n) EXPECT_EQ(stopped[n], n == 3 || n == 5) << "iteration " << n;
  EXPECT_EQ(r.loop.counters().optimizer_errors.load() + r.loop.counters().optimizer_nonfinite.load(), 0);
  EXPECT_EQ(r.loop.counters().partial_updates.load(), 2);
  EXPECT_EQ(r.loop.counters().anytime_holds.load(), 1);
  EXPECT_EQ(r.loop.counters().guard_takeovers.load(), 0);
  EXPECT_EQ(r.loop.timing_total().misses, 0);
  // Every cycle's own command went out: iteration 3's update, and for 5 the held plan
  // (cycle 4's, shifted).
  ASSERT_EQ(r.tx.commands.size(), 7u);
  EXPECT_EQ(r.tx.commands[2].mode, Mode::kNormal);
  EXPECT_FLOAT_EQ(r.tx.commands[2].u[0], 1030.0f);
  EXPECT_EQ(r.tx.commands[4].mode, Mode::kHoldPlan);
  EXPECT_FLOAT_EQ(r.tx.commands[4].u[0], 1041.0f);
  EXPECT_EQ(r.tx.commands[5].mode, Mode::kNormal);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(ControlLoop, DeadlineGuardStaysQuietWhenOnTime) {
  GuardRig r;
  ASSERT_NO_FATAL_FAILURE(r.cycles(10));
  EXPECT_EQ(r.loop.counters().guard_takeovers.load(), 0);
  EXPECT_EQ(r.loop.counters().guard_commands.load(), 0);
  EXPECT_EQ(r.loop.timing_total().misses, 0);
  ASSERT_EQ(r.tx.commands.size(), 10u);
  for (const auto& c : r.tx.commands) EXPECT_EQ(c.mode, Mode::kNormal);
}

// A stall longer than the failsafe timeout (60 ms) gets the failsafe from the guard: its
// publishes k periods past the deadline hold the plan while k * 20 ms <= 60 ms. The timeout
// the guard flies with is the loop's, as a parameter update set it (the hand-over).
TEST(ControlLoop, DeadlineGuardFallsToFailsafeWhenTheStallOutlastsTheFailsafeTimeout) {
  for (bool by_update : {false, true}) {
    SCOPED_TRACE(by_update ? "timeout set by daemon.failsafe_timeout_ms" : "timeout from the settings");
    daemon::LoopSettings s;
    s.state_timeout_ns = 30 * kMs;
    s.failsafe_timeout_ns = by_update ? 500 * kMs : 60 * kMs;
    GuardRig r(s);
    if (by_update) {
      transport::ParamUpdate p;
      std::strncpy(p.key, "daemon.failsafe_timeout_ms", sizeof(p.key) - 1);
      p.value = 60.0;
      r.inbox.offer_param(p);
    }
    r.ctl.compute_ns = [&r](int n) {
      if (n == 2) r.stall(150 * kMs);
      return std::int64_t{0};
    };
    ASSERT_NO_FATAL_FAILURE(r.cycles(2));
    EXPECT_EQ(r.loop.counters().params_applied.load(), by_update ? 1 : 0);
    std::vector<Mode> guard_modes;
    for (const auto& c : r.tx.commands)
      if (c.state_seq == 2) guard_modes.push_back(c.mode);
    const Mode H = Mode::kHoldPlan, F = Mode::kFailsafe;
    // Publishes at 20, 40, ..., 140 ms of the 150 ms stall: 0..6 periods past the deadline.
    EXPECT_EQ(guard_modes, (std::vector<Mode>{H, H, H, H, F, F, F}));
    EXPECT_FALSE(r.tx.any_nonfinite());
  }
}
