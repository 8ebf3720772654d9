#include <stdexcept>
#include <string>

#include "mppi/app/config.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/ddp/ddp_controller.hpp"
#include "mppi/params.hpp"
#include "mppi/tasks.hpp"
#ifdef MPPID_HAVE_CUDA
#include "mppi/gpu/cuda_backend.hpp"
#endif

namespace mppi::app {

std::string resolve_backend(const std::string& requested, std::string* why_not_cuda) {
  std::string why;
#ifdef MPPID_HAVE_CUDA
  const bool cuda = cuda_device_available(&why);
#else
  const bool cuda = false;
  why = "this build has no CUDA backend (configure with MPPID_CUDA=ON)";
#endif
  if (why_not_cuda) *why_not_cuda = cuda ? std::string() : why;
  if (requested == "auto") return cuda ? "cuda" : "cpu";
  return requested;
}

namespace {

std::unique_ptr<Controller> make_ddp_controller(const AppConfig& config) {
  if (!config.has_ddp) throw ConfigError("ddp: missing section (controller: ddp needs the DDP settings of the task)");
  std::unique_ptr<Controller> out;
  bool supported = false;
  visit_task(config.task, [&](auto tag) {
    using T = typename decltype(tag)::type;
    if constexpr (kDdpTask<T>) {
      supported = true;
      typename T::Params params{};
      for (const auto& [key, value] : config.params) {
        const std::string err = set_task_param<T>(params, key, value);
        if (!err.empty()) throw ConfigError(err);
      }
      try {
        out = std::make_unique<DdpController<T>>(config.task, config.mppi, config.ddp, params);
      } catch (const std::invalid_argument& e) {
        throw ConfigError(e.what());
      }
    }
  });
  if (!supported)
    throw ConfigError("controller: ddp is built for cartpole_swingup and quadrotor_forest, not '" + config.task + "'");
  return out;
}

}  // namespace

std::unique_ptr<Controller> make_controller(const AppConfig& file_config) {
  if (file_config.controller == "ddp") return make_ddp_controller(file_config);
  std::string why;
  const std::string backend = resolve_backend(file_config.backend, &why);
  const AppConfig& config = file_config.for_backend(backend);
  if (backend == "cuda" && !why.empty()) throw ConfigError("backend: cuda requested but " + why);
  if (backend != "cpu" && backend != "cuda") throw ConfigError("backend: must be cpu, cuda or auto");
  std::unique_ptr<Controller> out;
  visit_task(config.task, [&](auto tag) {
    using T = typename decltype(tag)::type;
    typename T::Params params{};
    for (const auto& [key, value] : config.params) {
      const std::string err = set_task_param<T>(params, key, value);
      if (!err.empty()) throw ConfigError(err);
    }
    std::unique_ptr<RolloutBackend<T>> b;
#ifdef MPPID_HAVE_CUDA
    if (backend == "cuda") b = make_cuda_backend<T>(config.mppi);
#endif
    if (!b) {
      try {
        b = std::make_unique<CpuBackend<T>>(config.mppi);
      } catch (const std::invalid_argument& e) {
        throw ConfigError(std::string("mppi.") + e.what());  // e.g. a SIMD target this CPU lacks
      }
    }
    out = std::make_unique<TaskController<T>>(config.task, config.mppi, params, std::move(b));
  });
  if (!out) throw ConfigError("task: unknown task '" + config.task + "'");
  return out;
}

}  // namespace mppi::app
