#include "source_dir.hpp"

namespace mppi::testing {

const std::string& source_dir() {
  static const std::string dir = MPPID_SOURCE_DIR;
  return dir;
}

}  // namespace mppi::testing
