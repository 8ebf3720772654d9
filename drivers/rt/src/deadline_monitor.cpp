#include "mppi/rt/deadline_monitor.hpp"

#include <algorithm>
#include <cstdint>
#include <cstdlib>

namespace mppi::rt {

namespace {
constexpr int kBins = 8000;
std::int64_t bin_for(std::int64_t period_ns) { return std::max<std::int64_t>(1000, period_ns * 4 / kBins); }
}  // namespace

DeadlineMonitor::DeadlineMonitor(std::int64_t period_ns)
    : period_(period_ns), w_(bin_for(period_ns), kBins), t_(bin_for(period_ns), kBins) {}

void DeadlineMonitor::record(std::int64_t start_ns, std::int64_t end_ns, bool missed) {
  last_compute_ = end_ns - start_ns;
  w_.compute.add(last_compute_);
  t_.compute.add(last_compute_);
  if (last_start_ >= 0) {
    const std::int64_t period = start_ns - last_start_;
    const std::int64_t jitter = std::llabs(period - period_);
    w_.period.add(period);
    t_.period.add(period);
    w_.jitter.add(jitter);
    t_.jitter.add(jitter);
  }
  last_start_ = start_ns;
  ++cycles_;
  if (missed) {
    ++misses_;
    if (last_compute_ <= period_) ++late_start_misses_;
    ++consecutive_;
    max_consecutive_ = std::max(max_consecutive_, consecutive_);
  } else {
    consecutive_ = 0;
  }
}

void DeadlineMonitor::add(Histogram Set::*h, std::int64_t ns) {
  (w_.*h).add(ns);
  (t_.*h).add(ns);
}

void DeadlineMonitor::record_latency(std::int64_t ns) { add(&Set::latency, ns); }

void DeadlineMonitor::record_age(std::int64_t ns) { add(&Set::age, ns); }

void DeadlineMonitor::record_lead(std::int64_t ns) { add(&Set::lead, ns); }

void DeadlineMonitor::record_wake(std::int64_t ns) { add(&Set::wake, ns); }

void DeadlineMonitor::record_optimize(std::int64_t ns) { add(&Set::optimize, ns); }

void DeadlineMonitor::reset_window() {
  for (Histogram* h : {&w_.compute, &w_.period, &w_.jitter, &w_.latency, &w_.age, &w_.lead, &w_.wake, &w_.optimize})
    h->clear();
}

TimingSummary DeadlineMonitor::summarise(const Set& s) const {
  TimingSummary out;
  out.compute = s.compute.summary();
  out.period = s.period.summary();
  out.jitter = s.jitter.summary();
  out.latency = s.latency.summary();
  out.age = s.age.summary();
  out.lead = s.lead.summary();
  out.wake = s.wake.summary();
  out.optimize = s.optimize.summary();
  out.cycles = cycles_;
  out.misses = misses_;
  out.late_start_misses = late_start_misses_;
  out.consecutive_misses = consecutive_;
  out.max_consecutive_misses = max_consecutive_;
  out.last_compute_ms = static_cast<double>(last_compute_) * 1e-6;
  return out;
}

}  // namespace mppi::rt
