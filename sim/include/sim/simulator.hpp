// The SITL simulator: integrates the plant at the scenario's physics rate, publishes state
// (and the obstacles, the reference, and in lock-step its clock) over LCM, applies the
// commands it receives after the actuation delay, detects collisions itself, and writes
// its truth log. Two clocks:
//  - real time: physics paced to the wall clock; commands apply when they arrive (+ delay);
//  - lock-step: after each state the simulator waits for the command answering it
//    (command.state_seq == state.seq), so a run is repeatable and as fast as the
//    controller; a missing answer past the timeout ends the run as a failure. The command
//    for the state of time t acts at t + the controller's latency + the actuation delay,
//    as in real time: the latency is the measured wall time from the state's publish to
//    the command's receipt (or the scenario's timing.controller_latency); `ideal` charges
//    none (the zero-latency lock-step, for algorithm studies).
#pragma once

#include <cstdint>
#include <string>

#include "sim/scenario.hpp"

namespace sim {

struct Channels {
  std::string state = "MPPI_STATE";
  std::string command = "MPPI_COMMAND";
  std::string obstacles = "MPPI_OBSTACLES";
  std::string reference = "MPPI_REFERENCE";
  std::string clock = "MPPI_SIM_CLOCK";
  std::string depth = "MPPI_DEPTH";  // point_cloud_t: the depth camera's frames
  std::string lidar = "MPPI_LIDAR";  // point_cloud_t: the LiDAR's revolutions
};

struct RunOptions {
  bool lockstep = false;
  std::string lcm_url;  // empty: LCM's default
  // The sensors' frames (point_cloud_t, up to megabytes a second) on a bus of their own, as a
  // camera's driver would be: the controller's bus then carries none. Empty: lcm_url's.
  std::string sensor_lcm_url;
  std::string out_dir = ".";
  Channels channels;
  bool quiet = false;
  bool ideal = false;             // lock-step: charge no controller latency
  double controller_latency = -2.0;  // >= 0: seconds charged; -1: measured; -2: the scenario's
};

// Outcome of a run, as written to summary.json.
enum class Outcome { kGoal, kDuration, kCollision, kControllerTimeout, kInterrupted, kError };
const char* to_string(Outcome o);

// Runs the scenario to its end; returns the process exit code (0: the run completed,
// whatever its outcome; 3: the controller stopped answering; 4: interrupted; 1: error).
int run_simulation(const Scenario& scenario, const RunOptions& options);

// Set from a signal handler: the run stops at the next step and still writes its logs.
void request_stop();

}  // namespace sim
