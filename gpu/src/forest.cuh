// The forest cost on the GPU. The obstacle loop dominates a rollout step (32 square roots
// against ~10 for the dynamics), and in ObstacleSet::nearest_surface it runs as one dependent
// chain over the cylinders. Here the cylinders (in shared memory with the parameters) are
// read eight at a time, so eight square roots are in flight at once, and may be split over
// G lanes of a warp that hold the same rollout (lane l takes cylinders l, l + G, ...), their
// minima combined by shuffles. Each cylinder's distance is computed with nearest_surface's
// operations; the running minimum uses its comparison, in cylinder order within a lane, so
// G = 1 is bit-identical to it, and G > 1 differs at most in the sign of a zero distance,
// which no term of the cost can see (d^2, d < radius).
// forest_vehicle() below is ForestCost::vehicle_at_distance (costs/forest.hpp) with that
// distance: the terms themselves are core's.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "mppi/costs/forest.hpp"
#include "mppi/hd.hpp"

namespace mppi::cuda_detail {

template <class Cost>
struct IsForestCost : std::false_type {};
template <class V>
struct IsForestCost<ForestCost<V>> : std::true_type {};

template <class T>
constexpr bool kForestTask = IsForestCost<typename T::Cost>::value;

// The bytes of T::Params the kernels stage into shared memory and read: for the forest
// tasks, everything before the obstacle grid. ObstacleGrid (costs/obstacles.hpp, the CPU
// backend's culling index, ~10 KB) is the parameters' last member and no kernel reads it:
// the cylinders are searched here (nearest_surface below), so it stays out of shared memory.
template <class T>
__host__ __device__ constexpr std::size_t staged_param_bytes() {
  using P = typename T::Params;
  if constexpr (kForestTask<T>) {
    using C = typename T::Cost::Params;
    static_assert(offsetof(P, cost) + sizeof(C) == sizeof(P), "the cost parameters come last");
    static_assert(offsetof(C, obstacle_grid) + sizeof(ObstacleGrid) == sizeof(C), "the obstacle grid comes last");
    return offsetof(P, cost) + offsetof(C, obstacle_grid);
  } else {
    return sizeof(P);
  }
}

constexpr unsigned kAllLanes = 0xffffffffu;

// ObstacleSet::nearest_surface over lane `lane`'s share of the cylinders, then the minimum
// over the G lanes of its group (G a power of two, groups aligned in the warp; every lane of
// the warp must call this when G > 1).
template <int G>
__device__ __forceinline__ float nearest_surface(const ObstacleSet& set, float px, float py, float t, int lane) {
  constexpr int kUnroll = G >= 4 ? 4 : 8;
  constexpr float kInf = __builtin_huge_valf();
  const int count = set.count < ObstacleSet::kCapacity ? set.count : ObstacleSet::kCapacity;
  float best = ObstacleSet::kFar;
  for (int base = 0; base < count; base += kUnroll * G) {
    float d[kUnroll];
#pragma unroll
    for (int u = 0; u < kUnroll; ++u) {
      const int n = base + u * G + lane;
      const Cylinder& c = set.items[n < ObstacleSet::kCapacity ? n : ObstacleSet::kCapacity - 1];
      const float v = ObstacleSet::surface_distance(c, px, py, t);
      d[u] = n < count ? v : kInf;  // past the count: never picked
    }
#pragma unroll
    for (int u = 0; u < kUnroll; ++u) best = d[u] < best ? d[u] : best;
  }
#pragma unroll
  for (int off = 1; off < G; off <<= 1) {
    const float o = __shfl_xor_sync(kAllLanes, best, off);
    best = o < best ? o : best;
  }
  return best;
}

// The obstacle grid the kernels search through (global memory: the cycle's copy of the
// parameters on the device, never staged; a few hundred bytes of it are touched per block,
// and they stay in L1), or null.
template <class T>
__device__ __forceinline__ const ObstacleGrid* device_grid(const typename T::Params& p) {
  if constexpr (kForestTask<T>) {
    return &p.cost.obstacle_grid;
  } else {
    (void)p;
    return nullptr;
  }
}

// ForestCost<Vehicle>::vehicle. One lane (G = 1) searches through the grid: core's own
// ObstacleGrid::nearest_surface, so the distance is CpuBackend's float (the grid's list of a
// cell holds the nearest cylinder of every point in it; outside, every cylinder). G > 1 lanes
// split the whole set (nearest_surface above).
template <class Vehicle, int G>
__device__ __forceinline__ float forest_vehicle(const typename ForestCost<Vehicle>::Params& p, const ObstacleGrid* grid,
                                                int j, const float* x, float t, int lane, bool* crash) {
  float pos[3];
  Vehicle::position(x, pos);
  float d;
  if (G == 1 && grid != nullptr) {
    d = grid->nearest_surface(p.obstacles, pos[0], pos[1], t);
  } else {
    d = nearest_surface<G>(p.obstacles, pos[0], pos[1], t, lane);
  }
  return ForestCost<Vehicle>::vehicle_at_distance(p, j, x, d, crash);
}

// Cost::vehicle; for forest tasks through forest_vehicle (grid: device_grid of the device's
// parameters, or null to scan every cylinder).
template <class T, int G = 1>
__device__ __forceinline__ float vehicle_cost(const typename T::Params& p, const ObstacleGrid* grid, int j,
                                              const float* x, float t, int lane, bool* hit) {
  if constexpr (kForestTask<T>) {
    return forest_vehicle<typename T::Vehicle, G>(p.cost, grid, j, x, t, lane, hit);
  } else {
    static_assert(G == 1, "only the forest cost splits over lanes");
    (void)lane;
    (void)grid;
    return T::Cost::vehicle(p.cost, j, x, t, hit);
  }
}

// Task::running (task.hpp), the vehicle terms through vehicle_cost.
template <class T, int G = 1>
__device__ __forceinline__ float running_cost(const typename T::Params& p, const ObstacleGrid* grid, const float* x,
                                              float t, int lane, std::uint32_t* crashed) {
  return T::running_with(p, x, crashed, [&](int j, const float* xj, bool* hit) {
    return vehicle_cost<T, G>(p, grid, j, xj, t, lane, hit);
  });
}

}  // namespace mppi::cuda_detail
