// The tracking cost (core/include/mppi/costs/tracking.hpp) for both quadrotor models against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "../fixtures.hpp"
#include "mppi/costs/tracking.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"

namespace mppi {
namespace {

using testing::rate_state;
using Q = Quadrotor;
using QR = QuadrotorRate;

TEST(TrackingCost, ZeroOnTheReferenceAndPositiveAway) {
  TrackingCost<Quadrotor>::Params c{};
  c.reference.kind = Reference::kCircle;
  c.reference.center[0] = 1.0f;
  c.reference.center[1] = -2.0f;
  c.reference.center[2] = 1.5f;
  c.reference.radius = 2.0f;
  c.reference.speed = 3.0f;
  c.reference.yaw = 0.3f;
  c.time0 = 4.0f;
  const float t = 0.7f;
  // On the circle at time0 + t: angle a = (speed / radius)(time0 + t) = 1.5 * 4.7 = 7.05 rad.
  const double a = 1.5 * 4.7;
  std::vector<float> x(16, 0.0f);
  x[Q::PX] = static_cast<float>(1.0 + 2.0 * std::cos(a));
  x[Q::PY] = static_cast<float>(-2.0 + 2.0 * std::sin(a));
  x[Q::PZ] = 1.5f;
  x[Q::VX] = static_cast<float>(-3.0 * std::sin(a));
  x[Q::VY] = static_cast<float>(3.0 * std::cos(a));
  x[Q::YAW] = 0.3f;
  bool crash = false;
  EXPECT_NEAR(TrackingCost<Quadrotor>::vehicle(c, 0, x.data(), t, &crash), 0.0f, 1e-3f);
  EXPECT_FALSE(crash);
  auto off = x;
  off[Q::PZ] += 0.1f;  // 100 * 0.01 = 1
  EXPECT_NEAR(TrackingCost<Quadrotor>::vehicle(c, 0, off.data(), t, &crash), 1.0f, 2e-3f);
  off = x;
  off[Q::VX] += 0.5f;  // 10 * 0.25 = 2.5
  EXPECT_NEAR(TrackingCost<Quadrotor>::vehicle(c, 0, off.data(), t, &crash), 2.5f, 2e-3f);
  off = x;
  off[Q::YAW] -= 0.2f;  // 10 * 0.04 = 0.4
  EXPECT_NEAR(TrackingCost<Quadrotor>::vehicle(c, 0, off.data(), t, &crash), 0.4f, 2e-3f);
  EXPECT_FALSE(crash);
  // The same state is off the reference at another time.
  EXPECT_GT(TrackingCost<Quadrotor>::vehicle(c, 0, x.data(), t + 0.5f, &crash), 10.0f);
  // Below ground: crash.
  off = x;
  off[Q::PZ] = -0.5f;
  EXPECT_GT(TrackingCost<Quadrotor>::vehicle(c, 0, off.data(), t, &crash), 1000.0f);
  EXPECT_TRUE(crash);
}

TEST(TrackingCost, RateQuadrotorYawFromQuaternion) {
  TrackingCost<QuadrotorRate>::Params c{};
  c.reference.kind = Reference::kHold;
  c.reference.center[2] = 2.0f;
  c.reference.yaw = 0.6f;
  auto x = rate_state(static_cast<float>(std::cos(0.3)), 0.0f, 0.0f, static_cast<float>(std::sin(0.3)));
  bool crash = false;
  EXPECT_NEAR(TrackingCost<QuadrotorRate>::vehicle(c, 0, x.data(), 1.0f, &crash), 0.0f, 1e-4f);
  x[QR::PX] = 0.2f;  // 100 * 0.04 = 4
  EXPECT_NEAR(TrackingCost<QuadrotorRate>::vehicle(c, 0, x.data(), 1.0f, &crash), 4.0f, 1e-3f);
}

}  // namespace
}  // namespace mppi
