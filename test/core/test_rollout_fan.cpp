// The display sample of a cycle's rollouts (rollout_fan.hpp): the rebuilt rollouts are the
// ones the backend weighed (their costs agree: bit for bit with the scalar kernel), the top
// ones are the lowest-cost, the weights are the update's, and nothing is kept unless asked.
#include <gtest/gtest.h>

#include "fixtures.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

TaskInputs forest_inputs() {
  TaskInputs in;
  in.vehicle_count = 3;
  for (int j = 0; j < 3; ++j) {
    in.goals[j][0] = 20.0f;
    in.goals[j][1] = static_cast<float>(j - 1);
    in.goals[j][2] = 2.0f;
  }
  in.obstacles.count = 3;
  in.obstacles.items[0] = Cylinder{4.0f, 0.5f, 0.5f, 0.0f, 0.0f};
  in.obstacles.items[1] = Cylinder{7.0f, -1.0f, 0.4f, 0.0f, 0.0f};
  in.obstacles.items[2] = Cylinder{10.0f, 1.0f, 0.6f, 0.0f, 1.0f};
  return in;
}

template <class T>
std::vector<float> hover_state() {
  Quadrotor::Params model;
  std::vector<float> x(T::kNx, 0.0f);
  for (int j = 0; j < T::kVehicles; ++j) {
    float* xj = x.data() + j * Quadrotor::kNx;
    xj[Quadrotor::PY] = static_cast<float>(j - 1);
    xj[Quadrotor::PZ] = 2.0f;
    for (int i = 0; i < 4; ++i) xj[Quadrotor::M1 + i] = Quadrotor::hover_speed(model);
  }
  return x;
}

template <class T>
MppiSettings settings_for(const std::string& simd) {
  MppiSettings s = testing::quadrotor_settings(256, 40, 1000.0f, 60.0f, 2);
  const float hover = Quadrotor::hover_speed(Quadrotor::Params{});
  s.sigma.assign(T::kNu, 60.0f);
  s.u_min.assign(T::kNu, 0.0f);
  s.u_max.assign(T::kNu, 6000.0f);
  s.u_init.assign(T::kNu, hover);
  s.u_nominal.assign(T::kNu, hover);
  s.simd = simd;
  return s;
}

// Three cycles (the plan warm-started, so the fan's plan is not u_init), the last kept.
template <class T>
std::unique_ptr<TaskController<T>> controller_after_kept_cycle(const std::string& simd) {
  const MppiSettings s = settings_for<T>(simd);
  auto c = std::make_unique<TaskController<T>>("fan", s, typename T::Params{}, std::make_unique<CpuBackend<T>>(s));
  c->set_inputs(forest_inputs());
  const std::vector<float> x = hover_state<T>();
  std::vector<float> u(T::kNu);
  c->iterate(x.data(), u.data());
  c->iterate(x.data(), u.data());
  c->keep_rollouts();
  c->iterate(x.data(), u.data());
  return c;
}

template <class T>
void expect_fan_is_the_update(const std::string& simd, float cost_tolerance) {
  auto c = controller_after_kept_cycle<T>(simd);
  const MppiSettings& s = c->settings();
  RolloutFan fan;
  fan.reserve(16, T::kVehicles, s.horizon);
  ASSERT_TRUE(c->fan(6, 10, &fan));
  const std::vector<float> costs = c->rollout_costs();
  ASSERT_EQ(fan.count, 16);
  EXPECT_EQ(fan.top, 6);
  EXPECT_EQ(fan.total, s.rollouts);
  EXPECT_EQ(fan.vehicles, T::kVehicles);
  EXPECT_EQ(fan.steps, s.horizon + 1);
  EXPECT_EQ(fan.cycle, c->noise_cycle() - 1);

  // The top six are the six lowest costs, lowest first.
  std::vector<float> sorted = costs;
  std::sort(sorted.begin(), sorted.end());
  for (int r = 0; r < fan.top; ++r) EXPECT_EQ(fan.cost[r], sorted[static_cast<std::size_t>(r)]) << r;
  // The random ten: one from each tenth of the sample index, none of them a top one.
  for (int m = 0; m < 10; ++m) {
    const int k = fan.index[static_cast<std::size_t>(fan.top + m)];
    EXPECT_GE(k, m * s.rollouts / 10);
    EXPECT_LT(k, (m + 1) * s.rollouts / 10);
    EXPECT_EQ(std::count(fan.index.begin(), fan.index.begin() + fan.top, k), 0) << k;
  }
  // So the weights shown never add up past the whole.
  EXPECT_LE(std::accumulate(fan.weight.begin(), fan.weight.begin() + fan.count, 0.0), 1.0 + 1e-5);
  const float best = sorted.front();
  double sum = 0.0;
  for (float q : costs) sum += std::exp(-(static_cast<double>(q) - best) / s.lambda);
  for (int r = 0; r < fan.count; ++r) {
    const int k = fan.index[static_cast<std::size_t>(r)];
    EXPECT_EQ(fan.cost[r], costs[static_cast<std::size_t>(k)]);
    // The rebuilt rollout is the one the backend costed.
    EXPECT_NEAR(fan.rebuilt_cost[r], fan.cost[r], cost_tolerance * std::max(1.0f, std::abs(fan.cost[r]))) << simd << " k=" << k;
    EXPECT_NEAR(fan.weight[r], std::exp(-(static_cast<double>(fan.cost[r]) - best) / s.lambda) / sum, 1e-5);
  }
  EXPECT_NEAR(fan.weight[0], *std::max_element(fan.weight.begin(), fan.weight.begin() + fan.count), 0.0f);
  // Positions: each vehicle starts where the state is and moves along its rollout.
  const std::vector<float> x = hover_state<T>();
  const std::size_t per = static_cast<std::size_t>(fan.steps) * 3;
  for (int r = 0; r < fan.count; ++r) {
    for (int j = 0; j < T::kVehicles; ++j) {
      const float* p = fan.xyz.data() + (static_cast<std::size_t>(r) * T::kVehicles + j) * per;
      EXPECT_EQ(p[0], x[static_cast<std::size_t>(j * Quadrotor::kNx + Quadrotor::PX)]);
      EXPECT_EQ(p[1], x[static_cast<std::size_t>(j * Quadrotor::kNx + Quadrotor::PY)]);
      EXPECT_EQ(p[2], x[static_cast<std::size_t>(j * Quadrotor::kNx + Quadrotor::PZ)]);
      const float* end = p + per - 3;
      EXPECT_GT(std::hypot(end[0] - p[0], end[1] - p[1], end[2] - p[2]), 0.0f);
      for (std::size_t i = 0; i < per; ++i) EXPECT_TRUE(std::isfinite(p[i]));
    }
  }
}

TEST(RolloutFan, ScalarBackendRebuildsEachRolloutBitForBit) {
  expect_fan_is_the_update<QuadrotorForest>("off", 0.0f);
  expect_fan_is_the_update<Team3Forest>("off", 0.0f);
}

TEST(RolloutFan, SimdBackendRebuildsEachRolloutToItsTolerance) {
  // The SIMD targets differ from the scalar code only in the transcendentals (a few ulp over
  // the horizon: test_simd.cpp's tolerance).
  expect_fan_is_the_update<QuadrotorForest>("auto", 1e-4f);
  expect_fan_is_the_update<Team3Forest>("auto", 1e-4f);
}

TEST(RolloutFan, NothingWithoutKeepAndOnlyForTheCycleKept) {
  using T = QuadrotorForest;
  const MppiSettings s = settings_for<T>("off");
  TaskController<T> c("fan", s, T::Params{}, std::make_unique<CpuBackend<T>>(s));
  c.set_inputs(forest_inputs());
  const std::vector<float> x = hover_state<T>();
  std::vector<float> u(T::kNu);
  RolloutFan fan;
  fan.reserve(8, 1, s.horizon);
  c.iterate(x.data(), u.data());
  EXPECT_FALSE(c.fan(4, 4, &fan));
  EXPECT_EQ(fan.count, 0);
  c.keep_rollouts();
  c.iterate(x.data(), u.data());
  EXPECT_TRUE(c.fan(4, 4, &fan));
  EXPECT_EQ(fan.count, 8);
  c.iterate(x.data(), u.data());  // not kept: the fan of the cycle before is not offered again
  EXPECT_FALSE(c.fan(4, 4, &fan));
}

TEST(RolloutFan, RandomOnesSkipTheTopOnesEvenInSmallStrata) {
  // 16 top of 40 rollouts and 20 random ones in strata of two: most strata hold a top one.
  const int top[4] = {3, 4, 10, 11};
  EXPECT_EQ(fan_detail::not_in(top, 4, 2, 4, 1), 2);   // draws 3 (taken): moves on, wraps to 2
  EXPECT_EQ(fan_detail::not_in(top, 4, 10, 12, 0), 10);  // both taken: keeps the draw
  EXPECT_EQ(fan_detail::not_in(top, 4, 4, 6, 0), 5);
}

TEST(RolloutFan, CapacityBoundsTheSample) {
  auto c = controller_after_kept_cycle<QuadrotorForest>("off");
  RolloutFan fan;
  fan.reserve(5, 1, c->settings().horizon);
  ASSERT_TRUE(c->fan(4, 10, &fan));
  EXPECT_EQ(fan.count, 5);
  EXPECT_EQ(fan.top, 4);
  ASSERT_TRUE(c->fan(0, 3, &fan));
  EXPECT_EQ(fan.count, 3);
  EXPECT_EQ(fan.top, 0);
}

}  // namespace
}  // namespace mppi
