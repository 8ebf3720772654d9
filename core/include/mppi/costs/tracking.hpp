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

  MPPI_HD static float vehicle(const Params& p, int, const float* x, float t, bool* crash) {
    float pos[3], ref_p[3], ref_v[3];
    Vehicle::position(x, pos);
    p.reference.eval(p.time0 + t, ref_p, ref_v);
    const float dyaw = Vehicle::yaw(x) - p.reference.yaw;
    float q = p.w_pos * (fsq(pos[0] - ref_p[0]) + fsq(pos[1] - ref_p[1]) + fsq(pos[2] - ref_p[2])) +
              p.w_vel * (fsq(x[3] - ref_v[0]) + fsq(x[4] - ref_v[1]) + fsq(x[5] - ref_v[2])) +
              p.w_yaw * dyaw * dyaw;
    if (pos[2] < p.ground_z) {
      q += p.w_crash;
      *crash = true;
    }
    return q;
  }
  MPPI_HD static float pair(const Params&, const float*, const float*, bool*) { return 0.0f; }
  MPPI_HD static float terminal(const Params&, int, const float*) { return 0.0f; }
};

}  // namespace mppi
