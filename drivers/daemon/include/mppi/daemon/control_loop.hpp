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
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/command_out.hpp"
#include "mppi/daemon/cycle_outcome.hpp"
#include "mppi/daemon/deadline_guard.hpp"
#include "mppi/daemon/delay_estimator.hpp"
#include "mppi/daemon/disturbance_observer.hpp"
#include "mppi/daemon/identification.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "mppi/daemon/loop_counters.hpp"
#include "mppi/daemon/plan_timeline.hpp"
#include "mppi/daemon/rollout_publisher.hpp"
#include "mppi/daemon/state_predictor.hpp"
#include "mppi/daemon/work_sizer.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/deadline_monitor.hpp"
#include "mppi/rt/latency_estimator.hpp"
#include "mppi/rt/schedule.hpp"
#include "mppi/rt/wakeup.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::daemon {

// Latency compensation: each fresh cycle optimises from the state predicted to the time
// its command will act, t_act = cycle start + expected latency + transport + actuation
// delay, through the commands already sent (they act meanwhile), and the plan is shifted
// by the control steps that really elapsed (skipped cycles, older states).
struct LatencySettings {
  bool compensate = true;
  rt::LatencyEstimatorSettings estimator;   // expected cycle start -> command sent
  std::int64_t transport_ns = 200'000;      // command sent -> the plant has it
  std::int64_t actuation_delay_ns = 0;      // the plant has it -> it acts (ESCs, autopilot)
  // How far the autopilot's position and velocity estimate trails the vehicle (its EKF's
  // delay; the vehicle file's estimate_lag): they are predicted from that much before the
  // sample time, the attitude and rates (the gyro's, current) from the sample time. Quadrotor
  // states only (position, velocity first).
  std::int64_t estimate_lag_ns = 0;
  // The state's age from its sample_utime, stamped on this host's wall clock (the
  // simulator and the MAVLink bridge do); false: from its receipt (a publisher whose clock
  // is not ours; the transport delay is then not seen).
  bool use_sample_time = true;
  std::int64_t future_tolerance_ns = 2'000'000;  // a sample time further ahead is refused
  // The actuation delay estimated in flight (delay_estimator.hpp): replaces actuation_delay_ns.
  DelayEstimateSettings delay_estimate;
};

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
  // One real-time cycle: sleeps until its release (trigger clock) or a state that starts it
  // (trigger state), then runs. False if stopped first.
  bool step_realtime(const std::atomic<bool>& stop);
  // One lock-step cycle per tick. False if no tick arrived before stop.
  bool step_lockstep(const std::atomic<bool>& stop);
  // The final status (healthy = 0), after the last cycle.
  void publish_final_status();

  const LoopCounters& counters() const { return counters_; }
  rt::TimingSummary timing_total() const { return monitor_.total(); }
  rt::TimingSummary timing_window() const { return monitor_.window(); }
  std::int64_t latency_estimate_ns() const { return latency_estimate_ns_.load(std::memory_order_relaxed); }
  // The disturbance observer's estimate (loop thread; tests and the final report).
  const float* disturbance_estimate() const { return observer_.estimate(); }
  std::int64_t skipped_periods() const { return schedule_.skipped_periods(); }
  transport::Mode mode() const { return mode_.load(std::memory_order_relaxed); }
  // For other threads while the loop runs (the histograms are the loop thread's alone).
  struct Snapshot {
    std::int64_t cycles, misses, consecutive_misses;
    double rate_hz;  // measured over the last status window
  };
  Snapshot snapshot() const {
    return {snap_cycles_.load(std::memory_order_relaxed), snap_misses_.load(std::memory_order_relaxed),
            snap_consecutive_.load(std::memory_order_relaxed), snap_rate_.load(std::memory_order_relaxed)};
  }
  // For the watchdog: monotonic time of the last completed cycle, and whether the loop
  // itself is well (cycling, not stuck in misses or optimizer failures).
  std::int64_t heartbeat_ns() const { return heartbeat_ns_.load(std::memory_order_relaxed); }
  bool loop_healthy() const { return loop_healthy_.load(std::memory_order_relaxed); }
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
  void set_expected_latency(std::int64_t ns) { expected_override_ns_ = ns; }
  // Replay: the next cycles' rollout count (command_t.rollouts) instead of the sizer's; <= 0:
  // the sizer's.
  void set_work_size(int rollouts) { work_.pin(rollouts); }
  const WorkSizer& work_sizer() const { return work_; }

 private:
  // What a cycle knows of the newest state, on the loop's timeline (now_state_ns's).
  struct CycleState {
    const transport::StateSample* x = nullptr;
    bool have = false;           // a state has arrived
    bool future = false;         // stamped further ahead than the tolerance
    bool new_sample = false;     // not the one the last fresh cycle optimised from
    std::int64_t seq = -1;
    std::int64_t now_ns = 0;      // the cycle's start
    std::int64_t t_state_ns = 0;  // the sample time
    std::int64_t age_ns = 0;
    std::int64_t t_act_ns = 0;    // when this cycle's command acts
    std::int64_t lead_ns = 0;     // t_act - sample time, with latency compensation; else 0
  };
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

  // The trigger (loop_trigger.cpp).
  bool step_state_triggered(const std::atomic<bool>& stop);
  // The cycle and its paths (control_loop.cpp): the state check's failsafe (starting over on
  // entry), the stale state's hold and the fresh state's update, each saying what the cycle
  // publishes; then the sends, and the bookkeeping after the command.
  void cycle(std::int64_t start_ns, std::int64_t deadline_ns, std::int64_t now_state_ns, bool lockstep);
  Outcome enter_failsafe();
  Outcome hold_stale(const CycleState& s);
  Outcome optimize(const CycleState& s, std::int64_t deadline_ns, bool lockstep);
  bool run_optimizer(const float* x0);
  void take_back_from_guard(int steps, bool good, std::int64_t deadline_ns);
  transport::Mode send_failsafe(const CycleState& s, std::int64_t t0);
  transport::Mode send_held(const CycleState& s, std::int64_t t0);
  transport::Mode send_fresh(const CycleState& s, std::int64_t t0, bool lockstep);
  bool publish(transport::Mode mode, const float* u, std::int64_t state_seq);
  bool publish_failsafe(std::int64_t state_seq);
  // Timing fields of the next command the loop sends (command_t age_us, compute_us, lead_us).
  void stamp_timing(std::int64_t age_ns, std::int64_t compute_ns, std::int64_t lead_ns);
  // The cycle's elapsed time on the loop's timeline when a command leaves.
  std::int64_t sent_ns(std::int64_t now_state_ns, std::int64_t t0) { return now_state_ns + (clock_->now_ns() - t0); }
  void remember(std::int64_t sent_ns, const float* u);
  void account(const CycleState& s, std::int64_t start_ns, std::int64_t t0, transport::Mode published, bool lockstep);
  void apply_between_cycles();

  // The act-time prediction (act_time.cpp): the newest state on the loop's timeline and
  // when this cycle's command acts; the state predicted to then.
  CycleState read_state(std::int64_t now_state_ns, bool lockstep) const;
  // The state's sample time on the loop's timeline, and whether it lies further in the
  // future than the tolerance.
  std::int64_t state_time_ns(const transport::StateSample& x, bool lockstep, bool* future) const;
  const float* predict_to_act(const CycleState& s);
  void catch_up_estimate(std::int64_t t_state_ns);

  // The adaptation (adaptation.cpp): what a new state teaches the loop (the external
  // acceleration and the mass through the disturbance observer, the actuation delay).
  void adapt_to(const float* x, std::int64_t t_state_ns);
  void forget_estimates();   // on failsafe and on restart_estimates
  void restart_estimates();  // daemon.restart_estimates

  // The task inputs (task_inputs.cpp): reference, goals and the nearest obstacles.
  void update_inputs(const transport::StateSample& x, bool reference_changed, bool obstacles_changed, bool map_changed);
  void note_map_age();
  void hold_where_the_state_is(const transport::StateSample& x);
  void select_obstacles(const transport::StateSample& x);

  // The status publishing (loop_status.cpp): mode changes, status, the display plan.
  void set_mode(transport::Mode m);
  void maybe_status(bool force);
  void maybe_plan(std::int64_t state_seq, const float* x0);

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
  int nu_;
  std::int64_t period_ns_;
  std::int64_t status_every_;
  std::int64_t plan_every_;
  RolloutPublisher rollouts_;
  LoopCounters counters_;

  rt::PeriodicSchedule schedule_;
  rt::DeadlineMonitor monitor_;
  CommandOut out_;  // the gate, the sequence and the transport: shared with the guard
  bool started_ = false;

  TaskInputs inputs_;
  transport::ObstacleInput obstacles_all_;  // last full set, nearest kept in inputs_
  std::vector<int> obstacle_order_;
  std::vector<float> distances_;
  std::int64_t reference_t0_utime_ = 0;
  bool have_reference_ = false;
  bool holding_ = false;  // goals set from the first state (no goal or reference yet)
  bool have_obstacles_ = false;
  bool have_map_ = false;           // inputs_.field points at the inbox's front map
  std::uint64_t map_stamp_ = 0;     // +1 per map taken (the CUDA backend's copy follows it)
  std::int64_t map_utime_ = 0;      // the map in use

  PlanTimeline plan_;           // the held plan, the warm start and when their step 0 acts
  std::vector<float> u_;        // this cycle's command
  std::vector<float> failsafe_;
  transport::Command cmd_;
  transport::StatusReport status_;
  UpdateStats last_stats_;
  std::int64_t last_state_seq_used_ = -1;
  std::int64_t cycle_index_ = 0;
  std::vector<float> plan_pos_ = std::vector<float>(3 * transport::kMaxPlanPositions);  // predicted path, xyz
  int consecutive_bad_updates_ = 0;
  std::int64_t last_tick_seq_ = -1;
  std::int64_t trigger_recv_ns_ = INT64_MIN;  // recv_ns of the state that started the last cycle
  bool grace_started_ = false;                // trigger state: the last cycle started without a state

  // Latency compensation (loop thread only).
  rt::LatencyEstimator latency_;
  CommandHistory history_;
  std::vector<float> x_pred_;
  std::vector<float> x_lag_;  // the estimate's position and velocity caught up (estimate_lag_ns)
  DisturbanceObserver observer_;
  DelayEstimator delays_;
  std::int64_t configured_delay_ns_ = 0;  // the settings' actuation delay (restart_estimates)
  IdentificationManoeuvre manoeuvre_;
  bool observe_ = false;  // the model takes an external acceleration and estimation is on
  std::atomic<std::int64_t> latency_estimate_ns_{0};

  rt::MonotonicClock own_guard_clock_;  // the guard's clock unless one is given
  std::unique_ptr<DeadlineGuard> guard_;  // real time with deadline_guard on; else null

  std::atomic<transport::Mode> mode_{transport::Mode::kFailsafe};
  transport::Mode last_status_mode_ = transport::Mode::kFailsafe;
  std::atomic<std::int64_t> heartbeat_ns_{0};
  std::atomic<bool> loop_healthy_{true};
  std::atomic<std::int64_t> snap_cycles_{0}, snap_misses_{0}, snap_consecutive_{0};
  std::atomic<double> snap_rate_{0.0};

  LiveOptimizer* live_ = nullptr;
  std::int64_t expected_override_ns_ = -1;
  WorkSizer work_;  // the rollout count (loop thread)
};

}  // namespace mppi::daemon
