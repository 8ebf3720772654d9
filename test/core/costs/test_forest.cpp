// The forest cost (core/include/mppi/costs/forest.hpp), alone and in a team of three, against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "../fixtures.hpp"
#include "mppi/costs/forest.hpp"
#include "mppi/models/quadrotor.hpp"

namespace mppi {
namespace {

using Q = Quadrotor;
using Team = testing::QuadrotorTeam3;

ForestCost<Quadrotor>::Params forest_cost_params() {
  ForestCost<Quadrotor>::Params c{};
  c.goal[0][0] = 10.0f;
  c.goal[0][1] = 0.0f;
  c.goal[0][2] = 1.0f;
  return c;
}

TEST(ForestCost, GoalYawSpeedTermsByHand) {
  auto c = forest_cost_params();
  std::vector<float> x(16, 0.0f);
  x[Q::PX] = 7.0f;   // dx = -3
  x[Q::PY] = 1.0f;   // dy = 1
  x[Q::PZ] = 1.5f;   // dz = 0.5
  x[Q::VX] = 2.0f;
  x[Q::VZ] = -1.0f;
  x[Q::YAW] = 0.2f;
  bool crash = false;
  // 2.5 (9 + 1) + 150 * 0.25 + 50 * 0.04 + (4 + 1) = 25 + 37.5 + 2 + 5 = 69.5
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash), 69.5f, 1e-4f);
  EXPECT_FALSE(crash);
  // Terminal: w_terminal times the goal terms only.
  c.w_terminal = 2.0f;
  EXPECT_NEAR(ForestCost<Quadrotor>::terminal(c, 0, x.data()), 2.0f * 62.5f, 1e-3f);
}

TEST(ForestCost, GoalPullTurnsLinearBeyondTheRadius) {
  auto c = forest_cost_params();  // goal (10, 0, 1)
  std::vector<float> x(16, 0.0f);
  x[Q::PZ] = 1.0f;
  bool crash = false;
  auto cost_at = [&](float px, float py) {
    x[Q::PX] = px;
    x[Q::PY] = py;
    return ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash);
  };
  // Off (the paper's quadratic): 2.5 * 25 at 5 m.
  EXPECT_NEAR(cost_at(5.0f, 0.0f), 2.5 * 25.0, 1e-4);
  c.w_xy = 25.0f;
  c.xy_linear_beyond = 2.0f;
  // Inside the radius: the quadratic, unchanged (1.2 m: 25 * 1.44).
  EXPECT_NEAR(cost_at(10.0f, 1.2f), 25.0 * 1.44, 1e-4);
  // At the radius both shapes agree; beyond it, r (2 e - r): e = 5 (3-4-5) gives 2 * 8 = 16.
  EXPECT_NEAR(cost_at(10.0f, 2.0f), 25.0 * 4.0, 1e-4);
  EXPECT_NEAR(cost_at(7.0f, 4.0f), 25.0 * 16.0, 1e-3);
  // Slope 2 w_xy r per metre, whatever the distance: 40 m and 41 m differ by 100.
  EXPECT_NEAR(cost_at(-31.0f, 0.0f) - cost_at(-30.0f, 0.0f), 2.0 * 25.0 * 2.0, 1e-2);
  // Continuous at the radius (no step a rollout could exploit).
  EXPECT_NEAR(cost_at(10.0f, 2.0001f) - cost_at(10.0f, 1.9999f), 25.0 * 4.0 * 0.0002, 1e-2);
  EXPECT_FALSE(crash);
  // The terminal term uses the same shape.
  c.w_terminal = 3.0f;
  x[Q::PX] = 7.0f;
  x[Q::PY] = 4.0f;
  EXPECT_NEAR(ForestCost<Quadrotor>::terminal(c, 0, x.data()), 3.0 * 25.0 * 16.0, 1e-2);
}

TEST(ForestCost, SpeedAboveTheLimitPaysTheSquareOfTheExcess) {
  auto c = forest_cost_params();  // goal (10, 0, 1)
  std::vector<float> x(16, 0.0f);
  x[Q::PX] = 10.0f;
  x[Q::PZ] = 1.0f;
  x[Q::VX] = 3.0f;
  x[Q::VY] = 4.0f;  // |v| = 5 m/s
  bool crash = false;
  auto cost = [&] { return ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash); };
  // Off by default: only the paper's |v|^2.
  EXPECT_NEAR(cost(), 25.0, 1e-4);
  c.max_speed = 4.0f;
  c.w_max_speed = 100.0f;
  // 25 + 100 (5 - 4)^2
  EXPECT_NEAR(cost(), 125.0, 1e-3);
  c.max_speed = 6.0f;  // below the limit: nothing added
  EXPECT_NEAR(cost(), 25.0, 1e-4);
  x[Q::VZ] = std::sqrt(39.0f);  // |v| = 8: 25 + 39 + 100 * 4
  EXPECT_NEAR(cost(), 464.0, 1e-2);
  EXPECT_FALSE(crash);
}

TEST(ForestCost, GroundCrash) {
  const auto c = forest_cost_params();
  std::vector<float> x(16, 0.0f);
  x[Q::PX] = 10.0f;
  x[Q::PZ] = -0.1f;  // below ground_z = 0; dz = -1.1
  bool crash = false;
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash), 150.0f * 1.21f + 1000.0f, 1e-3f);
  EXPECT_TRUE(crash);
  x[Q::PZ] = 0.1f;
  crash = false;
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash), 150.0f * 0.81f, 1e-3f);
  EXPECT_FALSE(crash);
}

TEST(ForestCost, ObstacleProximityAndCrash) {
  auto c = forest_cost_params();
  c.obstacles.count = 1;
  c.obstacles.items[0] = Cylinder{10.0f, 3.0f, 0.5f, 0.0f, 0.0f};
  std::vector<float> x(16, 0.0f);
  x[Q::PX] = 10.0f;
  x[Q::PZ] = 1.0f;  // at the goal: only the obstacle term remains
  bool crash = false;
  // Surface distance d = 3 - 0.5 = 2.5: 350 exp(-6.25 / 12) = 350 * 0.594 = 207.9
  const double expected = 350.0 * std::exp(-6.25 / 12.0);
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash), expected, 1e-3);
  EXPECT_FALSE(crash);
  // Inside the cylinder (axis 0.2 m away: d = -0.3): crash, w_crash added.
  x[Q::PY] = 2.8f;
  const double inside = 2.5 * 2.8 * 2.8 + 350.0 * std::exp(-0.09 / 12.0) + 1000.0;
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash), inside, 1e-3);
  EXPECT_TRUE(crash);
  // Within the vehicle radius (0.15) of the surface: a crash; just outside it: none.
  x[Q::PY] = 3.0f - 0.5f - 0.1f;
  crash = false;
  ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash);
  EXPECT_TRUE(crash);
  x[Q::PY] = 3.0f - 0.5f - 0.2f;
  crash = false;
  ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 0.0f, &crash);
  EXPECT_FALSE(crash);
  // A moving obstacle (vy = 1 m/s) is predicted at time t: at t = 2 s it sits 2 m further.
  c.obstacles.items[0].vy = 1.0f;
  x[Q::PY] = 5.0f;
  crash = false;
  EXPECT_NEAR(ForestCost<Quadrotor>::vehicle(c, 0, x.data(), 2.0f, &crash),
              2.5 * 25.0 + 350.0 * std::exp(-0.25 / 12.0) + 1000.0, 1e-3);
  EXPECT_TRUE(crash);
}

TEST(ForestCost, StickyCrashKeepsChargingAfterAMovingObstaclePassed) {
  Team::Params p{};
  for (int j = 0; j < 3; ++j) {
    p.cost.goal[j][1] = 10.0f * static_cast<float>(j);
    p.cost.goal[j][2] = 1.0f;
  }
  // One cylinder moving at 5 m/s in x, through vehicle 1's spot at t = 0.
  p.cost.obstacles.count = 1;
  p.cost.obstacles.items[0] = Cylinder{0.0f, 10.0f, 0.3f, 5.0f, 0.0f};
  std::vector<float> x(48, 0.0f);
  for (int j = 0; j < 3; ++j) {
    x[j * 16 + Q::PY] = 10.0f * static_cast<float>(j);  // everyone at its goal
    x[j * 16 + Q::PZ] = 1.0f;
  }
  auto obstacle_terms = [&](float t) {  // the obstacle terms of the three vehicles at time t
    float q = 0.0f;
    for (int j = 0; j < 3; ++j) {
      const float dj = p.cost.obstacles.nearest_surface(x[j * 16 + Q::PX], x[j * 16 + Q::PY], t);
      q += 350.0f * std::exp(-(dj * dj) / 12.0f);
    }
    return q;
  };
  for (float sticky : {0.0f, 1.0f}) {
    p.cost.crash_sticky = sticky;
    std::uint32_t crashed = 0;
    // t = 0: inside the cylinder: a crash of vehicle 1, charged either way.
    EXPECT_NEAR(Team::running(p, x.data(), 0.0f, &crashed), obstacle_terms(0.0f) + 1000.0f, 1e-2);
    EXPECT_EQ(crashed, 0b010u);
    // t = 1: the cylinder is 5 m on; the frozen vehicle is clear of it. Sticky: still charged.
    const float later = Team::running(p, x.data(), 1.0f, &crashed);
    EXPECT_NEAR(later, obstacle_terms(1.0f) + (sticky > 0.0f ? 1000.0f : 0.0f), 1e-2) << "sticky " << sticky;
    EXPECT_EQ(crashed, 0b010u);
    // A vehicle that never crashed is never charged (vehicle 1's bit alone carries it).
    std::uint32_t none = 0;
    EXPECT_NEAR(Team::running(p, x.data(), 1.0f, &none), obstacle_terms(1.0f), 1e-2);
    EXPECT_EQ(none, 0u);
  }
}

TEST(ForestCost, PairSeparationAndCollision) {
  Team::Params p{};
  for (int j = 0; j < 3; ++j) {
    p.cost.goal[j][0] = 0.0f;
    p.cost.goal[j][1] = 10.0f * static_cast<float>(j);
    p.cost.goal[j][2] = 1.0f;
  }
  std::vector<float> x(48, 0.0f);
  for (int j = 0; j < 3; ++j) {
    x[j * 16 + Q::PY] = 10.0f * static_cast<float>(j);  // everyone at its goal, far apart
    x[j * 16 + Q::PZ] = 1.0f;
  }
  std::uint32_t crashed = 0;
  // Pairs 100 m and 400 m apart: exp(-100) ~ 0.
  EXPECT_NEAR(Team::running(p, x.data(), 0.0f, &crashed), 0.0f, 1e-6f);
  EXPECT_EQ(crashed, 0u);
  // Vehicle 2 moved to 0.5 m from vehicle 0 (beyond 2 r = 0.3): 350 exp(-0.25 / 1), no crash.
  x[32 + Q::PY] = 0.0f;
  x[32 + Q::PX] = 0.3f;
  x[32 + Q::PZ] = 1.4f;
  const double goal2 = 2.5 * (0.09 + 400.0) + 150.0 * 0.16;  // vehicle 2's goal is (0, 20, 1)
  EXPECT_NEAR(Team::running(p, x.data(), 0.0f, &crashed), goal2 + 350.0 * std::exp(-0.25), 1e-2);
  EXPECT_EQ(crashed, 0u);
  bool pair_hit = false;
  EXPECT_NEAR(ForestCost<Quadrotor>::pair(p.cost, x.data(), x.data() + 32, &pair_hit), 350.0 * std::exp(-0.25), 1e-3);
  EXPECT_FALSE(pair_hit);
  // 0.2 m apart: a collision of vehicles 0 and 2 (bits 0 and 2), not 1.
  x[32 + Q::PX] = 0.2f;
  x[32 + Q::PZ] = 1.0f;
  const double goal2b = 2.5 * (0.04 + 400.0);
  EXPECT_NEAR(Team::running(p, x.data(), 0.0f, &crashed), goal2b + 350.0 * std::exp(-0.04) + 1000.0, 1e-2);
  EXPECT_EQ(crashed, 0b101u);
}

}  // namespace
}  // namespace mppi
