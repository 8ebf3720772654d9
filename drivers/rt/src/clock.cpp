#include "mppi/rt/clock.hpp"

#include <cstdint>
#include <ctime>

namespace mppi::rt {

namespace {
// A hint to the core that this is a spin-wait (x86 PAUSE, Arm YIELD).
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield" ::: "memory");
#endif
}

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
  if (spin_) {
    while (now_ns() < t_ns) cpu_relax();
    return;
  }
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / kNsPerS);
  ts.tv_nsec = static_cast<long>(t_ns % kNsPerS);
  // EINTR: a signal arrived; the caller's loop decides whether to stop or sleep again.
  (void)clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

bool MonotonicClock::sleep_until_or(Wakeup& wake, std::int64_t t_ns) {
  if (!spin_) return wake.wait_until(t_ns);
  for (;;) {
    if (wake.try_wait()) return true;
    if (now_ns() >= t_ns) return false;
    cpu_relax();
  }
}

}  // namespace mppi::rt
