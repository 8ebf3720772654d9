// Real-time set-up in one place: lock memory (mlockall), prefault the stack, SCHED_FIFO
// and a CPU affinity for the calling thread. Each step reports what the OS refused, so the
// daemon can say so and run on, or exit under --require-realtime.
#pragma once

#include <string>
#include <vector>

namespace mppi::rt {

struct RealtimeRequest {
  bool lock_memory = true;
  int fifo_priority = 80;  // 1..99; 0 = leave the scheduler alone
  int cpu = -1;            // -1 = no affinity
  std::size_t prefault_stack_bytes = 512 * 1024;
};

struct RealtimeResult {
  bool memory_locked = false;
  bool fifo = false;
  bool pinned = false;
  std::vector<std::string> refused;  // one line per refused step, with the OS's reason
  bool ok() const { return refused.empty(); }
};

// Process-wide part: mlockall(MCL_CURRENT | MCL_FUTURE). Call once, early.
void lock_memory(const RealtimeRequest& req, RealtimeResult* out);
// Calling-thread part: prefault the stack, SCHED_FIFO, affinity. Call from the loop thread.
void make_thread_realtime(const RealtimeRequest& req, RealtimeResult* out);

// Resident memory of this process (VmRSS of /proc/self/status), kB; -1 if unreadable.
long resident_kb();

}  // namespace mppi::rt
