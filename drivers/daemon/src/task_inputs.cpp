// ControlLoop: the task's inputs from what arrived between cycles: the reference and the
// goals, the hold in place before any, the obstacles nearest the vehicles and the local map.
#include <algorithm>
#include <cmath>

#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

void ControlLoop::update_inputs(const transport::StateSample& x, bool reference_changed, bool obstacles_changed,
                                bool map_changed) {
  if (reference_changed) {
    const transport::ReferenceInput& r = in_->reference.front();
    Reference& ref = inputs_.reference;
    ref.kind = (r.kind == 1)   ? Reference::kCircle
               : (r.kind == 2) ? Reference::kFigureEight
               : (r.kind == 4 && r.vehicle_count > 0) ? Reference::kLine  // to goals[0]
                                                      : Reference::kHold;
    std::copy_n(r.center, 3, ref.center);
    std::copy_n(r.vehicle_count > 0 ? r.goals[0] : r.center, 3, ref.end);
    ref.radius = r.radius;
    ref.speed = r.speed;
    ref.yaw = r.yaw;
    ref.ramp = r.ramp_s;
    ref.phase = r.phase;
    ref.end_s = r.end_s;
    reference_t0_utime_ = r.t0_utime;
    have_reference_ = true;
    const int n = std::min<int>(r.vehicle_count, inputs_.vehicle_count);
    for (int v = 0; v < n; ++v) std::copy_n(r.goals[v], 3, inputs_.goals[v]);
    // KIND_HOLD/KIND_WAYPOINT with no goals: hover at the centre.
    if (n == 0)
      for (int v = 0; v < inputs_.vehicle_count; ++v) std::copy_n(r.center, 3, inputs_.goals[v]);
  }
  if (obstacles_changed) {
    const transport::ObstacleInput& o = in_->obstacles.front();
    obstacles_all_.count = o.count;
    obstacles_all_.seq = o.seq;
    std::copy_n(o.items, o.count, obstacles_all_.items);
    have_obstacles_ = true;
  }
  if (map_changed) {
    // The cost reads the inbox's front map in place: it stays put until the next update()
    // of the slot, here, between cycles (no copy of its cells; a new stamp for the GPU's).
    const transport::LocalMapInput& m = in_->map->front();
    inputs_.field = m.grid.view(++map_stamp_);
    map_utime_ = m.utime;
    have_map_ = true;
  }
  if (!have_reference_ && !holding_ && in_->state.writes() > 0) hold_where_the_state_is(x);
  if (have_obstacles_) select_obstacles(x);
  if (have_reference_ && in_->state.writes() > 0)
    inputs_.reference_time = static_cast<float>(static_cast<double>(x.sample_utime - reference_t0_utime_) * 1e-6);
  if (have_reference_ || have_obstacles_ || holding_ || have_map_) c_->set_inputs(inputs_);
}

// The age of the map in use against the newest state's sample time; past map_timeout_ns the
// cost keeps the map and the cycle counts as flown with a stale one.
void ControlLoop::note_map_age() {
  if (!have_map_ || in_->state.writes() == 0) return;
  const std::int64_t age_us = in_->state.front().sample_utime - map_utime_;
  counters_.map_age_us.store(age_us, std::memory_order_relaxed);
  if (age_us * 1000 > s_.map_timeout_ns) counters_.map_stale_cycles.fetch_add(1, std::memory_order_relaxed);
}

// Before the first goal or reference: every vehicle's goal (and a tracking task's held
// point) is where the first state put it, so the loop hovers in place until one arrives.
// The task's own default is the origin, which a vehicle 2 m up would dive to: a real-time
// team flight on a loaded host whose first goal message came ~1 s late did exactly that.
void ControlLoop::hold_where_the_state_is(const transport::StateSample& x) {
  float xyz[3 * TaskInputs::kMaxVehicles];
  if (c_->positions(x.x, xyz, TaskInputs::kMaxVehicles) != inputs_.vehicle_count) return;
  for (int v = 0; v < inputs_.vehicle_count; ++v) std::copy_n(xyz + 3 * v, 3, inputs_.goals[v]);
  inputs_.reference.kind = Reference::kHold;
  std::copy_n(xyz, 3, inputs_.reference.center);
  holding_ = true;
  counters_.holds_without_goal.fetch_add(1, std::memory_order_relaxed);
}

// Keep the kCapacity cylinders nearest to any vehicle (surface distance), in place.
void ControlLoop::select_obstacles(const transport::StateSample& x) {
  const int n = obstacles_all_.count;
  ObstacleSet& out = inputs_.obstacles;
  if (n <= ObstacleSet::kCapacity) {
    out.count = n;
    std::copy_n(obstacles_all_.items, n, out.items);
    return;
  }
  const int vehicles = in_->state.writes() > 0 ? std::max<int>(1, x.vehicle_count) : 0;
  for (int i = 0; i < n; ++i) {
    const Cylinder& c = obstacles_all_.items[i];
    float best = 0.0f;
    for (int v = 0; v < vehicles; ++v) {
      const float dx = c.x - x.x[v * x.nx + 0], dy = c.y - x.x[v * x.nx + 1];
      const float d = std::sqrt(dx * dx + dy * dy) - c.radius;
      best = v == 0 ? d : std::min(best, d);
    }
    distances_[static_cast<std::size_t>(i)] = best;
    obstacle_order_[static_cast<std::size_t>(i)] = i;
  }
  auto first = obstacle_order_.begin();
  std::nth_element(first, first + ObstacleSet::kCapacity - 1, first + n, [this](int a, int b) {
    return distances_[static_cast<std::size_t>(a)] < distances_[static_cast<std::size_t>(b)];
  });
  out.count = ObstacleSet::kCapacity;
  for (int i = 0; i < ObstacleSet::kCapacity; ++i) out.items[i] = obstacles_all_.items[obstacle_order_[static_cast<std::size_t>(i)]];
}

}  // namespace mppi::daemon
