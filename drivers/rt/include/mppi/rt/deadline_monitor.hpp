// Timing of the control loop: compute time, period between cycle starts, jitter
// (|period - nominal|), state-to-command latency, the state's age at the cycle's start, the
// lead the state was predicted over, where a cycle's time went (the wake-up: a state's
// arrival -> its cycle's start; the optimizer: the update inside the cycle), deadline misses
// and the current run of consecutive misses. Two views: a window, reset each time the status is published, and
// totals since start for the --stats summary. Nothing allocates after construction.
#pragma once

#include <cstdint>

#include "mppi/rt/histogram.hpp"

namespace mppi::rt {

struct TimingSummary {
  DurationSummary compute, period, jitter, latency, age, lead, wake, optimize;
  std::int64_t cycles = 0;
  std::int64_t misses = 0;
  // Misses of cycles whose own work (start -> end) fit in one period: the thread woke late
  // (the OS or the hypervisor did not run it on time; cyclictest measures the machine).
  // misses - late_start_misses are the controller's own overruns.
  std::int64_t late_start_misses = 0;
  std::int64_t consecutive_misses = 0;
  std::int64_t max_consecutive_misses = 0;
  double last_compute_ms = 0.0;
};

class DeadlineMonitor {
 public:
  // Bins cover four periods at period/2000 resolution (10 us at 50 Hz).
  explicit DeadlineMonitor(std::int64_t period_ns);

  // One cycle: it started at start_ns, its work ended at end_ns; missed says whether it
  // ended after its deadline. The first cycle has no period. A miss whose work took no more
  // than a period started late (late_start_misses).
  void record(std::int64_t start_ns, std::int64_t end_ns, bool missed);
  // Time from the state's sample to the command leaving, when a fresh command went out.
  void record_latency(std::int64_t ns);
  // The state's age at the start of a cycle that optimised from it, and the span it was
  // predicted over (sample time -> expected actuation).
  void record_age(std::int64_t ns);
  void record_lead(std::int64_t ns);
  // A state-triggered cycle: the state's arrival (inbox) -> the cycle's start (the loop's
  // thread ran). Together with age and compute, where state -> command went.
  void record_wake(std::int64_t ns);
  // The optimizer's update inside a cycle (Controller::iterate).
  void record_optimize(std::int64_t ns);

  TimingSummary window() const { return summarise(w_); }
  TimingSummary total() const { return summarise(t_); }
  void reset_window();

  std::int64_t period_ns() const { return period_; }
  std::int64_t consecutive_misses() const { return consecutive_; }
  std::int64_t misses() const { return misses_; }
  std::int64_t late_start_misses() const { return late_start_misses_; }
  std::int64_t cycles() const { return cycles_; }

 private:
  struct Set {
    Set(std::int64_t bin, int bins)
        : compute(bin, bins),
          period(bin, bins),
          jitter(bin, bins),
          latency(bin, bins),
          age(bin, bins),
          lead(bin, bins),
          wake(bin, bins),
          optimize(bin, bins) {}
    Histogram compute, period, jitter, latency, age, lead, wake, optimize;
  };
  TimingSummary summarise(const Set& s) const;
  void add(Histogram Set::*h, std::int64_t ns);  // into the window and the totals

  std::int64_t period_;
  Set w_, t_;
  std::int64_t last_start_ = -1;
  std::int64_t last_compute_ = 0;
  std::int64_t cycles_ = 0, misses_ = 0, late_start_misses_ = 0, consecutive_ = 0, max_consecutive_ = 0;
};

}  // namespace mppi::rt
