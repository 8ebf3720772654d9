// The sensors of a scenario (sensing.depth_camera, sensing.lidar) on vehicle 0, driven by the
// simulator's clock: each captures at its own rate from the vehicle's true pose, and its frame
// is published (point_cloud_t) its latency later, stamped with the capture time. What the
// ray-casting costs is counted per sensor (sim_summary.json: "sensors").
#pragma once

#include <cstdint>
#include <cstdio>
#include <deque>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <mppi_lcm/point_cloud_t.hpp>
#include <string>
#include <vector>

#include "sim/scenario.hpp"
#include "sim/sensors.hpp"

namespace sim {

class SensorRig {
 public:
  SensorRig(const Scenario& s, lcm::LCM* lcm, std::string depth_channel, std::string lidar_channel);
  bool any() const { return camera_ != nullptr || lidar_ != nullptr; }
  // At simulated time t (s), the vehicle at `body`, the world's obstacles as they are now:
  // captures what is due, publishes what has waited its latency. `epoch_us` + t is the
  // capture's time stamp (0 in lock-step: simulated microseconds; the run's wall-clock
  // start in real time).
  void step(double t, const Pose& body, const std::vector<Obstacle>& obstacles, std::int64_t epoch_us) {
    capture_due(t, body, obstacles, epoch_us);
    publish_due(t);
  }
  // step's halves, for a rig driven by poses that arrive at their own times (the autopilot
  // flights' sensor node, sim/sensor_node.hpp): the captures due at t (a sensor more than a
  // period behind, after a gap in the poses, captures once and is due again a period later),
  // and the frames whose latency has passed by t.
  void capture_due(double t, const Pose& body, const std::vector<Obstacle>& obstacles, std::int64_t epoch_us);
  void publish_due(double t);
  // When the oldest waiting frame is due (s, the rig's time); +inf when none waits.
  double next_publish() const;
  // "sensors":{...} for sim_summary.json (frames, rays, ray-casting time per frame).
  void write_summary(std::FILE* f) const;

 private:
  struct Stats {
    std::int64_t frames = 0, rays = 0, points = 0;
    double cast_ms_total = 0.0, cast_ms_max = 0.0;
  };
  struct Pending {
    double publish_t;
    const std::string* channel;
    mppi_lcm::point_cloud_t msg;
  };
  void capture(double t, const Pose& body, std::int8_t kind, std::int64_t epoch_us);
  static void advance(double& next, double period, double t);

  const Scenario& s_;
  lcm::LCM* lcm_;
  std::string depth_channel_, lidar_channel_;
  std::unique_ptr<DepthCamera> camera_;
  std::unique_ptr<Lidar> lidar_;
  std::unique_ptr<RayWorld> world_;
  const std::vector<Obstacle>* obstacles_ = nullptr;
  Rng rng_;
  Frame frame_;
  double next_depth_ = 0.0, next_lidar_ = 0.0;
  std::int64_t depth_seq_ = 0, lidar_seq_ = 0;
  std::deque<Pending> pending_;
  Stats depth_stats_, lidar_stats_;
};

}  // namespace sim
