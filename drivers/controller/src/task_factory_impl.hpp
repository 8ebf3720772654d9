// The definitions of task_factory.hpp's builders, for the per-task translation units
// (task_factory.cpp.in) alone.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"
#include "task_factory.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/ddp/ddp_controller.hpp"
#include "mppi/params.hpp"
#include "mppi/tasks.hpp"
#ifdef MPPID_HAVE_CUDA
#include "mppi/gpu/cuda_backend.hpp"
#endif

namespace mppi::app {

template <class T>
typename T::Params task_params(const AppConfig& config) {
  typename T::Params params{};
  for (const auto& [key, value] : config.params) {
    const std::string err = set_task_param<T>(params, key, value);
    if (!err.empty()) throw ConfigError(err);
  }
  return params;
}

template <class T>
std::unique_ptr<Controller> make_task_controller(const AppConfig& config, [[maybe_unused]] const std::string& backend) {
  const typename T::Params params = task_params<T>(config);
  std::unique_ptr<RolloutBackend<T>> b;
#ifdef MPPID_HAVE_CUDA
  if (backend == "cuda") b = make_cuda_backend<T>(config.mppi, config.cuda_launch);
#endif
  if (!b) {
    try {
      b = std::make_unique<CpuBackend<T>>(config.mppi);
    } catch (const std::invalid_argument& e) {
      throw ConfigError(std::string("mppi.") + e.what());  // e.g. a SIMD target this CPU lacks
    }
  }
  return std::make_unique<TaskController<T>>(config.task, config.mppi, params, std::move(b));
}

template <class T>
std::unique_ptr<Controller> make_task_ddp_controller([[maybe_unused]] const AppConfig& config) {
  if constexpr (kDdpTask<T>) {
    try {
      return std::make_unique<DdpController<T>>(config.task, config.mppi, config.ddp, task_params<T>(config));
    } catch (const std::invalid_argument& e) {
      throw ConfigError(e.what());
    }
  } else {
    return nullptr;
  }
}

}  // namespace mppi::app
