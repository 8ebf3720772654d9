// The mppid binary the daemon tests start (or its emulator launcher in a cross build). Only
// daemon_binary_path.cpp is compiled with the build's path (test/support/source_dir.hpp says
// why).
#pragma once

#include <string>

namespace mppi::testing {

std::string daemon_binary_path();

}  // namespace mppi::testing
