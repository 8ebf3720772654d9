#include "mppi/rt/wakeup.hpp"

#include <cerrno>
#include <ctime>

#include "mppi/rt/clock.hpp"

namespace mppi::rt {

Wakeup::Wakeup() { sem_init(&sem_, 0, 0); }
Wakeup::~Wakeup() { sem_destroy(&sem_); }

void Wakeup::post() { sem_post(&sem_); }

bool Wakeup::wait_for(std::int64_t timeout_ns) {
  // sem_clockwait (glibc >= 2.30) waits on CLOCK_MONOTONIC, immune to wall-clock steps.
  const std::int64_t until = monotonic_ns() + timeout_ns;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(until / kNsPerS);
  ts.tv_nsec = static_cast<long>(until % kNsPerS);
  while (true) {
    if (sem_clockwait(&sem_, CLOCK_MONOTONIC, &ts) == 0) return true;
    if (errno != EINTR) return false;
  }
}

}  // namespace mppi::rt
