// The exact distance field of vertical cylinders of a finite height standing on the ground,
// sampled at the cell centres of a DistanceFieldGrid (costs/distance_field.hpp): the field a
// perfect mapper would publish for a known forest. For tests, benchmarks and comparisons of a
// sensed map against the truth. Host only; allocates nothing.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "mppi/costs/distance_field.hpp"
#include "mppi/costs/obstacles.hpp"

namespace mppi {

// Signed distance from (x, y, z) to cylinder c (at t = 0) standing from z = -inf to `height`:
// the trees' trunks and crowns as one column; the ground is the cost's own term.
inline float cylinder_column_distance(const Cylinder& c, float height, float x, float y, float z) {
  const float e = std::hypot(x - c.x, y - c.y) - c.radius;  // horizontal, negative inside
  const float above = z - height;
  if (above <= 0.0f) return e < 0.0f ? std::max(e, above) : e;
  return e <= 0.0f ? above : std::hypot(e, above);
}

// Lays a grid of nx x ny x nz cells of side `resolution` from `origin` and fills it with the
// distance to the nearest of `set`'s cylinders (their height `height`), saturated at
// max_distance, in millimetres. False (grid untouched) when the shape is not valid
// (DistanceFieldGrid::invalid).
inline bool fill_from_cylinders(const ObstacleSet& set, float height, const float origin[3], float resolution, int nx,
                                int ny, int nz, float max_distance, DistanceFieldGrid* grid) {
  const std::int64_t cells = static_cast<std::int64_t>(nx) * ny * nz;
  if (DistanceFieldGrid::invalid_shape(origin, resolution, nx, ny, nz, max_distance, cells) != nullptr) return false;
  DistanceFieldGrid& g = *grid;
  g.resolution = resolution;
  g.nx = nx;
  g.ny = ny;
  g.nz = nz;
  g.n_cells = static_cast<int>(cells);
  g.max_distance = max_distance;
  std::copy_n(origin, 3, g.origin);
  for (int k = 0; k < nz; ++k) {
    const float z = origin[2] + (static_cast<float>(k) + 0.5f) * resolution;
    for (int j = 0; j < ny; ++j) {
      const float y = origin[1] + (static_cast<float>(j) + 0.5f) * resolution;
      for (int i = 0; i < nx; ++i) {
        const float x = origin[0] + (static_cast<float>(i) + 0.5f) * resolution;
        float d = max_distance;
        for (int n = 0; n < set.count; ++n) d = std::min(d, cylinder_column_distance(set.items[n], height, x, y, z));
        const float mm = std::round(std::clamp(d, -DistanceField::kMaxDistanceLimit, max_distance) * 1000.0f);
        g.distance_mm[i + nx * (j + ny * k)] = static_cast<std::int16_t>(mm);
      }
    }
  }
  return true;
}

}  // namespace mppi
