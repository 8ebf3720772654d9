// The 16-state quadrotor (core/include/mppi/models/quadrotor.hpp, Appendix E) against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <vector>

#include "../fixtures.hpp"
#include "integration_check.hpp"
#include "mppi/models/quadrotor.hpp"

namespace mppi {
namespace {

using testing::check_integrator;
using testing::derivative_of;
using testing::quad_hover_state;
using testing::state_with;
using Q = Quadrotor;

TEST(Quadrotor, HoverSpeedFromPaperConstants) {
  // Four motors carry m g: 4 k_F w^2 = m g  =>  w = sqrt(0.25 * 9.81 / (4 * 6.11e-8))
  //   = sqrt(2.4525 / 2.444e-7) = sqrt(1.00348e7) = 3167.8 rpm  (paper: "about 3,170 rpm").
  const double by_hand = std::sqrt(0.25 * 9.81 / (4.0 * 6.11e-8));
  EXPECT_NEAR(by_hand, 3167.8, 0.1);
  EXPECT_NEAR(Q::hover_speed(Q::Params{}), by_hand, 0.05);
  EXPECT_NEAR(Q::hover_speed(Q::Params{}), 3168.0, 1.0);
}

TEST(Quadrotor, HoverIsAnEquilibrium) {
  const Q::Params p;
  const auto x = quad_hover_state(p);
  const std::vector<float> u(4, Q::hover_speed(p));
  const auto dx = derivative_of<Q>(p, x, u);
  for (int i = Q::VX; i <= Q::VZ; ++i) EXPECT_LT(std::fabs(dx[i]), 1e-4f) << "acceleration " << i;
  for (int i = 0; i < Q::kNx; ++i) EXPECT_NEAR(dx[i], 0.0f, 1e-4f) << "state " << i;
  // The motors hold their speed: no lag term at all.
  for (int i = Q::M1; i <= Q::M4; ++i) EXPECT_EQ(dx[i], 0.0f);
}

// Body torque of the four thrusts and drag moments, from the motor positions (motor 1 on
// +x, 2 on +y, 3 on -x, 4 on -y, thrust along body +z) as r x F, plus the reaction
// moments (1 and 3 spin one way, 2 and 4 the other).
Eigen::Vector3d torque_from_geometry(const Q::Params& p, const std::array<double, 4>& w) {
  const double L = p.arm;
  const std::array<Eigen::Vector3d, 4> pos = {Eigen::Vector3d(L, 0.0, 0.0), Eigen::Vector3d(0.0, L, 0.0),
                                              Eigen::Vector3d(-L, 0.0, 0.0), Eigen::Vector3d(0.0, -L, 0.0)};
  Eigen::Vector3d tau = Eigen::Vector3d::Zero();
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d f(0.0, 0.0, static_cast<double>(p.k_force) * w[i] * w[i]);
    tau += pos[i].cross(f);
    tau.z() += (i % 2 == 0 ? 1.0 : -1.0) * static_cast<double>(p.k_moment) * w[i] * w[i];
  }
  return tau;
}

TEST(Quadrotor, DifferentialThrustGivesRollPitchYawTorques) {
  const Q::Params p;
  const double h = Q::hover_speed(p);
  struct Case {
    std::array<double, 4> w;
    int axis;  // the one rate derivative that must be nonzero
  };
  const double e = 40.0;  // rpm
  const Case cases[] = {
      {{h, h + e, h, h - e}, 0},          // motor 2 vs 4: roll
      {{h - e, h, h + e, h}, 1},          // motor 3 vs 1: pitch
      {{h + e, h - e, h + e, h - e}, 2},  // M1 - M2 + M3 - M4: yaw
  };
  const Eigen::Vector3d inertia(p.ixx, p.iyy, p.izz);
  for (const auto& c : cases) {
    auto x = quad_hover_state(p);
    for (int i = 0; i < 4; ++i) x[Q::M1 + i] = static_cast<float>(c.w[i]);
    const std::vector<float> u(x.begin() + Q::M1, x.end());
    const auto dx = derivative_of<Q>(p, x, u);
    const Eigen::Vector3d tau = torque_from_geometry(p, c.w);
    for (int a = 0; a < 3; ++a) {
      const double expected = tau[a] / inertia[a];  // body at rest: no gyroscopic term
      if (a == c.axis) {
        ASSERT_GT(std::fabs(expected), 1.0);
        EXPECT_NEAR(dx[Q::WX + a], expected, 2e-3 * std::fabs(expected)) << "axis " << a;
      } else {
        EXPECT_NEAR(dx[Q::WX + a], 0.0, 1e-2) << "axis " << a;
      }
    }
  }
  // Closed forms of the brief, signs explicit: w2 > w4 rolls positive; w3 > w1 pitches positive.
  auto x = quad_hover_state(p);
  x[Q::M2] = static_cast<float>(h + e);
  x[Q::M4] = static_cast<float>(h - e);
  const std::vector<float> u(x.begin() + Q::M1, x.end());
  const auto dx = derivative_of<Q>(p, x, u);
  const double roll = p.arm * p.k_force * ((h + e) * (h + e) - (h - e) * (h - e)) / p.ixx;  // = L kF 4 h e / Ixx
  EXPECT_GT(dx[Q::WX], 0.0f);
  EXPECT_NEAR(dx[Q::WX], roll, 2e-3 * roll);
  // Collective thrust is unchanged to first order but grows by 2 kF e^2.
  const double az = (4 * h * h + 2 * e * e) * p.k_force / p.mass - p.gravity;
  EXPECT_NEAR(dx[Q::VZ], az, 1e-3);
}

TEST(Quadrotor, GyroscopicTermIsOmegaCrossIOmega) {
  const Q::Params p;
  auto x = quad_hover_state(p);
  x[Q::WX] = 1.5f;
  x[Q::WY] = -2.0f;
  x[Q::WZ] = 0.7f;
  const std::vector<float> u(x.begin() + Q::M1, x.end());
  const auto dx = derivative_of<Q>(p, x, u);
  const Eigen::Vector3d w(1.5, -2.0, 0.7);
  const Eigen::Vector3d inertia(p.ixx, p.iyy, p.izz);
  const Eigen::Vector3d g = w.cross(inertia.asDiagonal() * w);
  for (int a = 0; a < 3; ++a) {
    const double expected = -g[a] / inertia[a];  // equal motors: no torque
    EXPECT_NEAR(dx[Q::WX + a], expected, 1e-3 * (1.0 + std::fabs(expected))) << a;
  }
  // Ixx = Iyy: no roll/pitch coupling of (wy, wz) into each other's z... but x and y terms
  // are (Iyy - Izz) wy wz / Ixx, nonzero here.
  EXPECT_NEAR(dx[Q::WX], (p.iyy - p.izz) * (-2.0) * 0.7 / p.ixx, 1e-3);
}

TEST(Quadrotor, TiltedThrustAcceleratesAlongBodyZ) {
  const Q::Params p;
  const double h = Q::hover_speed(p);
  const double angles[][3] = {{0.3, 0.0, 0.0}, {0.0, 0.25, 0.0}, {0.3, -0.2, 0.7}, {-0.4, 0.35, -2.1}};
  for (const auto& a : angles) {
    auto x = quad_hover_state(p);
    x[Q::ROLL] = static_cast<float>(a[0]);
    x[Q::PITCH] = static_cast<float>(a[1]);
    x[Q::YAW] = static_cast<float>(a[2]);
    const double w = 1.1 * h;
    for (int i = 0; i < 4; ++i) x[Q::M1 + i] = static_cast<float>(w);
    const std::vector<float> u(x.begin() + Q::M1, x.end());
    const auto dx = derivative_of<Q>(p, x, u);
    // ZXY Euler angles: R_WB = Rz(psi) Rx(phi) Ry(theta), built by matrix products here.
    const Eigen::Matrix3d r = Eigen::AngleAxisd(a[2], Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                              Eigen::AngleAxisd(a[0], Eigen::Vector3d::UnitX()).toRotationMatrix() *
                              Eigen::AngleAxisd(a[1], Eigen::Vector3d::UnitY()).toRotationMatrix();
    const double thrust = 4.0 * p.k_force * w * w;
    for (int d = 0; d < 3; ++d) {
      const double expected = r(d, 2) * thrust / p.mass - (d == 2 ? p.gravity : 0.0);
      EXPECT_NEAR(dx[Q::VX + d], expected, 1e-4 * (1.0 + std::fabs(expected)))
          << "axis " << d << " at (" << a[0] << ", " << a[1] << ", " << a[2] << ")";
    }
  }
  // Pure roll phi: horizontal acceleration is -sin(phi) T/m along y (positive roll about x
  // tilts body z towards -y).
  auto x = quad_hover_state(p);
  x[Q::ROLL] = 0.3f;
  const std::vector<float> u(x.begin() + Q::M1, x.end());
  const auto dx = derivative_of<Q>(p, x, u);
  EXPECT_NEAR(dx[Q::VX], 0.0f, 1e-5f);
  EXPECT_NEAR(dx[Q::VY], -std::sin(0.3) * p.gravity, 1e-4);
  EXPECT_NEAR(dx[Q::VZ], std::cos(0.3) * p.gravity - p.gravity, 1e-4);
}

TEST(Quadrotor, EulerRatesInvertTheBodyRateMap) {
  // omega = W(phi, theta) Phi_dot with W = [[c0, 0, -cf s0], [0, 1, sf], [s0, 0, cf c0]]
  // (paper, Appendix E); solve it for Phi_dot (LU with partial pivoting; det W = cos phi).
  const Q::Params p;
  const double cases[][6] = {
      // phi, theta, psi, p, q, r
      {0.0, 0.0, 0.0, 0.4, -0.3, 0.2},
      {0.3, -0.2, 0.9, 0.5, 0.1, -0.4},
      {-0.6, 0.4, -1.2, -1.0, 0.8, 0.6},
      {1.2, 1.0, 2.5, 0.3, -0.7, 1.1},
  };
  for (const auto& c : cases) {
    auto x = quad_hover_state(p);
    x[Q::ROLL] = static_cast<float>(c[0]);
    x[Q::PITCH] = static_cast<float>(c[1]);
    x[Q::YAW] = static_cast<float>(c[2]);
    x[Q::WX] = static_cast<float>(c[3]);
    x[Q::WY] = static_cast<float>(c[4]);
    x[Q::WZ] = static_cast<float>(c[5]);
    const std::vector<float> u(x.begin() + Q::M1, x.end());
    const auto dx = derivative_of<Q>(p, x, u);
    const double cf = std::cos(c[0]), sf = std::sin(c[0]), c0 = std::cos(c[1]), s0 = std::sin(c[1]);
    Eigen::Matrix3d W;
    W << c0, 0.0, -cf * s0,  //
        0.0, 1.0, sf,        //
        s0, 0.0, cf * c0;
    const Eigen::Vector3d rates = W.partialPivLu().solve(Eigen::Vector3d(c[3], c[4], c[5]));
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(dx[Q::ROLL + a], rates[a], 1e-5 * (1.0 + std::fabs(rates[a]))) << "angle " << a << " case phi=" << c[0];
  }
  // A hand case: phi = 0, theta = 0 makes W the identity.
  const auto x = state_with<Q>({{Q::WX, 0.25f}, {Q::WY, -0.5f}, {Q::WZ, 0.75f}}, quad_hover_state(p));
  const std::vector<float> u(x.begin() + Q::M1, x.end());
  const auto dx = derivative_of<Q>(p, x, u);
  EXPECT_FLOAT_EQ(dx[Q::ROLL], 0.25f);
  EXPECT_FLOAT_EQ(dx[Q::PITCH], -0.5f);
  EXPECT_FLOAT_EQ(dx[Q::YAW], 0.75f);
}

TEST(Quadrotor, MotorsAreFirstOrderLags) {
  const Q::Params p;
  auto x = quad_hover_state(p);
  const float speeds[4] = {3000.0f, 3100.0f, 3300.0f, 2900.0f};
  const float desired[4] = {3500.0f, 3100.0f, 3000.0f, 0.0f};
  for (int i = 0; i < 4; ++i) x[Q::M1 + i] = speeds[i];
  const std::vector<float> u(desired, desired + 4);
  const auto dx = derivative_of<Q>(p, x, u);
  for (int i = 0; i < 4; ++i) EXPECT_FLOAT_EQ(dx[Q::M1 + i], 20.0f * (desired[i] - speeds[i])) << i;
  // Velocity integrates into position.
  const auto dx2 = derivative_of<Q>(p, state_with<Q>({{Q::VX, 1.0f}, {Q::VY, -2.0f}, {Q::VZ, 0.5f}}, x), u);
  EXPECT_EQ(dx2[Q::PX], 1.0f);
  EXPECT_EQ(dx2[Q::PY], -2.0f);
  EXPECT_EQ(dx2[Q::PZ], 0.5f);
}

TEST(Integration, EulerConvergesToRk4Quadrotor) {
  const Q::Params p;
  auto x = quad_hover_state(p);
  x[Q::VX] = 1.0f;
  x[Q::ROLL] = 0.1f;
  x[Q::PITCH] = -0.05f;
  x[Q::YAW] = 0.2f;
  x[Q::WX] = 0.3f;
  x[Q::WY] = -0.2f;
  x[Q::WZ] = 0.1f;
  const float h = Q::hover_speed(p);
  x[Q::M1] = h - 30.0f;
  x[Q::M3] = h + 20.0f;
  const std::vector<float> u = {h + 4.0f, h - 3.0f, h + 60.0f, h + 1.0f};
  check_integrator<Q>(p, x, u, "quadrotor");
}

}  // namespace
}  // namespace mppi
