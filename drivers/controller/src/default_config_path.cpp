// default_config_path() alone: the one file of the library compiled with the checkout's path
// (CMakeLists.txt says why).
#include "mppi/app/config.hpp"

namespace mppi::app {

std::string default_config_path(const std::string& task) {
  return std::string(MPPID_SOURCE_DIR) + "/config/tasks/" + task + ".yaml";
}

}  // namespace mppi::app
