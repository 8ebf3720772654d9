#include <gtest/gtest.h>

#include "fixtures.hpp"

#include <cmath>
#include <memory>
#include <numeric>
#include <vector>

#include "mppi/cpu_backend.hpp"
#include "mppi/optimizer.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

MppiSettings quad_settings(int k = 256, int t = 50) { return testing::quadrotor_settings(k, t, 10.0f, 150.0f); }

QuadrotorForest::Params forest_params() {
  QuadrotorForest::Params p{};
  p.cost.goal[0][0] = 20.0f;
  p.cost.goal[0][1] = 0.0f;
  p.cost.goal[0][2] = 2.0f;
  p.cost.obstacles.count = 1;
  p.cost.obstacles.items[0] = Cylinder{5.0f, 0.5f, 0.5f, 0.0f, 0.0f};
  return p;
}

std::vector<float> run_cycles(int threads, int cycles) {
  MppiSettings s = quad_settings();
  s.threads = threads;
  Mppi<QuadrotorForest> mppi(s, std::make_unique<CpuBackend<QuadrotorForest>>(s));
  const auto params = forest_params();
  auto x = testing::quad_hover_state(Quadrotor::Params{});
  float u[4];
  for (int c = 0; c < cycles; ++c) mppi.iterate(x.data(), params, u);
  return mppi.plan();
}

TEST(CpuBackend, SameSeedSamePlan) { EXPECT_EQ(run_cycles(1, 3), run_cycles(1, 3)); }

TEST(CpuBackend, ThreadCountDoesNotChangeThePlan) { EXPECT_EQ(run_cycles(1, 3), run_cycles(2, 3)); }

TEST(CpuBackend, PlanStaysInsideLimitsAndFinite) {
  const auto plan = run_cycles(2, 5);
  for (float u : plan) {
    EXPECT_TRUE(std::isfinite(u));
    EXPECT_GE(u, 0.0f);
    EXPECT_LE(u, 6000.0f);
  }
}

}  // namespace
}  // namespace mppi

#include "mppi/controller.hpp"
namespace mppi {
namespace {
TEST(Controller, EveryTaskInstantiates) {
  for (const auto& name : task_names()) {
    const bool known = visit_task(name, [&](auto tag) {
      using T = typename decltype(tag)::type;
      typename T::Params params{};
      EXPECT_EQ(set_task_param<T>(params, "model.nonexistent", 1.0), "model.nonexistent: unknown parameter");
    });
    EXPECT_TRUE(known) << name;
  }
}
}  // namespace
}  // namespace mppi
