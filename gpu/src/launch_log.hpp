// The CUDA backend's one log line of its launch plan (spdlog, info: the program's logger when it
// set one up, as the daemon does, else stderr). Plain C++ (launch_log.cpp), declared here for
// the CUDA units.
#pragma once

#include <string>

namespace mppi::cuda_detail {

// Logs `line` unless it is the line logged last in this process: a controller built again with
// the same settings (a live update of another setting) says nothing new.
void log_cuda_launch(const std::string& line);

}  // namespace mppi::cuda_detail
