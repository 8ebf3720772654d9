#include <stdexcept>
#include <string>

#include "mppi/app/config.hpp"
#include "mppi/tasks.hpp"
#include "task_factory.hpp"
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
  visit_task(config.task, [&](auto tag) { out = make_task_ddp_controller<typename decltype(tag)::type>(config); });
  if (!out)
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
  visit_task(config.task, [&](auto tag) { out = make_task_controller<typename decltype(tag)::type>(config, backend); });
  if (!out) throw ConfigError("task: unknown task '" + config.task + "'");
  return out;
}

}  // namespace mppi::app
