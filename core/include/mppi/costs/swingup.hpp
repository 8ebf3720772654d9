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
  template <class V>
  MPPI_HD static V vehicle(const Params& p, int, const V* x, float, mask_t<V>* crash) {
    const V c = 1.0f + fcos(x[Cartpole::THETA]);
    const V q = p.w_pos * fsq(x[Cartpole::X]) + p.w_angle * c * c + p.w_rate * fsq(x[Cartpole::THETADOT]) +
                p.w_vel * fsq(x[Cartpole::XDOT]);
    const mask_t<V> off_rail = fabs_(x[Cartpole::X]) > p.track_limit;
    *crash = mask_or(*crash, off_rail);
    return select(off_rail, q + p.w_crash, q);
  }
  template <class V>
  MPPI_HD static V pair(const Params&, const V*, const V*, mask_t<V>*) { return V(0.0f); }
  template <class V>
  MPPI_HD static V terminal(const Params&, int, const V*) { return V(0.0f); }
};

}  // namespace mppi
