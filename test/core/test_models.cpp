// Vehicle models and costs against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mppi/costs/ellipse.hpp"
#include "mppi/costs/forest.hpp"
#include "mppi/costs/reference.hpp"
#include "mppi/costs/tracking.hpp"
#include "mppi/models/cartpole.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"
#include "mppi/models/racecar.hpp"
#include "mppi/task.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

template <class Model>
std::vector<float> derivative_of(const typename Model::Params& p, const std::vector<float>& x,
                                 const std::vector<float>& u) {
  std::vector<float> dx(Model::kNx, 0.0f);
  Model::derivative(p, x.data(), u.data(), dx.data());
  return dx;
}

// ---------------------------------------------------------------------------------------
// Quadrotor (16 states, Appendix E)
// ---------------------------------------------------------------------------------------
using Q = Quadrotor;

std::vector<float> quad_hover_state(const Q::Params& p) {
  std::vector<float> x(Q::kNx, 0.0f);
  x[Q::PZ] = 2.0f;
  for (int i = 0; i < 4; ++i) x[Q::M1 + i] = Q::hover_speed(p);
  return x;
}

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
  auto x = quad_hover_state(p);
  x[Q::WX] = 0.25f;
  x[Q::WY] = -0.5f;
  x[Q::WZ] = 0.75f;
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
  x[Q::VX] = 1.0f;
  x[Q::VY] = -2.0f;
  x[Q::VZ] = 0.5f;
  const auto dx2 = derivative_of<Q>(p, x, u);
  EXPECT_EQ(dx2[Q::PX], 1.0f);
  EXPECT_EQ(dx2[Q::PY], -2.0f);
  EXPECT_EQ(dx2[Q::PZ], 0.5f);
}

// ---------------------------------------------------------------------------------------
// QuadrotorRate (13 states)
// ---------------------------------------------------------------------------------------
using QR = QuadrotorRate;

std::vector<float> rate_state(float qw = 1, float qx = 0, float qy = 0, float qz = 0) {
  std::vector<float> x(QR::kNx, 0.0f);
  x[QR::PZ] = 2.0f;
  x[QR::QW] = qw;
  x[QR::QX] = qx;
  x[QR::QY] = qy;
  x[QR::QZ] = qz;
  return x;
}

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

// ---------------------------------------------------------------------------------------
// Cart-pole (Appendix C)
// ---------------------------------------------------------------------------------------
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

// ---------------------------------------------------------------------------------------
// Race car (Appendix D)
// ---------------------------------------------------------------------------------------
using RC = Racecar;

TEST(Racecar, StraightDrivingHasNoLateralForce) {
  const RC::Params p;
  std::vector<float> x(RC::kNx, 0.0f);
  x[RC::PSI] = 0.4f;
  x[RC::VX] = 5.0f;
  x[RC::FX] = 30.0f;
  const auto dx = derivative_of<RC>(p, x, {0.0f, 30.0f});
  EXPECT_NEAR(dx[RC::X], 5.0 * std::cos(0.4), 1e-5);
  EXPECT_NEAR(dx[RC::Y], 5.0 * std::sin(0.4), 1e-5);
  EXPECT_EQ(dx[RC::PSI], 0.0f);
  EXPECT_EQ(dx[RC::BETA], 0.0f);
  EXPECT_FLOAT_EQ(dx[RC::VX], 30.0f / 21.0f);  // Fx / M
  EXPECT_EQ(dx[RC::VY], 0.0f);
  EXPECT_EQ(dx[RC::R], 0.0f);
  EXPECT_EQ(dx[RC::DELTA], 0.0f);
  EXPECT_EQ(dx[RC::FX], 0.0f);
}

TEST(Racecar, BrushTireShape) {
  const RC::Params p;  // C = 1200, mu = 0.55
  const float fz = 100.0f;
  // xi = 1 with no longitudinal force; gamma = atan(3 * 0.55 * 100 / 1200) = atan(0.1375)
  //    = 0.136643 rad; saturated force mu xi Fz = 55 N.
  const double gamma = std::atan(3.0 * 0.55 * 100.0 / 1200.0);
  EXPECT_NEAR(gamma, 0.136643, 1e-6);
  EXPECT_EQ(RC::lateral_force(p, 0.0f, fz, 0.0f), 0.0f);
  for (float a : {0.01f, 0.05f, 0.1f, 0.13f, 0.2f, 0.5f, 1.0f}) {
    const float f = RC::lateral_force(p, a, fz, 0.0f);
    EXPECT_FLOAT_EQ(RC::lateral_force(p, -a, fz, 0.0f), -f) << "odd at " << a;
    EXPECT_LT(f, 0.0f) << "opposes the slip at " << a;
    EXPECT_LE(std::fabs(f), 55.0f * (1 + 1e-6f));
  }
  // Linear region: slope -C at the origin (central difference).
  const double slope = (RC::lateral_force(p, 1e-4f, fz, 0.0f) - RC::lateral_force(p, -1e-4f, fz, 0.0f)) / 2e-4;
  EXPECT_NEAR(slope, -1200.0, 12.0);
  // Monotone towards saturation.
  float prev = 0.0f;
  for (int i = 1; i <= 100; ++i) {
    const float f = RC::lateral_force(p, static_cast<float>(gamma * i / 100.0), fz, 0.0f);
    EXPECT_LE(f, prev + 1e-3f) << i;
    prev = f;
  }
  // Saturated beyond gamma: -mu xi Fz sgn(alpha), with xi < 1 under a longitudinal force:
  // Fx = 30 N: xi = sqrt(55^2 - 30^2) / 55 = sqrt(2125) / 55 = 0.838148.
  EXPECT_FLOAT_EQ(RC::lateral_force(p, 0.3f, fz, 0.0f), -55.0f);
  EXPECT_FLOAT_EQ(RC::lateral_force(p, -0.3f, fz, 0.0f), 55.0f);
  EXPECT_NEAR(RC::lateral_force(p, 0.5f, fz, 30.0f), -55.0 * 0.838148, 1e-3);
  EXPECT_NEAR(RC::lateral_force(p, -0.5f, fz, -30.0f), 55.0 * 0.838148, 1e-3);
  // Continuous at gamma (the brush curve reaches -mu xi Fz with zero slope there).
  for (float fx : {0.0f, 30.0f}) {
    const double xi = std::sqrt(55.0 * 55.0 - fx * fx) / 55.0;
    const double g = std::atan(3.0 * xi * 55.0 / 1200.0);
    const float below = RC::lateral_force(p, static_cast<float>(g - 1e-4), fz, fx);
    const float above = RC::lateral_force(p, static_cast<float>(g + 1e-4), fz, fx);
    EXPECT_NEAR(below, above, 1e-2) << "fx " << fx;
    EXPECT_NEAR(above, -55.0 * xi, 1e-3) << "fx " << fx;
  }
}

TEST(Racecar, SteeringAndDriveTrackTheirSetpoints) {
  const RC::Params p;
  std::vector<float> x(RC::kNx, 0.0f);
  x[RC::VX] = 3.0f;
  x[RC::DELTA] = 0.1f;
  x[RC::FX] = 20.0f;
  const auto dx = derivative_of<RC>(p, x, {0.3f, 5.0f});
  EXPECT_FLOAT_EQ(dx[RC::DELTA], 10.0f * (0.3f - 0.1f));  // towards delta_des
  EXPECT_FLOAT_EQ(dx[RC::FX], 10.0f * (5.0f - 20.0f));
  // Integrating: delta converges to delta_des.
  for (int i = 0; i < 2000; ++i) RC::step(p, x.data(), std::vector<float>{0.3f, 5.0f}.data(), 1e-3f);
  EXPECT_NEAR(x[RC::DELTA], 0.3f, 1e-3f);
  // Steering left (delta > 0) at speed turns the car left (positive yaw rate).
  EXPECT_GT(x[RC::R], 0.0f);
}

// ---------------------------------------------------------------------------------------
// Model::step (explicit Euler) against a local RK4
// ---------------------------------------------------------------------------------------

// Classic RK4 with the state accumulated in double (the derivative is the model's float one):
// its error at h = 1e-3 over 1 s is ~h^4 (1e-12), far below everything it is compared with.
template <class Model>
std::vector<double> rk4(const typename Model::Params& p, std::vector<double> x, const std::vector<float>& u,
                        double h, int steps) {
  const int n = Model::kNx;
  auto f = [&](const std::vector<double>& s) {
    std::vector<float> sf(s.begin(), s.end()), df(n);
    for (int i = 0; i < n; ++i) sf[i] = static_cast<float>(s[i]);
    Model::derivative(p, sf.data(), u.data(), df.data());
    return std::vector<double>(df.begin(), df.end());
  };
  std::vector<double> tmp(n);
  for (int k = 0; k < steps; ++k) {
    const auto k1 = f(x);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5 * h * k1[i];
    const auto k2 = f(tmp);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + 0.5 * h * k2[i];
    const auto k3 = f(tmp);
    for (int i = 0; i < n; ++i) tmp[i] = x[i] + h * k3[i];
    const auto k4 = f(tmp);
    for (int i = 0; i < n; ++i) x[i] += h / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  }
  return x;
}

template <class Model>
std::vector<float> euler(const typename Model::Params& p, std::vector<float> x, const std::vector<float>& u,
                         float h, int steps) {
  for (int k = 0; k < steps; ++k) Model::step(p, x.data(), u.data(), h);
  return x;
}

// Explicit Euler with the state accumulated in double, on the model's float derivative.
template <class Model>
std::vector<double> euler_double(const typename Model::Params& p, std::vector<double> x, const std::vector<float>& u,
                                 double h, int steps) {
  std::vector<float> xf(x.size()), df(x.size());
  for (int k = 0; k < steps; ++k) {
    for (std::size_t i = 0; i < x.size(); ++i) xf[i] = static_cast<float>(x[i]);
    Model::derivative(p, xf.data(), u.data(), df.data());
    for (std::size_t i = 0; i < x.size(); ++i) x[i] += h * df[i];
  }
  return x;
}

// Error norm with every component scaled by (1 + |reference|), so rpm and metres weigh alike.
template <class V>
double scaled_error(const V& x, const std::vector<double>& ref) {
  double e = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) e = std::max(e, std::fabs(x[i] - ref[i]) / (1.0 + std::fabs(ref[i])));
  return e;
}

template <class Model>
void check_integrator(const typename Model::Params& p, const std::vector<float>& x0, const std::vector<float>& u,
                      const char* what) {
  SCOPED_TRACE(what);
  const std::vector<double> x0d(x0.begin(), x0.end());
  const auto ref = rk4<Model>(p, x0d, u, 1e-3, 1000);  // 1 s
  for (double v : ref) ASSERT_TRUE(std::isfinite(v));
  // The trajectory actually moves (otherwise agreement would prove nothing).
  double moved = 0.0;
  for (std::size_t i = 0; i < ref.size(); ++i) moved = std::max(moved, std::fabs(ref[i] - x0d[i]) / (1 + std::fabs(x0d[i])));
  EXPECT_GT(moved, 0.05);

  // Model::step (float Euler) is first order: halving the step halves the error (ratio 2;
  // 1.6..2.5 allows the O(h^2) terms at these steps).
  const double e1 = scaled_error(euler<Model>(p, x0, u, 1e-2f, 100), ref);
  const double e2 = scaled_error(euler<Model>(p, x0, u, 5e-3f, 200), ref);
  const double e3 = scaled_error(euler<Model>(p, x0, u, 2.5e-3f, 400), ref);
  EXPECT_GT(e1, 1e-4) << "the coarse step must show a truncation error well above rounding";
  EXPECT_NEAR(e1 / e2, 2.0, 0.45) << e1 << " " << e2;
  EXPECT_NEAR(e2 / e3, 2.0, 0.45) << e2 << " " << e3;

  // Euler at h = 1e-4 (state accumulated in double: in float, a motor speed of ~3170 rpm
  // stops moving once h k_m |w_des - w| < ulp/2, i.e. within 0.06 rpm of its command, which
  // is rounding, not the integrator). Leading global error (h T / 2) max|x''| / (1 + |x|):
  // the fastest dynamics here are ~40 s^-2 (cart-pole: (m_c + m_p) g / (l m_c) = 39.6), so
  // ~2e-3 at most; 5e-3 leaves margin. And being first order, it is ~1/100 of e1.
  const auto fine = euler_double<Model>(p, x0d, u, 1e-4, 10000);
  const double e_fine = scaled_error(fine, ref);
  EXPECT_LT(e_fine, 5e-3);
  EXPECT_GT(e_fine, 0.5 * e1 / 100.0);
  EXPECT_LT(e_fine, 1.5 * e1 / 100.0);
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

TEST(Integration, EulerConvergesToRk4Cartpole) {
  check_integrator<CP>(CP::Params{}, {0.0f, 0.0f, 1.0f, 0.0f, 0.0f}, {0.5f}, "cartpole");
}

TEST(Integration, EulerConvergesToRk4Racecar) {
  std::vector<float> x(RC::kNx, 0.0f);
  x[RC::VX] = 5.0f;
  x[RC::BETA] = 0.01f;
  x[RC::R] = 0.1f;
  x[RC::DELTA] = 0.02f;
  x[RC::FX] = 10.0f;
  check_integrator<RC>(RC::Params{}, x, {0.05f, 20.0f}, "racecar");
}

// ---------------------------------------------------------------------------------------
// Teams and costs
// ---------------------------------------------------------------------------------------
using Team = Task<Quadrotor, ForestCost<Quadrotor>, 3>;

std::vector<float> team_state() {
  const Q::Params p;
  std::vector<float> x;
  for (int j = 0; j < 3; ++j) {
    auto v = quad_hover_state(p);
    v[Q::PX] = 2.0f * static_cast<float>(j);
    v[Q::VY] = 0.5f * static_cast<float>(j);
    v[Q::ROLL] = 0.05f * static_cast<float>(j + 1);
    v[Q::WZ] = -0.2f * static_cast<float>(j);
    x.insert(x.end(), v.begin(), v.end());
  }
  return x;
}

TEST(Team, AdvanceMovesEachVehicleAlone) {
  Team::Params p{};
  const float h = Q::hover_speed(p.vehicle);
  const std::vector<float> u = {h + 50, h, h - 50, h, h, h + 80, h, h - 20, h + 10, h + 10, h + 10, h + 10};
  const float dt = 0.02f;
  const int substeps = 4;
  auto team = team_state();
  const auto start = team;
  Team::advance(p, team.data(), u.data(), dt, substeps, 0u);
  for (int j = 0; j < 3; ++j) {
    std::vector<float> alone(start.begin() + j * 16, start.begin() + (j + 1) * 16);
    for (int s = 0; s < substeps; ++s) Q::step(p.vehicle, alone.data(), u.data() + 4 * j, dt / substeps);
    for (int i = 0; i < 16; ++i) EXPECT_EQ(team[j * 16 + i], alone[i]) << "vehicle " << j << " state " << i;
    EXPECT_NE(team[j * 16 + Q::PZ], start[j * 16 + Q::PZ]) << "it moved";
  }
  // Vehicle 1 crashed: frozen; the others move as before.
  auto team2 = start;
  Team::advance(p, team2.data(), u.data(), dt, substeps, 0b010u);
  for (int i = 0; i < 16; ++i) EXPECT_EQ(team2[16 + i], start[16 + i]) << "frozen state " << i;
  for (int i = 0; i < 16; ++i) {
    EXPECT_EQ(team2[i], team[i]);
    EXPECT_EQ(team2[32 + i], team[32 + i]);
  }
}

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

// ---------------------------------------------------------------------------------------
// Race car on the ellipse (Sec. VI.B): the paper's q = 100 d^2 + (vx - 7)^2 and the
// optional line, edge, track-limit and drift terms.
// ---------------------------------------------------------------------------------------
// A car on the major axis at residual d: x = 13 sqrt(1 + d), y = 0.
std::vector<float> car_at(double d, float vx, float vy) {
  std::vector<float> x(RC::kNx, 0.0f);
  x[RC::X] = static_cast<float>(13.0 * std::sqrt(1.0 + d));
  x[RC::VX] = vx;
  x[RC::VY] = vy;
  return x;
}

TEST(EllipseCost, PaperCostByHandAndExtrasOffByDefault) {
  const EllipseCost::Params c;
  bool crash = false;
  // d = 0.2, vx = 5: 100 * 0.04 + (5 - 7)^2 = 8; a wild vy and |d| costs nothing more.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 5.0f, -4.0f).data(), 0.0f, &crash), 8.0f, 1e-3f);
  EXPECT_FALSE(crash);
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(2.0, 7.0f, 0.0f).data(), 0.0f, &crash), 400.0f, 0.05f);
  EXPECT_FALSE(crash) << "the paper's cost has no track limit";
}

TEST(EllipseCost, LineEdgeTrackLimitAndDriftByHand) {
  EllipseCost::Params c;
  c.w_track = 10.0f;
  c.line = 0.2f;
  c.edge = 0.3f;
  c.w_edge = 100.0f;
  c.track_limit = 0.5f;
  c.w_crash = 1000.0f;
  c.drift = 0.25f;
  c.w_drift = 10.0f;
  bool crash = false;
  // On the line at target speed, sliding less than the drift angle: nothing to pay.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 7.0f, -1.5f).data(), 0.0f, &crash), 0.0f, 1e-3f);
  EXPECT_FALSE(crash);
  // d = 0.4: track 10 * 0.2^2 = 0.4, edge 100 * 0.1^2 = 1.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.4, 7.0f, 0.0f).data(), 0.0f, &crash), 1.4f, 1e-3f);
  EXPECT_FALSE(crash);
  // Inside, d = -0.4: track 10 * 0.6^2 = 3.6, edge on |d| too: 1.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(-0.4, 7.0f, 0.0f).data(), 0.0f, &crash), 4.6f, 1e-3f);
  EXPECT_FALSE(crash);
  // d = 0.6, past the limit: crashed, pays w_crash on top (track 0.16 * 10, edge 100 * 0.09).
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.6, 7.0f, 0.0f).data(), 0.0f, &crash), 1000.0f + 1.6f + 9.0f, 1e-2f);
  EXPECT_TRUE(crash);
  crash = false;
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(-0.55, 7.0f, 0.0f).data(), 0.0f, &crash),
              1000.0f + 10.0f * 0.75f * 0.75f + 100.0f * 0.25f * 0.25f, 1e-2f);
  EXPECT_TRUE(crash) << "off the inside edge";
  crash = false;
  // Sliding: vx = 4, vy = -3 (either side): |vy| - 0.25 * 4 = 2 over, 10 * 4 = 40.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 4.0f, -3.0f).data(), 0.0f, &crash), 9.0f + 40.0f, 1e-3f);
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 4.0f, 3.0f).data(), 0.0f, &crash), 9.0f + 40.0f, 1e-3f);
  // A crab: vx = 0, vy = 5: the whole vy is over.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 0.0f, 5.0f).data(), 0.0f, &crash), 49.0f + 250.0f, 1e-3f);
  EXPECT_FALSE(crash);
}

TEST(EllipseCost, RacingLineStadiumByHand) {
  EllipseCost::Params c;
  c.w_track = 0.0f;  // only the line term (vx = 7 = target speed)
  c.w_line = 3.0f;
  c.line_radius = 7.0f;
  c.line_half = 2.5f;
  auto at = [](float px, float py) {
    std::vector<float> x(RC::kNx, 0.0f);
    x[RC::X] = px;
    x[RC::Y] = py;
    x[RC::VX] = 7.0f;
    return x;
  };
  bool crash = false;
  auto q = [&](float px, float py) { return EllipseCost::vehicle(c, 0, at(px, py).data(), 0.0f, &crash); };
  EXPECT_NEAR(q(9.5f, 0.0f), 0.0f, 1e-4f);    // the end's apex, 7 m beyond the centre (2.5, 0)
  EXPECT_NEAR(q(-9.5f, 0.0f), 0.0f, 1e-4f);   // the other end
  EXPECT_NEAR(q(0.0f, 7.0f), 0.0f, 1e-4f);    // on the straight
  EXPECT_NEAR(q(1.0f, -8.0f), 3.0f, 1e-4f);   // 1 m outside the straight
  EXPECT_NEAR(q(-2.0f, 6.0f), 3.0f, 1e-4f);   // 1 m inside it
  EXPECT_NEAR(q(5.5f, 4.0f), 3.0f * 4.0f, 1e-4f);    // (3, 4) from the centre: 5 m, 2 m inside
  EXPECT_NEAR(q(-8.5f, -8.0f), 3.0f * 9.0f, 1e-4f);  // (6, 8) from (-2.5, 0): 10 m, 3 m outside
  EXPECT_FALSE(crash);
  c.w_line = 0.0f;
  EXPECT_EQ(q(-8.5f, -8.0f), 0.0f) << "off by default";
}

TEST(Reference, VelocityIsTheDerivativeOfPosition) {
  for (int kind : {Reference::kCircle, Reference::kFigureEight}) {
    Reference r;
    r.kind = kind;
    r.center[0] = 0.5f;
    r.center[1] = -1.0f;
    r.center[2] = 2.0f;
    r.radius = 2.0f;
    r.speed = 1.5f;
    for (float t : {0.0f, 0.37f, 1.2f, 3.3f, 7.9f}) {
      const float h = 1e-3f;
      float p1[3], p2[3], p0[3], v[3], v_unused[3];
      r.eval(t - h, p1, v_unused);
      r.eval(t + h, p2, v_unused);
      r.eval(t, p0, v);
      for (int d = 0; d < 3; ++d) {
        const double fd = (static_cast<double>(p2[d]) - p1[d]) / (2.0 * h);
        // Central difference: truncation ~h^2 |x'''| / 6 ~ 1e-6; rounding ~ulp(2) / h ~ 2.4e-4.
        EXPECT_NEAR(v[d], fd, 1e-3) << "kind " << kind << " t " << t << " axis " << d;
      }
    }
    // The circle runs at the given speed.
    if (kind == Reference::kCircle) {
      float p[3], v[3];
      r.eval(0.9f, p, v);
      EXPECT_NEAR(std::hypot(v[0], v[1]), 1.5, 1e-5);
      EXPECT_NEAR(std::hypot(p[0] - 0.5, p[1] + 1.0), 2.0, 1e-5);
    }
  }
  // Hold: fixed point, zero velocity.
  Reference hold;
  hold.center[0] = 3.0f;
  float p[3], v[3];
  hold.eval(5.0f, p, v);
  EXPECT_EQ(p[0], 3.0f);
  EXPECT_EQ(p[2], 1.0f);
  EXPECT_EQ(v[0], 0.0f);
  EXPECT_EQ(v[1], 0.0f);
}

}  // namespace
}  // namespace mppi
