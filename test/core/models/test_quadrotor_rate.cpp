// The 13-state rate quadrotor (core/include/mppi/models/quadrotor_rate.hpp) against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "../fixtures.hpp"
#include "integration_check.hpp"
#include "mppi/models/quadrotor_rate.hpp"

namespace mppi {
namespace {

using testing::check_integrator;
using testing::derivative_of;
using testing::rate_state;
using QR = QuadrotorRate;

TEST(QuadrotorRate, HoverIsAnEquilibrium) {
  const QR::Params p;
  const auto x = rate_state();
  const std::vector<float> u = {p.mass * p.gravity, 0.0f, 0.0f, 0.0f};
  const auto dx = derivative_of<QR>(p, x, u);
  for (int i = 0; i < QR::kNx; ++i) EXPECT_NEAR(dx[i], 0.0f, 1e-6f) << i;
  EXPECT_FLOAT_EQ(QR::hover_thrust(p), 9.81f);
}

TEST(QuadrotorRate, QuaternionStaysUnit) {
  const QR::Params p;
  auto x = rate_state(0.9f, 0.1f, -0.3f, 0.2f);  // not even unit at the start
  QR::project(x.data());
  x[QR::WX] = 1.0f;
  x[QR::WY] = -2.0f;
  x[QR::WZ] = 3.0f;
  const std::vector<float> u = {9.81f, 1.0f, -2.0f, 3.0f};
  for (int n = 0; n < 5000; ++n) QR::step(p, x.data(), u.data(), 0.01f);
  const double norm = Eigen::Quaterniond(x[QR::QW], x[QR::QX], x[QR::QY], x[QR::QZ]).norm();
  EXPECT_NEAR(norm, 1.0, 1e-5);
  for (float v : x) EXPECT_TRUE(std::isfinite(v));
}

TEST(QuadrotorRate, PureYawRateRotatesAboutZ) {
  const QR::Params p;
  auto x = rate_state();
  const float r = 0.8f;
  x[QR::WZ] = r;
  const std::vector<float> u = {9.81f, 0.0f, 0.0f, r};
  const double dt = 1e-4;
  const int n = 10000;  // 1 s
  for (int i = 0; i < n; ++i) QR::step(p, x.data(), u.data(), static_cast<float>(dt));
  const double t = n * dt;
  // q(t) = (cos(r t / 2), 0, 0, sin(r t / 2)).
  EXPECT_NEAR(x[QR::QW], std::cos(r * t / 2), 1e-3);
  EXPECT_NEAR(x[QR::QX], 0.0, 1e-6);
  EXPECT_NEAR(x[QR::QY], 0.0, 1e-6);
  EXPECT_NEAR(x[QR::QZ], std::sin(r * t / 2), 1e-3);
  EXPECT_NEAR(QR::yaw(x.data()), r * t, 2e-3);
  // Hover thrust along the untilted body z: the vehicle stays put.
  EXPECT_NEAR(x[QR::PZ], 2.0f, 1e-3f);
  EXPECT_NEAR(x[QR::PX], 0.0f, 1e-6f);
}

TEST(QuadrotorRate, RateLoopIsFirstOrderWithTimeConstantTau) {
  const QR::Params p;  // rate_tau_x/y/z = 0.05 s, gains 1
  auto x = rate_state();
  const std::vector<float> u = {9.81f, 1.0f, -2.0f, 0.5f};
  const double dt = 1e-5;
  const int n = static_cast<int>(std::lround(p.rate_tau_x / dt));
  for (int i = 0; i < n; ++i) QR::step(p, x.data(), u.data(), static_cast<float>(dt));
  // After one time constant, 1 - e^-1 = 63.2 % of the step (Euler at dt = tau / 5000 is
  // within 1e-4 relative of the exponential).
  const double frac = 1.0 - std::exp(-1.0);
  EXPECT_NEAR(x[QR::WX], 1.0 * frac, 1e-3);
  EXPECT_NEAR(x[QR::WY], -2.0 * frac, 2e-3);
  EXPECT_NEAR(x[QR::WZ], 0.5 * frac, 1e-3);
  EXPECT_NEAR(frac, 0.632, 1e-3);
  // The derivative is exactly (u - w) / tau.
  auto y = rate_state();
  y[QR::WX] = 0.2f;
  const auto dx = derivative_of<QR>(p, y, u);
  EXPECT_FLOAT_EQ(dx[QR::WX], (1.0f - 0.2f) / 0.05f);
  EXPECT_FLOAT_EQ(dx[QR::WY], -2.0f / 0.05f);
}

TEST(QuadrotorRate, ThrustAlongRotatedBodyZ) {
  QR::Params p;
  p.mass = 1.3f;
  // Rotation by angle a about the unit axis n: q = (cos a/2, sin a/2 n), built by Eigen::AngleAxisd.
  const double axes[][3] = {{1, 0, 0}, {0, 1, 0}, {1, 2, -0.5}, {-0.3, 0.4, 0.9}};
  const double angle = 0.6;
  for (const auto& ax : axes) {
    const Eigen::Vector3d nvec = Eigen::Vector3d(ax[0], ax[1], ax[2]).normalized();
    const Eigen::Quaterniond q(Eigen::AngleAxisd(angle, nvec));
    auto x = rate_state(static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                        static_cast<float>(q.z()));
    const std::vector<float> u = {15.0f, 0.0f, 0.0f, 0.0f};
    const auto dx = derivative_of<QR>(p, x, u);
    // Rodrigues: R e3 = e3 cos a + (n x e3) sin a + n (n . e3)(1 - cos a).
    const Eigen::Vector3d e3 = Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d nxe = nvec.cross(e3);
    for (int d = 0; d < 3; ++d) {
      const double bz = e3[d] * std::cos(angle) + nxe[d] * std::sin(angle) + nvec[d] * nvec[2] * (1 - std::cos(angle));
      const double expected = 15.0 / 1.3 * bz - (d == 2 ? 9.81 : 0.0);
      EXPECT_NEAR(dx[QR::VX + d], expected, 1e-4 * (1 + std::fabs(expected))) << d;
    }
  }
}

TEST(Integration, EulerConvergesToRk4QuadrotorRate) {
  const QR::Params p;
  const Eigen::Quaterniond q = Eigen::Quaterniond(0.9, 0.1, -0.3, 0.2).normalized();
  auto x = rate_state(static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                      static_cast<float>(q.z()));
  x[QR::VY] = 0.5f;
  x[QR::WX] = 0.5f;
  x[QR::WY] = -0.3f;
  x[QR::WZ] = 0.8f;
  check_integrator<QR>(p, x, {11.0f, 0.2f, 0.4f, -0.5f}, "quadrotor_rate");
}

}  // namespace
}  // namespace mppi
