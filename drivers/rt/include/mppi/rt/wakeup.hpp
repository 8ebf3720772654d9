// A counting wake-up for the lock-step loop: the receive thread posts one per clock tick,
// the loop waits with a timeout so it can still notice a stop request. POSIX semaphores:
// sem_post is async-signal-safe and takes no lock the waiter could hold.
#pragma once

#include <semaphore.h>

#include <cstdint>

namespace mppi::rt {

class Wakeup {
 public:
  Wakeup();
  ~Wakeup();
  Wakeup(const Wakeup&) = delete;
  Wakeup& operator=(const Wakeup&) = delete;

  void post();
  // True when a post was consumed, false on timeout.
  bool wait_for(std::int64_t timeout_ns);
  // The same with an absolute CLOCK_MONOTONIC deadline.
  bool wait_until(std::int64_t monotonic_ns);
  // Takes a pending post without waiting; false when there is none.
  bool try_wait();

 private:
  sem_t sem_;
};

}  // namespace mppi::rt
