// The paper's systems flown in closed loop against their models (RK4 at 10x the control
// rate as the plant), with the task settings shipped in config/tasks/.
#include <cstdint>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "../support/task_controller.hpp"
#include "mppi/app/config.hpp"
#include "mppi/offline/offline.hpp"

namespace mppi {
namespace {

TEST(ClosedLoop, CartpoleSwingsUpAndHolds) {
  auto c = test::task_controller("cartpole_swingup", {}, "backend=cpu");
  const auto r = offline::fly(*c, offline::cartpole_scenario(*c));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_LT(r.max_angle_error_late, 0.1f) << "|theta - pi| from 4 s to 10 s";
  EXPECT_TRUE(r.success);
}

class Forest : public ::testing::TestWithParam<int> {};

TEST_P(Forest, QuadrotorCrossesWithoutCollision) {
  auto c = test::task_controller("quadrotor_forest", {}, "backend=cpu");
  const auto scenario = offline::forest_scenario(*c, 4.0f, static_cast<std::uint64_t>(GetParam()));
  ASSERT_GT(scenario.forest.size(), 30u);
  const auto r = offline::fly(*c, scenario);
  EXPECT_FALSE(r.collided) << "collision at " << r.collision_time << " s";
  EXPECT_TRUE(r.reached) << "goal not reached in " << scenario.duration << " s";
  EXPECT_GT(r.min_clearance, scenario.vehicle_radius);
}
INSTANTIATE_TEST_SUITE_P(Seeds, Forest, ::testing::Values(1, 2, 3));

TEST(ClosedLoop, RateQuadrotorTracksCircle) {
  auto c = test::task_controller("quadrotor_rate_track", {}, "backend=cpu");
  const auto r = offline::fly(*c, offline::tracking_scenario(*c, Reference::kCircle, 5.0f, 3.0f));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_LT(r.tracking_rmse, 0.3f);
  EXPECT_NEAR(r.mean_speed, 3.0f, 0.3f);
}

TEST(ClosedLoop, RacecarLapsTheEllipse) {
  auto c = test::task_controller("racecar_ellipse", {}, "backend=cpu");
  const auto r = offline::fly(*c, offline::ellipse_scenario(*c));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_GE(r.mean_speed, 6.0f);
  // Never off the track (the SITL scenario's |d| <= 0.6) and round it at least once.
  float worst = 0.0f, turned = 0.0f, last = 0.0f;
  for (std::size_t i = 0; i < r.t.size(); ++i) {
    const float* x = &r.x[i * static_cast<std::size_t>(r.nx)];
    const float d = std::pow(x[Racecar::X] / 13.0f, 2.0f) + std::pow(x[Racecar::Y] / 6.0f, 2.0f) - 1.0f;
    worst = std::max(worst, std::fabs(d));
    const float a = std::atan2(x[Racecar::Y] / 6.0f, x[Racecar::X] / 13.0f);
    if (i > 0) turned += std::remainder(a - last, 6.2831853f);
    last = a;
  }
  std::printf("[racecar] mean speed %.2f m/s, max |d| %.3f, %.2f laps\n", r.mean_speed, worst, turned / 6.2831853f);
  EXPECT_LT(worst, 0.6f) << "off the track";
  EXPECT_GT(turned, 6.2831853f) << "less than a lap";
}

}  // namespace
}  // namespace mppi
