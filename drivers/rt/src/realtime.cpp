#include "mppi/rt/realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace mppi::rt {

void lock_memory(const RealtimeRequest& req, RealtimeResult* out) {
  if (!req.lock_memory) return;
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
    out->memory_locked = true;
  } else {
    out->refused.push_back(std::string("mlockall: ") + std::strerror(errno) +
                           " (raise LimitMEMLOCK / ulimit -l, or run with CAP_IPC_LOCK)");
  }
}

namespace {
// Touch the stack once so page faults happen now, not in the first cycles.
__attribute__((noinline)) void prefault_stack(std::size_t bytes) {
  constexpr std::size_t kChunk = 4096;
  unsigned char page[kChunk];
  std::memset(page, 0, kChunk);
  asm volatile("" : : "r"(page) : "memory");  // keep the writes
  if (bytes > kChunk) prefault_stack(bytes - kChunk);
}
}  // namespace

void make_thread_realtime(const RealtimeRequest& req, RealtimeResult* out) {
  if (req.prefault_stack_bytes > 0) prefault_stack(req.prefault_stack_bytes);
  if (req.fifo_priority > 0) {
    sched_param sp{};
    sp.sched_priority = req.fifo_priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (rc == 0) {
      out->fifo = true;
    } else {
      out->refused.push_back("SCHED_FIFO priority " + std::to_string(req.fifo_priority) + ": " + std::strerror(rc) +
                             " (raise LimitRTPRIO / ulimit -r, or run with CAP_SYS_NICE)");
    }
  }
  if (req.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(req.cpu, &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    if (rc == 0) {
      out->pinned = true;
    } else {
      out->refused.push_back("CPU affinity " + std::to_string(req.cpu) + ": " + std::strerror(rc));
    }
  }
}

long resident_kb() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return -1;
  char line[256];
  long kb = -1;
  while (std::fgets(line, sizeof(line), f)) {
    if (std::strncmp(line, "VmRSS:", 6) == 0) {
      kb = std::strtol(line + 6, nullptr, 10);
      break;
    }
  }
  std::fclose(f);
  return kb;
}

}  // namespace mppi::rt
