// The paper's systems flown in closed loop against their models (RK4 at 10x the control
// rate as the plant), with the task settings shipped in config/tasks/.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "mppi/app/config.hpp"
#include "mppi/offline/offline.hpp"

namespace mppi {
namespace {

std::unique_ptr<Controller> controller_for(const std::string& task, std::vector<std::string> sets = {}) {
  sets.push_back("backend=cpu");
  return app::make_controller(app::load_config(app::default_config_path(task), sets));
}

TEST(ClosedLoop, CartpoleSwingsUpAndHolds) {
  auto c = controller_for("cartpole_swingup");
  const auto r = offline::fly(*c, offline::cartpole_scenario(*c));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_LT(r.max_angle_error_late, 0.1f) << "|theta - pi| from 4 s to 10 s";
  EXPECT_TRUE(r.success);
}

class Forest : public ::testing::TestWithParam<int> {};

TEST_P(Forest, QuadrotorCrossesWithoutCollision) {
  auto c = controller_for("quadrotor_forest");
  const auto scenario = offline::forest_scenario(*c, 4.0f, static_cast<std::uint64_t>(GetParam()));
  ASSERT_GT(scenario.forest.size(), 30u);
  const auto r = offline::fly(*c, scenario);
  EXPECT_FALSE(r.collided) << "collision at " << r.collision_time << " s";
  EXPECT_TRUE(r.reached) << "goal not reached in " << scenario.duration << " s";
  EXPECT_GT(r.min_clearance, scenario.vehicle_radius);
}
INSTANTIATE_TEST_SUITE_P(Seeds, Forest, ::testing::Values(1, 2, 3));

TEST(ClosedLoop, RateQuadrotorTracksCircle) {
  auto c = controller_for("quadrotor_rate_track");
  const auto r = offline::fly(*c, offline::tracking_scenario(*c, Reference::kCircle, 5.0f, 3.0f));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_LT(r.tracking_rmse, 0.3f);
  EXPECT_NEAR(r.mean_speed, 3.0f, 0.3f);
}

TEST(ClosedLoop, RacecarLapsTheEllipse) {
  auto c = controller_for("racecar_ellipse");
  const auto r = offline::fly(*c, offline::ellipse_scenario(*c));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_GE(r.mean_speed, 5.5f);
  // Still on the track at the end: |d| small.
  const float* x = &r.x[(r.t.size() - 1) * r.nx];
  const float d = std::pow(x[Racecar::X] / 13.0f, 2.0f) + std::pow(x[Racecar::Y] / 6.0f, 2.0f) - 1.0f;
  EXPECT_LT(std::fabs(d), 0.5f);
}

}  // namespace
}  // namespace mppi
