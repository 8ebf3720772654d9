#include "mppi/transport/inbox.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>

namespace mppi::transport {

const char* to_string(Mode m) {
  switch (m) {
    case Mode::kNormal: return "normal";
    case Mode::kHoldPlan: return "hold_plan";
    case Mode::kFailsafe: return "failsafe";
  }
  return "?";
}

const char* to_string(Reject r) {
  switch (r) {
    case Reject::kNone: return "accepted";
    case Reject::kNan: return "non-finite value";
    case Reject::kDuplicate: return "duplicate seq";
    case Reject::kOutOfOrder: return "out-of-order seq";
    case Reject::kShape: return "wrong shape or model";
    case Reject::kUndecodable: return "undecodable";
    case Reject::kTime: return "sample time out of range";
  }
  return "?";
}

namespace {

// The counter of the states refused for `why`.
std::atomic<std::int64_t>& state_rejections(InboxCounters& c, Reject why) {
  switch (why) {
    case Reject::kShape: return c.rejected_shape;
    case Reject::kNan: return c.rejected_nan;
    case Reject::kTime: return c.rejected_time;
    case Reject::kDuplicate: return c.rejected_duplicate;
    default: return c.rejected_out_of_order;
  }
}

bool finite_reference_scalars(const ReferenceInput& r) {
  return std::isfinite(r.radius) && std::isfinite(r.speed) && std::isfinite(r.yaw) && std::isfinite(r.phase) &&
         std::isfinite(r.ramp_s) && r.ramp_s >= 0.0f && std::isfinite(r.end_s) && r.end_s >= 0.0f;
}

// The centre and each vehicle's goal finite (the count checked before).
bool finite_reference_points(const ReferenceInput& r) {
  bool ok = true;
  for (int d = 0; d < 3; ++d) ok = ok && std::isfinite(r.center[d]);
  for (int v = 0; ok && v < r.vehicle_count; ++v)
    for (int d = 0; d < 3; ++d) ok = ok && std::isfinite(r.goals[v][d]);
  return ok;
}

}  // namespace

Reject Inbox::offer_state() {
  const StateSample& s = state.back();
  const Reject why = check_state(s);
  if (why != Reject::kNone) {
    state_rejections(counters, why).fetch_add(1, std::memory_order_relaxed);
    return why;
  }
  accept_state(s);
  return Reject::kNone;
}

// Why `s` is refused: its shape or model, a non-finite value, its sample time, or its seq
// against the stream's (a repeat; an older one unless the stream was quiet long enough to
// be a restart). Reject::kNone: it is taken.
Reject Inbox::check_state(const StateSample& s) const {
  if (s.nx != expect_.nx || s.vehicle_count != expect_.vehicles || s.n != s.nx * s.vehicle_count ||
      s.n > kMaxStates || (expect_.model != 0 && s.model != expect_.model))
    return Reject::kShape;
  for (int i = 0; i < s.n; ++i)
    if (!std::isfinite(s.x[i])) return Reject::kNan;
  if (s.sample_utime < 0 || s.sample_utime > kMaxUtime) return Reject::kTime;
  if (!have_last_) return Reject::kNone;
  if (s.seq == last_seq_) return Reject::kDuplicate;
  if (s.seq < last_seq_ && s.recv_ns - last_recv_ns_ < expect_.restart_after_ns) return Reject::kOutOfOrder;
  return Reject::kNone;
}

// `s` becomes the stream's newest and goes to the loop (with its wake-up or tick).
void Inbox::accept_state(const StateSample& s) {
  have_last_ = true;
  if (s.sample_utime > last_sample_utime_.load(std::memory_order_relaxed))
    last_sample_utime_.store(s.sample_utime, std::memory_order_relaxed);
  last_seq_ = s.seq;
  last_recv_ns_ = s.recv_ns;
  state.publish();
  counters.states.fetch_add(1, std::memory_order_relaxed);
  last_state_recv_ns_.store(last_recv_ns_, std::memory_order_release);
  if (expect_.wake_on_state) state_wake.post();
  if (expect_.tick_on_state) {
    ClockTick t;
    t.seq = s.seq;
    t.sim_utime = s.sample_utime;
    offer_tick(t);
  }
}

void Inbox::offer_reference() {
  const ReferenceInput& r = reference.back();
  const bool ok = r.vehicle_count >= 0 && r.vehicle_count <= kMaxVehicles && r.t0_utime >= 0 &&
                  r.t0_utime <= kMaxUtime && finite_reference_scalars(r) && finite_reference_points(r);
  if (!ok) return count_bad_input();
  reference.publish();
}

void Inbox::offer_obstacles() {
  const ObstacleInput& o = obstacles.back();
  bool ok = o.count >= 0 && o.count <= kMaxObstaclesIn;
  for (int i = 0; ok && i < o.count; ++i) {
    const Cylinder& c = o.items[i];
    ok = std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.radius) && c.radius >= 0.0f &&
         std::isfinite(c.vx) && std::isfinite(c.vy);
  }
  if (!ok) return count_bad_input();
  obstacles.publish();
}

// A map replaces the last whole: its grid must be one the cost can read, its seq and utime
// after the last map's (a seq that steps back is a publisher restart after a quiet
// restart_after_ns, as for states), and it must not be older than map_timeout_ns behind the
// newest state. A rejected map leaves the last good one in place.
Reject Inbox::offer_map() {
  if (!map) return Reject::kShape;
  const LocalMapInput& m = map->back();
  auto reject = [](std::atomic<std::int64_t>& c, Reject r) {
    c.fetch_add(1, std::memory_order_relaxed);
    return r;
  };
  if (m.grid.invalid() != nullptr) return reject(counters.maps_rejected_invalid, Reject::kShape);
  if (m.utime < 0 || m.utime > kMaxUtime) return reject(counters.maps_rejected_time, Reject::kTime);
  if (have_map_) {
    const bool restart = m.recv_ns - last_map_recv_ns_ >= expect_.restart_after_ns;
    if (!restart && (m.seq <= last_map_seq_ || m.utime < last_map_utime_))
      return reject(counters.maps_rejected_out_of_order, Reject::kOutOfOrder);
  }
  const std::int64_t newest_state = last_sample_utime_.load(std::memory_order_relaxed);
  if (newest_state >= 0 && (newest_state - m.utime) * 1000 > expect_.map_timeout_ns)
    return reject(counters.maps_rejected_stale, Reject::kTime);
  have_map_ = true;
  last_map_seq_ = m.seq;
  last_map_utime_ = m.utime;
  last_map_recv_ns_ = m.recv_ns;
  map->publish();
  counters.maps.fetch_add(1, std::memory_order_relaxed);
  return Reject::kNone;
}

void Inbox::offer_param(const ParamUpdate& p) {
  if (!params.push(p)) counters.params_dropped.fetch_add(1, std::memory_order_relaxed);
}

void Inbox::offer_tick(const ClockTick& t) {
  if (t.sim_utime < 0 || t.sim_utime > kMaxUtime) {
    counters.ticks_rejected.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (!ticks.push(t)) {
    counters.ticks_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  counters.ticks.fetch_add(1, std::memory_order_relaxed);
  wake.post();
}

}  // namespace mppi::transport
