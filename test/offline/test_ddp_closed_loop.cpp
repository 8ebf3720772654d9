// The MPC-DDP baseline in closed loop against the models (RK4 plant, no transport), with the
// settings shipped in config/tasks/ (controller: ddp), and its settings refused by name.
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "../support/task_controller.hpp"
#include "mppi/app/config.hpp"
#include "mppi/ddp/ddp_controller.hpp"
#include "mppi/offline/offline.hpp"

namespace mppi {
namespace {

TEST(DdpClosedLoop, CartpoleSwingsUpAndHolds) {
  auto c = test::task_controller("cartpole_swingup", {}, "controller=ddp");
  ASSERT_STREQ(c->backend(), "ddp");
  const auto r = offline::fly(*c, offline::cartpole_scenario(*c));
  ASSERT_FALSE(r.nonfinite);
  EXPECT_LT(r.max_angle_error_late, 0.1f) << "|theta - pi| from 4 s to 10 s";
  EXPECT_TRUE(r.success);
}

TEST(DdpClosedLoop, CartpoleStaysDownWithoutThePush) {
  // From rest at the bottom with a zero guess every gradient is zero: the push of
  // ddp.initial_plan is what starts the swing (the settings file says why it is there).
  auto c = test::task_controller("cartpole_swingup", {"ddp.initial_plan=[0.0]"}, "controller=ddp");
  const auto r = offline::fly(*c, offline::cartpole_scenario(*c));
  EXPECT_FALSE(r.success);
}

TEST(DdpClosedLoop, QuadrotorCrossesAForest) {
  auto c = test::task_controller("quadrotor_forest", {}, "controller=ddp");
  const auto scenario = offline::forest_scenario(*c, 4.0f, 1);  // a tuning seed
  const auto r = offline::fly(*c, scenario);
  EXPECT_FALSE(r.collided) << "collision at " << r.collision_time << " s";
  EXPECT_TRUE(r.reached) << "goal not reached in " << scenario.duration << " s";
  EXPECT_GT(r.min_clearance, scenario.vehicle_radius);
}

std::string config_error(const std::string& task, const std::vector<std::string>& sets) {
  try {
    auto c = test::task_controller(task, sets, "controller=ddp");
    return "";
  } catch (const app::ConfigError& e) {
    return e.what();
  }
}

TEST(DdpSettingsFile, BadSettingsAreRefusedNamingTheField) {
  EXPECT_EQ(config_error("quadrotor_forest", {}), "");
  auto starts = [](const std::string& e, const std::string& field) { return e.rfind(field, 0) == 0; };
  std::string e = config_error("quadrotor_forest", {"ddp.max_iterations=0"});
  EXPECT_TRUE(starts(e, "ddp.max_iterations:")) << e;
  e = config_error("quadrotor_forest", {"ddp.r=[1,2]"});
  EXPECT_TRUE(starts(e, "ddp.r:")) << e;
  e = config_error("quadrotor_forest", {"ddp.obstacle_wieght=3"});
  EXPECT_TRUE(starts(e, "ddp.obstacle_wieght:")) << e;
  e = config_error("quadrotor_forest", {"ddp.obstacle_softness=-1"});
  EXPECT_TRUE(starts(e, "ddp.obstacle_softness:")) << e;
  e = config_error("quadrotor_forest", {"ddp.convexify=maybe"});
  EXPECT_TRUE(starts(e, "ddp.convexify:")) << e;
  try {
    (void)app::load_config(app::default_config_path("quadrotor_forest"), {"controller=ilqg"});
    e.clear();
  } catch (const app::ConfigError& err) {
    e = err.what();
  }
  EXPECT_TRUE(starts(e, "controller:")) << e;
  e = config_error("racecar_ellipse", {"ddp.max_iterations=3"});
  EXPECT_TRUE(starts(e, "controller:")) << e;  // no DDP for this task
  e = config_error("quadrotor_rate_track", {});
  EXPECT_TRUE(starts(e, "ddp:")) << e;  // no ddp: section in its file
}

}  // namespace
}  // namespace mppi
