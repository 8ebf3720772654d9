// Field tables of every model's and cost's parameters: name, reference, and the range a
// value must lie in. The config loader and the daemon's parameter updates set parameters
// by name through these tables, so a bad or unknown field is always reported by name.
#pragma once

#include <cmath>
#include <string>
#include <type_traits>

#include "mppi/tasks.hpp"

namespace mppi {

// A visitor is called as v(name, float& value, lo, hi).
template <class V>
void visit_fields(Quadrotor::Params& p, V&& v) {
  v("mass", p.mass, 1e-3f, 100.0f);
  v("gravity", p.gravity, 0.0f, 20.0f);
  v("arm", p.arm, 1e-3f, 5.0f);
  v("ixx", p.ixx, 1e-7f, 10.0f);
  v("iyy", p.iyy, 1e-7f, 10.0f);
  v("izz", p.izz, 1e-7f, 10.0f);
  v("motor_gain", p.motor_gain, 1e-3f, 1e4f);
  v("k_force", p.k_force, 1e-12f, 1.0f);
  v("k_moment", p.k_moment, 1e-14f, 1.0f);
  v("drag", p.drag, 0.0f, 100.0f);
  v("accel_x", p.accel_x, -50.0f, 50.0f);
  v("accel_y", p.accel_y, -50.0f, 50.0f);
  v("accel_z", p.accel_z, -50.0f, 50.0f);
}
template <class V>
void visit_fields(QuadrotorRate::Params& p, V&& v) {
  v("mass", p.mass, 1e-3f, 100.0f);
  v("gravity", p.gravity, 0.0f, 20.0f);
  v("rate_tau_x", p.rate_tau_x, 1e-3f, 10.0f);
  v("rate_tau_y", p.rate_tau_y, 1e-3f, 10.0f);
  v("rate_tau_z", p.rate_tau_z, 1e-3f, 10.0f);
  v("rate_gain_x", p.rate_gain_x, 0.05f, 20.0f);
  v("rate_gain_y", p.rate_gain_y, 0.05f, 20.0f);
  v("rate_gain_z", p.rate_gain_z, 0.05f, 20.0f);
  v("drag", p.drag, 0.0f, 100.0f);
  v("accel_x", p.accel_x, -50.0f, 50.0f);
  v("accel_y", p.accel_y, -50.0f, 50.0f);
  v("accel_z", p.accel_z, -50.0f, 50.0f);
}
template <class V>
void visit_fields(Cartpole::Params& p, V&& v) {
  v("gravity", p.gravity, 0.0f, 20.0f);
  v("cart_mass", p.cart_mass, 1e-3f, 100.0f);
  v("pole_mass", p.pole_mass, 1e-4f, 100.0f);
  v("length", p.length, 1e-3f, 10.0f);
  v("motor_gain", p.motor_gain, 1e-3f, 1e4f);
}
template <class V>
void visit_fields(Racecar::Params& p, V&& v) {
  v("mass", p.mass, 0.1f, 5000.0f);
  v("yaw_inertia", p.yaw_inertia, 1e-3f, 1e4f);
  v("front", p.front, 1e-3f, 5.0f);
  v("rear", p.rear, 1e-3f, 5.0f);
  v("gravity", p.gravity, 0.0f, 20.0f);
  v("cornering", p.cornering, 1.0f, 1e6f);
  v("friction", p.friction, 1e-3f, 3.0f);
  v("min_speed", p.min_speed, 1e-2f, 10.0f);
  v("steer_gain", p.steer_gain, 1e-2f, 1e3f);
  v("force_gain", p.force_gain, 1e-2f, 1e3f);
}
template <class Vehicle, class V>
void visit_fields(typename ForestCost<Vehicle>::Params& p, V&& v) {
  v("w_xy", p.w_xy, 0.0f, 1e6f);
  v("w_z", p.w_z, 0.0f, 1e6f);
  v("w_yaw", p.w_yaw, 0.0f, 1e6f);
  v("w_speed", p.w_speed, 0.0f, 1e6f);
  v("w_obstacle", p.w_obstacle, 0.0f, 1e6f);
  v("obstacle_scale", p.obstacle_scale, 1e-3f, 1e3f);
  v("w_crash", p.w_crash, 0.0f, 1e9f);
  v("vehicle_radius", p.vehicle_radius, 0.0f, 10.0f);
  v("ground_z", p.ground_z, -1e3f, 1e3f);
  v("w_separation", p.w_separation, 0.0f, 1e6f);
  v("separation_scale", p.separation_scale, 1e-3f, 1e3f);
  v("w_terminal", p.w_terminal, 0.0f, 1e6f);
  v("xy_linear_beyond", p.xy_linear_beyond, 0.0f, 1e4f);
  v("crash_sticky", p.crash_sticky, 0.0f, 1.0f);
  v("ground_margin", p.ground_margin, 0.0f, 100.0f);
  v("tilt_cos_min", p.tilt_cos_min, -1.0f, 1.0f);
  v("floor_z", p.floor_z, -1e3f, 1e3f);
  v("floor_lookahead", p.floor_lookahead, 0.0f, 10.0f);
  v("w_floor", p.w_floor, 0.0f, 1e9f);
  v("max_speed", p.max_speed, 0.0f, 100.0f);
  v("w_max_speed", p.w_max_speed, 0.0f, 1e9f);
  v("obstacle_reach", p.obstacle_reach, 0.0f, 1e3f);
  v("obstacle_cell", p.obstacle_cell, 0.05f, 1e3f);
}
template <class Vehicle, class V>
void visit_fields(typename TrackingCost<Vehicle>::Params& p, V&& v) {
  v("w_pos", p.w_pos, 0.0f, 1e6f);
  v("w_vel", p.w_vel, 0.0f, 1e6f);
  v("w_yaw", p.w_yaw, 0.0f, 1e6f);
  v("w_crash", p.w_crash, 0.0f, 1e9f);
  v("ground_z", p.ground_z, -1e3f, 1e3f);
}
template <class V>
void visit_fields(SwingupCost::Params& p, V&& v) {
  v("w_pos", p.w_pos, 0.0f, 1e6f);
  v("w_angle", p.w_angle, 0.0f, 1e6f);
  v("w_rate", p.w_rate, 0.0f, 1e6f);
  v("w_vel", p.w_vel, 0.0f, 1e6f);
  v("track_limit", p.track_limit, 0.0f, 1e9f);
  v("w_crash", p.w_crash, 0.0f, 1e9f);
}
template <class V>
void visit_fields(EllipseCost::Params& p, V&& v) {
  v("semi_x", p.semi_x, 0.1f, 1e3f);
  v("semi_y", p.semi_y, 0.1f, 1e3f);
  v("w_track", p.w_track, 0.0f, 1e6f);
  v("line", p.line, -1.0f, 10.0f);
  v("target_speed", p.target_speed, 0.0f, 100.0f);
  v("w_speed", p.w_speed, 0.0f, 1e6f);
  v("w_slip", p.w_slip, 0.0f, 1e6f);
  v("track_limit", p.track_limit, 0.0f, 1e9f);
  v("w_crash", p.w_crash, 0.0f, 1e9f);
  v("edge", p.edge, 0.0f, 1e9f);
  v("w_edge", p.w_edge, 0.0f, 1e9f);
  v("w_line", p.w_line, 0.0f, 1e6f);
  v("line_radius", p.line_radius, 0.0f, 1e3f);
  v("line_half", p.line_half, 0.0f, 1e3f);
  v("drift", p.drift, 0.0f, 1e9f);
  v("w_drift", p.w_drift, 0.0f, 1e9f);
}

// Cost tables by task (the cost template parameter cannot be deduced from its Params).
template <class T, class V>
void visit_cost_fields(typename T::Params& p, V&& v) {
  using Cost = typename T::Cost;
  if constexpr (std::is_same_v<Cost, ForestCost<typename T::Vehicle>> ||
                std::is_same_v<Cost, TrackingCost<typename T::Vehicle>>) {
    visit_fields<typename T::Vehicle>(p.cost, v);
  } else {
    visit_fields(p.cost, v);
  }
}

// Sets "model.NAME" or "cost.NAME" of a task's parameters. Empty on success, else an error
// naming the field.
template <class T>
std::string set_task_param(typename T::Params& p, const std::string& key, double value) {
  std::string err = "unknown parameter";
  bool found = false;
  auto setter = [&](const std::string& prefix) {
    return [&, prefix](const char* name, float& field, float lo, float hi) {
      if (found || key != prefix + name) return;
      found = true;
      const auto f = static_cast<float>(value);
      if (!std::isfinite(value) || f < lo || f > hi)
        err = "out of range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
      else {
        field = f;
        err.clear();
      }
    };
  };
  visit_fields(p.vehicle, setter("model."));
  visit_cost_fields<T>(p, setter("cost."));
  return err.empty() ? std::string() : key + ": " + err;
}

}  // namespace mppi
