// Vertical cylinders (the paper's forests), in a fixed-capacity array so cost parameters
// are plain data that copies to the GPU unchanged; and ObstacleGrid, the per-cycle index
// that makes the nearest-surface search depend on the nearby cylinders only.
#pragma once

#include <cstdint>

#include "mppi/hd.hpp"

namespace mppi {

struct Cylinder {
  float x = 0.0f, y = 0.0f;  // axis position, m
  float radius = 0.0f;       // m
  float vx = 0.0f, vy = 0.0f;  // m/s, for moving obstacles (predicted at constant velocity)
};

struct ObstacleSet {
  static constexpr int kCapacity = 256;
  int count = 0;
  Cylinder items[kCapacity];

  // What nearest_surface returns when there are no obstacles.
  static constexpr float kFar = 1e9f;

  // Distance from (px, py) at time t to cylinder c's surface (negative inside), the
  // cylinder predicted at constant velocity. Every search over the set uses this.
  template <class V>
  MPPI_HD static V surface_distance(const Cylinder& c, const V& px, const V& py, float t) {
    const V dx = px - (c.x + c.vx * t);
    const V dy = py - (c.y + c.vy * t);
    return fsqrt(dx * dx + dy * dy) - c.radius;
  }

  // Distance from (px, py) at time t to the nearest cylinder surface (negative inside);
  // kFar when there are no obstacles. Every cylinder, in order: the reference search.
  template <class V>
  MPPI_HD V nearest_surface(const V& px, const V& py, float t) const {
    V best = kFar;
    for (int i = 0; i < count; ++i) {
      const V d = surface_distance(items[i], px, py, t);
      best = select(d < best, d, best);
    }
    return best;
  }
};

// Cell index of (fx, fy), both inside [0, nx) x [0, ny), for each sample of the number:
// out[0] for a float; a SIMD number type overloads this.
MPPI_HD void store_cell_indices(float fx, float fy, int nx, int* out) {
  out[0] = static_cast<int>(fx) + nx * static_cast<int>(fy);
}

MPPI_HD void store_cell_indices(double fx, double fy, int nx, int* out) {
  out[0] = static_cast<int>(fx) + nx * static_cast<int>(fy);
}

// Obstacle culling. Each cycle, a uniform grid is laid over the region the rollouts can
// reach (the plan's noise-free path, widened by a reach distance), and each cell lists the
// cylinders that can be the nearest one for some point of the cell at some time of the
// horizon: with U the least upper bound, over the cylinders, of the surface distance from
// any point of the cell at any time, a cylinder is listed when its least possible distance
// to the cell is within U. The nearest cylinder of every point of the cell is then listed,
// so the search over the cell's list returns exactly ObstacleSet::nearest_surface (the same
// float, computed by the same surface_distance; min does not depend on the order). The
// bounds are computed in double with a slack that covers the float rounding of
// surface_distance and of the cell lookup. Points outside the grid, or non-finite ones,
// search every cylinder. Cylinders in no list are the ones no rollout inside the region can
// see: they cost nothing per step. A moving cylinder is bounded by the segment it sweeps
// over [0, t_end].
//
// The search costs the length of the lists (a few cylinders in a forest) instead of the
// whole set; a SIMD batch of samples searches the union of its samples' lists.
struct ObstacleGrid {
  static constexpr int kMaxCells = 1024;
  static constexpr int kMaxRefs = 8192;
  static constexpr int kBlock = 4;  // cells per block side in the build

  int nx = 0, ny = 0;  // cells; 0 when there is no grid (every search scans the set)
  float x0 = 0.0f, y0 = 0.0f;
  float inv_cell = 0.0f;  // 1 / cell side
  int listed = 0;         // cylinders in at least one list (for reports)
  std::uint16_t first[kMaxCells + 1] = {};  // cell c lists refs[first[c] .. first[c + 1])
  std::uint8_t refs[kMaxRefs] = {};         // indices into ObstacleSet::items

  // ObstacleSet::nearest_surface(px, py, t), through the grid.
  template <class V>
  MPPI_HD V nearest_surface(const ObstacleSet& set, const V& px, const V& py, float t) const {
    if (nx > 0) {
      const V fx = (px - x0) * inv_cell;
      const V fy = (py - y0) * inv_cell;
      const auto inside = mask_and(mask_and(fx >= 0.0f, fx < static_cast<float>(nx)),
                                   mask_and(fy >= 0.0f, fy < static_cast<float>(ny)));
      if (all_of(inside)) {
        constexpr int L = LaneCount<V>::value;
        int cell[L];
        store_cell_indices(fx, fy, nx, cell);
        V best = ObstacleSet::kFar;
        if constexpr (L == 1) {
          for (int r = first[cell[0]]; r < first[cell[0] + 1]; ++r) {
            const V d = ObstacleSet::surface_distance(set.items[refs[r]], px, py, t);
            best = select(d < best, d, best);
          }
        } else {
          // A batch of samples: the union of its samples' lists (neighbouring cells share
          // most of theirs), each cylinder once, in index order.
          constexpr int kWords = ObstacleSet::kCapacity / 64;
          std::uint64_t bits[kWords] = {};
          for (int l = 0; l < L; ++l)
            for (int r = first[cell[l]]; r < first[cell[l] + 1]; ++r) bits[refs[r] >> 6] |= std::uint64_t{1} << (refs[r] & 63);
          for (int w = 0; w < kWords; ++w) {
            for (std::uint64_t b = bits[w]; b != 0; b &= b - 1) {
              const int i = 64 * w + __builtin_ctzll(b);
              const V d = ObstacleSet::surface_distance(set.items[i], px, py, t);
              best = select(d < best, d, best);
            }
          }
        }
        return best;
      }
    }
    return set.nearest_surface(px, py, t);
  }

  // Builds the grid over the bounding box of `points` (xy pairs; non-finite ones skipped)
  // widened by `reach`, with cells of side `cell` (or larger, to stay within kMaxSide x
  // kMaxSide and kMaxCells), for times [0, t_end]. reach <= 0, no obstacles or no finite
  // point: no grid. If the lists overflow kMaxRefs, coarser cells (ObstacleGridLayout); past
  // its last attempt no grid either (the search stays exact, only slower). Allocates
  // nothing; host only (core/src/obstacle_grid.cpp).
  static constexpr int kMaxSide = 64;
  void build(const ObstacleSet& set, const float* points, int n_points, float t_end, float reach, float cell);
};

// How ObstacleGrid::build lays its grid out (ObstacleGrid::layout, host, cheap): the corner,
// the slacks that cover float rounding, and the cell sides it tries in turn, each coarser,
// until the lists fit kMaxRefs. Plain data, so the lists can also be filled elsewhere (the
// CUDA backend fills them on the device, one warp a cell: gpu/src/obstacle_grid.cuh).
struct ObstacleGridLayout {
  static constexpr int kMaxAttempts = 8;
  struct Attempt {
    double side;  // 1 / inv, in double: the cells as the float lookup sees them
    float inv;    // ObstacleGrid::inv_cell
    int cx, cy;   // cells per side
  };
  int attempts = 0;  // 0: no grid
  int n = 0;         // cylinders indexed (the set's first n)
  double lox = 0.0, loy = 0.0;  // the corner, float values
  double slack = 0.0;           // on the surface distances
  double grow = 0.0;            // on the cells' sides
  double t_end = 0.0;
  Attempt attempt[kMaxAttempts] = {};

  static ObstacleGridLayout plan(const ObstacleSet& set, const float* points, int n_points, float t_end, float reach,
                                 float cell);
};

// The bounds the lists are built from, in double, one definition for the host build and the
// CUDA backend's.
namespace grid_bounds {

// A cylinder as the build sees it: the segment its axis sweeps over [0, t_end], the
// bounding box of that segment, and its radius.
struct Swept {
  double ax, ay, bx, by;      // axis at t = 0 and t = t_end
  double lox, loy, hix, hiy;  // bounding box of the segment
  double r;
};

struct Box {
  double x0, y0, x1, y1;
};

MPPI_HD Swept swept(const Cylinder& c, double t_end) {
  Swept o;
  o.ax = c.x;
  o.ay = c.y;
  o.bx = static_cast<double>(c.x) + static_cast<double>(c.vx) * t_end;
  o.by = static_cast<double>(c.y) + static_cast<double>(c.vy) * t_end;
  o.lox = fmin_(o.ax, o.bx);
  o.hix = fmax_(o.ax, o.bx);
  o.loy = fmin_(o.ay, o.by);
  o.hiy = fmax_(o.ay, o.by);
  o.r = c.radius;
  return o;
}

// Cells ix0..ix1-1 by iy0..iy1-1 of a grid of side s from (lox, loy), grown by `grow`.
MPPI_HD Box cells(double lox, double loy, double s, int ix0, int iy0, int ix1, int iy1, double grow) {
  return Box{lox + ix0 * s - grow, loy + iy0 * s - grow, lox + ix1 * s + grow, loy + iy1 * s + grow};
}

// Largest distance from a point of the box to (px, py).
MPPI_HD double max_distance(const Box& b, double px, double py) {
  const double dx = fmax_(fabs_(px - b.x0), fabs_(px - b.x1));
  const double dy = fmax_(fabs_(py - b.y0), fabs_(py - b.y1));
  return fsqrt(dx * dx + dy * dy);
}

// Upper bound of the surface distance from any point of the box, at any time, to s: the
// distance to a point of a segment is convex along it, so its maximum is at an end.
MPPI_HD double upper(const Box& b, const Swept& s) {
  return fmax_(max_distance(b, s.ax, s.ay), max_distance(b, s.bx, s.by)) - s.r;
}

// Lower bound of the same: the distance between the box and the segment's bounding box.
MPPI_HD double lower(const Box& b, const Swept& s) {
  const double dx = fmax_(0.0, fmax_(s.lox - b.x1, b.x0 - s.hix));
  const double dy = fmax_(0.0, fmax_(s.loy - b.y1, b.y0 - s.hiy));
  return fsqrt(dx * dx + dy * dy) - s.r;
}

}  // namespace grid_bounds

}  // namespace mppi
