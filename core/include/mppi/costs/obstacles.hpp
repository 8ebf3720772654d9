// Vertical cylinders (the paper's forests), in a fixed-capacity array so cost parameters
// are plain data that copies to the GPU unchanged.
#pragma once

#include "mppi/hd.hpp"

namespace mppi {

struct Cylinder {
  float x = 0.0f, y = 0.0f;  // axis position, m
  float radius = 0.0f;       // m
  float vx = 0.0f, vy = 0.0f;  // m/s, for moving obstacles (predicted at constant velocity)
};

struct ObstacleSet {
  static constexpr int kCapacity = 64;
  int count = 0;
  Cylinder items[kCapacity];

  // What nearest_surface returns when there are no obstacles.
  static constexpr float kFar = 1e9f;

  // Distance from (px, py) at time t to cylinder c's surface (negative inside), the
  // cylinder predicted at constant velocity. Every search over the set uses this.
  MPPI_HD static float surface_distance(const Cylinder& c, float px, float py, float t) {
    const float dx = px - (c.x + c.vx * t);
    const float dy = py - (c.y + c.vy * t);
    return fsqrt(dx * dx + dy * dy) - c.radius;
  }

  // Distance from (px, py) at time t to the nearest cylinder surface (negative inside);
  // kFar when there are no obstacles.
  MPPI_HD float nearest_surface(float px, float py, float t) const {
    float best = kFar;
    for (int i = 0; i < count; ++i) {
      const float d = surface_distance(items[i], px, py, t);
      best = d < best ? d : best;
    }
    return best;
  }
};

}  // namespace mppi
