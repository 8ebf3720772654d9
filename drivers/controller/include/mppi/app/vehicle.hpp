// A vehicle file (config/vehicles/*.yaml, docs/vehicle.md): what one airframe is — its mass,
// hover thrust, limits and the response of its autopilot's rate loop — written once, by hand
// or by tools/sysid, and read by both mppid (here: into the task's model parameters, the
// daemon's actuation delay, and checked against the task's limits and hover) and the MAVLink
// bridge (drivers/mavlink/mppi_mavlink/vehicle.py: its thrust map), so the two cannot
// disagree. A task file names its vehicle (`vehicle: ../vehicles/x.yaml`, relative to the
// task file) or mppid is given one (`--vehicle FILE`); a value both give differently is
// refused at start, naming both files.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>
#include <utility>
#include <vector>

namespace mppi::app {

struct VehicleFile {
  std::string path;
  std::string name;
  std::string model;  // the mppid model it describes: quadrotor_rate | quadrotor
  // What it sets in a task's settings, by their dotted names (model.*, daemon.latency.*).
  std::vector<std::pair<std::string, double>> settings;
  // One vehicle's control range, per channel: what the airframe can fly.
  std::vector<float> u_lo, u_hi;
};

// Reads and validates a vehicle file; ConfigError naming the file and the field.
VehicleFile load_vehicle(const std::string& path);

// Puts the vehicle's settings into the settings tree of `task` (after its overrides; `file`:
// the tree as the file gave it). The task must fly the vehicle's model, and a value the tree
// already has and the vehicle gives differently is a ConfigError naming both: the task file
// `task_label` (or its --set) and v.path.
void merge_vehicle(const VehicleFile& v, YAML::Node root, const YAML::Node& file, const std::string& task,
                   const std::string& task_label);

// The checks that need the parsed settings: the control limits lie inside the vehicle's, and
// a numeric u_init / u_nominal on a hover channel is the vehicle's hover (within 1 %).
// `hover` and the lists are per vehicle, repeated for a team.
void check_vehicle_fits(const VehicleFile& v, const std::vector<float>& hover,
                        const std::vector<float>& u_min, const std::vector<float>& u_max,
                        const std::vector<float>& u_init, const std::vector<float>& u_nominal,
                        const std::string& task_label);

}  // namespace mppi::app
