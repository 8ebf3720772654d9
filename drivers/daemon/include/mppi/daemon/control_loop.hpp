// The runner: one fixed-rate (or lock-step) control cycle after another around a
// type-erased mppi::Controller. Per cycle: apply what arrived between cycles (parameters,
// reference, obstacles), take the newest valid state, run one MPPI iteration, gate and
// publish the command, then the status (at its own rate) and the display plan.
//
// Every failure publishes something safe instead of something wrong: a missed deadline,
// a non-finite optimizer output or an optimizer error publishes the shifted previous
// plan (MODE_HOLD_PLAN); a stale state holds the plan, and a state older than the second
// timeout publishes the failsafe command (MODE_FAILSAFE). Nothing that fails the command
// gate (finite, inside limits) ever leaves the process.
//
// The loop orchestrates collaborators that each own their state: Pacing (what starts a
// cycle, real time or lock-step), ActTime (latency compensation: when the command acts, the
// command history, the state predicted to then), Estimators (disturbance, mass, actuation
// delay), IdentificationManoeuvre, TaskInputFeed (reference, goals, obstacles, the map),
// PlanTimeline (the held plan and the warm start), LoopOutputs (commands, mode, status,
// displays, the snapshot for other threads) and the DeadlineGuard. Another collaborator is one
// more member, called from the step of the cycle it belongs to (README: "A cycle").
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/act_time.hpp"
#include "mppi/daemon/adaptation.hpp"
#include "mppi/daemon/cycle_outcome.hpp"
#include "mppi/daemon/deadline_guard.hpp"
#include "mppi/daemon/disturbance_observer.hpp"
#include "mppi/daemon/identification.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "mppi/daemon/param_schedule.hpp"
#include "mppi/daemon/loop_counters.hpp"
#include "mppi/daemon/loop_outputs.hpp"
#include "mppi/daemon/pacing.hpp"
#include "mppi/daemon/plan_timeline.hpp"
#include "mppi/daemon/task_inputs.hpp"
#include "mppi/daemon/work_sizer.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/deadline_monitor.hpp"
#include "mppi/rt/wakeup.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::daemon {

// Real time: what starts a cycle.
//   kClock  the fixed-rate grid at rate_hz; a state waits up to a period for its cycle.
//   kState  each state received at least min_gap periods after the last cycle's start
//           starts one at once (so at most rate_hz / min_gap cycles a second, and state-in
//           -> command-out is the cycle's own time); with no such state, a cycle starts
//           `grace` periods after its grid time, and the next state then starts one at once
//           (a state stream slower than rate_hz is followed state by state); with no states
//           at all, cycles on the grid take the stale path (hold, then failsafe).
//           The inbox must post state_wake (Inbox::Expect::wake_on_state).
enum class Trigger { kClock, kState };

struct LoopSettings {
  double rate_hz = 50.0;
  Trigger trigger = Trigger::kClock;
  double state_trigger_min_gap = 0.75;  // periods
  double state_trigger_grace = 0.5;     // periods
  std::int64_t state_timeout_ns = 100 * rt::kNsPerMs;
  std::int64_t failsafe_timeout_ns = 500 * rt::kNsPerMs;
  double status_hz = 1.0;
  double plan_hz = 5.0;
  bool lockstep = false;
  std::int64_t lockstep_poll_ns = 10 * rt::kNsPerMs;  // how often a lock-step wait checks stop
  int watchdog_max_consecutive_misses = 5;  // the loop stops feeding the watchdog past this
  int watchdog_max_optimizer_errors = 5;    // ... or past this many consecutive bad updates
  std::int8_t command_kind = -1;            // command_t::KIND_*; -1 = from the task name
  std::vector<float> failsafe_u;            // per control channel; empty = u_init
  // Deadline guard (real time only): a second thread that, when the optimizer is still
  // running at the deadline, publishes the held plan's next step at that deadline and at
  // every period after it until the optimizer returns, so commands keep their rate
  // through a stall. It always sleeps on CLOCK_MONOTONIC (off with a fake clock).
  bool deadline_guard = false;
  int guard_fifo_priority = 0;  // SCHED_FIFO priority of the guard thread; 0 = inherit
  LatencySettings latency;
  DisturbanceSettings disturbance;
  IdentificationSettings identification;  // the manoeuvre `daemon.identify` starts (rate tasks)
  // Anytime cycle (with the deadline guard): this long before the deadline the guard asks
  // the optimizer to stop its rollouts (Controller::set_stop_flag), which then updates from
  // the rollouts done, or, below mppi.min_rollouts, sends the held plan; the command goes
  // out on time. 0: off.
  std::int64_t anytime_margin_ns = 0;
  // A display sample of the rollouts on their own channel (tools/view); off by default.
  FanSettings rollouts;
  // The local map (local_map_t, forest tasks; the inbox takes it): a map older than this behind
  // the newest state is stale. Arriving, it is refused; in use (no newer one came), the cost
  // keeps it and its cycles are counted (map_stale_cycles): the trees it holds are still
  // there, while a map dropped would leave the cost blind to them (docs/sensing.md).
  std::int64_t map_timeout_ns = 500 * rt::kNsPerMs;
  // The rollout count sized to the computer (work_sizer.hpp); off: mppi.rollouts, pinned.
  WorkSizerSettings work;
};

class ControlLoop {
 public:
  // clock: CLOCK_MONOTONIC in service, a fake in tests. In lock-step the schedule comes
  // from the inbox's ticks and `clock` only measures compute time. guard_clock: the deadline
  // guard's (its thread sleeps on it); null: a CLOCK_MONOTONIC of its own. A test gives both
  // one fake clock that threads can share.
  ControlLoop(Controller* controller, rt::Clock* clock, transport::Transport* transport,
              transport::Inbox* inbox, LoopSettings settings, rt::Clock* guard_clock = nullptr);
  ~ControlLoop();
  ControlLoop(const ControlLoop&) = delete;
  ControlLoop& operator=(const ControlLoop&) = delete;

  // Runs until stop is set (or max_cycles cycles, if >= 0). Real-time or lock-step.
  void run(const std::atomic<bool>& stop, std::int64_t max_cycles = -1);
  // Starts the deadline guard thread (if enabled) without starting the schedule: call it
  // before reporting ready, so no thread (and no locked stack) appears later.
  void prepare();
  // Fixes the first release (real time) at clock now; run() calls it if not done.
  void start();
  // One cycle, when the pacing starts it: real time, at its release (trigger clock) or on a
  // state (trigger state); lock-step, on a tick. False if stopped first (or, lock-step, the
  // tick was answered already).
  bool step(const std::atomic<bool>& stop);
  bool step_realtime(const std::atomic<bool>& stop) { return step(stop); }
  bool step_lockstep(const std::atomic<bool>& stop) { return step(stop); }
  // The final status (healthy = 0), after the last cycle.
  void publish_final_status();

  const LoopCounters& counters() const { return counters_; }
  rt::TimingSummary timing_total() const { return monitor_.total(); }
  rt::TimingSummary timing_window() const { return monitor_.window(); }
  std::int64_t latency_estimate_ns() const { return act_.published_estimate_ns(); }
  // The disturbance observer's estimate (loop thread; tests and the final report).
  const float* disturbance_estimate() const { return estimators_.disturbance(); }
  std::int64_t skipped_periods() const { return pacing_->skipped_periods(); }
  transport::Mode mode() const { return outputs_.mode(); }
  // For other threads while the loop runs (the histograms are the loop thread's alone).
  struct Snapshot {
    std::int64_t cycles, misses, consecutive_misses;
    double rate_hz;  // measured over the last status window
  };
  Snapshot snapshot() const {
    return {outputs_.snap_cycles(), outputs_.snap_misses(), outputs_.snap_consecutive(), outputs_.snap_rate()};
  }
  // For the watchdog: monotonic time of the last completed cycle, and whether the loop
  // itself is well (cycling, not stuck in misses or optimizer failures).
  std::int64_t heartbeat_ns() const { return outputs_.heartbeat_ns(); }
  bool loop_healthy() const { return outputs_.loop_healthy(); }
  const LoopSettings& settings() const { return s_; }

  // Live optimizer updates (control_loop_live.cpp): with `live` set (before the first
  // cycle; its current() must be the loop's controller), mppi.* updates go to its builder
  // and the controller it builds is swapped in between two cycles. Null: mppi.* refused.
  void set_live_optimizer(LiveOptimizer* live) { live_ = live; }
  // The controller in service (it changes with a live update; loop thread).
  Controller& controller() const { return *c_; }
  // The index of the next cycle (0 = the first): param_result_t's cycle.
  std::int64_t cycle_index() const { return cycle_index_; }
  // Replay: the next cycles' expected latency (ns) instead of the estimator's; < 0: the
  // estimator's.
  void set_expected_latency(std::int64_t ns) { act_.set_expected_latency(ns); }
  // Replay: the next cycles' rollout count (command_t.rollouts) instead of the sizer's; <= 0:
  // the sizer's.
  void set_work_size(int rollouts) { work_.pin(rollouts); }
  const WorkSizer& work_sizer() const { return work_; }

 private:
  // One row of the parameter table (loop_params.cpp): the key (a prefix when it ends in
  // '.'; "" matches every key), whether a live optimizer's builder takes it instead, the
  // check (nullptr: none) and the change (nullptr: none); each returns "" or "key: why".
  struct ParamRoute {
    const char* key;
    bool live;
    std::string (ControlLoop::*validate)(const std::string& key, double v) const;
    std::string (ControlLoop::*apply)(const std::string& key, double v);
  };
  static const ParamRoute& route_for(const char* key);

  // The cycle and its paths (control_loop.cpp): decide (the state check's failsafe, starting
  // over on entry; the stale state's hold; the fresh state's update), each saying what the
  // cycle publishes; then the sends, the plan settled on the outcome (PlanTimeline), and the
  // bookkeeping after the command.
  void cycle(const CycleTimes& t);
  Outcome decide(const CycleState& s, std::int64_t deadline_ns);
  transport::Mode send(Outcome outcome, const CycleState& s, std::int64_t t0);
  Outcome enter_failsafe();
  Outcome hold_stale(const CycleState& s);
  Outcome optimize(const CycleState& s, std::int64_t deadline_ns);
  bool run_optimizer(const float* x0);
  void take_back_from_guard(int steps, bool good, std::int64_t deadline_ns);
  transport::Mode send_failsafe(const CycleState& s, std::int64_t t0);
  transport::Mode send_held(const CycleState& s, std::int64_t t0);
  transport::Mode send_fresh(const CycleState& s, std::int64_t t0);
  // The cycle's elapsed time on the loop's timeline when a command leaves.
  std::int64_t sent_ns(std::int64_t now_state_ns, std::int64_t t0) { return now_state_ns + (clock_->now_ns() - t0); }
  void account(const CycleState& s, std::int64_t start_ns, std::int64_t t0, transport::Mode published);
  void apply_between_cycles();
  void apply_due_params();

  // The state predicted to when this cycle's command acts (ActTime), after what it teaches
  // (Estimators).
  const float* predict_to_act(const CycleState& s);
  void adapt_to(const CycleState& s);
  void forget_estimates();   // on failsafe and on restart_estimates
  void restart_estimates();  // daemon.restart_estimates

  // The status, when due (LoopOutputs), from the loop's owners.
  void maybe_status(bool force);

  // Parameters (loop_params.cpp): the table's checks and changes.
  std::string apply_param(const transport::ParamUpdate& p);
  std::string check_state_timeout(const std::string& key, double v) const;
  std::string check_failsafe_timeout(const std::string& key, double v) const;
  std::string check_identify(const std::string& key, double v) const;
  std::string refuse_daemon_key(const std::string& key, double v) const;
  std::string refuse_optimizer_key(const std::string& key, double v) const;
  std::string set_state_timeout(const std::string& key, double v);
  std::string set_failsafe_timeout(const std::string& key, double v);
  std::string set_identify(const std::string& key, double v);
  std::string set_restart_estimates(const std::string& key, double v);
  std::string set_task_param(const std::string& key, double v);
  // Live updates (control_loop_live.cpp): the answer to one update on the reply channel;
  // forward an mppi.* update to the builder (true when taken); answer the builder's
  // refusals and swap in a controller it built.
  void answer_param(const transport::ParamUpdate& p, bool applied, const std::string& why);
  bool forward_live_param(const transport::ParamUpdate& p);
  void service_live();
  void swap_in(OptimizerBundle* b);

  Controller* c_;
  rt::Clock* clock_;
  transport::Transport* tx_;
  transport::Inbox* in_;
  LoopSettings s_;
  std::int64_t period_ns_;
  LoopCounters counters_;

  rt::DeadlineMonitor monitor_;
  std::unique_ptr<Pacing> pacing_;  // real time or lock-step: what starts a cycle, the timeline
  LoopOutputs outputs_;  // commands (CommandOut, shared with the guard), mode, status, displays, snapshot

  TaskInputFeed feed_;  // reference, goals, the nearest obstacles, the local map

  PlanTimeline plan_;           // the held plan, the warm start and when their step 0 acts
  std::vector<float> u_;        // this cycle's command
  std::int64_t last_state_seq_used_ = -1;
  std::int64_t cycle_index_ = 0;
  int consecutive_bad_updates_ = 0;

  ActTime act_;              // latency compensation: the latency estimate, the command history
  Estimators estimators_;    // the disturbance, mass and actuation delay estimates
  IdentificationManoeuvre manoeuvre_;

  rt::MonotonicClock own_guard_clock_;  // the guard's clock unless one is given
  std::unique_ptr<DeadlineGuard> guard_;  // real time with deadline_guard on; else null

  LiveOptimizer* live_ = nullptr;
  ParamSchedule params_;  // updates held until the state time they name
  WorkSizer work_;        // the rollout count (loop thread)
};

}  // namespace mppi::daemon
