// Rate-controlled quadrotor (13 states): what the controller flies through an autopilot,
// which takes collective thrust and body-rate setpoints. State: position, velocity,
// attitude quaternion (w, x, y, z; body to world), body rates. Controls: thrust (N) and
// body-rate setpoints (rad/s), tracked by the autopilot's rate loop as a first-order lag
// per axis, w' = (K u - w) / tau (gain K and time constant tau per axis: tools/sysid fits
// them; a pure delay of the whole response is the daemon's daemon.latency.actuation_delay_ms).
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/euler.hpp"

namespace mppi {

struct QuadrotorRate {
  static constexpr int kNx = 13;
  static constexpr int kNu = 4;
  static constexpr const char* kName = "quadrotor_rate";

  enum : int { PX, PY, PZ, VX, VY, VZ, QW, QX, QY, QZ, WX, WY, WZ };
  enum : int { THRUST, RATE_X, RATE_Y, RATE_Z };

  struct Params {
    float mass = 1.0f;        // kg
    float gravity = 9.81f;    // m/s^2
    // The autopilot's rate loop per body axis (x roll, y pitch, z yaw): time constant (s)
    // and steady-state gain of the first-order response to the rate setpoint.
    float rate_tau_x = 0.05f, rate_tau_y = 0.05f, rate_tau_z = 0.05f;
    float rate_gain_x = 1.0f, rate_gain_y = 1.0f, rate_gain_z = 1.0f;
    float drag = 0.0f;        // linear drag, N s/m
    // External acceleration, world frame, m/s^2 (the daemon's disturbance observer).
    float accel_x = 0.0f, accel_y = 0.0f, accel_z = 0.0f;
  };

  MPPI_HD static float hover_thrust(const Params& p) { return p.mass * p.gravity; }
  // The control that holds the vehicle level where it is (one vehicle's kNu floats).
  static void hover_control(const Params& p, float* u) {
    u[THRUST] = hover_thrust(p);
    u[RATE_X] = u[RATE_Y] = u[RATE_Z] = 0.0f;
  }
  // Controls u (one vehicle's) made to hold a vehicle `ratio` times as heavy: the thrust.
  static void scale_hover(float ratio, float* u) { u[THRUST] *= ratio; }

  template <class V>
  MPPI_HD static void derivative(const Params& p, const V* x, const V* u, V* dx) {
    const V qw = x[QW], qx = x[QX], qy = x[QY], qz = x[QZ];
    const V wx = x[WX], wy = x[WY], wz = x[WZ];
    dx[PX] = x[VX];
    dx[PY] = x[VY];
    dx[PZ] = x[VZ];
    // Body z axis in the world frame: third column of R(q).
    const V bx = 2.0f * (qx * qz + qw * qy);
    const V by = 2.0f * (qy * qz - qw * qx);
    const V bz = 1.0f - 2.0f * (qx * qx + qy * qy);
    const V a = u[THRUST] / p.mass;
    const float drag = p.drag / p.mass;
    dx[VX] = a * bx - drag * x[VX] + p.accel_x;
    dx[VY] = a * by - drag * x[VY] + p.accel_y;
    dx[VZ] = a * bz - p.gravity - drag * x[VZ] + p.accel_z;
    // q_dot = 1/2 q (x) (0, omega)
    dx[QW] = 0.5f * (-qx * wx - qy * wy - qz * wz);
    dx[QX] = 0.5f * (qw * wx + qy * wz - qz * wy);
    dx[QY] = 0.5f * (qw * wy - qx * wz + qz * wx);
    dx[QZ] = 0.5f * (qw * wz + qx * wy - qy * wx);
    dx[WX] = (1.0f / p.rate_tau_x) * (p.rate_gain_x * u[RATE_X] - wx);
    dx[WY] = (1.0f / p.rate_tau_y) * (p.rate_gain_y * u[RATE_Y] - wy);
    dx[WZ] = (1.0f / p.rate_tau_z) * (p.rate_gain_z * u[RATE_Z] - wz);
  }

  // Back onto the unit quaternions after an integration step.
  template <class V>
  MPPI_HD static void project(V* x) {
    const V n = fsqrt(x[QW] * x[QW] + x[QX] * x[QX] + x[QY] * x[QY] + x[QZ] * x[QZ]);
    const V inv = select(n > 0.0f, 1.0f / n, V(1.0f));
    for (int i = QW; i <= QZ; ++i) x[i] *= inv;
  }

  // Explicit Euler, then back onto the unit quaternions.
  template <class V>
  MPPI_HD static void step(const Params& p, V* x, const V* u, float dt) {
    euler_step<QuadrotorRate>(p, x, u, dt);
    project(x);
  }

  template <class V>
  MPPI_HD static void position(const V* x, V* pos) {
    pos[0] = x[PX];
    pos[1] = x[PY];
    pos[2] = x[PZ];
  }
  // Cosine of the tilt: the world-z component of the body z axis.
  template <class V>
  MPPI_HD static V tilt_cos(const V* x) { return 1.0f - 2.0f * (x[QX] * x[QX] + x[QY] * x[QY]); }
  // Heading (yaw about world z) of the body x axis.
  template <class V>
  MPPI_HD static V yaw(const V* x) {
    const V qw = x[QW], qx = x[QX], qy = x[QY], qz = x[QZ];
    return fatan2(2.0f * (qw * qz + qx * qy), 1.0f - 2.0f * (qy * qy + qz * qz));
  }
};

}  // namespace mppi
