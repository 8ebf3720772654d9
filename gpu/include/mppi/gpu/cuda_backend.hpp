// The CUDA rollout backend: the same MPPI update as CpuBackend (cpu_backend.hpp is the
// reference semantics), run on the GPU. Plain C++: nothing here needs the CUDA headers,
// so any target can hold a backend through RolloutBackend<T>.
#pragma once

#include <memory>
#include <string>

#include "mppi/backend.hpp"
#include "mppi/gpu/cuda_settings.hpp"
#include "mppi/settings.hpp"
#include "mppi/tasks.hpp"

namespace mppi {

// A CUDA backend for task T on the current device, launched as plan_launch (launch_plan.hpp)
// plans it with the `mppi.cuda` settings `cuda` (the defaults: the backend's own choices); the
// plan is logged once (spdlog, info) with the settings. Every device and pinned host buffer is
// allocated here; update() allocates nothing. Throws std::runtime_error naming the CUDA
// error and what was attempted (no device, allocation, invalid launch size, bad settings).
// Explicitly instantiated for every task of tasks.hpp.
template <class T>
std::unique_ptr<RolloutBackend<T>> make_cuda_backend(const MppiSettings& s, const CudaSettings& cuda = {});

// True when a CUDA device can run this build's kernels; else false and, if why is given,
// the reason (driver missing, no device, no kernel image for the device, ...).
bool cuda_device_available(std::string* why = nullptr);

// Name of the current CUDA device, or "" when there is none.
std::string cuda_device_name();

// ObstacleGrid::build's grid as the CUDA backend builds it each cycle, on the device (tests:
// its search must be the full scan's). Throws as make_cuda_backend does.
ObstacleGrid build_obstacle_grid_on_device(const ObstacleSet& set, const float* points, int n_points, float t_end,
                                           float reach, float cell);

#define MPPI_CUDA_DECLARE(T) \
  extern template std::unique_ptr<RolloutBackend<T>> make_cuda_backend<T>(const MppiSettings&, const CudaSettings&);
MPPI_CUDA_DECLARE(CartpoleSwingup)
MPPI_CUDA_DECLARE(RacecarEllipse)
MPPI_CUDA_DECLARE(QuadrotorForest)
MPPI_CUDA_DECLARE(QuadrotorTrack)
MPPI_CUDA_DECLARE(RateQuadrotorForest)
MPPI_CUDA_DECLARE(RateQuadrotorTrack)
MPPI_CUDA_DECLARE(Team3Forest)
MPPI_CUDA_DECLARE(Team9Forest)
#undef MPPI_CUDA_DECLARE

}  // namespace mppi
