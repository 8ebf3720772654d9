// The forest tasks' obstacle grid (core's ObstacleGrid, costs/obstacles.hpp) built on the
// device, inside the update's graph, so the host's share of a cycle is the plan's path and
// the layout (ObstacleGridLayout::plan: a few microseconds) instead of the whole build
// (~30-100 us on a host core for 32 cylinders; the lists were the cycle's largest host cost).
//   grid_lists  one warp per (attempt, cell) of every cell side the layout tries: the cell's
//               list with core's bounds (grid_bounds): U = the least upper bound over every
//               cylinder, then each cylinder whose lower bound is within U + slack, in index
//               order, into a scratch row per cell;
//   grid_pack   one block: the first attempt whose lists fit ObstacleGrid::kMaxRefs, packed
//               into the grid of the cycle's parameters on the device; none fits: no grid.
// A list holds the nearest cylinder of every point of its cell at every time of the horizon
// (the argument of costs/obstacles.hpp), so the search returns exactly
// ObstacleSet::nearest_surface, as with the host's grid. The host build filters each cell's
// candidates through its 4 x 4 block's list first; here every cell takes its U over all
// cylinders, so a list is never longer than the host's for the same cells.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "mppi/costs/obstacles.hpp"

namespace mppi::cuda_detail {

// Scratch of grid_lists: one row of kCapacity bytes and a count per (attempt, cell).
constexpr std::size_t kGridCells = static_cast<std::size_t>(ObstacleGridLayout::kMaxAttempts) * ObstacleGrid::kMaxCells;
constexpr std::size_t kGridListBytes = kGridCells * ObstacleSet::kCapacity;
constexpr std::size_t kGridCountBytes = kGridCells * sizeof(int);

// Enqueues the build of *grid from the cylinders *set and the layout *layout (all in device
// memory) on stream st (gpu/src/obstacle_grid.cu). Returns the launch error, if any. pdl: the
// pack is a programmatic dependent launch of the lists and lets the kernel after it be one
// too (sm_90 on), which must then griddep_wait() before it reads the grid.
cudaError_t enqueue_obstacle_grid(cudaStream_t st, const ObstacleSet* set, const ObstacleGridLayout* layout,
                                  std::uint8_t* lists, int* counts, ObstacleGrid* grid, bool pdl);

}  // namespace mppi::cuda_detail
