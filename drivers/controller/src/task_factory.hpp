// The controller of one task: MPPI on a backend, or the MPC-DDP baseline. Each named task's
// builders are instantiated in a translation unit of their own (task_factory.cpp.in,
// generated per task by CMakeLists.txt, definitions in task_factory_impl.hpp), so the tasks
// compile in parallel and a change to one recompiles one; factory.cpp only dispatches on the
// task's name.
#pragma once

#include <memory>
#include <string>

#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"

namespace mppi::app {

// MPPI on `backend` ("cpu" or "cuda", resolved and checked by the caller).
template <class T>
std::unique_ptr<Controller> make_task_controller(const AppConfig& config, const std::string& backend);

// The MPC-DDP baseline; null for a task it is not built for.
template <class T>
std::unique_ptr<Controller> make_task_ddp_controller(const AppConfig& config);

}  // namespace mppi::app
