// The hot path allocates nothing: after warm-up, cycles of the real quadrotor controller
// (CPU backend) through the loop, with states arriving, obstacles/reference inputs set,
// the status and the plan published, make zero heap allocations. Counted by replacing the
// global operator new in this test binary.
#include <cstdint>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "source_dir.hpp"

namespace {
std::atomic<long> g_allocs{0};
std::atomic<bool> g_counting{false};
}  // namespace

void* operator new(std::size_t n) {
  // The live optimizer's builder thread allocates by design (off the loop thread).
  if (g_counting.load(std::memory_order_relaxed) && !mppi::daemon::LiveOptimizer::on_builder_thread())
    g_allocs.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

using namespace mppi;

namespace {
// Publishes into fixed storage: what a transport must do to keep the loop allocation-free.
class NullTransport final : public test::InMemoryTransport {
 public:
  bool publish_command(const transport::Command& c) override {
    last = c;
    ++commands;
    return true;
  }
  bool publish_status(const transport::StatusReport&) override { return ++statuses > 0; }
  bool publish_plan(const transport::PlanView&) override { return ++plans > 0; }
  bool publish_rollouts(const transport::RolloutsView& r) override {
    for (long i = 0; i < static_cast<long>(r.count) * r.vehicles * r.steps * 3; ++i)
      if (!std::isfinite(r.xyz[i])) return false;
    last_fan = r.count;
    return ++fans > 0;
  }
  transport::Command last;
  long commands = 0, statuses = 0, plans = 0, fans = 0, last_fan = 0;
};
}  // namespace

// trigger state: each state arrives a period after the last, so each starts its cycle (the
// wait on the inbox's semaphore is on the path).
void steady_state_cycles_allocate_nothing(daemon::Trigger trigger, bool rollouts = false) {
  app::AppConfig cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                        {"mppi.rollouts=128", "mppi.horizon=30"});
  auto controller = app::make_controller(cfg);
  test::FakeClock clock;
  clock.sleeps.reserve(1000);  // the fake's own record must not count
  NullTransport tx;
  transport::Inbox::Expect e;
  e.nx = 16;
  e.model = 1;
  e.wake_on_state = trigger == daemon::Trigger::kState;
  e.local_map = true;  // a local map every fifth cycle: the forest cost reads it in place
  transport::Inbox inbox(e);
  daemon::LoopSettings s;
  s.trigger = trigger;
  s.status_hz = 5;  // several status messages inside the counted window
  if (rollouts) s.rollouts = daemon::FanSettings{10.0, 8, 8};  // every fifth cycle: tools/view's fan
  s.disturbance.mass.estimate = true;  // the mass estimate and the hover it moves, as the task files fly
  s.latency.delay_estimate.estimate = true;  // and the actuation delay estimate (its window is scored here)
  daemon::ControlLoop loop(controller.get(), &clock, &tx, &inbox, s);
  std::atomic<bool> stop{false};
  auto offer_state = [&](std::int64_t seq) {
    if (trigger == daemon::Trigger::kState && seq > 1) clock.advance(20 * rt::kNsPerMs);
    auto& st = inbox.state_buffer();
    test::shape_state(st, seq);
    st.recv_ns = clock.now_ns();
    for (int i = 0; i < 16; ++i) st.x[i] = 0.0f;
    st.x[2] = 2.0f;
    for (int i = 12; i < 16; ++i) st.x[i] = 3168.4f;
    inbox.offer_state();
  };
  auto& obs = inbox.obstacles_buffer();
  obs.count = 100;  // more than 64: the nearest-64 selection runs every cycle
  for (int i = 0; i < 100; ++i) obs.items[i] = Cylinder{4.0f + static_cast<float>(i % 10), static_cast<float>(i / 10), 0.3f, 0, 0};
  inbox.offer_obstacles();
  std::int64_t map_seq = 0;
  auto offer_map = [&] {
    transport::LocalMapInput& m = *inbox.map_buffer();
    m.seq = ++map_seq;
    m.utime = 0;
    m.recv_ns = clock.now_ns();
    DistanceFieldGrid& g = m.grid;
    g.origin[0] = -5.0f, g.origin[1] = -5.0f, g.origin[2] = 0.0f;
    g.resolution = 0.25f;
    g.nx = 40, g.ny = 40, g.nz = 16;
    g.n_cells = g.nx * g.ny * g.nz;
    g.max_distance = 5.0f;
    for (int c = 0; c < g.n_cells; ++c) g.distance_mm[c] = static_cast<std::int16_t>(2000 + c % 1000);
    inbox.offer_map();
  };
  std::int64_t seq = 0;
  for (int k = 0; k < 20; ++k) {  // warm-up: thread pool, first touches
    if (k % 5 == 0) offer_map();
    offer_state(++seq);
    ASSERT_TRUE(loop.step_realtime(stop));
  }
  g_allocs = 0;
  g_counting = true;
  for (int k = 0; k < 60; ++k) {
    offer_state(++seq);
    inbox.offer_obstacles();
    if (k % 5 == 0) offer_map();
    loop.step_realtime(stop);
  }
  g_counting = false;
  EXPECT_EQ(g_allocs.load(), 0);
  EXPECT_EQ(inbox.counters.maps.load(), 16);
  EXPECT_EQ(inbox.counters.maps_rejected(), 0);
  EXPECT_EQ(tx.commands, 80);
  EXPECT_GE(tx.statuses, 5);
  EXPECT_GE(tx.plans, 5);
  EXPECT_EQ(tx.last.mode, transport::Mode::kNormal);
  if (trigger == daemon::Trigger::kState) {
    EXPECT_EQ(loop.counters().state_triggered.load(), 80);
  }
  if (rollouts) {
    EXPECT_GE(tx.fans, 15);  // 80 cycles, one fan in five
    EXPECT_EQ(tx.last_fan, 16);
  } else {
    EXPECT_EQ(tx.fans, 0);  // off by default
  }
}

TEST(HotPath, SteadyStateCyclesAllocateNothing) { steady_state_cycles_allocate_nothing(daemon::Trigger::kClock); }
TEST(HotPath, StateTriggeredCyclesAllocateNothing) { steady_state_cycles_allocate_nothing(daemon::Trigger::kState); }
TEST(HotPath, CyclesPublishingRolloutsAllocateNothing) {
  steady_state_cycles_allocate_nothing(daemon::Trigger::kClock, true);
}

// A live optimizer update: the builder thread builds the new controller (allocating, off
// the loop thread); the loop forwards the updates, swaps the new controller in between two
// cycles (plan resampled onto the new horizon) and runs on: zero heap allocations on the
// loop thread over the forwarding cycle, the swap and the cycles after it.
TEST(HotPath, LiveOptimizerSwapAllocatesNothingInTheLoop) {
  const app::AppConfig cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                              {"mppi.rollouts=128", "mppi.horizon=30"});
  daemon::LiveSettings lim;
  lim.max_horizon = 100;
  daemon::LiveOptimizer live(app::make_controller(cfg),
                             [cfg](const MppiSettings& s) {
                               return app::make_controller(cfg.with_mppi(s));
                             },
                             lim);
  test::FakeClock clock;
  clock.sleeps.reserve(1000);
  NullTransport tx;
  transport::Inbox::Expect e;
  e.nx = 16;
  e.model = 1;
  transport::Inbox inbox(e);
  daemon::LoopSettings s;
  s.status_hz = 5;
  daemon::ControlLoop loop(live.current(), &clock, &tx, &inbox, s);
  loop.set_live_optimizer(&live);
  std::atomic<bool> stop{false};
  std::int64_t seq = 0;
  auto offer_state = [&] {
    auto& st = inbox.state_buffer();
    test::shape_state(st, ++seq);
    st.recv_ns = clock.now_ns();
    st.sample_utime = clock.now_ns() / 1000;
    for (int i = 0; i < 16; ++i) st.x[i] = 0.0f;
    st.x[2] = 2.0f;
    for (int i = 12; i < 16; ++i) st.x[i] = 3168.4f;
    inbox.offer_state();
  };
  auto& obs = inbox.obstacles_buffer();
  obs.count = 100;
  for (int i = 0; i < 100; ++i) obs.items[i] = Cylinder{4.0f + static_cast<float>(i % 10), static_cast<float>(i / 10), 0.3f, 0, 0};
  inbox.offer_obstacles();
  for (int k = 0; k < 20; ++k) {
    offer_state();
    ASSERT_TRUE(loop.step_realtime(stop));
  }
  const Controller* before = &loop.controller();
  auto param = [&](const char* key, double v) {
    transport::ParamUpdate p;
    std::strncpy(p.key, key, sizeof(p.key) - 1);
    p.value = v;
    inbox.offer_param(p);
  };
  param("mppi.rollouts", 256);
  param("mppi.horizon", 45);
  param("mppi.lambda", 2.0);
  // The cycle that forwards the updates to the builder.
  g_allocs = 0;
  g_counting = true;
  offer_state();
  loop.step_realtime(stop);
  g_counting = false;
  EXPECT_EQ(g_allocs.load(), 0) << "forwarding";
  // The swap and the cycles after it. The builder may take the three updates in one build or,
  // when the first woke it before the others were queued, in two: the loop takes each in turn
  // (the builder's allocations are not the loop's).
  g_allocs = 0;
  g_counting = true;
  for (int k = 0; k < 40; ++k) {
    if (loop.counters().params_applied.load() < 3) live.wait_idle();
    offer_state();
    inbox.offer_obstacles();
    loop.step_realtime(stop);
  }
  g_counting = false;
  EXPECT_EQ(g_allocs.load(), 0) << "swap and the cycles after it";
  EXPECT_NE(&loop.controller(), before);
  EXPECT_EQ(loop.controller().horizon(), 45);
  EXPECT_EQ(loop.controller().settings().rollouts, 256);
  EXPECT_EQ(loop.counters().params_applied.load(), 3);
  EXPECT_EQ(tx.commands, 61);
  EXPECT_EQ(tx.last.mode, transport::Mode::kNormal);
}
