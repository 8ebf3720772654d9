// Everything the loop sends and shows besides its decisions: the command (the gate, the
// message, the failsafe command; CommandOut is shared with the deadline guard), the mode and
// its changes, the status at its rate (and on each mode change), the display plan, the
// rollouts' display sample, and the snapshot other threads read (heartbeat, health, cycle
// counts: relaxed atomics). The loop thread writes; allocates nothing after construction.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "mppi/backend.hpp"
#include "mppi/controller.hpp"
#include "mppi/daemon/command_out.hpp"
#include "mppi/daemon/loop_counters.hpp"
#include "mppi/daemon/rollout_publisher.hpp"
#include "mppi/held_plan.hpp"
#include "mppi/rt/deadline_monitor.hpp"
#include "mppi/transport/inbox.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::daemon {

struct OutputSettings {
  double rate_hz = 50.0;
  double status_hz = 1.0;
  double plan_hz = 5.0;
  std::int8_t command_kind = 0;  // command_t::KIND_*
  std::vector<float> failsafe_u;  // per control channel
  FanSettings rollouts;
};

// What the status reports of the loop's other owners.
struct StatusSources {
  const rt::TimingSummary& window;
  std::int64_t latency_expected_ns;
  const float* disturbance;  // 3
  float model_mass;
  std::int64_t actuation_delay_ns;
  const UpdateStats& stats;
  const transport::InboxCounters& inbox;
  int rollouts_active;             // the work sizer's count
  std::int64_t work_size_changes;  // and how often it changed
};

class LoopOutputs {
 public:
  LoopOutputs(transport::Transport* tx, LoopCounters* counters, const Controller& c, OutputSettings s);

  // ---- commands
  bool passes(const float* u) const { return out_.passes(u); }
  // Timing fields of the next command (command_t age_us, compute_us, lead_us).
  // The next command's timing fields, and the rollout count its update ran (or will run).
  void stamp_timing(std::int64_t age_ns, std::int64_t compute_ns, std::int64_t lead_ns, int rollouts);
  // u through the gate and out; false (nothing sent) when it fails the gate.
  bool publish(transport::Mode mode, const float* u, std::int64_t state_seq);
  // The failsafe command; false (counted as blocked) when even it fails the gate.
  bool publish_failsafe(std::int64_t state_seq);
  // The last command again, if one went out (a lock-step answer lost on the way).
  void resend_last();
  const std::vector<float>& failsafe() const { return failsafe_; }
  CommandOut* command_out() { return &out_; }
  int nu() const { return out_.nu(); }
  std::int8_t kind() const { return out_.kind(); }

  // ---- mode, status, display
  void set_mode(transport::Mode m);
  transport::Mode mode() const { return mode_.load(std::memory_order_relaxed); }
  // The controller in service (its backend, task, rollouts and horizon in the status).
  void describe(const Controller& c);
  // A status is due at this cycle (its rate), or forced, or the mode changed since the last.
  bool status_due(std::int64_t cycle_index, bool force) const;
  void publish_status(const StatusSources& src);
  // The display plan of a cycle that flew the optimizer's command, at its rate: the held plan
  // and the path it flies from x0.
  void maybe_plan(const Controller& c, std::int64_t cycle_index, transport::Mode published, const HeldPlan& held,
                  std::int64_t state_seq, const float* x0);
  void after_cycle_rollouts(Controller& c, std::int64_t cycle_index, std::int64_t state_seq, bool fresh) {
    rollouts_.after_cycle(c, *tx_, cycle_index, state_seq, fresh);
  }

  // ---- the snapshot for other threads
  void note_cycle(const rt::DeadlineMonitor& m, bool healthy, std::int64_t heartbeat_ns);
  void set_heartbeat(std::int64_t ns) { heartbeat_ns_.store(ns, std::memory_order_relaxed); }
  void set_unhealthy() { loop_healthy_.store(false, std::memory_order_relaxed); }
  std::int64_t heartbeat_ns() const { return heartbeat_ns_.load(std::memory_order_relaxed); }
  bool loop_healthy() const { return loop_healthy_.load(std::memory_order_relaxed); }
  std::int64_t snap_cycles() const { return snap_cycles_.load(std::memory_order_relaxed); }
  std::int64_t snap_misses() const { return snap_misses_.load(std::memory_order_relaxed); }
  std::int64_t snap_consecutive() const { return snap_consecutive_.load(std::memory_order_relaxed); }
  double snap_rate() const { return snap_rate_.load(std::memory_order_relaxed); }

 private:
  void fill_timing(const rt::TimingSummary& w);
  void fill_counts(const transport::InboxCounters& ic);

  transport::Transport* tx_;
  LoopCounters* counters_;
  CommandOut out_;  // the gate, the sequence and the transport: shared with the guard
  transport::Command cmd_;
  std::vector<float> failsafe_;
  transport::StatusReport status_;
  transport::Mode last_status_mode_ = transport::Mode::kFailsafe;
  std::int64_t status_every_, plan_every_;
  std::vector<float> plan_pos_ = std::vector<float>(3 * transport::kMaxPlanPositions);  // predicted path, xyz
  RolloutPublisher rollouts_;

  std::atomic<transport::Mode> mode_{transport::Mode::kFailsafe};
  std::atomic<std::int64_t> heartbeat_ns_{0};
  std::atomic<bool> loop_healthy_{true};
  std::atomic<std::int64_t> snap_cycles_{0}, snap_misses_{0}, snap_consecutive_{0};
  std::atomic<double> snap_rate_{0.0};
};

}  // namespace mppi::daemon
