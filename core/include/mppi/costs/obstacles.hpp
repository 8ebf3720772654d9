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

  // Distance from (px, py) at time t to the nearest cylinder surface (negative inside);
  // a large number when there are no obstacles.
  MPPI_HD float nearest_surface(float px, float py, float t) const {
    float best = 1e9f;
    for (int i = 0; i < count; ++i) {
      const Cylinder& c = items[i];
      const float dx = px - (c.x + c.vx * t);
      const float dy = py - (c.y + c.vy * t);
      const float d = fsqrt(dx * dx + dy * dy) - c.radius;
      best = d < best ? d : best;
    }
    return best;
  }
};

}  // namespace mppi
