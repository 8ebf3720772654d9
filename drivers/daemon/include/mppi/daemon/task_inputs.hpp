// The task's inputs from what arrived between cycles: the reference and the goals (held
// where the first state put the vehicles until one comes), the obstacles nearest the
// vehicles, the local map and its age. TaskInputFeed owns them and hands them to the
// controller (Controller::set_inputs). Loop thread only; allocates nothing after
// construction (the cost reads the inbox's front map in place).
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/loop_counters.hpp"
#include "mppi/transport/inbox.hpp"

namespace mppi::daemon {

class TaskInputFeed {
 public:
  // What changed between two cycles (the inbox's slots whose front is new).
  struct Changed {
    bool reference = false, obstacles = false, map = false;
  };

  // `vehicles` of the task; a map older than map_timeout_ns behind the newest state is stale.
  TaskInputFeed(int vehicles, std::int64_t map_timeout_ns);

  // The inbox's new fronts (and the newest state) into the controller's inputs.
  void update(const transport::Inbox& in, Controller& c, LoopCounters& counters, Changed changed);
  // The age of the map in use against the newest state's sample time; past map_timeout_ns the
  // cost keeps the map and the cycle counts as flown with a stale one.
  void note_map_age(const transport::Inbox& in, LoopCounters& counters) const;
  // Latency compensation: a moving reference is compared with the state predicted lead_ns
  // past x's sample time, so it is taken at that time.
  void reference_at_lead(Controller& c, const transport::StateSample& x, std::int64_t lead_ns);

 private:
  void take_reference(const transport::ReferenceInput& r);
  void take_obstacles(const transport::ObstacleInput& o);
  void take_map(const transport::LocalMapInput& m);
  void hold_where_the_state_is(const transport::StateSample& x, Controller& c, LoopCounters& counters);
  void select_obstacles(const transport::StateSample& x, bool have_state);

  TaskInputs inputs_;
  std::int64_t map_timeout_ns_;
  transport::ObstacleInput obstacles_all_;  // last full set, nearest kept in inputs_
  std::vector<int> obstacle_order_;
  std::vector<float> distances_;
  std::int64_t reference_t0_utime_ = 0;
  bool have_reference_ = false;
  bool holding_ = false;  // goals set from the first state (no goal or reference yet)
  bool have_obstacles_ = false;
  bool have_map_ = false;        // inputs_.field points at the inbox's front map
  std::uint64_t map_stamp_ = 0;  // +1 per map taken (the CUDA backend's copy follows it)
  std::int64_t map_utime_ = 0;   // the map in use
};

}  // namespace mppi::daemon
