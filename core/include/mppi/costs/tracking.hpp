// Trajectory tracking for either quadrotor model: follow a time-parameterised reference
// (position and velocity) while keeping heading, away from the ground.
//   q = w_pos |p - p_ref(t)|^2 + w_vel |v - v_ref(t)|^2 + w_yaw (yaw - yaw_ref)^2 + w_crash C
#pragma once

#include "mppi/costs/reference.hpp"
#include "mppi/hd.hpp"

namespace mppi {

template <class Vehicle>
struct TrackingCost {
  struct Params {
    Reference reference;
    float time0 = 0.0f;  // reference time at the plan's first step, s
    float w_pos = 100.0f;
    float w_vel = 10.0f;
    float w_yaw = 10.0f;
    float w_crash = 1000.0f;
    float ground_z = 0.0f;
  };

  // The reference depends on time only, which every sample of a step shares: it is float.
  template <class V>
  MPPI_HD static V vehicle(const Params& p, int, const V* x, float t, mask_t<V>* crash) {
    V pos[3];
    float ref_p[3], ref_v[3];
    Vehicle::position(x, pos);
    p.reference.eval(p.time0 + t, ref_p, ref_v);
    const V dyaw = Vehicle::yaw(x) - p.reference.yaw;
    const V q = p.w_pos * (fsq(pos[0] - ref_p[0]) + fsq(pos[1] - ref_p[1]) + fsq(pos[2] - ref_p[2])) +
                p.w_vel * (fsq(x[Vehicle::VX] - ref_v[0]) + fsq(x[Vehicle::VY] - ref_v[1]) + fsq(x[Vehicle::VZ] - ref_v[2])) +
                p.w_yaw * dyaw * dyaw;
    const mask_t<V> below = pos[2] < p.ground_z;
    *crash = mask_or(*crash, below);
    return select(below, q + p.w_crash, q);
  }
  template <class V>
  MPPI_HD static V pair(const Params&, const V*, const V*, mask_t<V>*) { return V(0.0f); }
  template <class V>
  MPPI_HD static V terminal(const Params&, int, const V*) { return V(0.0f); }
};

}  // namespace mppi
