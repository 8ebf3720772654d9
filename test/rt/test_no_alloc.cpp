// The hot path allocates nothing: after warm-up, cycles of the real quadrotor controller
// (CPU backend) through the loop, with states arriving, obstacles/reference inputs set,
// the status and the plan published, make zero heap allocations. Counted by replacing the
// global operator new in this test binary.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"

namespace {
std::atomic<long> g_allocs{0};
std::atomic<bool> g_counting{false};
}  // namespace

void* operator new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_allocs.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

using namespace mppi;

namespace {
// Publishes into fixed storage: what a transport must do to keep the loop allocation-free.
class NullTransport final : public transport::Transport {
 public:
  std::string self_test() override { return {}; }
  void start(transport::Inbox*) override {}
  void stop() override {}
  bool publish_command(const transport::Command& c) override {
    last = c;
    ++commands;
    return true;
  }
  bool publish_status(const transport::StatusReport&) override { return ++statuses > 0; }
  bool publish_plan(const transport::PlanView&) override { return ++plans > 0; }
  transport::Command last;
  long commands = 0, statuses = 0, plans = 0;
};
}  // namespace

TEST(HotPath, SteadyStateCyclesAllocateNothing) {
  app::AppConfig cfg = app::load_config(std::string(MPPID_SOURCE_DIR) + "/config/tasks/quadrotor_forest.yaml",
                                        {"mppi.rollouts=128", "mppi.horizon=30"});
  auto controller = app::make_controller(cfg);
  test::FakeClock clock;
  clock.sleeps.reserve(1000);  // the fake's own record must not count
  NullTransport tx;
  transport::Inbox::Expect e;
  e.nx = 16;
  e.model = 1;
  transport::Inbox inbox(e);
  daemon::LoopSettings s;
  s.status_hz = 5;  // several status messages inside the counted window
  daemon::ControlLoop loop(controller.get(), &clock, &tx, &inbox, s);
  std::atomic<bool> stop{false};
  auto offer_state = [&](std::int64_t seq) {
    auto& st = inbox.state_buffer();
    st.seq = seq;
    st.nx = 16;
    st.n = 16;
    st.vehicle_count = 1;
    st.model = 1;
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
  std::int64_t seq = 0;
  for (int k = 0; k < 20; ++k) {  // warm-up: thread pool, first touches
    offer_state(++seq);
    ASSERT_TRUE(loop.step_realtime(stop));
  }
  g_allocs = 0;
  g_counting = true;
  for (int k = 0; k < 60; ++k) {
    offer_state(++seq);
    inbox.offer_obstacles();
    loop.step_realtime(stop);
  }
  g_counting = false;
  EXPECT_EQ(g_allocs.load(), 0);
  EXPECT_EQ(tx.commands, 80);
  EXPECT_GE(tx.statuses, 5);
  EXPECT_GE(tx.plans, 5);
  EXPECT_EQ(tx.last.mode, transport::Mode::kNormal);
}
