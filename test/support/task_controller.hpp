// A controller for a task shipped in config/tasks/, as mppid builds it from its settings file.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"

namespace mppi::test {

// config/tasks/<task>.yaml with `sets` (key=value), then `last`, applied on top.
inline std::unique_ptr<Controller> task_controller(const std::string& task, std::vector<std::string> sets,
                                                   const std::string& last) {
  sets.push_back(last);
  return app::make_controller(app::load_config(app::default_config_path(task), sets));
}

}  // namespace mppi::test
