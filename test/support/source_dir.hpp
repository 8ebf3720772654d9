// The checkout's root, an absolute path (the build's PROJECT_SOURCE_DIR), for the tests and
// benchmarks that read config/ and test/ files. Only source_dir.cpp is compiled with the path:
// every file that asks for it compiles the same in any clone, so a compile cache (ccache with
// CCACHE_BASEDIR, tools/setup.sh) serves them to a fresh clone in another folder.
#pragma once

#include <string>

namespace mppi::testing {

const std::string& source_dir();

}  // namespace mppi::testing
