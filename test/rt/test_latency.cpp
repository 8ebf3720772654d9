// Latency compensation: the estimator of the controller's own latency, the history of sent
// commands the state is predicted through, and the loop using both (fake clock, scripted
// controller whose model the tests follow by hand: x[0] moves at u[0] units per second).
#include <cstdint>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/disturbance_observer.hpp"
#include "mppi/daemon/state_predictor.hpp"
#include "mppi/rt/latency_estimator.hpp"
#include "source_dir.hpp"

using namespace mppi;
using transport::Mode;

namespace {
constexpr std::int64_t kMs = rt::kNsPerMs;

rt::LatencyEstimatorSettings est(double q, int window, std::int64_t lo, std::int64_t hi) {
  rt::LatencyEstimatorSettings s;
  s.quantile = q;
  s.window = window;
  s.floor_ns = lo;
  s.ceiling_ns = hi;
  return s;
}
}  // namespace

TEST(LatencyEstimator, HighQuantileOfTheWindowInsideFloorAndCeiling) {
  rt::LatencyEstimator e(est(0.9, 10, 1 * kMs, 20 * kMs));
  EXPECT_EQ(e.estimate_ns(), 1 * kMs + 19 * kMs / 2);  // before any measurement: the middle
  for (int k = 1; k <= 10; ++k) EXPECT_TRUE(e.add(k * kMs));  // 1..10 ms
  EXPECT_EQ(e.estimate_ns(), 9 * kMs);                         // rank ceil(0.9 * 10) = 9th
  // The window slides: ten cycles of 3 ms forget the old ones.
  for (int k = 0; k < 10; ++k) e.add(3 * kMs);
  EXPECT_EQ(e.estimate_ns(), 3 * kMs);
  // One outlier in ten does not move a 0.9 quantile; two do.
  e.add(50 * kMs);
  EXPECT_EQ(e.estimate_ns(), 3 * kMs);
  e.add(15 * kMs);
  EXPECT_EQ(e.estimate_ns(), 15 * kMs);
  // Clamped: below the floor and above the ceiling.
  for (int k = 0; k < 10; ++k) e.add(100'000);
  EXPECT_EQ(e.estimate_ns(), 1 * kMs);
  for (int k = 0; k < 10; ++k) e.add(40 * kMs);
  EXPECT_EQ(e.estimate_ns(), 20 * kMs);
}

TEST(LatencyEstimator, ClockJumpsAreRefusedAndCountedNeverNegative) {
  rt::LatencyEstimator e(est(0.95, 50, 1 * kMs, 20 * kMs));
  for (int k = 0; k < 50; ++k) e.add(4 * kMs);
  EXPECT_FALSE(e.add(-5 * kMs));            // the clock stepped back
  EXPECT_FALSE(e.add(10'000 * kMs));        // a stopped process, not a latency
  EXPECT_EQ(e.rejected(), 2);
  EXPECT_EQ(e.samples(), 50);
  EXPECT_EQ(e.estimate_ns(), 4 * kMs);
  // Settings out of order still give a finite estimate inside a sane range.
  rt::LatencyEstimator odd(est(7.0, 0, 5 * kMs, 1 * kMs));
  EXPECT_TRUE(odd.add(2 * kMs));
  EXPECT_EQ(odd.estimate_ns(), 5 * kMs);
}

TEST(CommandHistory, PredictsThroughEachCommandInEffect) {
  test::FakeClock clock;
  test::FakeController c(&clock);
  daemon::CommandHistory h(4, {100, 0, 0, 0});
  const float u1[4] = {200, 0, 0, 0}, u2[4] = {-50, 0, 0, 0};
  h.add(10 * kMs, u1);
  h.add(30 * kMs, u2);
  float x[16] = {};
  // [0, 10) at 100, [10, 30) at 200, [30, 40) at -50: 1 + 4 - 0.5.
  EXPECT_EQ(h.predict(c, x, 0, 40 * kMs), 3);
  EXPECT_NEAR(x[0], 4.5f, 1e-5f);
  // From inside a segment, and nothing for an empty or reversed span.
  float y[16] = {};
  EXPECT_EQ(h.predict(c, y, 20 * kMs, 25 * kMs), 1);
  EXPECT_NEAR(y[0], 1.0f, 1e-5f);
  EXPECT_EQ(h.predict(c, y, 25 * kMs, 25 * kMs), 0);
  EXPECT_EQ(h.predict(c, y, 30 * kMs, 20 * kMs), 0);
  EXPECT_NEAR(y[0], 1.0f, 1e-5f);
  // A command stamped before the last one acts after it (plants apply in arrival order).
  const float u3[4] = {7, 0, 0, 0};
  h.add(5 * kMs, u3);
  EXPECT_FLOAT_EQ(h.at(29 * kMs)[0], 200.0f);
  EXPECT_FLOAT_EQ(h.at(30 * kMs)[0], 7.0f);
}

TEST(CommandHistory, KeepsTheNewestAndWhatActedBeforeThem) {
  test::FakeClock clock;
  test::FakeController c(&clock);
  daemon::CommandHistory h(4, {1, 0, 0, 0});
  for (int k = 0; k < daemon::CommandHistory::kCapacity + 5; ++k) {
    const float u[4] = {static_cast<float>(10 + k), 0, 0, 0};
    h.add(k * kMs, u);
  }
  EXPECT_EQ(h.size(), daemon::CommandHistory::kCapacity);
  EXPECT_FLOAT_EQ(h.at(-1)[0], 14.0f);  // the last command dropped acts before the kept ones
  EXPECT_FLOAT_EQ(h.at(100 * kMs)[0], static_cast<float>(10 + daemon::CommandHistory::kCapacity + 4));
  h.reset();
  EXPECT_EQ(h.size(), 0);
  EXPECT_FLOAT_EQ(h.at(0)[0], 1.0f);
}

namespace {
struct LoopRig {
  explicit LoopRig(daemon::LoopSettings s) : inbox(expect()), loop(&ctl, &clock, &tx, &inbox, s) {}
  static transport::Inbox::Expect expect() {
    transport::Inbox::Expect e;
    e.nx = 16;
    e.model = 1;
    return e;
  }
  // A state sampled `age_ns` before now, received now; x[0] = 0.
  void state(std::int64_t age_ns, std::int64_t wall_ahead_ns = 0) {
    auto& s = inbox.state_buffer();
    test::shape_state(s, ++seq);
    s.recv_ns = clock.now_ns();
    // A wall clock 1000 s ahead of the monotonic one: only differences matter.
    s.recv_utime = (clock.now_ns() + 1000 * rt::kNsPerS) / 1000;
    s.sample_utime = s.recv_utime - age_ns / 1000 + wall_ahead_ns / 1000;
    for (float& v : s.x) v = 0.0f;
    ASSERT_EQ(inbox.offer_state(), transport::Reject::kNone);
  }
  test::FakeClock clock;
  test::RecordingTransport tx;
  test::FakeController ctl{&clock};
  transport::Inbox inbox;
  daemon::ControlLoop loop;
  std::atomic<bool> run{false};
  std::int64_t seq = 0;
};

daemon::LoopSettings fixed_latency(std::int64_t latency, std::int64_t actuation) {
  daemon::LoopSettings s;
  s.latency.estimator.floor_ns = s.latency.estimator.ceiling_ns = latency;
  s.latency.transport_ns = 0;
  s.latency.actuation_delay_ns = actuation;
  return s;
}
}  // namespace

TEST(LatencyCompensation, OptimisesFromTheStatePredictedToTheActuationTime) {
  LoopRig r(fixed_latency(5 * kMs, 10 * kMs));
  r.ctl.compute_ns = [](int) { return 5 * kMs; };
  // Cycle 1: the state is 3 ms old at the start; nothing was sent yet, u_init (3000/s) acts.
  r.state(3 * kMs);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  const std::int64_t t1 = r.clock.now_ns() - 5 * kMs;  // its start
  // lead = 3 (age) + 5 (latency) + 10 (actuation) = 18 ms.
  EXPECT_NEAR(r.ctl.last_x0[0], 3000.0f * 0.018f, 1e-3f);
  EXPECT_EQ(r.tx.commands.back().lead_us, 18000);
  EXPECT_EQ(r.tx.commands.back().age_us, 3000);
  EXPECT_EQ(r.tx.commands.back().compute_us, 5000);
  // It sent u = 1010 at t1 + 5 ms; it acts from t1 + 15 ms.
  ASSERT_FLOAT_EQ(r.tx.commands.back().u[0], 1010.0f);
  // Cycle 2 starts at t1 + 20 ms from a state sampled at t1 + 8 ms: predicted over
  // [t1+8, t1+15) at 3000 and [t1+15, t1+35) at 1010.
  r.clock.set(t1 + 8 * kMs);
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.clock.now_ns(), t1 + 25 * kMs);
  EXPECT_NEAR(r.ctl.last_x0[0], 3000.0f * 0.007f + 1010.0f * 0.020f, 1e-3f);
  EXPECT_EQ(r.tx.commands.back().lead_us, 27000);
  EXPECT_EQ(r.ctl.shifts, 0);  // on time: the plan's one shift per cycle is enough
  const auto t = r.loop.timing_total();
  EXPECT_NEAR(t.lead.max_ms, 27.0, 0.02);
  EXPECT_NEAR(t.age.max_ms, 12.0, 0.02);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

// A moving reference (circle, figure-eight) is evaluated at the time of the predicted state,
// not at the sample time: otherwise a tracking task lags its reference by the lead (in real
// time on the 2-core VM: RMSE 0.071 m instead of 0.046 m in lock-step on the 5 m/s circle).
TEST(LatencyCompensation, AMovingReferenceIsTakenAtTheActuationTime) {
  LoopRig r(fixed_latency(5 * kMs, 10 * kMs));
  r.ctl.compute_ns = [](int) { return 5 * kMs; };
  auto& ref = r.inbox.reference_buffer();
  ref.kind = 1;  // circle
  ref.radius = 2.0f;
  ref.speed = 1.0f;
  ref.vehicle_count = 1;
  ref.t0_utime = (r.clock.now_ns() + 1000 * rt::kNsPerS) / 1000 - 2'000'000;  // 2 s ago on the wall clock
  r.inbox.offer_reference();
  r.state(3 * kMs);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  // Sampled 3 ms ago: 1.997 s after the epoch; lead = 3 (age) + 5 (latency) + 10 (actuation).
  EXPECT_NEAR(r.ctl.inputs.reference_time, 1.997f + 0.018f, 1e-4f);
  EXPECT_EQ(r.tx.commands.back().lead_us, 18000);
}

// The autopilot's position and velocity trail the vehicle by estimate_lag (its EKF); its
// attitude and rates do not. Each row: the state's age, the lag; the position is predicted
// over lag + age + latency + actuation, a rate over age + latency + actuation, and the lead
// (sample -> act, which replay and the timing read) and the age stay without the lag.
TEST(LatencyCompensation, TheEstimatesLagIsPredictedOverForPositionAndVelocityOnly) {
  struct Row {
    std::int64_t age_ms, lag_ms;
  };
  for (const Row row : {Row{3, 0}, Row{3, 25}, Row{0, 10}, Row{8, 40}}) {
    daemon::LoopSettings s = fixed_latency(5 * kMs, 10 * kMs);
    s.latency.estimate_lag_ns = row.lag_ms * kMs;
    LoopRig r(s);
    r.ctl.compute_ns = [](int) { return 5 * kMs; };
    r.state(row.age_ms * kMs);
    ASSERT_TRUE(r.loop.step_realtime(r.run));
    const float lead_s = static_cast<float>(row.age_ms + 5 + 10) * 1e-3f;
    const float lag_s = static_cast<float>(row.lag_ms) * 1e-3f;
    EXPECT_NEAR(r.ctl.last_x0[0], 3000.0f * (lead_s + lag_s), 1e-3f) << row.age_ms << " " << row.lag_ms;
    EXPECT_NEAR(r.ctl.last_x0[10], 3000.0f * lead_s, 1e-3f) << row.age_ms << " " << row.lag_ms;
    EXPECT_EQ(r.tx.commands.back().lead_us, (row.age_ms + 15) * 1000);
    EXPECT_EQ(r.tx.commands.back().age_us, row.age_ms * 1000);
  }
}

TEST(LatencyCompensation, OffMeansTheMeasuredStateAsIs) {
  daemon::LoopSettings s = fixed_latency(5 * kMs, 10 * kMs);
  s.latency.compensate = false;
  LoopRig r(s);
  r.state(3 * kMs);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_FLOAT_EQ(r.ctl.last_x0[0], 0.0f);
  EXPECT_EQ(r.ctl.propagations, 0);
  EXPECT_EQ(r.tx.commands.back().lead_us, 0);
}

TEST(LatencyCompensation, ThePlanMovesOnByTheStepsThatReallyElapsed) {
  LoopRig r(fixed_latency(2 * kMs, 0));
  r.ctl.compute_ns = [](int) { return 2 * kMs; };
  for (int k = 0; k < 3; ++k) {
    r.state(0);
    ASSERT_TRUE(r.loop.step_realtime(r.run));
  }
  EXPECT_EQ(r.ctl.shifts, 0);
  // The loop is held up (the schedule skips, it does not catch up): that cycle starts
  // late and holds; the plan has moved on by the control steps that elapsed.
  r.clock.advance(58 * kMs);
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kHoldPlan);
  // The plan's next step was for 20 ms after the last command's t_act; 40 ms more passed.
  EXPECT_EQ(r.ctl.shifts, 2);
  EXPECT_EQ(r.loop.counters().plan_skips.load(), 2);
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kNormal);
  EXPECT_EQ(r.ctl.shifts, 2);
}

// A held step the gate refuses is not what acts: the failsafe went out instead, and the
// command history the next state is predicted through must say so.
TEST(LatencyCompensation, ARefusedHeldStepIsNotRememberedTheFailsafeIs) {
  daemon::LoopSettings s = fixed_latency(5 * kMs, 0);
  s.state_timeout_ns = 15 * kMs;
  LoopRig r(s);
  // Iteration 1's plan is past u_max (6000) from step 1 on: its command (step 0) passes the
  // gate, the held plan's next step will not.
  r.ctl.fault = [](int n, std::vector<float>* plan, UpdateStats*) {
    if (n == 1) std::fill(plan->begin() + 4, plan->end(), 9000.0f);
    return false;
  };
  const std::int64_t start = r.clock.now_ns();
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));  // fresh: 1010 goes out
  ASSERT_TRUE(r.loop.step_realtime(r.run));  // 20 ms old: stale, the held 9000 is refused
  ASSERT_EQ(r.tx.commands.size(), 2u);
  EXPECT_EQ(r.tx.commands[1].mode, Mode::kFailsafe);
  EXPECT_FLOAT_EQ(r.tx.commands[1].u[0], 3000.0f);  // u_init: the failsafe
  // Cycle 3 at start + 40 ms from a state sampled at start + 39 ms: predicted to t_act =
  // start + 45 ms through the command in effect since start + 20 ms, the failsafe's 3000/s.
  r.clock.set(start + 39 * kMs);
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kNormal);
  EXPECT_EQ(r.tx.commands.back().lead_us, 6000);
  EXPECT_NEAR(r.ctl.last_x0[0], 3000.0f * 0.006f, 1e-3f) << "the refused held step (9000/s) was remembered";
}

TEST(LatencyCompensation, AStateFromTheFutureIsHandledAsStaleAndCounted) {
  LoopRig r(fixed_latency(2 * kMs, 0));
  r.state(0);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  ASSERT_EQ(r.tx.commands.back().mode, Mode::kNormal);
  const int before = r.ctl.iterations;
  r.state(0, 5 * kMs);  // stamped 5 ms ahead of the receiver's clock (tolerance 2 ms)
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.ctl.iterations, before);  // not optimised from
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kHoldPlan);
  EXPECT_EQ(r.loop.counters().future_states.load(), 1);
  EXPECT_EQ(r.loop.counters().stale_cycles.load(), 1);
  // Within the tolerance it is a state like any other.
  r.state(0, 1 * kMs);
  ASSERT_TRUE(r.loop.step_realtime(r.run));
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kNormal);
  r.loop.publish_final_status();
  EXPECT_EQ(r.tx.statuses.back().rejected_future, 1);
  EXPECT_GT(r.tx.statuses.back().latency_expected_ms, 0.0f);
}

TEST(LatencyCompensation, ARepeatedLockstepTickIsNotAnsweredTwice) {
  daemon::LoopSettings s = fixed_latency(2 * kMs, 0);
  s.lockstep = true;
  LoopRig r(s);
  auto tick = [&](std::int64_t seq) {
    transport::ClockTick t;
    t.seq = seq;
    t.sim_utime = seq * 20000;
    r.inbox.offer_tick(t);
  };
  r.state(0);
  tick(1);
  ASSERT_TRUE(r.loop.step_lockstep(r.run));
  tick(1);  // the simulator republished state 1 and its tick
  EXPECT_FALSE(r.loop.step_lockstep(r.run));
  // Answered with the command already sent for it, not with a new cycle.
  ASSERT_EQ(r.tx.commands.size(), 2u);
  EXPECT_EQ(r.tx.commands[1].seq, r.tx.commands[0].seq);
  EXPECT_EQ(r.tx.commands[1].state_seq, 1);
  EXPECT_EQ(r.ctl.iterations, 1);
  EXPECT_EQ(r.loop.counters().repeated_ticks.load(), 1);
  r.state(0);
  tick(2);
  ASSERT_TRUE(r.loop.step_lockstep(r.run));
  EXPECT_EQ(r.ctl.iterations, 2);
  EXPECT_EQ(r.tx.commands.back().state_seq, 2);
  // A new simulator run, far behind: followed.
  tick(2 + 500);
  ASSERT_TRUE(r.loop.step_lockstep(r.run));
  tick(1);
  ASSERT_TRUE(r.loop.step_lockstep(r.run));
  EXPECT_EQ(r.ctl.iterations, 4);
}

TEST(DisturbanceObserver, FindsTheAccelerationTheModelMisses) {
  // The fake model: x[0] moves at u[0]/s and nothing moves the velocities x[3..5]; the
  // "plant" accelerates x[5] at -0.8 m/s^2 (a heavier vehicle). The estimate converges to it.
  test::FakeClock clock;
  test::FakeController c(&clock);
  daemon::CommandHistory h(4, {0, 0, 0, 0});
  daemon::DisturbanceSettings s;
  s.time_constant_s = 0.2;
  daemon::DisturbanceObserver obs(s, 1, 16);
  float x[16] = {};
  std::int64_t t = 0;
  EXPECT_FALSE(obs.update(c, h, x, t));  // the first state has nothing to compare with
  for (int k = 0; k < 200; ++k) {
    t += 20 * kMs;
    // The fake model ignores the estimate, so this is the integrator of a constant residual:
    // the plant's velocity keeps falling behind the model's unchanged one.
    x[5] -= 0.8f * 0.02f;
    ASSERT_TRUE(obs.update(c, h, x, t));
  }
  EXPECT_NEAR(obs.estimate()[2], -s.limit, 1e-5f);  // a constant residual integrates to the limit
  EXPECT_FLOAT_EQ(obs.estimate()[0], 0.0f);
  // A gap longer than max_gap_ns restarts the comparison instead of dividing by it.
  obs.reset();
  EXPECT_FALSE(obs.update(c, h, x, t));
  EXPECT_FALSE(obs.update(c, h, x, t + 500 * kMs));
  EXPECT_FLOAT_EQ(obs.estimate()[2], 0.0f);
}

TEST(DisturbanceObserver, RealModelConvergesToTheMismatch) {
  // The 16-state quadrotor at hover in the model; the plant is 5 % heavier: it sinks. The
  // observer, whose estimate enters the model it predicts with, settles at the plant's
  // missing acceleration, -g * 0.05 / 1.05.
  app::AppConfig cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                        {"mppi.rollouts=16", "mppi.horizon=5", "mppi.threads=1", "mppi.simd=off"});
  auto c = app::make_controller(cfg);
  const float hover = cfg.mppi.u_init[0];
  daemon::CommandHistory h(4, cfg.mppi.u_init);
  daemon::DisturbanceObserver obs(daemon::DisturbanceSettings{}, 1, 16);
  auto plant_cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                    {"model.mass=0.2625", "mppi.rollouts=16", "mppi.horizon=5", "mppi.simd=off"});
  auto plant = app::make_controller(plant_cfg);
  float x[16] = {};
  x[2] = 2.0f;
  for (int i = 12; i < 16; ++i) x[i] = hover;
  const float u[4] = {hover, hover, hover, hover};
  std::int64_t t = 0;
  for (int k = 0; k < 250; ++k) {  // 5 s
    if (obs.update(*c, h, x, t)) c->set_external_accel(obs.estimate());
    plant->propagate(x, u, 0.02f);
    t += 20 * kMs;
  }
  EXPECT_NEAR(obs.estimate()[2], -9.81f * 0.05f / 1.05f, 0.01f);
  EXPECT_NEAR(obs.estimate()[0], 0.0f, 1e-4f);
}

// Controller::positions, the hold before any goal reads it: each vehicle's xyz from a state,
// vehicle by vehicle (team3: x, y, z at 16 j), for the MPPI and the DDP controllers alike.
TEST(Controllers, PositionsAreEachVehiclesXyz) {
  const std::string dir = mppi::testing::source_dir() + "/config/tasks/";
  auto team = app::make_controller(
      app::load_config(dir + "team3_forest.yaml", {"mppi.rollouts=16", "mppi.horizon=5", "mppi.simd=off"}));
  std::vector<float> x(48, 0.0f);
  for (int j = 0; j < 3; ++j)
    for (int d = 0; d < 3; ++d) x[static_cast<std::size_t>(16 * j + d)] = static_cast<float>(10 * j + d + 1);
  float xyz[9] = {};
  ASSERT_EQ(team->positions(x.data(), xyz, 3), 3);
  for (int j = 0; j < 3; ++j)
    for (int d = 0; d < 3; ++d) EXPECT_FLOAT_EQ(xyz[3 * j + d], static_cast<float>(10 * j + d + 1));
  EXPECT_EQ(team->positions(x.data(), xyz, 2), 0) << "room for fewer vehicles than the task has";
  auto ddp = app::make_controller(app::load_config(dir + "quadrotor_forest.yaml",
                                                   {"controller=ddp", "mppi.horizon=5", "mppi.simd=off"}));
  ASSERT_EQ(ddp->positions(x.data(), xyz, 1), 1);
  EXPECT_FLOAT_EQ(xyz[2], 3.0f);
}
