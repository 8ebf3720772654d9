// The cart-pole swing-up cost (core/include/mppi/costs/swingup.hpp, Sec. VI.A), by hand:
// q = p^2 + 500 (1 + cos theta)^2 + theta_dot^2 + p_dot^2, and the optional rail limit.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mppi/costs/swingup.hpp"
#include "mppi/models/cartpole.hpp"

namespace mppi {
namespace {

using CP = Cartpole;

float swingup(const SwingupCost::Params& p, const std::vector<float>& x, bool* crash) {
  *crash = false;
  return SwingupCost::vehicle(p, 0, x.data(), 0.0f, crash);
}

TEST(SwingupCost, PaperCostByHand) {
  const SwingupCost::Params p;
  bool crash = false;
  std::vector<float> x(CP::kNx, 0.0f);
  x[CP::THETA] = static_cast<float>(M_PI);  // upright: the angle term vanishes
  EXPECT_NEAR(swingup(p, x, &crash), 0.0f, 1e-6f);
  x[CP::X] = 0.5f;
  x[CP::XDOT] = -2.0f;
  x[CP::THETA] = static_cast<float>(M_PI / 2);  // (1 + cos)^2 = 1
  x[CP::THETADOT] = 3.0f;
  EXPECT_NEAR(swingup(p, x, &crash), 0.25 + 500.0 + 9.0 + 4.0, 1e-3);
  x[CP::THETA] = 0.0f;  // hanging down: (1 + 1)^2 = 4
  EXPECT_NEAR(swingup(p, x, &crash), 0.25 + 2000.0 + 9.0 + 4.0, 1e-3);
  EXPECT_FALSE(crash) << "no rail limit by default";
}

TEST(SwingupCost, OffTheRailIsACrash) {
  SwingupCost::Params p;
  p.track_limit = 1.0f;
  p.w_crash = 1000.0f;
  bool crash = false;
  std::vector<float> x(CP::kNx, 0.0f);
  x[CP::THETA] = static_cast<float>(M_PI);
  x[CP::X] = 0.9f;
  EXPECT_NEAR(swingup(p, x, &crash), 0.81f, 1e-5f);
  EXPECT_FALSE(crash);
  x[CP::X] = -1.2f;
  EXPECT_NEAR(swingup(p, x, &crash), 1.44f + 1000.0f, 1e-3f);
  EXPECT_TRUE(crash);
}

}  // namespace
}  // namespace mppi
