// mppid-sensors: the simulator's sensors (SensorRig: the same depth camera and LiDAR, the same
// ray-casting) for a vehicle the simulator does not fly: an autopilot's SITL (ArduCopter).
// The vehicle's true pose comes as vehicle_state_t on a truth channel (the harness's referee,
// tools/sitl_harness/ap_truth.py, publishes the SITL's SIM_STATE there: position ENU, attitude
// FLU -> ENU, sampled at sample_utime on this host's wall clock); the world, the trees, as
// obstacles_t on a world channel (the mission tool's trees of a sensed mission, which mppid
// never gets). Frames go out as point_cloud_t at the sensors' rates, stamped with the truth's
// sample time, each its latency after that time (docs/sensing.md).
//
// A truth is refused, and counted, when it is undecodable or of another layout, not finite or
// not a unit quaternion, older than max_truth_age behind the wall clock (or as far ahead), or
// not newer than the last one taken. Nothing is captured before the first world: a frame cast
// without the trees would tell the mapper the space they stand in is free.
#pragma once

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <mppi_lcm/obstacles_t.hpp>
#include <string>
#include <vector>

#include "sim/scenario.hpp"
#include "sim/sensor_rig.hpp"

namespace sim {

struct SensorNodeSettings {
  std::string truth_channel = "SIM_TRUTH";
  std::string world_channel = "MPPI_WORLD";
  std::string depth_channel = "MPPI_DEPTH";
  std::string lidar_channel = "MPPI_LIDAR";
  double tree_height = 10.0;     // m above the ground: obstacles_t's cylinders carry none
  double max_truth_age = 0.1;    // s: a truth older than this behind the wall clock is stale
};

struct TruthCounters {
  std::int64_t taken = 0, undecodable = 0, layout = 0, not_finite = 0, stale = 0, out_of_order = 0,
               before_world = 0;
  std::int64_t worlds = 0, bad_worlds = 0;
};

class SensorNode {
 public:
  using WallClock = std::function<std::int64_t()>;  // us, this host's wall clock
  // `s`: the sensing spec, the seed (noise) and ground_z; truths and worlds from `in`, frames
  // to `out` (the same bus or the sensors' own).
  SensorNode(const Scenario& s, const SensorNodeSettings& settings, lcm::LCM* in, lcm::LCM* out, WallClock wall);
  // A truth (an encoded vehicle_state_t) received at wall time `now_us`: checked, then what is
  // due captured; false if refused (and counted).
  bool on_truth(const void* data, std::size_t size, std::int64_t now_us);
  void on_world(const mppi_lcm::obstacles_t& m);
  // Publishes the frames whose latency has passed by `now_us`.
  void publish_due(std::int64_t now_us);
  // Wall time the next frame is due (us); INT64_MAX when none waits.
  std::int64_t next_publish_us() const;
  // Until *stop: both buses' messages, the frames on time.
  void run(const volatile std::sig_atomic_t* stop);
  const TruthCounters& counters() const { return n_; }
  // {"truth": {...counters}, "sensors": {...}} (the rig's frames, rays, ray-casting time).
  void write_stats(std::FILE* f) const;

 private:
  static constexpr int kDrainMax = 100000;  // messages taken at most when stopping (a bus that never empties)
  void on_world_msg(const lcm::ReceiveBuffer* rb, const std::string& channel, const mppi_lcm::obstacles_t* m);
  void on_truth_msg(const lcm::ReceiveBuffer* rb, const std::string& channel);
  bool check_truth(const void* data, std::size_t size, std::int64_t now_us, Pose* pose, std::int64_t* sample_us);
  double rig_time(std::int64_t us) const { return 1e-6 * static_cast<double>(us - epoch_us_); }

  Scenario s_;
  SensorNodeSettings settings_;
  lcm::LCM* in_;
  lcm::LCM* out_;
  WallClock wall_;
  SensorRig rig_;
  std::vector<Obstacle> trees_;
  bool have_world_ = false;
  std::int64_t epoch_us_ = -1;  // the first truth's sample time: the rig's t = 0
  std::int64_t last_sample_us_ = -1;
  TruthCounters n_;
};

}  // namespace sim
