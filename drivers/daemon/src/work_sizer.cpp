#include "mppi/daemon/work_sizer.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace mppi::daemon {

namespace {

// The 99th percentile's rank (1-based, ascending) among n samples.
int p99_rank(int n) { return (99 * n + 99) / 100; }

}  // namespace

WorkSizer::WorkSizer(const WorkSizerSettings& s, std::int64_t period_ns)
    : s_(s),
      target_ns_(std::llround(s.target * static_cast<double>(period_ns))),
      grow_ns_(std::llround(s.grow_below * static_cast<double>(period_ns))),
      over_limit_(std::max(1, s.window) - p99_rank(std::max(1, s.window)) + 1),
      window_(static_cast<std::size_t>(std::max(1, s.window))),
      scratch_(window_.size()) {}

int WorkSizer::floor() const { return std::max(1, std::min(s_.floor, ceiling_)); }

void WorkSizer::follow_ceiling(int ceiling, int quantum) {
  quantum_ = quantum;
  if (ceiling == ceiling_) return;
  ceiling_ = ceiling;
  size_ = size_ == 0 ? ceiling : std::clamp(size_, floor(), ceiling);
  filled_ = over_ = high_ = 0;
}

void WorkSizer::before_update(Controller& c) {
  follow_ceiling(c.settings().rollouts, c.rollout_quantum());
  if (quantum_ == 0) return;  // no rollouts to size (DDP)
  const int want = pinned_ > 0 ? std::min(pinned_, ceiling_) : s_.enabled ? size_ : ceiling_;
  if (c.active_rollouts() != want) c.set_active_rollouts(want);
}

void WorkSizer::after_update(std::int64_t compute_ns) {
  if (!s_.enabled || pinned_ > 0 || ceiling_ == 0 || quantum_ == 0) return;
  window_[static_cast<std::size_t>(filled_++)] = compute_ns;
  if (compute_ns > target_ns_) ++over_;
  if (compute_ns >= grow_ns_) ++high_;
  // Enough samples over the target put the window's p99 over it, whatever the rest will be.
  if (over_ >= over_limit_) decide(true);
  else if (filled_ == static_cast<int>(window_.size())) decide(false);
}

std::int64_t WorkSizer::window_p99() {
  std::copy_n(window_.begin(), filled_, scratch_.begin());
  const auto nth = scratch_.begin() + (p99_rank(filled_) - 1);
  std::nth_element(scratch_.begin(), nth, scratch_.begin() + filled_);
  return *nth;
}

void WorkSizer::decide(bool over_target) {
  const std::int64_t p99 = window_p99();
  if (over_target) {
    const int q = std::max(1, quantum_);
    const int down = static_cast<int>(std::floor(size_ * s_.shrink / q)) * q;
    change_to(std::max(floor(), down), "over the target", p99, target_ns_);
  } else if (high_ < over_limit_) {
    const int q = std::max(1, quantum_);
    const int up = static_cast<int>(std::ceil(size_ * s_.grow / q)) * q;
    change_to(std::min(ceiling_, std::max(up, size_ + 1)), "below the growth bound", p99, grow_ns_);
  }
  filled_ = over_ = high_ = 0;  // a new window, at the new count
}

void WorkSizer::change_to(int n, const char* why, std::int64_t p99_ns, std::int64_t bound_ns) {
  if (n == size_) return;
  spdlog::info("work: {} -> {} rollouts (compute p99 {:.2f} ms over {} cycles, {} {:.2f} ms)", size_, n,
               static_cast<double>(p99_ns) / 1e6, filled_, why, static_cast<double>(bound_ns) / 1e6);
  size_ = n;
  ++changes_;
}

}  // namespace mppi::daemon
