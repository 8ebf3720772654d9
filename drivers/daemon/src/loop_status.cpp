// ControlLoop: what the loop reports besides its commands: mode changes, the status at its
// rate (and on each mode change), the final status and the display plan.
#include <spdlog/spdlog.h>

#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

using transport::Mode;

void ControlLoop::set_mode(Mode m) {
  const Mode before = mode_.exchange(m, std::memory_order_relaxed);
  if (before == m) return;
  if (m == Mode::kFailsafe) {
    counters_.failsafe_entries.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("mode {} -> failsafe", transport::to_string(before));
  } else if (m == Mode::kHoldPlan) {
    spdlog::warn("mode {} -> hold_plan", transport::to_string(before));
  } else {
    spdlog::info("mode {} -> normal", transport::to_string(before));
  }
}

void ControlLoop::maybe_status(bool force) {
  if (!force && (status_every_ == 0 || cycle_index_ % status_every_ != 0)) return;
  const rt::TimingSummary w = monitor_.window();
  auto f = [](double v) { return static_cast<float>(v); };
  status_.utime = rt::wall_utime();
  ++status_.seq;
  status_.mode = mode_.load(std::memory_order_relaxed);
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
  status_.latency_expected_ms = f(static_cast<double>(latency_.estimate_ns()) * 1e-6);
  status_.lead_ms_mean = f(w.lead.mean_ms);
  status_.lead_ms_p99 = f(w.lead.p99_ms);
  std::copy_n(observer_.estimate(), 3, status_.disturbance_accel);
  status_.model_mass = c_->mass();
  status_.actuation_delay_ms = static_cast<float>(static_cast<double>(s_.latency.actuation_delay_ns) * 1e-6);
  status_.ess = last_stats_.ess;
  status_.min_cost = last_stats_.min_cost;
  const auto& ic = in_->counters;
  auto ld = [](const std::atomic<std::int64_t>& a) { return a.load(std::memory_order_relaxed); };
  status_.rejected_nan = ld(ic.rejected_nan);
  status_.rejected_stale = ld(counters_.stale_cycles);
  status_.rejected_out_of_order = ld(ic.rejected_out_of_order) + ld(ic.rejected_duplicate);
  status_.rejected_undecodable = ld(ic.rejected_undecodable) + ld(ic.rejected_shape) + ld(ic.rejected_inputs);
  status_.rejected_params = ld(counters_.params_rejected) + ld(ic.params_dropped);
  status_.rejected_future = ld(counters_.future_states);
  status_.maps_accepted = ld(ic.maps);
  status_.maps_rejected = ic.maps_rejected();
  const std::int64_t map_age_us = ld(counters_.map_age_us);
  status_.map_age_ms = map_age_us < 0 ? -1.0f : static_cast<float>(static_cast<double>(map_age_us) * 1e-3);
  status_.map_stale_cycles = ld(counters_.map_stale_cycles);
  status_.partial_updates = ld(counters_.partial_updates);
  status_.anytime_holds = ld(counters_.anytime_holds);
  status_.rollouts_active = c_->active_rollouts();
  status_.work_size_changes = work_.changes();
  status_.healthy = status_.mode == Mode::kNormal && loop_healthy_.load(std::memory_order_relaxed);
  tx_->publish_status(status_);
  counters_.status_published.fetch_add(1, std::memory_order_relaxed);
  last_status_mode_ = status_.mode;
  monitor_.reset_window();
}

void ControlLoop::publish_final_status() {
  loop_healthy_.store(false, std::memory_order_relaxed);
  maybe_status(true);
  // The forced status above reports the mode; mark the final one unhealthy explicitly.
}

void ControlLoop::maybe_plan(std::int64_t state_seq, const float* x0) {
  transport::PlanView p;
  p.utime = rt::wall_utime();
  p.seq = counters_.plans_published.load(std::memory_order_relaxed) + 1;
  p.state_seq = state_seq;
  p.horizon = c_->horizon();
  p.nu = nu_;
  p.dt = c_->dt();
  p.u = plan_.held().data();
  // The path the held plan flies from this cycle's state (a nominal rollout, T model steps).
  p.npos = c_->predict(x0, plan_.held().data(), plan_pos_.data(), transport::kMaxPlanPositions);
  p.pos = plan_pos_.data();
  if (tx_->publish_plan(p)) counters_.plans_published.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace mppi::daemon
