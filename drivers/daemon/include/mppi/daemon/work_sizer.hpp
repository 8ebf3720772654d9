// The work of a cycle sized to the computer: the rollout count the optimizer runs
// (Controller::set_active_rollouts), between a floor and mppi.rollouts (the ceiling), from the
// compute time of the cycles that ran it, measured on the loop's clock.
//
// A window of `window` fresh cycles is judged by its 99th percentile against the period: above
// `target` of the period, the count shrinks (x shrink) as soon as the window's p99 is certain
// to be above it (a window of 50 cycles: at its first cycle over the target, so a slow machine
// is answered within a cycle, not a window); below `grow_below` for a whole window, it grows
// (x grow). Between the two it holds: the band is the hysteresis, and the settings are refused
// unless grow_below x grow < target (the grown count's compute then stays under the target, if
// compute is proportional to the count), so a steady load never moves it back and forth. Each
// change starts a new window, logged (spdlog) and counted (controller_status_t). Counts are
// multiples of the backend's quantum (Controller::rollout_quantum) inside [floor, ceiling]; a
// controller without rollouts (quantum 0: DDP) is left alone.
//
// The noise of sample k is the same at any count and the plan goes on, so a change costs the
// update nothing but its rollouts. Replay pins the recorded count instead of deciding (pin).
// Nothing allocates after construction.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"

namespace mppi::daemon {

struct WorkSizerSettings {
  bool enabled = false;      // the daemon's default is on (daemon.work.enabled)
  double target = 0.6;       // a window's p99 compute above this fraction of the period: shrink
  double grow_below = 0.35;  // a whole window's p99 below this fraction: grow
  int floor = 512;           // the fewest rollouts (mppi.rollouts when that is fewer)
  int window = 50;           // fresh cycles a decision looks at
  double shrink = 0.5;       // the count's factor down
  double grow = 1.25;        // the count's factor up
};

// Read from daemon.work through the daemon's settings table (daemon_settings.hpp).

class WorkSizer {
 public:
  WorkSizer(const WorkSizerSettings& s, std::int64_t period_ns);

  // Before an update: the controller runs the count decided (or pinned), which starts at its
  // mppi.rollouts and follows it when that changes (a live update). Sets it only when it differs.
  void before_update(Controller& c);
  // After the update: its compute time (the loop's clock). May decide the next count.
  void after_update(std::int64_t compute_ns);
  // Replay: run this many rollouts from the next update on, deciding nothing; <= 0: decide.
  void pin(int rollouts) { pinned_ = rollouts; }

  // The count decided (before the first update: 0), the changes since start.
  int rollouts() const { return size_; }
  std::int64_t changes() const { return changes_; }
  const WorkSizerSettings& settings() const { return s_; }

 private:
  void follow_ceiling(int ceiling, int quantum);
  void decide(bool over_target);
  void change_to(int n, const char* why, std::int64_t p99_ns, std::int64_t bound_ns);
  std::int64_t window_p99();
  int floor() const;

  WorkSizerSettings s_;
  std::int64_t target_ns_, grow_ns_;
  int over_limit_;                   // samples over a bound that put the window's p99 over it
  std::vector<std::int64_t> window_, scratch_;
  int filled_ = 0, over_ = 0, high_ = 0;  // this window: samples, over the target, >= grow bound
  int ceiling_ = 0, size_ = 0, pinned_ = 0;
  int quantum_ = 0;  // the controller's (0: it has no rollouts to size)
  std::int64_t changes_ = 0;
};

}  // namespace mppi::daemon
