// Race car on the elliptical track (Sec. VI.B): q = 100 d^2 + (vx - 7)^2 with
// d = (x / 13)^2 + (y / 6)^2 - 1.
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/racecar.hpp"

namespace mppi {

struct EllipseCost {
  struct Params {
    float semi_x = 13.0f;  // m
    float semi_y = 6.0f;   // m
    float w_track = 100.0f;
    float target_speed = 7.0f;  // m/s
    float w_speed = 1.0f;
    float w_slip = 0.0f;        // optional sideslip penalty
  };
  template <class V>
  MPPI_HD static V vehicle(const Params& p, int, const V* x, float, mask_t<V>*) {
    const V d = fsq(x[Racecar::X] / p.semi_x) + fsq(x[Racecar::Y] / p.semi_y) - 1.0f;
    return p.w_track * d * d + p.w_speed * fsq(x[Racecar::VX] - p.target_speed) + p.w_slip * fsq(x[Racecar::BETA]);
  }
  template <class V>
  MPPI_HD static V pair(const Params&, const V*, const V*, mask_t<V>*) { return V(0.0f); }
  template <class V>
  MPPI_HD static V terminal(const Params&, int, const V*) { return V(0.0f); }
};

}  // namespace mppi
