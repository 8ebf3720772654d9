// LoopOutputs: what the loop sends and reports besides its decisions: the commands through
// the gate, mode changes, the status at its rate (and on each mode change), the display
// plan, and the snapshot other threads read.
#include "mppi/daemon/loop_outputs.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "mppi/rt/clock.hpp"

namespace mppi::daemon {

using transport::Mode;

namespace {
std::int64_t every(double rate_hz, double sub_hz) {
  if (sub_hz <= 0.0) return 0;
  return std::max<std::int64_t>(1, std::llround(rate_hz / sub_hz));
}
}  // namespace

LoopOutputs::LoopOutputs(transport::Transport* tx, LoopCounters* counters, const Controller& c, OutputSettings s)
    : tx_(tx),
      counters_(counters),
      out_(tx, counters, c.settings().u_min, c.settings().u_max, c.nu(), s.command_kind),
      failsafe_(s.failsafe_u.empty() ? c.settings().u_init : s.failsafe_u),
      status_every_(every(s.rate_hz, s.status_hz)),
      plan_every_(every(s.rate_hz, s.plan_hz)),
      rollouts_(s.rollouts, s.rate_hz, c.vehicles(), c.horizon()) {
  describe(c);
}

void LoopOutputs::describe(const Controller& c) {
  status_.rollouts = c.settings().rollouts;
  status_.horizon = c.horizon();
  status_.backend = c.backend();
  status_.task = c.task().c_str();
}

// ---- commands ---------------------------------------------------------------------------

void LoopOutputs::stamp_timing(std::int64_t age_ns, std::int64_t compute_ns, std::int64_t lead_ns, int rollouts) {
  auto us = [](std::int64_t ns) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(ns / rt::kNsPerUs, 0, INT32_MAX));
  };
  cmd_.age_us = us(age_ns);
  cmd_.compute_us = us(compute_ns);
  cmd_.lead_us = us(lead_ns);
  cmd_.rollouts = rollouts;
}

bool LoopOutputs::publish(Mode mode, const float* u, std::int64_t state_seq) {
  if (!out_.passes(u)) return false;
  out_.send(&cmd_, mode, u, state_seq);
  return true;
}

bool LoopOutputs::publish_failsafe(std::int64_t state_seq) {
  if (publish(Mode::kFailsafe, failsafe_.data(), state_seq)) return true;
  counters_->commands_blocked.fetch_add(1, std::memory_order_relaxed);
  return false;
}

void LoopOutputs::resend_last() {
  if (cmd_.seq > 0) out_.resend(cmd_);
}

// ---- mode, status, display -----------------------------------------------------------------

void LoopOutputs::set_mode(Mode m) {
  const Mode before = mode_.exchange(m, std::memory_order_relaxed);
  if (before == m) return;
  if (m == Mode::kFailsafe) {
    counters_->failsafe_entries.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("mode {} -> failsafe", transport::to_string(before));
  } else if (m == Mode::kHoldPlan) {
    spdlog::warn("mode {} -> hold_plan", transport::to_string(before));
  } else {
    spdlog::info("mode {} -> normal", transport::to_string(before));
  }
}

bool LoopOutputs::status_due(std::int64_t cycle_index, bool force) const {
  if (force || mode() != last_status_mode_) return true;
  return status_every_ != 0 && cycle_index % status_every_ == 0;
}

void LoopOutputs::publish_status(const StatusSources& src) {
  status_.utime = rt::wall_utime();
  ++status_.seq;
  status_.mode = mode_.load(std::memory_order_relaxed);
  fill_timing(src.window);
  status_.latency_expected_ms = static_cast<float>(static_cast<double>(src.latency_expected_ns) * 1e-6);
  std::copy_n(src.disturbance, 3, status_.disturbance_accel);
  status_.model_mass = src.model_mass;
  status_.actuation_delay_ms = static_cast<float>(static_cast<double>(src.actuation_delay_ns) * 1e-6);
  status_.ess = src.stats.ess;
  status_.min_cost = src.stats.min_cost;
  fill_counts(src.inbox);
  status_.rollouts_active = src.rollouts_active;
  status_.work_size_changes = src.work_size_changes;
  status_.healthy = status_.mode == Mode::kNormal && loop_healthy_.load(std::memory_order_relaxed);
  tx_->publish_status(status_);
  counters_->status_published.fetch_add(1, std::memory_order_relaxed);
  last_status_mode_ = status_.mode;
}

void LoopOutputs::fill_timing(const rt::TimingSummary& w) {
  auto f = [](double v) { return static_cast<float>(v); };
  status_.compute_ms_last = f(w.last_compute_ms);
  status_.compute_ms_min = f(w.compute.min_ms);
  status_.compute_ms_mean = f(w.compute.mean_ms);
  status_.compute_ms_max = f(w.compute.max_ms);
  status_.compute_ms_p99 = f(w.compute.p99_ms);
  status_.period_ms_min = f(w.period.min_ms);
  status_.period_ms_mean = f(w.period.mean_ms);
  status_.period_ms_max = f(w.period.max_ms);
  status_.period_ms_p99 = f(w.period.p99_ms);
  status_.jitter_ms_p99 = f(w.jitter.p99_ms);
  if (w.period.count > 0 && w.period.mean_ms > 0.0) snap_rate_.store(1000.0 / w.period.mean_ms, std::memory_order_relaxed);
  status_.cycles = w.cycles;
  status_.misses = w.misses;
  status_.late_start_misses = w.late_start_misses;
  status_.consecutive_misses = w.consecutive_misses;
  status_.state_to_command_ms_p99 = f(w.latency.p99_ms);
  status_.state_age_ms_p99 = f(w.age.p99_ms);
  status_.lead_ms_mean = f(w.lead.mean_ms);
  status_.lead_ms_p99 = f(w.lead.p99_ms);
}

void LoopOutputs::fill_counts(const transport::InboxCounters& ic) {
  const LoopCounters& lc = *counters_;
  auto ld = [](const std::atomic<std::int64_t>& a) { return a.load(std::memory_order_relaxed); };
  status_.rejected_nan = ld(ic.rejected_nan);
  status_.rejected_stale = ld(lc.stale_cycles);
  status_.rejected_out_of_order = ld(ic.rejected_out_of_order) + ld(ic.rejected_duplicate);
  status_.rejected_undecodable = ld(ic.rejected_undecodable) + ld(ic.rejected_shape) + ld(ic.rejected_inputs);
  status_.rejected_params = ld(lc.params_rejected) + ld(ic.params_dropped);
  status_.rejected_future = ld(lc.future_states);
  status_.maps_accepted = ld(ic.maps);
  status_.maps_rejected = ic.maps_rejected();
  const std::int64_t map_age_us = ld(lc.map_age_us);
  status_.map_age_ms = map_age_us < 0 ? -1.0f : static_cast<float>(static_cast<double>(map_age_us) * 1e-3);
  status_.map_stale_cycles = ld(lc.map_stale_cycles);
  status_.partial_updates = ld(lc.partial_updates);
  status_.anytime_holds = ld(lc.anytime_holds);
}

void LoopOutputs::maybe_plan(const Controller& c, std::int64_t cycle_index, Mode published, const HeldPlan& held,
                             std::int64_t state_seq, const float* x0) {
  if (plan_every_ <= 0 || cycle_index % plan_every_ != 0 || published != Mode::kNormal) return;
  transport::PlanView p;
  p.utime = rt::wall_utime();
  p.seq = counters_->plans_published.load(std::memory_order_relaxed) + 1;
  p.state_seq = state_seq;
  p.horizon = c.horizon();
  p.nu = out_.nu();
  p.dt = c.dt();
  p.u = held.data();
  // The path the held plan flies from this cycle's state (a nominal rollout, T model steps).
  p.npos = c.predict(x0, held.data(), plan_pos_.data(), transport::kMaxPlanPositions);
  p.pos = plan_pos_.data();
  if (tx_->publish_plan(p)) counters_->plans_published.fetch_add(1, std::memory_order_relaxed);
}

// ---- the snapshot -------------------------------------------------------------------------

void LoopOutputs::note_cycle(const rt::DeadlineMonitor& m, bool healthy, std::int64_t heartbeat_ns) {
  loop_healthy_.store(healthy, std::memory_order_relaxed);
  snap_cycles_.store(m.cycles(), std::memory_order_relaxed);
  snap_misses_.store(m.misses(), std::memory_order_relaxed);
  snap_consecutive_.store(m.consecutive_misses(), std::memory_order_relaxed);
  heartbeat_ns_.store(heartbeat_ns, std::memory_order_relaxed);
}

}  // namespace mppi::daemon
