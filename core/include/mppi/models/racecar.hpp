// Race car of Appendix D: bicycle model with a brush tire model. State (x, y, psi, beta,
// vx, vy, r, delta, Fx); controls (delta_des, Fx_des). The paper gives C and mu only; the
// mass and geometry are a 1:5 scale car (documented in docs of the task settings).
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/euler.hpp"

namespace mppi {

struct Racecar {
  static constexpr int kNx = 9;
  static constexpr int kNu = 2;
  static constexpr const char* kName = "racecar";
  enum : int { X, Y, PSI, BETA, VX, VY, R, DELTA, FX };
  enum : int { STEER, DRIVE };

  struct Params {
    float mass = 21.0f;          // M, kg
    float yaw_inertia = 1.1f;    // I_z, kg m^2
    float front = 0.28f;         // a, CG to front axle, m
    float rear = 0.22f;          // b, CG to rear axle, m
    float gravity = 9.81f;
    float cornering = 1200.0f;   // C, N/rad
    float friction = 0.55f;      // mu
    float min_speed = 1.0f;      // vx floor in the slip angles, m/s (keeps them finite at rest)
    float steer_gain = 10.0f;    // 1/s
    float force_gain = 10.0f;    // 1/s
  };

  // Brush tire lateral force for slip angle alpha, normal load fz, longitudinal force fx.
  // Past the slip angle gamma the tire slides: the force saturates at xi mu fz.
  template <class V>
  MPPI_HD static V lateral_force(const Params& p, const V& alpha, float fz, const V& fx) {
    const float mu_fz = p.friction * fz;
    const V fx_c = fclamp(fx, -0.99f * mu_fz, 0.99f * mu_fz);
    const V xi = fsqrt(mu_fz * mu_fz - fx_c * fx_c) / mu_fz;
    const V gamma = fatan(3.0f * xi * mu_fz / p.cornering);
    const V sliding = -xi * mu_fz * select(alpha > 0.0f, V(1.0f), V(-1.0f));
    const V ta = ftan(alpha);
    const float c = p.cornering;
    const V gripping = -c * ta + c * c / (3.0f * xi * mu_fz) * fabs_(ta) * ta -
                       c * c * c / (27.0f * xi * xi * mu_fz * mu_fz) * ta * ta * ta;
    return select(fabs_(alpha) >= gamma, sliding, gripping);
  }

  template <class V>
  MPPI_HD static void derivative(const Params& p, const V* x, const V* u, V* dx) {
    const float wheelbase = p.front + p.rear;
    const float fz_front = p.mass * p.gravity * p.rear / wheelbase;
    const float fz_rear = p.mass * p.gravity * p.front / wheelbase;
    const V vx = fmax_(x[VX], V(p.min_speed));
    const V beta = x[BETA], r = x[R], delta = x[DELTA], fx = x[FX];
    const V alpha_f = fatan(beta + p.front * r / vx) - delta;
    const V alpha_r = fatan(beta - p.rear * r / vx);
    const V fyf = lateral_force(p, alpha_f, fz_front, V(0.0f));
    const V fyr = lateral_force(p, alpha_r, fz_rear, fx);
    const V spsi = fsin(x[PSI]), cpsi = fcos(x[PSI]);
    dx[X] = x[VX] * cpsi - x[VY] * spsi;
    dx[Y] = x[VX] * spsi + x[VY] * cpsi;
    dx[PSI] = r;
    dx[BETA] = (fyf + fyr) / (p.mass * vx) - r;
    dx[VX] = (fx - fyf * fsin(delta)) / p.mass + r * x[VX] * beta;
    dx[VY] = (fyf + fyr) / p.mass - r * x[VX];
    dx[R] = (p.front * fyf - p.rear * fyr) / p.yaw_inertia;
    dx[DELTA] = p.steer_gain * (u[STEER] - delta);  // tracks delta_des (the raw text's sign slip fixed)
    dx[FX] = p.force_gain * (u[DRIVE] - fx);
  }

  // Keeps the state on its manifold after an integration step (nothing to do here).
  template <class V>
  MPPI_HD static void project(V*) {}

  template <class V>
  MPPI_HD static void position(const V* x, V* pos) {
    pos[0] = x[X];
    pos[1] = x[Y];
    pos[2] = V(0.0f);
  }

  template <class V>
  MPPI_HD static void step(const Params& p, V* x, const V* u, float dt) {
    euler_step<Racecar>(p, x, u, dt);
  }
};

}  // namespace mppi
