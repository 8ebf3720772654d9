#include "mppi/daemon/deadline_guard.hpp"

#include <pthread.h>
#include <sched.h>

#include <algorithm>

namespace mppi::daemon {

using transport::Mode;

DeadlineGuard::DeadlineGuard(const GuardSettings& s, rt::Clock* clock, CommandOut* out, LoopCounters* counters,
                             const HeldPlan& held, std::vector<float> failsafe)
    : s_(s),
      clock_(clock),
      out_(out),
      counters_(counters),
      u_init_(held.u_init()),
      failsafe_(std::move(failsafe)),
      plan_(held.size(), 0.0f) {}

DeadlineGuard::~DeadlineGuard() {
  quit_.store(true);
  wake_.post();
  if (thread_.joinable()) thread_.join();
}

void DeadlineGuard::start() {
  if (!thread_.joinable()) thread_ = std::thread([this] { watch(); });
}

std::atomic<bool>* DeadlineGuard::next_stop_flag() {
  std::atomic<bool>* stop = &stop_[(id_ + 1) & 1u];
  stop->store(false, std::memory_order_relaxed);
  return stop;
}

void DeadlineGuard::arm(std::int64_t deadline_ns, std::int64_t state_seq, const HeldPlan& held) {
  std::copy_n(held.data(), std::min(held.size(), plan_.size()), plan_.begin());
  state_seq_ = state_seq;
  steps_.store(0, std::memory_order_relaxed);
  deadline_.store(deadline_ns, std::memory_order_relaxed);
  word_.store((++id_ << 2) | kArmed, std::memory_order_release);
  wake_.post();
}

int DeadlineGuard::disarm() {
  std::uint64_t armed = (id_ << 2) | kArmed;
  if (word_.compare_exchange_strong(armed, id_ << 2, std::memory_order_acq_rel)) return 0;
  // The guard took over: take the cycle back between two of its publishes.
  while (true) {
    std::uint64_t waiting = (id_ << 2) | kWaiting;
    if (word_.compare_exchange_weak(waiting, id_ << 2, std::memory_order_acq_rel)) break;
    std::this_thread::yield();
  }
  return std::max(1, steps_.load(std::memory_order_acquire));
}

const float* DeadlineGuard::step(int i) const {
  const int steps = static_cast<int>(plan_.size()) / out_->nu();
  return i >= 0 && i < steps ? plan_.data() + static_cast<std::ptrdiff_t>(i) * out_->nu() : u_init_.data();
}

void DeadlineGuard::publish(int step) {
  const float* u = this->step(step);
  Mode mode = Mode::kHoldPlan;
  // A stall longer than the failsafe timeout is no better than no state: failsafe.
  const bool too_long = static_cast<std::int64_t>(step) * s_.period_ns > s_.failsafe_timeout_ns;
  if (too_long || !out_->passes(u)) {
    u = failsafe_.data();
    mode = Mode::kFailsafe;
    if (!out_->passes(u)) {
      counters_->commands_blocked.fetch_add(1, std::memory_order_relaxed);
      return;
    }
  }
  out_->send(&cmd_, mode, u, state_seq_);
  counters_->guard_commands.fetch_add(1, std::memory_order_relaxed);
}

bool DeadlineGuard::sleep_until(std::int64_t t) {
  while (clock_->now_ns() < t && !quit_.load(std::memory_order_relaxed)) clock_->sleep_until(t);
  return !quit_.load(std::memory_order_relaxed);
}

// Anytime: ask the optimizer, still at work on cycle `id`, to wrap up before the deadline.
void DeadlineGuard::raise_stop_flag(std::uint64_t id, std::int64_t deadline_ns) {
  sleep_until(deadline_ns - s_.anytime_margin_ns);
  if (word_.load(std::memory_order_acquire) == ((id << 2) | kArmed)) stop_[id & 1u].store(true, std::memory_order_release);
}

// Cycle `id` is still armed at its deadline: publish a held step now and every period
// after, until the loop takes the cycle back.
void DeadlineGuard::cover(std::uint64_t id, std::int64_t deadline_ns) {
  std::int64_t t = deadline_ns;
  for (int step = 0;; ++step) {
    publish(step);
    steps_.store(step + 1, std::memory_order_release);
    word_.store((id << 2) | kWaiting, std::memory_order_release);
    t += s_.period_ns;
    sleep_until(t);
    std::uint64_t waiting = (id << 2) | kWaiting;
    if (quit_.load(std::memory_order_relaxed) ||
        !word_.compare_exchange_strong(waiting, (id << 2) | kPublishing, std::memory_order_acq_rel))
      return;  // the loop took the cycle back
  }
}

void DeadlineGuard::watch() {
  if (s_.fifo_priority > 0) {
    sched_param sp{};
    sp.sched_priority = s_.fifo_priority;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);  // refused: runs on at its policy
  }
  while (!quit_.load(std::memory_order_relaxed)) {
    const std::uint64_t w = word_.load(std::memory_order_acquire);
    if ((w & 3u) != kArmed) {
      wake_.wait_for(s_.period_ns);
      continue;
    }
    const std::uint64_t id = w >> 2;
    const std::int64_t t = deadline_.load(std::memory_order_relaxed);
    if (anytime()) raise_stop_flag(id, t);
    sleep_until(t);
    std::uint64_t armed = (id << 2) | kArmed;
    if (!word_.compare_exchange_strong(armed, (id << 2) | kPublishing, std::memory_order_acq_rel))
      continue;  // the loop finished in time (or already re-armed): nothing to do
    counters_->guard_takeovers.fetch_add(1, std::memory_order_relaxed);
    cover(id, t);
  }
}

}  // namespace mppi::daemon
