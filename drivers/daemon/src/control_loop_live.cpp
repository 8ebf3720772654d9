// ControlLoop: answers to parameter updates, and live optimizer updates (the swap of a
// controller built by LiveOptimizer's builder thread, between two cycles).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>

#include "mppi/daemon/control_loop.hpp"

namespace mppi::daemon {

void ControlLoop::answer_param(const transport::ParamUpdate& p, bool applied, const std::string& why) {
  tx_->publish_param_result(transport::answer_to(p, applied, why, cycle_index_));
}

void ControlLoop::service_live() {
  if (OptimizerBundle* b = live_->take_ready()) swap_in(b);
  transport::ParamResult r;
  while (live_->pop_refusal(&r)) {
    r.cycle = cycle_index_;
    counters_.params_rejected.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("parameter update seq {} rejected: {}", r.update_seq, r.reason);
    tx_->publish_param_result(r);
  }
}

// Between two cycles: the new controller takes the running one's task state (inputs,
// run-time model and cost parameters, the disturbance estimate, the noise counter) and its
// plan, resampled onto the new horizon; the loop's own state (latency estimate, command
// history, disturbance observer, the plan's timeline) stays as it is. Pointer and vector
// swaps only: the buffers came with the bundle, and the old ones leave with it.
void ControlLoop::swap_in(OptimizerBundle* b) {
  Controller* next = b->controller.get();
  if (!next->adopt(*c_)) {
    // Cannot happen with the daemon's factory (same task); refuse rather than lose the task state.
    for (int i = 0; i < b->count; ++i) {
      counters_.params_rejected.fetch_add(1, std::memory_order_relaxed);
      answer_param(b->updates[i], false, std::string(b->updates[i].key) + ": the new optimizer cannot take over");
    }
    b->count = 0;
    live_->retire(b);
    return;
  }
  plan_.rebase(next, b->held);  // both plans onto the new horizon; b->held takes the old one
  if (guard_ != nullptr) guard_->swap_plan(b->guard);
  const int threads_before = live_->current_threads();
  live_->swap_current(b);  // b now holds the old controller
  c_ = next;
  // A new team size: libgomp starts or ends workers here, between cycles (the one step of
  // a live update that is not a pointer swap; only when mppi.threads changed).
  if (live_->current_threads() != threads_before && std::strncmp(c_->backend(), "cpu", 3) == 0)
    resize_worker_team(live_->current_threads());
  outputs_.describe(*c_);
  for (int i = 0; i < b->count; ++i) {
    counters_.params_applied.fetch_add(1, std::memory_order_relaxed);
    spdlog::info("parameter {} = {} applied (update seq {}, cycle {})", b->updates[i].key, b->updates[i].value,
                 b->updates[i].seq, cycle_index_);
    answer_param(b->updates[i], true, {});
  }
  live_->retire(b);
}

}  // namespace mppi::daemon
