#include "mppi/rt/wakeup.hpp"

#include <cerrno>
#include <cstdint>
#include <ctime>

#include "mppi/rt/clock.hpp"

namespace mppi::rt {

Wakeup::Wakeup() { sem_init(&sem_, 0, 0); }
Wakeup::~Wakeup() { sem_destroy(&sem_); }

void Wakeup::post() { sem_post(&sem_); }

bool Wakeup::wait_for(std::int64_t timeout_ns) { return wait_until(monotonic_ns() + timeout_ns); }

bool Wakeup::try_wait() {
  while (true) {
    if (sem_trywait(&sem_) == 0) return true;
    if (errno != EINTR) return false;
  }
}

bool Wakeup::wait_until(std::int64_t until) {
  // sem_clockwait (glibc >= 2.30) waits on CLOCK_MONOTONIC, immune to wall-clock steps.
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(until / kNsPerS);
  ts.tv_nsec = static_cast<long>(until % kNsPerS);
  while (true) {
    if (sem_clockwait(&sem_, CLOCK_MONOTONIC, &ts) == 0) return true;
    if (errno != EINTR) return false;
  }
}

}  // namespace mppi::rt
