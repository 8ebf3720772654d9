#include "daemon_binary_path.hpp"

namespace mppi::testing {

std::string daemon_binary_path() { return MPPID_BIN; }

}  // namespace mppi::testing
