// TaskInputFeed: the task's inputs from what arrived between cycles: the reference and the
// goals, the hold in place before any, the obstacles nearest the vehicles and the local map.
#include "mppi/daemon/task_inputs.hpp"

#include <algorithm>
#include <cmath>

namespace mppi::daemon {

TaskInputFeed::TaskInputFeed(int vehicles, std::int64_t map_timeout_ns)
    : map_timeout_ns_(map_timeout_ns),
      obstacle_order_(transport::kMaxObstaclesIn),
      distances_(transport::kMaxObstaclesIn) {
  inputs_.vehicle_count = vehicles;
}

void TaskInputFeed::update(const transport::Inbox& in, Controller& c, LoopCounters& counters, Changed changed) {
  const transport::StateSample& x = in.state.front();
  const bool have_state = in.state.writes() > 0;
  if (changed.reference) take_reference(in.reference.front());
  if (changed.obstacles) take_obstacles(in.obstacles.front());
  if (changed.map) take_map(in.map->front());
  if (!have_reference_ && !holding_ && have_state) hold_where_the_state_is(x, c, counters);
  if (have_obstacles_) select_obstacles(x, have_state);
  if (have_reference_ && have_state)
    inputs_.reference_time = static_cast<float>(static_cast<double>(x.sample_utime - reference_t0_utime_) * 1e-6);
  if (have_reference_ || have_obstacles_ || holding_ || have_map_) c.set_inputs(inputs_);
}

void TaskInputFeed::take_reference(const transport::ReferenceInput& r) {
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

void TaskInputFeed::take_obstacles(const transport::ObstacleInput& o) {
  obstacles_all_.count = o.count;
  obstacles_all_.seq = o.seq;
  std::copy_n(o.items, o.count, obstacles_all_.items);
  have_obstacles_ = true;
}

// The cost reads the inbox's front map in place: it stays put until the next update() of the
// slot, between cycles (no copy of its cells; a new stamp for the GPU's).
void TaskInputFeed::take_map(const transport::LocalMapInput& m) {
  inputs_.field = m.grid.view(++map_stamp_);
  map_utime_ = m.utime;
  have_map_ = true;
}

void TaskInputFeed::note_map_age(const transport::Inbox& in, LoopCounters& counters) const {
  if (!have_map_ || in.state.writes() == 0) return;
  const std::int64_t age_us = in.state.front().sample_utime - map_utime_;
  counters.map_age_us.store(age_us, std::memory_order_relaxed);
  if (age_us * 1000 > map_timeout_ns_) counters.map_stale_cycles.fetch_add(1, std::memory_order_relaxed);
}

void TaskInputFeed::reference_at_lead(Controller& c, const transport::StateSample& x, std::int64_t lead_ns) {
  if (!have_reference_ || inputs_.reference.kind == Reference::kHold) return;
  inputs_.reference_time = static_cast<float>(static_cast<double>(x.sample_utime - reference_t0_utime_) * 1e-6 +
                                              static_cast<double>(lead_ns) * 1e-9);
  c.set_inputs(inputs_);
}

// Before the first goal or reference: every vehicle's goal (and a tracking task's held
// point) is where the first state put it, so the loop hovers in place until one arrives.
// The task's own default is the origin, which a vehicle 2 m up would dive to: a real-time
// team flight on a loaded host whose first goal message came ~1 s late did exactly that.
void TaskInputFeed::hold_where_the_state_is(const transport::StateSample& x, Controller& c, LoopCounters& counters) {
  float xyz[3 * TaskInputs::kMaxVehicles];
  if (c.positions(x.x, xyz, TaskInputs::kMaxVehicles) != inputs_.vehicle_count) return;
  for (int v = 0; v < inputs_.vehicle_count; ++v) std::copy_n(xyz + 3 * v, 3, inputs_.goals[v]);
  inputs_.reference.kind = Reference::kHold;
  std::copy_n(xyz, 3, inputs_.reference.center);
  holding_ = true;
  counters.holds_without_goal.fetch_add(1, std::memory_order_relaxed);
}

// Keep the kCapacity cylinders nearest to any vehicle (surface distance), in place.
void TaskInputFeed::select_obstacles(const transport::StateSample& x, bool have_state) {
  const int n = obstacles_all_.count;
  ObstacleSet& out = inputs_.obstacles;
  if (n <= ObstacleSet::kCapacity) {
    out.count = n;
    std::copy_n(obstacles_all_.items, n, out.items);
    return;
  }
  const int vehicles = have_state ? std::max<int>(1, x.vehicle_count) : 0;
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
