// 16-state quadrotor of Appendix E (Williams et al. 2017): position, velocity, ZXY Euler
// angles, body rates, motor speeds; controls are desired motor speeds in rpm.
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/euler.hpp"

namespace mppi {

struct Quadrotor {
  static constexpr int kNx = 16;
  static constexpr int kNu = 4;
  static constexpr const char* kName = "quadrotor";

  // State layout.
  enum : int { PX, PY, PZ, VX, VY, VZ, ROLL, PITCH, YAW, WX, WY, WZ, M1, M2, M3, M4 };

  struct Params {
    float mass = 0.25f;         // kg
    float gravity = 9.81f;      // m/s^2
    float arm = 0.1f;           // L, m
    float ixx = 2.5e-4f;        // kg m^2
    float iyy = 2.5e-4f;
    float izz = 1.2e-3f;
    float motor_gain = 20.0f;   // k_m, 1/s
    float k_force = 6.11e-8f;   // N / rpm^2
    float k_moment = 1.5e-9f;   // N m / rpm^2
    float drag = 0.0f;          // linear drag, N s/m (0 in the paper; the SITL plant may differ)
    // External acceleration, world frame, m/s^2: what the daemon's disturbance observer
    // estimates (model mismatch, wind); 0 in the paper's model.
    float accel_x = 0.0f, accel_y = 0.0f, accel_z = 0.0f;
  };

  // Motor speed at which the four motors hold the vehicle level.
  MPPI_HD static float hover_speed(const Params& p) {
    return fsqrt(p.mass * p.gravity / (4.0f * p.k_force));
  }

  // The control that holds the vehicle level where it is (one vehicle's kNu floats).
  static void hover_control(const Params& p, float* u) {
    for (int i = 0; i < kNu; ++i) u[i] = hover_speed(p);
  }
  // Controls u (one vehicle's motor speeds) made to hold a vehicle `ratio` times as heavy.
  static void scale_hover(float ratio, float* u) {
    const float k = fsqrt(ratio);
    for (int i = 0; i < kNu; ++i) u[i] *= k;
  }

  template <class V>
  MPPI_HD static void derivative(const Params& p, const V* x, const V* u, V* dx) {
    V sphi, cphi_raw, sth, cth, spsi, cpsi;
    fsincos(x[ROLL], &sphi, &cphi_raw);
    fsincos(x[PITCH], &sth, &cth);
    fsincos(x[YAW], &spsi, &cpsi);
    // The ZXY Euler map is singular at roll = +-90 deg; keep it finite there.
    const V cphi = select(fabs_(cphi_raw) < 1e-3f, select(cphi_raw < 0.0f, V(-1e-3f), V(1e-3f)), cphi_raw);

    V force[4], moment[4];
    for (int i = 0; i < 4; ++i) {
      const V w = x[M1 + i];
      force[i] = p.k_force * w * w;
      moment[i] = p.k_moment * w * w;
    }
    const V thrust = force[0] + force[1] + force[2] + force[3];
    const V a = thrust / p.mass;

    dx[PX] = x[VX];
    dx[PY] = x[VY];
    dx[PZ] = x[VZ];
    // Third column of R_WB times the collective thrust.
    const float drag = p.drag / p.mass;
    dx[VX] = a * (cpsi * sth + cth * sphi * spsi) - drag * x[VX] + p.accel_x;
    dx[VY] = a * (spsi * sth - cpsi * cth * sphi) - drag * x[VY] + p.accel_y;
    dx[VZ] = a * (cphi_raw * cth) - p.gravity - drag * x[VZ] + p.accel_z;

    const V wx = x[WX], wy = x[WY], wz = x[WZ];
    dx[ROLL] = cth * wx + sth * wz;
    dx[PITCH] = wy + (sphi / cphi) * (sth * wx - cth * wz);
    dx[YAW] = (-sth * wx + cth * wz) / cphi;

    const V tx = p.arm * (force[1] - force[3]);
    const V ty = p.arm * (force[2] - force[0]);
    const V tz = moment[0] - moment[1] + moment[2] - moment[3];
    // omega_dot = I^-1 (tau - omega x I omega)
    dx[WX] = (tx - (wy * p.izz * wz - wz * p.iyy * wy)) / p.ixx;
    dx[WY] = (ty - (wz * p.ixx * wx - wx * p.izz * wz)) / p.iyy;
    dx[WZ] = (tz - (wx * p.iyy * wy - wy * p.ixx * wx)) / p.izz;

    for (int i = 0; i < 4; ++i) dx[M1 + i] = p.motor_gain * (u[i] - x[M1 + i]);
  }

  // Keeps the state on its manifold after an integration step (nothing to do here).
  template <class V>
  MPPI_HD static void project(V*) {}

  // Explicit Euler, as Algorithm 1.
  template <class V>
  MPPI_HD static void step(const Params& p, V* x, const V* u, float dt) {
    euler_step<Quadrotor>(p, x, u, dt);
  }

  template <class V>
  MPPI_HD static void position(const V* x, V* pos) {
    pos[0] = x[PX];
    pos[1] = x[PY];
    pos[2] = x[PZ];
  }
  template <class V>
  MPPI_HD static V yaw(const V* x) { return x[YAW]; }
  // Cosine of the tilt: the world-z component of the body z axis (ZXY Euler angles).
  template <class V>
  MPPI_HD static V tilt_cos(const V* x) { return fcos(x[ROLL]) * fcos(x[PITCH]); }
};

}  // namespace mppi
