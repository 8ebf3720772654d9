// Time for the control loop, in nanoseconds on one monotonic timeline. The loop only
// reads time and sleeps until an absolute time through this seam, so tests drive it with
// a fake clock and lock-step runs drive it with the simulator's clock.
#pragma once

#include <cstdint>

#include "mppi/rt/wakeup.hpp"

namespace mppi::rt {

constexpr std::int64_t kNsPerMs = 1'000'000;
constexpr std::int64_t kNsPerUs = 1'000;
constexpr std::int64_t kNsPerS = 1'000'000'000;

class Clock {
 public:
  virtual ~Clock() = default;
  virtual std::int64_t now_ns() = 0;
  // Returns at or after t_ns (absolute), or early when interrupted; callers re-check.
  virtual void sleep_until(std::int64_t t_ns) = 0;
  // sleep_until that a post on `wake` ends early (true then: the post was taken). A clock
  // that cannot wait on it sleeps the whole way.
  virtual bool sleep_until_or(Wakeup& wake, std::int64_t t_ns) {
    (void)wake;
    sleep_until(t_ns);
    return false;
  }
};

// CLOCK_MONOTONIC with absolute-time clock_nanosleep (TIMER_ABSTIME): no drift from
// relative sleeps, no jump with wall-clock changes. Spinning (daemon.spin): the waits poll the
// clock and the wake-up instead of sleeping, so the thread is running when the time or a post
// comes (no scheduler wake-up, no idle CPU state to leave), at the cost of a busy core.
class MonotonicClock final : public Clock {
 public:
  explicit MonotonicClock(bool spin = false) : spin_(spin) {}
  std::int64_t now_ns() override;
  void sleep_until(std::int64_t t_ns) override;
  bool sleep_until_or(Wakeup& wake, std::int64_t t_ns) override;

 private:
  bool spin_;
};

// CLOCK_MONOTONIC now, for code that has no Clock at hand (receive-time stamps).
std::int64_t monotonic_ns();
// CLOCK_REALTIME in microseconds: the utime field of published messages.
std::int64_t wall_utime();

}  // namespace mppi::rt
