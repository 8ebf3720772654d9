// Forests, paths and the exactness check shared by the obstacle grid's tests: the host build
// (test/core/test_obstacle_grid.cpp) and the CUDA backend's (test/gpu/test_obstacle_grid_device.cpp).
#pragma once

#include <cstdint>
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "mppi/costs/obstacles.hpp"

namespace mppi::testing {

inline bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof(float)) == 0; }

// A forest of n cylinders on a 4 m lattice starting at x = 4 (rows of `per_row` along y,
// centred on y = 0), jittered; every `moving`-th one moves at up to 2 m/s.
inline ObstacleSet forest(int n, int per_row, int moving, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  ObstacleSet set;
  for (int i = 0; i < n && i < ObstacleSet::kCapacity; ++i) {
    Cylinder& c = set.items[i];
    c.radius = 0.3f + 0.2f * unit(rng);
    c.x = 4.0f + 4.0f * static_cast<float>(i / per_row) + 0.5f + 3.0f * unit(rng);
    c.y = 4.0f * static_cast<float>(i % per_row - per_row / 2) + 0.5f + 3.0f * unit(rng);
    if (moving > 0 && i % moving == 0) {
      c.vx = 4.0f * unit(rng) - 2.0f;
      c.vy = 4.0f * unit(rng) - 2.0f;
    }
    set.count = i + 1;
  }
  return set;
}

// A straight path from (0, 0) along x, `length` m in `points` points.
inline std::vector<float> path(float length, int points) {
  std::vector<float> xy;
  for (int i = 0; i < points; ++i) {
    xy.push_back(length * static_cast<float>(i) / static_cast<float>(points - 1));
    xy.push_back(0.25f * static_cast<float>(i % 3));
  }
  return xy;
}

// Every sampled point (some outside the grid) and time: the grid's search is the full scan.
inline int expect_exact(const ObstacleSet& set, const ObstacleGrid& grid, float t_end, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> x(-20.0f, 45.0f), y(-25.0f, 25.0f), t(0.0f, t_end);
  int inside = 0;
  for (int n = 0; n < 40000; ++n) {
    const float px = x(rng), py = y(rng), tt = n % 7 == 0 ? t_end : t(rng);
    const float a = grid.nearest_surface(set, px, py, tt);
    const float b = set.nearest_surface(px, py, tt);
    if (!same_bits(a, b)) {
      ADD_FAILURE() << "at (" << px << ", " << py << ", t = " << tt << "): grid " << a << ", scan " << b;
      return inside;
    }
    const float fx = (px - grid.x0) * grid.inv_cell, fy = (py - grid.y0) * grid.inv_cell;
    inside += fx >= 0.0f && fx < static_cast<float>(grid.nx) && fy >= 0.0f && fy < static_cast<float>(grid.ny);
  }
  return inside;
}

}  // namespace mppi::testing
