// The obstacle grid's kernels (obstacle_grid.cuh), and its test entry point
// (cuda_backend.hpp: build_obstacle_grid_on_device).
#include <cuda_runtime.h>

#include <cub/block/block_scan.cuh>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "cuda_check.cuh"
#include "mppi/gpu/cuda_backend.hpp"
#include "kernels.cuh"
#include "obstacle_grid.cuh"

namespace mppi::cuda_detail {
namespace {

constexpr unsigned kWarp = 0xffffffffu;
// 2048 warps: every (attempt, cell) row of a grid at the cell limit in one round (attempt 0
// has at most kMaxCells, the coarser ones about 0.8 kMaxCells together).
constexpr int kListThreads = 256, kListBlocks = 256;
constexpr int kPackThreads = ObstacleGrid::kMaxCells;  // one thread a cell

__global__ void __launch_bounds__(kListThreads) grid_lists(const ObstacleSet* set, const ObstacleGridLayout* layout,
                                                           std::uint8_t* lists, int* counts) {
  griddep_launch_dependents();  // grid_pack may be scheduled now; it waits for these lists
  const ObstacleGridLayout& L = *layout;
  const int lane = static_cast<int>(threadIdx.x) & 31;
  const int first_warp = static_cast<int>((blockIdx.x * blockDim.x + threadIdx.x) >> 5);
  const int warps = static_cast<int>((gridDim.x * blockDim.x) >> 5);
  int cells_total = 0;
  for (int a = 0; a < L.attempts; ++a) cells_total += L.attempt[a].cx * L.attempt[a].cy;
  // Work item w: the cells of attempt 0, then those of attempt 1, ... (no idle warps).
  for (int w = first_warp; w < cells_total; w += warps) {
    int attempt = 0, cell = w;
    for (int n = L.attempt[0].cx * L.attempt[0].cy; cell >= n; n = L.attempt[attempt].cx * L.attempt[attempt].cy) {
      cell -= n;
      ++attempt;
    }
    const ObstacleGridLayout::Attempt& a = L.attempt[attempt];
    const int row = attempt * ObstacleGrid::kMaxCells + cell;
    const int ix = cell % a.cx, iy = cell / a.cx;
    const grid_bounds::Box b = grid_bounds::cells(L.lox, L.loy, a.side, ix, iy, ix + 1, iy + 1, L.grow);
    double u = 1e300;  // the host's HUGE_VAL: the layout has at least one cylinder
    for (int i = lane; i < L.n; i += 32) u = fmin_(u, grid_bounds::upper(b, grid_bounds::swept(set->items[i], L.t_end)));
    for (int off = 16; off > 0; off >>= 1) u = fmin_(u, __shfl_xor_sync(kWarp, u, off));
    std::uint8_t* out = lists + static_cast<std::size_t>(row) * ObstacleSet::kCapacity;
    int k = 0;
    for (int base = 0; base < L.n; base += 32) {
      const int i = base + lane;
      const bool listed = i < L.n && grid_bounds::lower(b, grid_bounds::swept(set->items[i], L.t_end)) <= u + L.slack;
      const unsigned ballot = __ballot_sync(kWarp, listed);
      if (listed) out[k + __popc(ballot & ((1u << lane) - 1u))] = static_cast<std::uint8_t>(i);
      k += __popc(ballot);
    }
    if (lane == 0) counts[row] = k;
  }
}

__global__ void __launch_bounds__(kPackThreads) grid_pack(const ObstacleGridLayout* layout, const std::uint8_t* lists,
                                                          const int* counts, ObstacleGrid* grid) {
  griddep_launch_dependents();  // the rollouts may start their noise and dynamics now
  griddep_wait();               // grid_lists is complete and its lists visible
  using Scan = cub::BlockScan<int, kPackThreads>;
  __shared__ typename Scan::TempStorage scan;
  __shared__ int used[ObstacleSet::kCapacity];
  const ObstacleGridLayout& L = *layout;
  const int t = static_cast<int>(threadIdx.x);
  if (t < ObstacleSet::kCapacity) used[t] = 0;
  // The first attempt whose lists fit: this thread's cell, where its list starts, the total.
  int chosen = -1, mine = 0, start = 0, total = 0;
  for (int a = 0; a < L.attempts && chosen < 0; ++a) {
    const int cells = L.attempt[a].cx * L.attempt[a].cy;
    mine = t < cells ? counts[a * ObstacleGrid::kMaxCells + t] : 0;
    Scan(scan).ExclusiveSum(mine, start, total);
    __syncthreads();  // the scan's storage is used again
    if (total <= ObstacleGrid::kMaxRefs) chosen = a;  // total: the same in every thread
  }
  if (chosen < 0) {
    if (t == 0) {
      grid->nx = grid->ny = 0;
      grid->listed = 0;
    }
    return;
  }
  const ObstacleGridLayout::Attempt& a = L.attempt[chosen];
  const int cells = a.cx * a.cy;
  if (t < cells) {
    grid->first[t] = static_cast<std::uint16_t>(start);
    const std::uint8_t* src = lists + (static_cast<std::size_t>(chosen) * ObstacleGrid::kMaxCells + t) * ObstacleSet::kCapacity;
    for (int m = 0; m < mine; ++m) {
      grid->refs[start + m] = src[m];
      used[src[m]] = 1;
    }
  }
  __syncthreads();
  const int listed = __syncthreads_count(t < L.n && used[t] != 0);
  if (t == 0) {
    grid->first[cells] = static_cast<std::uint16_t>(total);
    grid->listed = listed;
    grid->x0 = static_cast<float>(L.lox);
    grid->y0 = static_cast<float>(L.loy);
    grid->inv_cell = a.inv;
    grid->nx = a.cx;
    grid->ny = a.cy;
  }
}

}  // namespace

cudaError_t enqueue_obstacle_grid(cudaStream_t st, const ObstacleSet* set, const ObstacleGridLayout* layout,
                                  std::uint8_t* lists, int* counts, ObstacleGrid* grid, bool pdl) {
  grid_lists<<<kListBlocks, kListThreads, 0, st>>>(set, layout, lists, counts);
  const cudaError_t e = cudaGetLastError();
  if (e != cudaSuccess) return e;
  // grid_pack as a programmatic dependent launch of grid_lists (sm_90 on; elsewhere a plain
  // launch): scheduled while the lists are computed, it waits for them on the device.
  cudaLaunchAttribute attr;
  const cudaLaunchConfig_t cfg = launch_config(dim3(1), dim3(kPackThreads), 0, st, pdl, &attr);
  return cudaLaunchKernelEx(&cfg, grid_pack, layout, static_cast<const std::uint8_t*>(lists),
                            static_cast<const int*>(counts), grid);
}

}  // namespace mppi::cuda_detail

namespace mppi {

ObstacleGrid build_obstacle_grid_on_device(const ObstacleSet& set, const float* points, int n_points, float t_end,
                                           float reach, float cell) {
  using namespace cuda_detail;
  std::string why;
  if (!cuda_device_available(&why)) throw std::runtime_error("cuda backend: no usable CUDA device (" + why + ")");
  const ObstacleGridLayout layout = ObstacleGridLayout::plan(set, points, n_points, t_end, reach, cell);
  DeviceBuffer d_set(sizeof(ObstacleSet), "the cylinders"), d_layout(sizeof(layout), "the grid layout");
  DeviceBuffer d_lists(kGridListBytes, "the grid's scratch lists"), d_counts(kGridCountBytes, "the grid's counts");
  DeviceBuffer d_grid(sizeof(ObstacleGrid), "the obstacle grid");
  check(cudaMemcpy(d_set.as<void>(), &set, sizeof(set), cudaMemcpyHostToDevice), "cudaMemcpy of the cylinders");
  check(cudaMemcpy(d_layout.as<void>(), &layout, sizeof(layout), cudaMemcpyHostToDevice), "cudaMemcpy of the layout");
  check(cudaMemset(d_grid.as<void>(), 0xff, sizeof(ObstacleGrid)), "cudaMemset of the grid");  // poisoned
  check(enqueue_obstacle_grid(nullptr, d_set.as<ObstacleSet>(), d_layout.as<ObstacleGridLayout>(),
                              d_lists.as<std::uint8_t>(), d_counts.as<int>(), d_grid.as<ObstacleGrid>(), true),
        "launching the obstacle grid build");
  ObstacleGrid grid;
  check(cudaMemcpy(&grid, d_grid.as<void>(), sizeof(grid), cudaMemcpyDeviceToHost), "the obstacle grid build");
  return grid;
}

}  // namespace mppi
