// Cart-pole of Appendix C: state (x, x_dot, theta, theta_dot, f), theta from the downward
// vertical, f the motor force with a first-order response to the desired force (the
// control). Sec. VI.A describes a velocity input instead; Appendix C is the model used.
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/euler.hpp"

namespace mppi {

struct Cartpole {
  static constexpr int kNx = 5;
  static constexpr int kNu = 1;
  static constexpr const char* kName = "cartpole";
  enum : int { X, XDOT, THETA, THETADOT, FORCE };

  struct Params {
    float gravity = 9.81f;
    float cart_mass = 1.0f;   // m_c, kg
    float pole_mass = 0.01f;  // m_p, kg
    float length = 0.25f;     // l, m
    float motor_gain = 20.0f; // 1/s
  };

  template <class V>
  MPPI_HD static void derivative(const Params& p, const V* x, const V* u, V* dx) {
    const V s = fsin(x[THETA]), c = fcos(x[THETA]);
    const V w = x[THETADOT], f = x[FORCE];
    const V den = p.cart_mass + p.pole_mass * s * s;
    dx[X] = x[XDOT];
    dx[XDOT] = (f + p.pole_mass * s * (p.length * w * w + p.gravity * c)) / den;
    dx[THETA] = w;
    dx[THETADOT] = (-f * c - p.pole_mass * p.length * w * w * c * s - (p.cart_mass + p.pole_mass) * p.gravity * s) /
                   (p.length * den);
    dx[FORCE] = p.motor_gain * (u[0] - f);
  }

  // Keeps the state on its manifold after an integration step (nothing to do here).
  template <class V>
  MPPI_HD static void project(V*) {}

  // Where the cart is, for displays: (x, 0, 0).
  template <class V>
  MPPI_HD static void position(const V* x, V* pos) {
    pos[0] = x[X];
    pos[1] = V(0.0f);
    pos[2] = V(0.0f);
  }

  template <class V>
  MPPI_HD static void step(const Params& p, V* x, const V* u, float dt) {
    euler_step<Cartpole>(p, x, u, dt);
  }
};

}  // namespace mppi
