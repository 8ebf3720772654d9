#include "mppi/rt/clock.hpp"

#include <cstdint>
#include <ctime>

namespace mppi::rt {

namespace {
std::int64_t read(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}
}  // namespace

std::int64_t monotonic_ns() { return read(CLOCK_MONOTONIC); }
std::int64_t wall_utime() { return read(CLOCK_REALTIME) / kNsPerUs; }

std::int64_t MonotonicClock::now_ns() { return read(CLOCK_MONOTONIC); }

void MonotonicClock::sleep_until(std::int64_t t_ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / kNsPerS);
  ts.tv_nsec = static_cast<long>(t_ns % kNsPerS);
  // EINTR: a signal arrived; the caller's loop decides whether to stop or sleep again.
  (void)clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

}  // namespace mppi::rt
