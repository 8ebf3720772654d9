// A settings file (YAML) as mppid reads it: parse_config (task, backend, mppi, model and
// cost sections), parse_daemon_settings (the daemon section) and, for settings small enough
// to build in a moment, the controller and one iteration of it. A bad file must end in a
// ConfigError naming the field (mppid exits 2 with it); any other exception is a crash.
// Input: the file's text.
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/daemon/daemon_settings.hpp"

using namespace mppi;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  YAML::Node root;
  try {
    root = YAML::Load(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const YAML::Exception&) {
    return 0;  // load_config turns a syntax error into a ConfigError with the file's name
  }
  try {
    app::AppConfig cfg = app::parse_config(root);
    const int nu = static_cast<int>(cfg.mppi.u_init.size());
    const daemon::DaemonSettings ds = daemon::parse_daemon_settings(cfg.root["daemon"], cfg.task, nu);
    (void)ds;
    const MppiSettings& m = cfg.mppi;
    if (m.rollouts > 64 || m.horizon > 64 || m.substeps > 8) return 0;  // valid, but not built here
    cfg.backend = "cpu";
    cfg.mppi.threads = 1;
    const auto controller = app::make_controller(cfg);
    std::vector<float> x(static_cast<std::size_t>(controller->nx()), 0.0f), u(static_cast<std::size_t>(nu));
    const UpdateStats& st = controller->iterate(x.data(), u.data());
    if (st.finite)
      for (float v : u)
        if (!std::isfinite(v)) __builtin_trap();  // a non-finite command reported finite
  } catch (const app::ConfigError&) {
  }
  return 0;
}
