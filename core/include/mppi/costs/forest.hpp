// The quadrotor forest cost of Sec. VI.C, for any vehicle whose state starts with position
// and velocity, and for teams (a separation term couples the vehicles):
//   q = 2.5 (px - gx)^2 + 2.5 (py - gy)^2 + 150 (pz - gz)^2 + 50 yaw^2 + |v|^2
//       + 350 exp(-d^2 / 12) + 1000 C
// with d the distance to the nearest obstacle surface and C = 1 on a crash (ground,
// obstacle, or, in a team, another vehicle).
//
// Flight-envelope terms, off by default (the paper's cost), on in the task files: a fast
// quadrotor flown with latency otherwise trades altitude for speed until it meets the
// ground. A rollout counts as crashed below ground_z + ground_margin or tilted beyond
// the tilt whose cosine is tilt_cos_min (the world-z component of the body z axis;
// 0.5 = 60 deg; the controller keeps margins the plant does not have), and pays
//   w_floor * max(0, floor_z - (pz + floor_lookahead * min(vz, 0)))^2
// when its altitude, predicted floor_lookahead seconds ahead at its sink rate, is below
// floor_z (a sink-rate limit that tightens near the ground).
//
// Goal pull beyond a radius (xy_linear_beyond = r > 0, off by default): the xy goal term
// w_xy e^2 (e the horizontal distance to the goal) becomes w_xy r (2 e - r) beyond e = r,
// the quadratic continued along its slope there (a Huber loss). The pull towards a far goal
// is then bounded (2 w_xy r per metre), so w_xy can be large enough to hold each vehicle of a
// team on its own goal near the end without flinging it off the start line 40 m away at
// top speed. The terminal term uses the same shape.
//
// A speed limit (max_speed = v > 0, off by default): w_max_speed max(0, |vel| - v)^2. The
// paper's |vel|^2 term damps but sets no speed: on forest_4m the vehicle accelerates for the
// whole 40 m (14.6 m/s at its peak, seed 3, offline) whatever w_speed is; a team or an operator
// that wants the forest flown at 5 or 10 m/s sets the limit (issue 30's speed curve).
//
// The sensed obstacles (issue 30): with a distance field (costs/distance_field.hpp: a mapper's
// local map) in `field`, d is the nearer of the cylinders' surface and the field's
// interpolated distance at the vehicle's position (3-D: the field knows the trees' height),
// and the obstacle and crash terms read that d. Without a field (field.cells null) nothing
// changes: the known-cylinder cost, bit for bit.
#pragma once

#include "mppi/costs/distance_field.hpp"
#include "mppi/costs/obstacles.hpp"
#include "mppi/hd.hpp"

namespace mppi {

template <class Vehicle>
struct ForestCost {
  static constexpr int kMaxVehicles = 32;
  struct Params {
    float goal[kMaxVehicles][3] = {};  // per vehicle
    float w_xy = 2.5f;
    float w_z = 150.0f;
    float w_yaw = 50.0f;
    float w_speed = 1.0f;
    float w_obstacle = 350.0f;
    float obstacle_scale = 12.0f;  // m^2, in exp(-d^2 / scale)
    float w_crash = 1000.0f;
    float vehicle_radius = 0.15f;   // m
    float ground_z = 0.0f;          // m
    float w_separation = 350.0f;    // team only: exp barrier on vehicle-vehicle distance
    float separation_scale = 1.0f;  // m^2
    float w_terminal = 0.0f;        // multiplies the goal terms at the horizon's end
    float xy_linear_beyond = 0.0f;  // m; > 0: the xy goal term grows linearly beyond it
    float crash_sticky = 0.0f;      // > 0: w_crash at every step after a crash (moving obstacles)
    float ground_margin = 0.0f;     // m above ground_z that a rollout treats as the ground
    float tilt_cos_min = -1.0f;     // a rollout tilted further is a crash (-1: no limit)
    float floor_z = 0.0f;           // m, the floor of the predicted altitude
    float floor_lookahead = 0.0f;   // s
    float w_floor = 0.0f;
    float max_speed = 0.0f;         // m/s; > 0: a speed above it pays w_max_speed per (m/s)^2 over
    float w_max_speed = 1000.0f;    // chosen offline on seeds 1-3: max 10.1-10.2 m/s at 10 (300: 10.3-10.6)
    // Obstacle culling (ObstacleGrid): the grid covers the plan's path widened by
    // obstacle_reach, in cells of obstacle_cell. It changes no cost (the search is exact);
    // a rollout leaving the grid searches every obstacle. obstacle_reach 0: no grid.
    float obstacle_reach = 8.0f;    // m
    float obstacle_cell = 1.0f;     // m
    // The local distance field (a view: the cells live with whoever set it, e.g. the
    // daemon's inbox); none by default. Before the obstacles: the kernels stage it.
    DistanceField field;
    ObstacleSet obstacles;
    ObstacleGrid obstacle_grid;     // rebuilt each cycle by prepare()
  };

  template <class V>
  MPPI_HD static V vehicle(const Params& p, int j, const V* x, float t, mask_t<V>* crash) {
    V pos[3];
    Vehicle::position(x, pos);
    return vehicle_at_distance(p, j, x, p.obstacle_grid.nearest_surface(p.obstacles, pos[0], pos[1], t), crash);
  }

  // Every term of vehicle() given d_cylinders, the distance to the nearest cylinder's
  // surface: a backend may search the cylinders its own way (the CUDA one splits them over
  // lanes). The distance field, when there is one, is read here, so every backend's search
  // feeds the one formula. kField = false compiles the field out: for a kernel a backend runs
  // only while the parameters carry none (the CUDA chunked kernel: its field-less registers).
  template <class V, bool kField = true>
  MPPI_HD static V vehicle_at_distance(const Params& p, int j, const V* x, const V& d_cylinders, mask_t<V>* crash) {
    V pos[3];
    Vehicle::position(x, pos);
    const bool field = kField && p.field.present();
    const V d = field ? fmin_(d_cylinders, p.field.distance(pos[0], pos[1], pos[2])) : d_cylinders;
    const float* g = p.goal[j];
    const V yaw = Vehicle::yaw(x);
    V q = p.w_xy * goal_xy(p, fsq(pos[0] - g[0]) + fsq(pos[1] - g[1])) + p.w_z * fsq(pos[2] - g[2]) +
          p.w_yaw * yaw * yaw;
    const V speed2 = fsq(x[Vehicle::VX]) + fsq(x[Vehicle::VY]) + fsq(x[Vehicle::VZ]);
    q += p.w_speed * speed2;
    if (p.max_speed > 0.0f) {
      const V over = fmax_(fsqrt(speed2) - p.max_speed, V(0.0f));
      q += p.w_max_speed * over * over;
    }
    if (p.obstacles.count > 0 || field) q += p.w_obstacle * fexp(-(d * d) / p.obstacle_scale);
    if (p.w_floor > 0.0f) {
      const V z_ahead = pos[2] + p.floor_lookahead * fmin_(x[Vehicle::VZ], V(0.0f));
      const V below = fmax_(V(p.floor_z) - z_ahead, V(0.0f));
      q += p.w_floor * below * below;
    }
    mask_t<V> hit = mask_or(d < p.vehicle_radius, pos[2] < p.ground_z + p.ground_margin);
    if (p.tilt_cos_min > -1.0f) hit = mask_or(hit, Vehicle::tilt_cos(x) < p.tilt_cos_min);
    // crash_sticky: a vehicle that crashed at an earlier step (*crash on entry) pays w_crash
    // at every later step too, as the paper's frozen vehicle does when its obstacle stands
    // still; a moving obstacle would otherwise sweep past the frozen vehicle, and a rollout
    // that grazes one pay a few steps of w_crash instead of the rest of the horizon.
    const mask_t<V> charged = p.crash_sticky > 0.0f ? mask_or(hit, *crash) : hit;
    *crash = mask_or(*crash, hit);
    return select(charged, q + p.w_crash, q);
  }

  template <class V>
  MPPI_HD static V pair(const Params& p, const V* xa, const V* xb, mask_t<V>* crash) {
    V a[3], b[3];
    Vehicle::position(xa, a);
    Vehicle::position(xb, b);
    const V d2 = fsq(a[0] - b[0]) + fsq(a[1] - b[1]) + fsq(a[2] - b[2]);
    const V q = p.w_separation * fexp(-d2 / p.separation_scale);
    const mask_t<V> hit = d2 < fsq(2.0f * p.vehicle_radius);
    *crash = mask_or(*crash, hit);
    return select(hit, q + p.w_crash, q);
  }

  template <class V>
  MPPI_HD static V terminal(const Params& p, int j, const V* x) {
    if (p.w_terminal == 0.0f) return V(0.0f);
    V pos[3];
    Vehicle::position(x, pos);
    const float* g = p.goal[j];
    return p.w_terminal * (p.w_xy * goal_xy(p, fsq(pos[0] - g[0]) + fsq(pos[1] - g[1])) + p.w_z * fsq(pos[2] - g[2]));
  }

  // The xy goal term's shape of the squared horizontal distance e2: e2 itself, or with
  // xy_linear_beyond = r > 0, r (2 e - r) beyond e = r (see the top of the file).
  template <class V>
  MPPI_HD static V goal_xy(const Params& p, const V& e2) {
    const float r = p.xy_linear_beyond;
    if (r <= 0.0f) return e2;
    return select(e2 > r * r, r * (2.0f * fsqrt(e2) - r), e2);
  }

  // Once per cycle, before the rollouts (host): index the obstacles near the plan's
  // noise-free path (xy of `n_points` points) for times [0, t_end] (ObstacleGrid).
  static constexpr bool kUsesPath = true;
  static void prepare(Params& p, const float* path_xy, int n_points, float t_end) {
    p.obstacle_grid.build(p.obstacles, path_xy, n_points, t_end, p.obstacle_reach, p.obstacle_cell);
  }
};

}  // namespace mppi
