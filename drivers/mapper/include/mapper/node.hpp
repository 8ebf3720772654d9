// mppid-mapper's LCM side: point_cloud_t frames in (a depth camera, a LiDAR: any number of
// channels), the rolling map updated per frame, local_map_t out at a fixed rate when something
// new came in. Settings from a YAML file (config/mapper/mapper.yaml) and key=value overrides.
// Timing of every frame's update and every map's distance transform is kept (write_stats).
#pragma once

#include <csignal>
#include <cstdint>
#include <lcm/lcm-cpp.hpp>
#include <mppi_lcm/local_map_t.hpp>
#include <mppi_lcm/point_cloud_t.hpp>
#include <cstdio>
#include <string>
#include <unordered_set>
#include <vector>

#include "mapper/local_map.hpp"

namespace mapper {

struct NodeSettings {
  MapSettings map;
  double rate_hz = 10.0;                                      // local_map_t at most this often
  std::vector<std::string> inputs{"MPPI_DEPTH", "MPPI_LIDAR"};  // point_cloud_t channels
  std::string output = "MPPI_LOCAL_MAP";
  double max_ray = 0.0;  // m: returns beyond are cut to misses at this range (0: the sensor's own)
  // The bus the maps go out on ("": LCM's default, udpm://239.255.76.67:7667?ttl=0) and the
  // one the frames come in on ("": the maps' bus); --lcm-url / --sensor-lcm-url override them.
  std::string lcm_url;
  std::string sensor_lcm_url;
};

// `path` (empty: defaults) then each "a.b=value" of `sets` (map.resolution=0.2, rate_hz=20,
// inputs=[MPPI_DEPTH]); throws std::runtime_error naming the bad key.
NodeSettings load_settings(const std::string& path, const std::vector<std::string>& sets);

// point_cloud_t's count checked against the bytes there before the generated decoder sizes
// anything by it; false: undecodable.
bool decode_cloud(const void* data, std::size_t size, mppi_lcm::point_cloud_t* m);

class MapperNode {
 public:
  // Frames from `sensors`, maps to `maps` (the same bus, or the sensors on one of their own).
  MapperNode(const NodeSettings& s, lcm::LCM* maps, lcm::LCM* sensors);
  MapperNode(const NodeSettings& s, lcm::LCM* lcm) : MapperNode(s, lcm, lcm) {}
  // Integrates one frame into the map (what the subscription calls).
  void integrate(const mppi_lcm::point_cloud_t& cloud);
  // Computes and publishes the map if a frame came since the last one; true if published.
  bool publish();
  // Until *stop: handles frames, publishes at rate_hz.
  void run(const volatile std::sig_atomic_t* stop);
  // {"frames":..., "maps":..., "integrate_ms":{p50,p99,max}, "publish_ms":{...}, ...}
  std::string stats_json() const;
  const LocalMap& map() const { return map_; }
  // From now on, each map that holds occupied columns (x, y cells) never occupied before
  // appends a JSON line to `f`: {"t" (s since the first frame), "utime", "sensor" (its
  // position), "columns": [[x, y] world centres]}: what was sensed and when (the harness's
  // score names each tree's first sighting from it). A column counts once it is occupied
  // within kSensedBand of the sensor's height, where the vehicle flies: a trunk seen only at
  // its foot (a camera looking down) is not yet an obstacle to the flight.
  void record_sensed(std::FILE* f) { sensed_ = f; }
  static constexpr double kSensedBand = 0.5;  // m

 private:
  void on_cloud(const lcm::ReceiveBuffer* rb, const std::string& channel);
  void centre_on(const float* position);
  void write_new_columns();

  int wait_and_handle(int timeout_ms);

  NodeSettings s_;
  lcm::LCM* lcm_;
  lcm::LCM* sensors_;
  LocalMap map_;
  mppi_lcm::point_cloud_t in_;
  mppi_lcm::local_map_t out_;
  bool dirty_ = false;
  std::int64_t newest_utime_ = 0;
  std::int64_t frames_ = 0, undecodable_ = 0, maps_ = 0;
  double last_pos_[3] = {0, 0, 0};
  double heading_[2] = {0, 0};  // unit horizontal direction of motion (lead)
  bool have_pos_ = false;
  // Wall and CPU time per frame and per map, and each map's age as it leaves [ms]; reserved
  // at start: no allocation per frame.
  std::vector<float> integrate_ms_, integrate_cpu_ms_, publish_ms_, publish_cpu_ms_, age_ms_;
  std::FILE* sensed_ = nullptr;
  std::unordered_set<std::int64_t> columns_seen_;  // world (x, y) cells ever occupied
  std::vector<std::int64_t> new_columns_;
  std::int64_t first_utime_ = -1;
  float sensor_pos_[3] = {0, 0, 0};
};

}  // namespace mapper
