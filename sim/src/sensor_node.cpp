#include "sim/sensor_node.hpp"

#include <poll.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <mppi_lcm/vehicle_state_t.hpp>

namespace sim {
namespace {

// vehicle_state_t's fixed part: fingerprint, utime, seq, sample_utime, model, vehicle_count,
// nx, n (big-endian); then n floats.
constexpr std::size_t kStateHeader = 8 + 8 + 8 + 8 + 1 + 2 + 2 + 4;
// The rate quadrotor's layout (core/include/mppi/models/quadrotor_rate.hpp: PX.. QW..).
constexpr int kRateNx = 13, kPx = 0, kQw = 6;

std::int64_t system_wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The truth's bytes decoded, when their length is the one their own count n gives.
bool decode_truth(const void* data, std::size_t size, mppi_lcm::vehicle_state_t* m) {
  std::int32_t n = -1;
  if (size >= kStateHeader) {
    const auto* b = static_cast<const std::uint8_t*>(data) + kStateHeader - 4;
    n = static_cast<std::int32_t>((std::uint32_t{b[0]} << 24) | (std::uint32_t{b[1]} << 16) |
                                  (std::uint32_t{b[2]} << 8) | std::uint32_t{b[3]});
  }
  return n >= 0 && size == kStateHeader + 4 * static_cast<std::size_t>(n) && m->decode(data, 0, static_cast<int>(size)) >= 0;
}

// The rate quadrotor's states (one or more vehicles).
bool rate_quadrotor_layout(const mppi_lcm::vehicle_state_t& m) {
  return m.model == mppi_lcm::vehicle_state_t::MODEL_QUADROTOR_RATE && m.nx == kRateNx && m.vehicle_count >= 1 &&
         m.n == m.nx * m.vehicle_count;
}

}  // namespace

SensorNode::SensorNode(const Scenario& s, const SensorNodeSettings& settings, lcm::LCM* in, lcm::LCM* out,
                       WallClock wall)
    : s_(s), settings_(settings), in_(in), out_(out), wall_(wall ? std::move(wall) : WallClock(system_wall_us)),
      rig_(s_, out, settings.depth_channel, settings.lidar_channel) {
  in_->subscribe(settings_.world_channel, &SensorNode::on_world_msg, this);
  out_->subscribe(settings_.truth_channel, &SensorNode::on_truth_msg, this);
}

void SensorNode::on_world_msg(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::obstacles_t* m) {
  on_world(*m);
}

void SensorNode::on_truth_msg(const lcm::ReceiveBuffer* rb, const std::string&) {
  on_truth(rb->data, rb->data_size, wall_());
}

void SensorNode::on_world(const mppi_lcm::obstacles_t& m) {
  const bool ok = m.n >= 0 && static_cast<std::size_t>(m.n) == m.cylinders.size() &&
                  std::all_of(m.cylinders.begin(), m.cylinders.end(), [](const mppi_lcm::cylinder_t& c) {
                    return std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.radius) && c.radius > 0.0f;
                  });
  if (!ok) {
    ++n_.bad_worlds;
    return;
  }
  ++n_.worlds;
  // The same vector, its contents replaced: the rig's RayWorld keeps pointing at it.
  trees_.resize(m.cylinders.size());
  for (std::size_t i = 0; i < trees_.size(); ++i) {
    const auto& c = m.cylinders[i];
    trees_[i] = Obstacle{c.x, c.y, c.radius, 0.0, 0.0, settings_.tree_height};
  }
  have_world_ = true;
}

bool SensorNode::check_truth(const void* data, std::size_t size, std::int64_t now_us, Pose* pose,
                             std::int64_t* sample_us) {
  mppi_lcm::vehicle_state_t m;
  if (!decode_truth(data, size, &m)) {
    ++n_.undecodable;
    return false;
  }
  if (!rate_quadrotor_layout(m)) {
    ++n_.layout;
    return false;
  }
  double qn = 0.0;
  for (int i = 0; i < 4; ++i) qn += static_cast<double>(m.x[kQw + i]) * m.x[kQw + i];
  const bool finite = std::all_of(m.x.begin(), m.x.begin() + kQw + 4, [](float v) { return std::isfinite(v); });
  if (!finite || std::fabs(std::sqrt(qn) - 1.0) > 0.01) {
    ++n_.not_finite;
    return false;
  }
  const double age = 1e-6 * static_cast<double>(now_us - m.sample_utime);
  if (std::fabs(age) > settings_.max_truth_age) {
    ++n_.stale;
    return false;
  }
  if (m.sample_utime <= last_sample_us_) {
    ++n_.out_of_order;
    return false;
  }
  const double inv = 1.0 / std::sqrt(qn);
  for (int i = 0; i < 3; ++i) pose->p[static_cast<std::size_t>(i)] = m.x[kPx + i];
  for (int i = 0; i < 4; ++i) pose->q[static_cast<std::size_t>(i)] = m.x[kQw + i] * inv;
  *sample_us = m.sample_utime;
  return true;
}

bool SensorNode::on_truth(const void* data, std::size_t size, std::int64_t now_us) {
  Pose body;
  std::int64_t sample_us = 0;
  if (!check_truth(data, size, now_us, &body, &sample_us)) return false;
  last_sample_us_ = sample_us;
  if (!have_world_) {
    ++n_.before_world;
    return false;
  }
  ++n_.taken;
  if (epoch_us_ < 0) epoch_us_ = sample_us;
  rig_.capture_due(rig_time(sample_us), body, trees_, epoch_us_);
  return true;
}

void SensorNode::publish_due(std::int64_t now_us) {
  if (epoch_us_ >= 0) rig_.publish_due(rig_time(now_us));
}

std::int64_t SensorNode::next_publish_us() const {
  const double t = rig_.next_publish();
  if (epoch_us_ < 0 || !std::isfinite(t)) return std::numeric_limits<std::int64_t>::max();
  return epoch_us_ + static_cast<std::int64_t>(std::ceil(t * 1e6));
}

void SensorNode::run(const volatile std::sig_atomic_t* stop) {
  const bool one_bus = in_ == out_;
  while (*stop == 0) {
    const std::int64_t now = wall_();
    const std::int64_t due = next_publish_us();
    const std::int64_t wait_us = std::clamp<std::int64_t>(due == std::numeric_limits<std::int64_t>::max()
                                                              ? 50'000 : due - now, 0, 50'000);
    pollfd fds[2] = {{in_->getFileno(), POLLIN, 0}, {out_->getFileno(), POLLIN, 0}};
    const int ready = ::poll(fds, one_bus ? 1 : 2, static_cast<int>((wait_us + 999) / 1000));
    if (ready > 0) {
      if ((fds[0].revents & POLLIN) != 0) in_->handleTimeout(0);
      if (!one_bus && (fds[1].revents & POLLIN) != 0) out_->handleTimeout(0);
    }
    publish_due(wall_());
  }
  // Stopping loses nothing: what is already on the buses is taken (a busy machine leaves the
  // last truths queued), and the frames captured go out now, before their latency.
  for (int n = 0; n < kDrainMax; ++n) {
    const int world = in_->handleTimeout(0);
    const int truth = one_bus ? 0 : out_->handleTimeout(0);
    if (world <= 0 && truth <= 0) break;
  }
  if (epoch_us_ >= 0) rig_.publish_due(std::numeric_limits<double>::infinity());
}

void SensorNode::write_stats(std::FILE* f) const {
  std::fprintf(f,
               "{\"truth\":{\"taken\":%lld,\"undecodable\":%lld,\"layout\":%lld,\"not_finite\":%lld,\"stale\":%lld,"
               "\"out_of_order\":%lld,\"before_world\":%lld},\"worlds\":%lld,\"bad_worlds\":%lld,\"trees\":%zu,",
               static_cast<long long>(n_.taken), static_cast<long long>(n_.undecodable),
               static_cast<long long>(n_.layout), static_cast<long long>(n_.not_finite),
               static_cast<long long>(n_.stale), static_cast<long long>(n_.out_of_order),
               static_cast<long long>(n_.before_world), static_cast<long long>(n_.worlds),
               static_cast<long long>(n_.bad_worlds), trees_.size());
  rig_.write_summary(f);  // "sensors":{...},
  std::fputs("\"ok\":true}\n", f);
}

}  // namespace sim
