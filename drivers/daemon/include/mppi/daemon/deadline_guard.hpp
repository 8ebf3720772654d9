// The deadline guard (real time only): a second thread that, when the optimizer is still
// running at a cycle's deadline, publishes the held plan's next step at that deadline and at
// every period after it until the optimizer returns, so commands keep their rate through a
// stall; a stall longer than the failsafe timeout gets the failsafe command. With an anytime
// margin it also asks the optimizer to stop its rollouts that long before the deadline.
//
//   loop:   arm(deadline, plan) -- optimizer ------------------ disarm() -> steps it sent
//   guard:        sleeps to deadline - margin: stop flag; to deadline: take over, publish,
//                 a period later publish again, ... until disarm() takes the cycle back
//
// The word = (cycle id << 2) | phase; phases: idle, armed (the loop is in the optimizer),
// guard waiting (it has taken the cycle over, between publishes), guard publishing.
//
// Memory ordering (what makes the plain fields safe): the loop thread writes the plan copy,
// the state sequence and the settings (set_failsafe_timeout) only while no cycle is armed,
// i.e. before arm() or after disarm() returned; arm()'s release store of the word publishes
// them, and the guard reads them only after an acquire load or CAS that saw that arm. The
// guard's release stores (waiting) are acquired by disarm()'s CAS, so its publishes happen
// before the loop's next write. The guard never reads the loop's settings: it has its own
// copy, handed over explicitly.
//
// The clock is injected: CLOCK_MONOTONIC in service, a fake shared by the test and the guard
// in tests (test/rt/test_deadline_guard.cpp), so every claim is checked on any machine.
#pragma once

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "mppi/daemon/command_out.hpp"
#include "mppi/daemon/loop_counters.hpp"
#include "mppi/held_plan.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/wakeup.hpp"

namespace mppi::daemon {

struct GuardSettings {
  std::int64_t period_ns = 20'000'000;
  std::int64_t failsafe_timeout_ns = 500'000'000;  // a longer stall publishes the failsafe
  std::int64_t anytime_margin_ns = 0;              // 0: no stop flag
  int fifo_priority = 0;                           // SCHED_FIFO priority of the thread; 0 = inherit
};

class DeadlineGuard {
 public:
  // `out`, `counters` and `clock` outlive the guard. `held` gives the plan's shape and the
  // u_init sent past its end; `failsafe` the command past the failsafe timeout.
  DeadlineGuard(const GuardSettings& s, rt::Clock* clock, CommandOut* out, LoopCounters* counters,
                const HeldPlan& held, std::vector<float> failsafe);
  ~DeadlineGuard();
  DeadlineGuard(const DeadlineGuard&) = delete;
  DeadlineGuard& operator=(const DeadlineGuard&) = delete;

  void start();  // the thread (allocates its stack: call before the cycles start)
  bool running() const { return thread_.joinable(); }
  bool anytime() const { return s_.anytime_margin_ns > 0; }

  // Loop thread, while no cycle is armed (see the ordering above).
  void set_failsafe_timeout(std::int64_t ns) { s_.failsafe_timeout_ns = ns; }
  // The anytime stop flag of the cycle the next arm() starts, cleared. Two flags in turn, so
  // a guard preempted between its check and its store cannot stop the cycle after.
  std::atomic<bool>* next_stop_flag();
  // The guard watches the cycle now: a copy of `held` (step 0 due at the deadline).
  void arm(std::int64_t deadline_ns, std::int64_t state_seq, const HeldPlan& held);
  // 0 when the loop kept the cycle, else the steps the guard sent (waits for it to finish
  // the one it may be sending).
  int disarm();
  // Step i of the plan copy of the last arm() (u_init past its end): what the guard sent.
  const float* step(int i) const;
  // A live update's plan length: `buffer` (the new horizon x nu) becomes the copy's buffer.
  void swap_plan(std::vector<float>& buffer) { plan_.swap(buffer); }

 private:
  enum : std::uint64_t { kIdle = 0, kArmed = 1, kWaiting = 2, kPublishing = 3 };
  void watch();  // the thread: each armed cycle, from its arm to its disarm
  bool sleep_until(std::int64_t t);  // false when told to quit
  void raise_stop_flag(std::uint64_t id, std::int64_t deadline_ns);
  void cover(std::uint64_t id, std::int64_t deadline_ns);
  void publish(int step);

  GuardSettings s_;
  rt::Clock* clock_;
  CommandOut* out_;
  LoopCounters* counters_;
  std::vector<float> u_init_, failsafe_, plan_;
  std::atomic<std::uint64_t> word_{0};
  std::atomic<std::int64_t> deadline_{0};
  std::atomic<int> steps_{0};
  std::atomic<bool> quit_{false};
  std::atomic<bool> stop_[2] = {false, false};
  std::uint64_t id_ = 0;  // loop thread
  std::int64_t state_seq_ = -1;
  transport::Command cmd_;  // the guard thread's own buffer
  rt::Wakeup wake_;
  std::thread thread_;
};

}  // namespace mppi::daemon
