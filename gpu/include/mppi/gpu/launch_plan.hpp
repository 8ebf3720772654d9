// How the CUDA backend launches a task's update: which rollout kernel, its grid, blocks,
// chunks and shared memory, where the noise is drawn, whether the perturbed controls are kept,
// the weighting's chunks, the obstacle grid, PDL and the graph. plan_launch is pure (no CUDA
// call: the device is described by CudaDeviceLimits, the task by CudaTaskShape), so the
// choices are table-tested without a GPU (test/gpu/test_launch_plan.cpp); CudaBackend
// (gpu/src/cuda_backend_impl.cuh) fills the two structs from the device and the task's
// kernels and launches what the plan says.
#pragma once

#include <cstddef>
#include <string>

#include "mppi/gpu/cuda_settings.hpp"
#include "mppi/settings.hpp"

namespace mppi {

// What the plan needs of a task's kernels (their layouts live in the CUDA headers).
struct CudaTaskShape {
  const char* name = "";            // for messages: the vehicle's name
  int vehicles = 1;
  int nu = 1;                       // control channels of the whole task
  bool forest = false;              // obstacle search: lanes per rollout, the device's obstacle grid
  int chunk_rollouts = 32;          // rollouts a block of the chunked kernel (32 / vehicles for teams)
  int team_rollouts_per_warp = 32;  // teams' lane kernel: rollouts a warp
  std::size_t staged_param_bytes = 0;  // the parameters the lane kernels stage in shared memory
  std::size_t team_rollout_bytes = 0;  // teams' lane kernel: shared memory a rollout
  // The chunked kernel's shared memory at `chunk_steps` steps a chunk over `horizon` steps.
  std::size_t (*chunk_smem_bytes)(int chunk_steps, int horizon) = nullptr;
};

// What the plan needs of the device (cudaDeviceProp, cudaMemGetInfo).
struct CudaDeviceLimits {
  int multiprocessors = 0;
  std::size_t shared_per_block_optin = 0;  // sharedMemPerBlockOptin
  long long max_grid_x = 0, max_grid_y = 0;
  int compute_major = 0;
  std::size_t free_bytes = 0;              // device memory free before the backend's buffers
};

struct CudaLaunchPlan {
  bool chunked = false;        // the chunked kernel, else the lane kernel
  bool prepass = false;        // the noise drawn by the pre-pass (sample<T>) into d_u, d_cc
  bool keep_controls = false;  // the perturbed controls kept in d_u for the update
  // The chunked kernel: blocks of chunk_rollouts rollouts.
  long long chunk_blocks = 0;
  int chunk_steps = 4, chunk_warps = 4;
  std::size_t chunk_smem = 0;
  // The lane kernel.
  int lanes = 1;               // threads a rollout (single-vehicle forest tasks)
  int warps_per_block = 0;     // teams
  int rollout_block = 0;       // threads a block
  long long rollout_grid = 0;  // blocks
  std::size_t rollout_smem = 0;
  // weigh_local (after the lane kernel): chunks of weigh_chunk rollouts, weigh_chunks of them.
  int weigh_chunk = 0, weigh_chunks = 0;
  bool device_grid = false;  // forest tasks: the obstacle grid built on the device
  bool pdl = false;          // programmatic dependent launches
  bool graph = true;
  std::string error;         // non-empty: the launch does not fit the device (why)

  // Partial sums the weighting writes per step: one per chunked block or weighting chunk.
  long long parts() const { return chunked ? chunk_blocks : weigh_chunks; }
  // The rollout kernel's name: rollout_chunked, rollout_chunked_team, rollout_single, rollout_team.
  const char* kernel_name(const CudaTaskShape& task) const;
};

// Bytes of the pre-pass's noise and of the kept controls: at most this much, and at most a
// quarter of the free device memory.
constexpr std::size_t kCudaNoiseBudgetMax = std::size_t{16} << 30;
// Single vehicles' chunked kernel keeps the controls while they fit in about the L2 cache.
constexpr std::size_t kCudaKeepControlsMax = std::size_t{48} << 20;
constexpr int kCudaReduceBlock = 256;  // threads a block of the weighting kernels

// The launch of task `task` with settings `s` (rollouts, horizon) on `device`, the choices of
// `cuda` applied over the built-in ones. Never throws: a launch the device cannot run comes
// back with `error` set (CudaBackend throws it).
CudaLaunchPlan plan_launch(const MppiSettings& s, const CudaTaskShape& task, const CudaDeviceLimits& device,
                           const CudaSettings& cuda);

// The launch `at_k` (plan_launch's at K) run over the first `rollouts` of its K samples (the
// active count, RolloutBackend::set_active_rollouts): every choice kept (kernel, blocks, lanes,
// chunks, noise, controls, weighting chunk), only the counts of blocks and weighting chunks
// made for `rollouts`, so the buffers sized for K hold it (parts() is at most at_k's).
CudaLaunchPlan resize_launch(const CudaLaunchPlan& at_k, const CudaTaskShape& task, long long rollouts);

// One line: the kernel and its launch shape, the noise, the controls, the weighting, the
// obstacle grid, PDL and the graph.
std::string describe(const CudaLaunchPlan& plan, const CudaTaskShape& task);

}  // namespace mppi
