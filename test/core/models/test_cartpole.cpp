// The cart-pole (core/include/mppi/models/cartpole.hpp, Appendix C) against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "../fixtures.hpp"
#include "integration_check.hpp"
#include "mppi/models/cartpole.hpp"

namespace mppi {
namespace {

using testing::check_integrator;
using testing::derivative_of;
using CP = Cartpole;

TEST(Cartpole, SpotValuesByHand) {
  const CP::Params p;  // g 9.81, m_c 1, m_p 0.01, l 0.25, gain 20
  // theta = pi/3 (sin = 0.8660254, cos = 0.5), theta_dot = 2, f = 1.5, f_des = 3:
  //   den  = 1 + 0.01 * 0.75 = 1.0075
  //   xdd  = [1.5 + 0.01 * 0.8660254 * (0.25 * 4 + 9.81 * 0.5)] / 1.0075
  //        = [1.5 + 0.008660254 * 5.905] / 1.0075 = 1.5511388 / 1.0075 = 1.5395919
  //   thdd = [-1.5 * 0.5 - 0.01 * 0.25 * 4 * 0.5 * 0.8660254 - 1.01 * 9.81 * 0.8660254]
  //          / (0.25 * 1.0075)
  //        = [-0.75 - 0.0043301 - 8.5806663] / 0.251875 = -37.062021
  //   fdot = 20 * (3 - 1.5) = 30
  const std::vector<float> x = {0.4f, -0.7f, static_cast<float>(M_PI / 3), 2.0f, 1.5f};
  const auto dx = derivative_of<CP>(p, x, {3.0f});
  EXPECT_FLOAT_EQ(dx[CP::X], -0.7f);
  EXPECT_NEAR(dx[CP::XDOT], 1.5395919, 2e-6 * 1.54);
  EXPECT_FLOAT_EQ(dx[CP::THETA], 2.0f);
  EXPECT_NEAR(dx[CP::THETADOT], -37.062021, 2e-6 * 37.1);
  EXPECT_FLOAT_EQ(dx[CP::FORCE], 30.0f);
}

TEST(Cartpole, EquilibriaBottomStableTopUnstable) {
  const CP::Params p;
  const auto bottom = derivative_of<CP>(p, {0, 0, 0, 0, 0}, {0.0f});
  for (float v : bottom) EXPECT_EQ(v, 0.0f);
  const auto top = derivative_of<CP>(p, {0, 0, static_cast<float>(M_PI), 0, 0}, {0.0f});
  // sin(float(pi)) = -8.7e-8, so the top is an equilibrium up to float rounding.
  for (float v : top) EXPECT_NEAR(v, 0.0f, 1e-5f);
  // A small deflection: restoring at the bottom, diverging at the top.
  const float eps = 0.01f;
  const auto near_bottom = derivative_of<CP>(p, {0, 0, eps, 0, 0}, {0.0f});
  const auto near_top = derivative_of<CP>(p, {0, 0, static_cast<float>(M_PI) + eps, 0, 0}, {0.0f});
  EXPECT_LT(near_bottom[CP::THETADOT], 0.0f);
  EXPECT_GT(near_top[CP::THETADOT], 0.0f);
  // Small-angle pendulum: thdd = -(m_c + m_p) g theta / (l m_c) = -39.6324 theta.
  EXPECT_NEAR(near_bottom[CP::THETADOT], -(1.01 * 9.81 / 0.25) * std::sin(0.01), 1e-3);
}

TEST(Cartpole, MirrorSymmetry) {
  const CP::Params p;
  const std::vector<float> x = {0.3f, 1.2f, 2.0f, -1.7f, 4.0f};
  const std::vector<float> mx = {-0.3f, -1.2f, -2.0f, 1.7f, -4.0f};
  const auto dx = derivative_of<CP>(p, x, {2.5f});
  const auto dmx = derivative_of<CP>(p, mx, {-2.5f});
  for (int i = 0; i < CP::kNx; ++i) EXPECT_NEAR(dmx[i], -dx[i], 1e-5f * (1 + std::fabs(dx[i]))) << i;
  // and the derivative is not trivially zero
  EXPECT_GT(std::fabs(dx[CP::THETADOT]), 1.0f);
}

TEST(Integration, EulerConvergesToRk4Cartpole) {
  check_integrator<CP>(CP::Params{}, {0.0f, 0.0f, 1.0f, 0.0f, 0.0f}, {0.5f}, "cartpole");
}

}  // namespace
}  // namespace mppi
