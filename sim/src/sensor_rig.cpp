#include "sim/sensor_rig.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

namespace sim {
namespace {

std::int64_t to_us(double s) { return static_cast<std::int64_t>(std::llround(s * 1e6)); }

void put_stats(std::FILE* f, const char* name, std::int64_t frames, std::int64_t rays, std::int64_t points,
               double total_ms, double max_ms) {
  std::fprintf(f, "\"%s\":{\"frames\":%lld,\"rays_per_frame\":%lld,\"points_per_frame\":%.1f,", name,
               static_cast<long long>(frames), static_cast<long long>(frames > 0 ? rays / frames : 0),
               frames > 0 ? static_cast<double>(points) / static_cast<double>(frames) : 0.0);
  std::fprintf(f, "\"cast_ms_mean\":%.4f,\"cast_ms_max\":%.4f}", frames > 0 ? total_ms / static_cast<double>(frames) : 0.0,
               max_ms);
}

}  // namespace

SensorRig::SensorRig(const Scenario& s, lcm::LCM* lcm, std::string depth_channel, std::string lidar_channel)
    : s_(s), lcm_(lcm), depth_channel_(std::move(depth_channel)), lidar_channel_(std::move(lidar_channel)),
      rng_(s.seed, 5) {
  if (s.sensing.depth_camera.enabled) camera_ = std::make_unique<DepthCamera>(s.sensing.depth_camera);
  if (s.sensing.lidar.enabled) lidar_ = std::make_unique<Lidar>(s.sensing.lidar);
}

void SensorRig::advance(double& next, double period, double t) {
  next += period;
  if (next + 1e-9 < t) next = t + period;  // fell behind (no pose for a while): no burst of frames
}

void SensorRig::capture_due(double t, const Pose& body, const std::vector<Obstacle>& obstacles,
                            std::int64_t epoch_us) {
  if (!any()) return;
  if (world_ == nullptr || obstacles_ != &obstacles) {
    world_ = std::make_unique<RayWorld>(&obstacles, s_.ground_z);
    obstacles_ = &obstacles;
  }
  if (camera_ != nullptr && t + 1e-9 >= next_depth_) {
    capture(t, body, mppi_lcm::point_cloud_t::SENSOR_DEPTH_CAMERA, epoch_us);
    advance(next_depth_, 1.0 / camera_->spec().rate_hz, t);
  }
  if (lidar_ != nullptr && t + 1e-9 >= next_lidar_) {
    capture(t, body, mppi_lcm::point_cloud_t::SENSOR_LIDAR, epoch_us);
    advance(next_lidar_, 1.0 / lidar_->spec().rate_hz, t);
  }
}

void SensorRig::publish_due(double t) {
  // In capture order, but the sensors' latencies differ: any that is due, not only the front.
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (it->publish_t > t + 1e-9) {
      ++it;
      continue;
    }
    lcm_->publish(*it->channel, &it->msg);
    it = pending_.erase(it);
  }
}

double SensorRig::next_publish() const {
  double t = std::numeric_limits<double>::infinity();
  for (const auto& p : pending_) t = std::min(t, p.publish_t);
  return t;
}

void SensorRig::capture(double t, const Pose& body, std::int8_t kind, std::int64_t epoch_us) {
  const bool depth = kind == mppi_lcm::point_cloud_t::SENSOR_DEPTH_CAMERA;
  const auto& dc = s_.sensing.depth_camera;
  const auto& ld = s_.sensing.lidar;
  const Pose pose = depth ? mounted(body, dc.offset, dc.pitch_deg * 3.14159265358979323846 / 180.0)
                          : mounted(body, ld.offset, 0.0);
  const auto t0 = std::chrono::steady_clock::now();
  if (depth)
    camera_->capture(*world_, pose, rng_, &frame_);
  else
    lidar_->capture(*world_, pose, rng_, &frame_);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  Stats& st = depth ? depth_stats_ : lidar_stats_;
  ++st.frames;
  st.rays += depth ? static_cast<std::int64_t>(dc.width) * dc.height : static_cast<std::int64_t>(ld.beams) * ld.azimuth_steps;
  st.points += static_cast<std::int64_t>(frame_.x.size());
  st.cast_ms_total += ms;
  st.cast_ms_max = std::max(st.cast_ms_max, ms);

  Pending p{t + (depth ? dc.latency : ld.latency), depth ? &depth_channel_ : &lidar_channel_, {}};
  auto& m = p.msg;
  m.utime = epoch_us + to_us(t);
  m.seq = depth ? depth_seq_++ : lidar_seq_++;
  m.sensor = kind;
  for (int i = 0; i < 3; ++i) m.position[i] = static_cast<float>(pose.p[static_cast<std::size_t>(i)]);
  for (int i = 0; i < 4; ++i) m.orientation[i] = static_cast<float>(pose.q[static_cast<std::size_t>(i)]);
  m.min_range = static_cast<float>(depth ? dc.min_range : ld.min_range);
  m.max_range = static_cast<float>(depth ? dc.max_range : ld.max_range);
  m.n = static_cast<std::int32_t>(frame_.x.size());
  m.x = frame_.x;
  m.y = frame_.y;
  m.z = frame_.z;
  m.hit = frame_.hit;
  pending_.push_back(std::move(p));
}

void SensorRig::write_summary(std::FILE* f) const {
  std::fputs("\"sensors\":{", f);
  bool first = true;
  if (camera_ != nullptr) {
    put_stats(f, "depth_camera", depth_stats_.frames, depth_stats_.rays, depth_stats_.points, depth_stats_.cast_ms_total,
              depth_stats_.cast_ms_max);
    first = false;
  }
  if (lidar_ != nullptr) {
    if (!first) std::fputc(',', f);
    put_stats(f, "lidar", lidar_stats_.frames, lidar_stats_.rays, lidar_stats_.points, lidar_stats_.cast_ms_total,
              lidar_stats_.cast_ms_max);
  }
  std::fputs("},", f);
}

}  // namespace sim
