#include "mppi/transport/lcm_decode.hpp"

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstring>

namespace mppi::transport {
namespace {

// LCM encodes integers big-endian.
bool read_be(const void* data, std::size_t size, std::size_t at, int bytes, std::int64_t* out) {
  if (size < at || size - at < static_cast<std::size_t>(bytes)) return false;
  const auto* b = static_cast<const unsigned char*>(data) + at;
  std::uint32_t u = 0;
  for (int i = 0; i < bytes; ++i) u = (u << 8) | b[i];
  if (bytes == 4) {
    std::int32_t v;
    std::memcpy(&v, &u, sizeof v);
    *out = v;
  } else {
    const auto u16 = static_cast<std::uint16_t>(u);
    std::int16_t v;
    std::memcpy(&v, &u16, sizeof v);
    *out = v;
  }
  return true;
}

// `count` elements of `elem` bytes from offset `from` lie inside the buffer.
bool backed(std::int64_t count, std::size_t elem, std::size_t from, std::size_t size) {
  return count >= 0 && from <= size && static_cast<std::uint64_t>(count) * elem <= size - from;
}

// The count at `at` (`bytes` wide) of `elem`-byte elements, then `tail` bytes of fixed fields.
bool counted(const void* data, std::size_t size, std::size_t at, int bytes, std::size_t elem, std::size_t tail = 0) {
  std::int64_t n = 0;
  return read_be(data, size, at, bytes, &n) && backed(n, elem, at + static_cast<std::size_t>(bytes) + tail, size);
}

// The whole buffer is one message: a wrong fingerprint, short or padded bytes fail.
template <class Msg>
bool run(Msg* m, const void* data, std::size_t size) {
  if (size > static_cast<std::size_t>(INT_MAX)) return false;
  const int n = static_cast<int>(size);
  try {
    return m->decode(data, 0, n) == n;
  } catch (...) {  // out of memory: nothing a datagram may cause once the counts are checked
    return false;
  }
}

}  // namespace

bool decode_message(const void* data, std::size_t size, mppi_lcm::vehicle_state_t* m) {
  return counted(data, size, wire::kStateCount, 4, sizeof(float)) && run(m, data, size);
}

bool decode_message(const void* data, std::size_t size, mppi_lcm::command_t* m) {
  return counted(data, size, wire::kCommandCount, 4, sizeof(float)) && run(m, data, size);
}

bool decode_message(const void* data, std::size_t size, mppi_lcm::obstacles_t* m) {
  return counted(data, size, wire::kObstaclesCount, 4, wire::kCylinderBytes) && run(m, data, size);
}

bool decode_message(const void* data, std::size_t size, mppi_lcm::reference_t* m) {
  return counted(data, size, wire::kReferenceCount, 2, 3 * sizeof(float), wire::kReferenceTail) && run(m, data, size);
}

bool decode_message(const void* data, std::size_t size, mppi_lcm::param_update_t* m) {
  // The length counts the terminating NUL: 0 (or less) has no room for it.
  std::int64_t len = 0;
  if (!read_be(data, size, wire::kParamKeyLength, 4, &len) || len < 1 ||
      !backed(len, 1, wire::kParamKeyLength + 4, size))
    return false;
  return run(m, data, size);
}

bool decode_message(const void* data, std::size_t size, mppi_lcm::sim_clock_t* m) { return run(m, data, size); }

bool decode_message(const void* data, std::size_t size, mppi_lcm::local_map_t* m) {
  std::int64_t n = 0;
  return read_be(data, size, wire::kLocalMapCount, 4, &n) && n <= DistanceField::kMaxCells &&
         backed(n, sizeof(std::int16_t), wire::kLocalMapCount + 4, size) && run(m, data, size);
}

}  // namespace mppi::transport

namespace mppi::transport {

LcmDecoder::LcmDecoder(rt::Clock* recv_clock, MapScratch maps) : recv_clock_(recv_clock) {
  state_in_.x.reserve(kMaxStates);
  obstacles_in_.cylinders.reserve(kMaxObstaclesIn);
  if (maps == MapScratch::kReserve) map_in_.distance_mm.reserve(DistanceField::kMaxCells);  // virtual until a map arrives
  reference_in_.goals.reserve(kMaxVehicles);
}

void LcmDecoder::state(const void* data, std::size_t size, Inbox* inbox) {
  const std::int64_t now = recv_clock_->now_ns();
  if (!decode_message(data, size, &state_in_)) return inbox->count_undecodable();
  const auto& m = state_in_;
  if (m.n != static_cast<std::int32_t>(m.x.size()) || m.n > kMaxStates || m.n < 0) return inbox->count_undecodable();
  StateSample& s = inbox->state_buffer();
  s.utime = m.utime;
  s.seq = m.seq;
  s.sample_utime = m.sample_utime;
  s.recv_ns = now;
  s.recv_utime = rt::wall_utime();
  s.model = m.model;
  s.vehicle_count = m.vehicle_count;
  s.nx = m.nx;
  s.n = m.n;
  std::copy(m.x.begin(), m.x.end(), s.x);
  inbox->offer_state();
}

void LcmDecoder::reference(const void* data, std::size_t size, Inbox* inbox) {
  if (!decode_message(data, size, &reference_in_)) return inbox->count_undecodable();
  const auto& m = reference_in_;
  if (m.vehicle_count < 0 || m.vehicle_count > kMaxVehicles) return inbox->count_bad_input();
  ReferenceInput& r = inbox->reference_buffer();
  r.seq = m.seq;
  r.kind = m.kind;
  std::copy_n(m.center, 3, r.center);
  r.radius = m.radius;
  r.speed = m.speed;
  r.yaw = m.yaw;
  r.ramp_s = m.ramp_s;
  r.phase = m.phase;
  r.end_s = m.end_s;
  r.t0_utime = m.t0_utime;
  r.vehicle_count = m.vehicle_count;
  for (int v = 0; v < m.vehicle_count; ++v)
    for (int d = 0; d < 3; ++d) r.goals[v][d] = m.goals[static_cast<std::size_t>(v)][static_cast<std::size_t>(d)];
  inbox->offer_reference();
}

void LcmDecoder::obstacles(const void* data, std::size_t size, Inbox* inbox) {
  if (!decode_message(data, size, &obstacles_in_)) return inbox->count_undecodable();
  const auto& m = obstacles_in_;
  if (m.n < 0 || m.n > kMaxObstaclesIn) return inbox->count_bad_input();
  ObstacleInput& o = inbox->obstacles_buffer();
  o.seq = m.seq;
  o.utime = m.utime;
  o.count = m.n;
  for (int i = 0; i < m.n; ++i) {
    const auto& c = m.cylinders[static_cast<std::size_t>(i)];
    o.items[i] = Cylinder{c.x, c.y, c.radius, c.vx, c.vy};
  }
  inbox->offer_obstacles();
}

void LcmDecoder::local_map(const void* data, std::size_t size, Inbox* inbox) {
  LocalMapInput* out = inbox->map_buffer();
  if (out == nullptr) return;
  const std::int64_t now = recv_clock_->now_ns();
  if (!decode_message(data, size, &map_in_)) {
    // A map too large to take is a valid message the daemon refuses, not garbage.
    std::int64_t n = 0;
    if (read_be(data, size, wire::kLocalMapCount, 4, &n) && n > DistanceField::kMaxCells) return inbox->count_invalid_map();
    return inbox->count_undecodable_map();
  }
  const auto& m = map_in_;
  out->utime = m.utime;
  out->seq = m.seq;
  out->recv_ns = now;
  DistanceFieldGrid& g = out->grid;
  std::copy_n(m.origin, 3, g.origin);
  g.resolution = m.resolution;
  g.nx = m.nx;
  g.ny = m.ny;
  g.nz = m.nz;
  g.max_distance = m.max_distance;
  g.n_cells = m.n_cells;
  std::copy(m.distance_mm.begin(), m.distance_mm.end(), g.distance_mm);  // n_cells <= kMaxCells (decode)
  inbox->offer_map();
}

void LcmDecoder::param(const void* data, std::size_t size, Inbox* inbox) {
  if (!decode_message(data, size, &param_in_)) return inbox->count_undecodable();
  ParamUpdate p;
  p.seq = param_in_.seq;
  p.value = param_in_.value;
  p.apply_utime = param_in_.apply_utime;
  if (param_in_.key.size() >= sizeof(p.key)) {
    // Too long for any known key: let the loop reject it by name (truncated, marked).
    std::memcpy(p.key, param_in_.key.data(), sizeof(p.key) - 4);
    std::memcpy(p.key + sizeof(p.key) - 4, "...", 4);
  } else {
    std::memcpy(p.key, param_in_.key.c_str(), param_in_.key.size() + 1);
  }
  inbox->offer_param(p);
}

void LcmDecoder::clock(const void* data, std::size_t size, Inbox* inbox) {
  if (!decode_message(data, size, &clock_in_)) return inbox->count_undecodable();
  ClockTick t;
  t.seq = clock_in_.seq;
  t.sim_utime = clock_in_.sim_utime;
  t.step = clock_in_.step;
  inbox->offer_tick(t);
}

}  // namespace mppi::transport
