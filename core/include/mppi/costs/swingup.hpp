// Cart-pole swing-up (Sec. VI.A): q = p^2 + 500 (1 + cos theta)^2 + theta_dot^2 + p_dot^2.
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/cartpole.hpp"

namespace mppi {

struct SwingupCost {
  struct Params {
    float w_pos = 1.0f;
    float w_angle = 500.0f;
    float w_rate = 1.0f;
    float w_vel = 1.0f;
    float track_limit = 1e9f;   // |p| beyond this is a crash (off the rail)
    float w_crash = 0.0f;
  };
  MPPI_HD static float vehicle(const Params& p, int, const float* x, float, bool* crash) {
    const float c = 1.0f + fcos(x[Cartpole::THETA]);
    float q = p.w_pos * fsq(x[Cartpole::X]) + p.w_angle * c * c + p.w_rate * fsq(x[Cartpole::THETADOT]) +
              p.w_vel * fsq(x[Cartpole::XDOT]);
    if (fabs_(x[Cartpole::X]) > p.track_limit) {
      q += p.w_crash;
      *crash = true;
    }
    return q;
  }
  MPPI_HD static float pair(const Params&, const float*, const float*, bool*) { return 0.0f; }
  MPPI_HD static float terminal(const Params&, int, const float*) { return 0.0f; }
};

}  // namespace mppi
