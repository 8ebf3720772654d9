// The local distance field the forest cost reads beside its cylinders (issue 30): a grid of
// signed distances to the nearest obstacle surface around the vehicle, as a mapper publishes
// it (local_map_t: int16 millimetres, x fastest), trilinearly interpolated.
//
// Two pieces:
//   DistanceField      what the cost parameters hold: the grid's geometry, a pointer to its
//                      cells and a stamp. Plain data (~48 bytes): it travels with the cost
//                      parameters wherever they go, and a backend that keeps its own copy of
//                      the cells (CUDA: device memory, uploaded when the stamp changes) points
//                      `cells` at it in the parameters it stages.
//   DistanceFieldGrid  the cells themselves, at a fixed capacity (kMaxCells, 2 MiB): what a
//                      map message becomes (the daemon's inbox holds these) and what tests and
//                      benchmarks fill. Allocated once, at start-up; nothing per cycle.
// Why not the cells inside the parameters, as the cylinders are: Mppi::iterate copies the
// parameters every cycle (Task::prepare's working copy), the CUDA backend copies them into its
// per-cycle input, and the daemon copies its inputs into them: 2 MiB each time, ~0.2 ms of a
// loaded host core and ~0.2 ms of copy to the device a cycle (1 MB: ~100-130 us measured), for
// a map that changes at the sensor's rate (10-30 Hz), not the loop's. Through the pointer a
// cycle copies 48 bytes and the GPU takes the cells once per map.
//
// The cell type and the capacity, with numbers. int16 millimetres is local_map_t's own type
// (the daemon takes a message without a conversion), spans +-32.7 m (far beyond the cost's
// reach: exp(-d^2 / 12) is 0.05 at 6 m) and its 1 mm step is 200 times finer than a 0.2 m
// cell's own error; float would double every copy for nothing, float16 would need F16C on the
// host and a conversion per corner. Capacity: at 10 m/s over the forest tasks' 2 s horizon
// (config/tasks/quadrotor_forest.yaml: T = 100, dt = 0.02) the plan reaches 20 m, and a
// rollout's lateral spread a few metres; obstacles weigh in within ~6 m of a rollout. A window
// of 32 x 32 x 6.4 m at 0.2 m cells (160 x 160 x 32 = 819,200 cells, 1.6 MB) rolling with the
// vehicle covers 1.6 s of the horizon at 10 m/s with the vehicle centred, the whole 20 m when
// the mapper keeps the vehicle a quarter in from the window's back edge (24 m ahead), and the
// trees' full height at forest altitude. kMaxCells = 2^20 (2 MiB) leaves room for 0.2 m cells
// over 32 x 32 x 8 m or 0.25 m over 40 x 40 x 10 m. Cost per sample and step: 8 corner reads
// (4 32-bit gathers on the SIMD lanes, the two x-neighbours of each read in one word) and ~25
// flops; measured (docs/sensing.md), a rollout step with the field alone is cheaper than
// with the cylinders on every SIMD target (AVX-512: 12.4 against 15.1 ns a sample-step).
//
// Lookup. The cell (i, j, k) holds the distance at its centre. A point inside the grid's box
// [origin, origin + n * resolution) reads the trilinear interpolation of the eight cell centres
// around it, the coordinates clamped to the outermost centres (the half cell along each face
// reads the face's cells). A point outside the box, or not finite, reads max_distance: the
// field knows nothing there, and the mapper's own saturation value is what "nothing near" means
// inside it too (unknown space inside the box is whatever the mapper makes of it:
// docs/sensing.md). The float operations are the same on every number type (scalar, SIMD
// lanes, CUDA with -fmad=false), so all backends read the same float.
#pragma once

#include <cstdint>

#include "mppi/hd.hpp"

namespace mppi {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "gather_corners (SIMD) reads two int16 cells as one word");

// The eight corners of a cell: cells[index + o] and the one after it, for o = 0, dy, dz,
// dz + dy (the (y, z) corners 00, 10, 01, 11), as floats in out[0..7], for each sample of the
// number (index: a whole number >= 0 as a float, exact below 2^24). Written out, no loop or
// offset table: on the device the corners stay in registers. A SIMD number type overloads
// this (simd/lanes.hpp: one 32-bit gather per pair).
template <class S>
MPPI_HD void gather_corners_scalar(const std::int16_t* cells, S index, int dy, int dz, S* out) {
  const std::int16_t* p = cells + static_cast<int>(index);
  out[0] = static_cast<S>(p[0]);
  out[1] = static_cast<S>(p[1]);
  out[2] = static_cast<S>(p[dy]);
  out[3] = static_cast<S>(p[dy + 1]);
  out[4] = static_cast<S>(p[dz]);
  out[5] = static_cast<S>(p[dz + 1]);
  out[6] = static_cast<S>(p[dz + dy]);
  out[7] = static_cast<S>(p[dz + dy + 1]);
}
MPPI_HD void gather_corners(const std::int16_t* cells, float index, int dy, int dz, float* out) {
  gather_corners_scalar(cells, index, dy, dz, out);
}
MPPI_HD void gather_corners(const std::int16_t* cells, double index, int dy, int dz, double* out) {
  gather_corners_scalar(cells, index, dy, dz, out);
}

struct DistanceField {
  // Cells at most: 2^20 int16 (2 MiB). A mapper sizes its grid within it (e.g. 160 x 160 x 32
  // at 0.2 m); larger maps are rejected by the daemon.
  static constexpr int kMaxCells = 1 << 20;
  static constexpr int kMinSide = 2;              // cells per axis at least (a cell and its neighbour)
  static constexpr float kMaxDistanceLimit = 32.767f;  // m: int16 millimetres

  const std::int16_t* cells = nullptr;  // nx * ny * nz, mm, x fastest; null: no field
  std::uint64_t stamp = 0;              // changes whenever the cells may have (a backend's copy follows it)
  float origin[3] = {0.0f, 0.0f, 0.0f};  // corner of cell (0, 0, 0), m
  float inv_resolution = 0.0f;           // 1 / cell side, 1/m
  int nx = 0, ny = 0, nz = 0;
  float max_distance = 0.0f;  // m: what a point outside the grid reads

  MPPI_HD bool present() const { return cells != nullptr; }

  // The distance at (px, py, pz) [m] (see the top of the file). Needs present().
  template <class V>
  MPPI_HD V distance(const V& px, const V& py, const V& pz) const {
    const float fx = static_cast<float>(nx), fy = static_cast<float>(ny), fz = static_cast<float>(nz);
    const V gx = (px - origin[0]) * inv_resolution;  // cells from the corner
    const V gy = (py - origin[1]) * inv_resolution;
    const V gz = (pz - origin[2]) * inv_resolution;
    const auto inside = mask_and(mask_and(mask_and(gx >= 0.0f, gx < fx), mask_and(gy >= 0.0f, gy < fy)),
                                 mask_and(gz >= 0.0f, gz < fz));
    if (!any_of(inside)) return V(max_distance);
    // Cell-centre coordinates, clamped to the outermost centres; 0 outside (never read).
    const V cx = select(inside, fclamp(gx - 0.5f, V(0.0f), V(fx - 1.0f)), V(0.0f));
    const V cy = select(inside, fclamp(gy - 0.5f, V(0.0f), V(fy - 1.0f)), V(0.0f));
    const V cz = select(inside, fclamp(gz - 0.5f, V(0.0f), V(fz - 1.0f)), V(0.0f));
    // The lower corner, at most n - 2 so that its neighbour is a cell (t = 1 on the last).
    const V ix = fmin_(ffloor(cx), V(fx - 2.0f));
    const V iy = fmin_(ffloor(cy), V(fy - 2.0f));
    const V iz = fmin_(ffloor(cz), V(fz - 2.0f));
    const V tx = cx - ix, ty = cy - iy, tz = cz - iz;
    const V index = ix + fx * (iy + fy * iz);  // exact: below kMaxCells
    V c[8];
    gather_corners(cells, index, nx, nx * ny, c);
    const V c00 = c[0] + tx * (c[1] - c[0]);
    const V c10 = c[2] + tx * (c[3] - c[2]);
    const V c01 = c[4] + tx * (c[5] - c[4]);
    const V c11 = c[6] + tx * (c[7] - c[6]);
    const V c0 = c00 + ty * (c10 - c00);
    const V c1 = c01 + ty * (c11 - c01);
    const V mm = c0 + tz * (c1 - c0);
    return select(inside, mm * 0.001f, V(max_distance));
  }
};

// The cells of one map at the fixed capacity, and its geometry (as local_map_t carries them).
// Large (2 MiB): allocate it once (std::make_unique), never on the stack.
struct DistanceFieldGrid {
  float origin[3] = {0.0f, 0.0f, 0.0f};  // m
  float resolution = 0.0f;               // m
  int nx = 0, ny = 0, nz = 0;
  float max_distance = 0.0f;  // m
  int n_cells = 0;
  std::int16_t distance_mm[DistanceField::kMaxCells];

  // Why this grid cannot be flown, or nullptr when it can: a non-finite or non-positive
  // resolution, a non-finite origin or max_distance, max_distance outside (0, 32.767] m, a
  // side below kMinSide, more than kMaxCells, n_cells other than nx * ny * nz.
  const char* invalid() const { return invalid_shape(origin, resolution, nx, ny, nz, max_distance, n_cells); }
  static const char* invalid_shape(const float origin[3], float resolution, int nx, int ny, int nz, float max_distance,
                                   std::int64_t n_cells) {
    for (int d = 0; d < 3; ++d)
      if (!ffinite(origin[d])) return "origin not finite";
    if (!ffinite(resolution) || !(resolution > 0.0f)) return "resolution not positive";
    if (!ffinite(max_distance) || !(max_distance > 0.0f) || max_distance > DistanceField::kMaxDistanceLimit)
      return "max_distance outside (0, 32.767] m";
    if (nx < DistanceField::kMinSide || ny < DistanceField::kMinSide || nz < DistanceField::kMinSide)
      return "a side below 2 cells";
    const auto cells = static_cast<std::int64_t>(nx) * ny * nz;
    if (cells > DistanceField::kMaxCells) return "more cells than DistanceField::kMaxCells";
    if (n_cells != cells) return "n_cells is not nx * ny * nz";
    return nullptr;
  }

  // The view the cost parameters hold (valid while this grid is neither changed nor freed).
  DistanceField view(std::uint64_t stamp) const {
    DistanceField f;
    f.cells = distance_mm;
    f.stamp = stamp;
    for (int d = 0; d < 3; ++d) f.origin[d] = origin[d];
    f.inv_resolution = 1.0f / resolution;
    f.nx = nx;
    f.ny = ny;
    f.nz = nz;
    f.max_distance = max_distance;
    return f;
  }
};

}  // namespace mppi
