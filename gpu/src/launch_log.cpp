#include "launch_log.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <memory>
#include <mutex>

namespace mppi::cuda_detail {
namespace {

// The program's logger when it set one up (the daemon: "mppid", on stderr, its pattern); else
// one of our own on stderr: spdlog's built-in default writes to stdout, where mppid-bench and
// mppid-gpu-timing print their JSON.
std::shared_ptr<spdlog::logger> launch_logger() {
  auto logger = spdlog::default_logger();
  if (logger && !logger->name().empty()) return logger;
  static const auto own =
      std::make_shared<spdlog::logger>("cuda", std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  return own;
}

}  // namespace

void log_cuda_launch(const std::string& line) {
  static std::mutex mutex;
  static std::string last;
  const std::lock_guard<std::mutex> lock(mutex);
  if (line == last) return;
  last = line;
  launch_logger()->info("cuda backend: {}", line);
}

}  // namespace mppi::cuda_detail
