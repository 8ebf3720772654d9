// No heap allocation per control cycle once started (the backend's interface promises it):
// the quadrotor forest at K = 256, T = 50 on two threads, through mppi::TaskController and
// through the config-driven factory. Links mppid_alloc_counter, which replaces the global
// operator new of this whole executable, hence its own test program.
#include <gtest/gtest.h>

#include "fixtures.hpp"

#include <atomic>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

constexpr int kWarmup = 2;
constexpr int kCycles = 100;

TaskInputs forest_inputs() {
  TaskInputs in;
  in.goals[0][0] = 20.0f;
  in.goals[0][2] = 2.0f;
  in.obstacles.count = 3;
  in.obstacles.items[0] = Cylinder{4.0f, 0.5f, 0.5f, 0.0f, 0.0f};
  in.obstacles.items[1] = Cylinder{7.0f, -1.0f, 0.4f, 0.0f, 0.0f};
  in.obstacles.items[2] = Cylinder{10.0f, 1.0f, 0.6f, 0.0f, 1.0f};
  return in;
}

// Runs warm-up cycles, then kCycles closed-loop cycles (with a fallback and an input update
// between some of them, as the daemon does); returns the operator-new calls during those.
std::size_t allocations_over_cycles(Controller& c) {
  EXPECT_EQ(c.nx(), Quadrotor::kNx);
  EXPECT_EQ(c.nu(), Quadrotor::kNu);
  const TaskInputs in = forest_inputs();
  c.set_inputs(in);
  Quadrotor::Params model;
  std::vector<float> x(Quadrotor::kNx, 0.0f);
  x[Quadrotor::PZ] = 2.0f;
  for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = Quadrotor::hover_speed(model);
  std::vector<float> u(Quadrotor::kNu, 0.0f);
  for (int n = 0; n < kWarmup; ++n) c.iterate(x.data(), u.data());

  bool finite = true;
  const std::size_t before = testing::allocation_count();
  for (int n = 0; n < kCycles; ++n) {
    if (n % 10 == 5) {
      c.fallback(u.data());
    } else {
      const UpdateStats& st = c.iterate(x.data(), u.data());
      finite = finite && st.finite;
    }
    if (n % 25 == 0) c.set_inputs(in);
    // The daemon's mass estimate: a new mass moves the nominal, the warm start and the plan.
    if (n % 20 == 10) c.set_mass(c.mass() * (n % 40 == 10 ? 1.1f : 1.0f / 1.1f));
    Quadrotor::step(model, x.data(), u.data(), c.dt());
  }
  const std::size_t after = testing::allocation_count();
  EXPECT_TRUE(finite);
  for (float v : x) EXPECT_TRUE(std::isfinite(v));
  return after - before;
}

MppiSettings forest_settings() { return testing::quadrotor_settings(256, 50, 1000.0f, 60.0f, 2); }

TEST(NoAlloc, CounterSeesAllocations) {
  // The counter is live in this program (else the zero below would prove nothing).
  const std::size_t before = testing::allocation_count();
  auto p = std::make_unique<std::vector<int>>(100);
  EXPECT_GE(testing::allocation_count(), before + 2);
}

TEST(NoAlloc, TaskControllerCyclesAllocateNothing) {
  for (Weighting wt : {Weighting::kCostToGo, Weighting::kTrajectory}) {
    MppiSettings s = forest_settings();
    s.weighting = wt;
    s.smoothing_window = wt == Weighting::kTrajectory ? 5 : 1;
    TaskController<QuadrotorForest> c("quadrotor_forest", s, QuadrotorForest::Params{},
                                      std::make_unique<CpuBackend<QuadrotorForest>>(s));
    EXPECT_EQ(allocations_over_cycles(c), 0u) << to_string(wt);
  }
}

TEST(NoAlloc, FactoryControllerCyclesAllocateNothing) {
  for (const std::string simd : {"off", "auto"}) {
    const auto config = app::load_config(app::default_config_path("quadrotor_forest"),
                                         {"mppi.rollouts=256", "mppi.horizon=50", "mppi.threads=2", "backend=cpu",
                                          "mppi.simd=" + simd});
    ASSERT_EQ(config.mppi.rollouts, 256);
    ASSERT_EQ(config.mppi.horizon, 50);
    ASSERT_EQ(config.mppi.threads, 2);
    auto c = app::make_controller(config);
    ASSERT_NE(c, nullptr);
    const simd::Target t = simd == "off" ? simd::Target::kScalar : simd::best();
    EXPECT_EQ(std::string(c->backend()), t == simd::Target::kScalar ? std::string("cpu") : std::string("cpu-") + simd::name(t));
    EXPECT_EQ(c->task(), "quadrotor_forest");
    EXPECT_EQ(allocations_over_cycles(*c), 0u) << simd;
    // The anytime cycle's chunked rollouts, with a stop flag that stays clear.
    std::atomic<bool> stop{false};
    c->set_stop_flag(&stop);
    EXPECT_EQ(allocations_over_cycles(*c), 0u) << simd << " with a stop flag";
  }
}

// A forest controller of one SIMD target, its first cycle flown from a hover 2 m up, and a fan
// of 32 reserved: the rig of the cycles below that keep and sample their rollouts.
struct HoverForest {
  explicit HoverForest(const std::string& simd)
      : s(with_simd(simd)),
        c("quadrotor_forest", s, QuadrotorForest::Params{}, std::make_unique<CpuBackend<QuadrotorForest>>(s)),
        x(Quadrotor::kNx, 0.0f),
        u(Quadrotor::kNu, 0.0f) {
    c.set_inputs(forest_inputs());
    fan.reserve(32, 1, s.horizon);
    x[Quadrotor::PZ] = 2.0f;
    for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = Quadrotor::hover_speed(model);
    c.iterate(x.data(), u.data());
  }
  static MppiSettings with_simd(const std::string& simd) {
    MppiSettings m = forest_settings();
    m.simd = simd;
    return m;
  }
  MppiSettings s;
  TaskController<QuadrotorForest> c;
  RolloutFan fan;
  Quadrotor::Params model;
  std::vector<float> x, u;
};

// The work sizer's changes (Controller::set_active_rollouts) between cycles, with and without
// the anytime stop flag, and the rollout fan of a cycle run at fewer than K.
TEST(NoAlloc, ChangingTheActiveRolloutsAllocatesNothing) {
  for (const std::string simd : {"off", "auto"}) {
    HoverForest r(simd);
    auto& [s, c, fan, model, x, u] = r;
    std::atomic<bool> stop{false};
    const int counts[] = {128, 64, 256, 96, 16, 256};
    int ran = 0;
    const std::size_t before = testing::allocation_count();
    for (int n = 0; n < 60; ++n) {
      if (n == 30) c.set_stop_flag(&stop);
      c.set_active_rollouts(counts[n % 6]);
      if (n % 4 == 0) c.keep_rollouts();
      ran += c.iterate(x.data(), u.data()).rollouts == counts[n % 6];
      c.fan(16, 16, &fan);
      Quadrotor::step(model, x.data(), u.data(), c.dt());
    }
    EXPECT_EQ(testing::allocation_count() - before, 0u) << simd;
    EXPECT_EQ(ran, 60) << simd;
    EXPECT_EQ(c.active_rollouts(), 256) << simd;
  }
}

TEST(NoAlloc, CyclesThatKeepAndSampleTheirRolloutsAllocateNothing) {
  // tools/view's rollout fan: every fifth cycle keeps its rollouts, then a sample of 32 is
  // rebuilt into a fan reserved before.
  for (const std::string simd : {"off", "auto"}) {
    HoverForest r(simd);
    auto& [s, c, fan, model, x, u] = r;
    int fans = 0;
    const std::size_t before = testing::allocation_count();
    for (int n = 0; n < 50; ++n) {
      if (n % 5 == 0) c.keep_rollouts();
      c.iterate(x.data(), u.data());
      if (c.fan(16, 16, &fan)) ++fans;
      Quadrotor::step(model, x.data(), u.data(), c.dt());
    }
    EXPECT_EQ(testing::allocation_count() - before, 0u) << simd;
    EXPECT_EQ(fans, 10) << simd;
    EXPECT_EQ(fan.count, 32) << simd;
  }
}

TEST(NoAlloc, DdpControllerCyclesAllocateNothing) {
  // The MPC-DDP baseline, as the daemon builds it (controller: ddp).
  const auto config = app::load_config(app::default_config_path("quadrotor_forest"),
                                       {"controller=ddp", "mppi.horizon=50"});
  auto c = app::make_controller(config);
  ASSERT_NE(c, nullptr);
  ASSERT_STREQ(c->backend(), "ddp");
  EXPECT_EQ(allocations_over_cycles(*c), 0u);
}

}  // namespace
}  // namespace mppi
