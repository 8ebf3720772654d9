// Fixed-rate release times on an absolute grid. After an overrun the schedule skips the
// lost periods instead of catching up with a burst of back-to-back cycles: it re-anchors
// the grid at the time the late cycle ended and counts the miss.
#pragma once

#include <cstdint>

namespace mppi::rt {

class PeriodicSchedule {
 public:
  explicit PeriodicSchedule(std::int64_t period_ns) : period_(period_ns) {}

  void start(std::int64_t now_ns) {
    release_ = now_ns;
    next_ = now_ns;
  }

  std::int64_t period_ns() const { return period_; }
  // Release time of the cycle now running (or about to run).
  std::int64_t release_ns() const { return release_; }
  // The deadline of the running cycle: its command is due before the next release.
  std::int64_t deadline_ns() const { return release_ + period_; }
  // When to wake for the next cycle.
  std::int64_t next_release_ns() const { return next_; }

  // Call when a cycle begins (after waking); fixes the release the cycle belongs to.
  void begin(std::int64_t /*now_ns*/) { release_ = next_; }
  // A cycle started by an event (a state) rather than the grid: the grid moves to it, the
  // cycle's deadline is a period after it.
  void begin_at(std::int64_t now_ns) {
    release_ = now_ns;
    next_ = now_ns;
  }

  // Call when the cycle's work is done at end_ns. Returns true when the cycle missed its
  // deadline; then the next release is end_ns itself (the grid is re-anchored there and
  // the lost periods are skipped), else it is release + period.
  bool finish(std::int64_t end_ns) {
    if (end_ns > deadline_ns()) {
      next_ = end_ns;
      ++misses_;
      skipped_ += (end_ns - release_) / period_;
      return true;
    }
    next_ = release_ + period_;
    return false;
  }

  std::int64_t misses() const { return misses_; }
  // Periods that passed without a cycle of their own because of overruns.
  std::int64_t skipped_periods() const { return skipped_; }

 private:
  std::int64_t period_;
  std::int64_t release_ = 0;
  std::int64_t next_ = 0;
  std::int64_t misses_ = 0;
  std::int64_t skipped_ = 0;
};

}  // namespace mppi::rt
