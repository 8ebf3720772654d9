// The daemon's own section of the settings file (`daemon:`), validated with errors that
// name the field ("daemon.rate_hz: must be in (0, 2000]").
#pragma once

#include <cstdint>
#include <yaml-cpp/yaml.h>

#include <string>

#include "mppi/daemon/control_loop.hpp"
#include "mppi/rt/realtime.hpp"
#include "mppi/transport/lcm_transport.hpp"

namespace mppi::daemon {

struct DaemonSettings {
  LoopSettings loop;
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  transport::LcmChannels channels;
  int receive_timeout_ms = 20;
  // daemon.spin: the loop thread and the LCM receive thread poll instead of sleeping (a busy
  // core each; for a host with cores to spare, e.g. next to a GPU): no wake-up latency.
  bool spin = false;
  std::string lockstep_trigger = "clock";  // clock | state
  rt::RealtimeRequest realtime;
  int warmup_iterations = 3;
  std::int8_t expect_model = 0;  // vehicle_state_t::MODEL_*, from the task
  LiveSettings live;             // live optimizer updates (mppi.* at run time)
  // daemon.map.enabled: the inbox takes local_map_t on channels.local_map (default: forest
  // tasks); the timeout is loop.map_timeout_ns (daemon.map.timeout_ms).
  bool local_map = false;
};

// Reads `section` (may be null: all defaults) for a controller with nu controls of task
// `task`. Throws mppi::app::ConfigError naming the field.
DaemonSettings parse_daemon_settings(const YAML::Node& section, const std::string& task, int nu);

// What the inbox accepts and when it posts a tick or a wake-up, for `controller` flown with
// these settings (mppid, mppid-replay).
transport::Inbox::Expect inbox_expects(const DaemonSettings& ds, const Controller& controller);

// command_t::KIND_* and vehicle_state_t::MODEL_* for a task name.
std::int8_t command_kind_for(const std::string& task);
std::int8_t state_model_for(const std::string& task);

}  // namespace mppi::daemon
