// The real-time building blocks on their own: schedule, histogram, monitor, latest-value
// slot, SPSC ring, command gate.
#include <cstdint>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <thread>

#include "mppi/rt/clock.hpp"
#include "mppi/rt/command_gate.hpp"
#include "mppi/rt/deadline_monitor.hpp"
#include "mppi/rt/histogram.hpp"
#include "mppi/rt/latest_value.hpp"
#include "mppi/rt/schedule.hpp"
#include "mppi/rt/spsc_ring.hpp"

using namespace mppi::rt;

TEST(PeriodicSchedule, OnTimeCyclesStayOnTheGrid) {
  PeriodicSchedule s(20 * kNsPerMs);
  s.start(1000);
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(s.next_release_ns(), 1000 + k * 20 * kNsPerMs);
    s.begin(s.next_release_ns());
    EXPECT_FALSE(s.finish(s.release_ns() + 5 * kNsPerMs));
  }
  EXPECT_EQ(s.misses(), 0);
}

TEST(PeriodicSchedule, OverrunSkipsAndReanchors) {
  PeriodicSchedule s(20 * kNsPerMs);
  s.start(0);
  s.begin(0);
  // 55 ms of work in a 20 ms period: two whole periods lost, no catch-up burst.
  EXPECT_TRUE(s.finish(55 * kNsPerMs));
  EXPECT_EQ(s.misses(), 1);
  EXPECT_EQ(s.skipped_periods(), 2);
  EXPECT_EQ(s.next_release_ns(), 55 * kNsPerMs);  // re-anchored where the late cycle ended
  s.begin(55 * kNsPerMs);
  EXPECT_FALSE(s.finish(56 * kNsPerMs));
  EXPECT_EQ(s.next_release_ns(), 75 * kNsPerMs);  // the new grid, not 60 or 80
}

TEST(Histogram, ExactExtremesAndP99) {
  Histogram h(1000, 1000);  // 1 us bins, 1 ms range
  for (int i = 1; i <= 100; ++i) h.add(i * 1000);  // 1..100 us
  const auto s = h.summary();
  EXPECT_EQ(s.count, 100);
  EXPECT_DOUBLE_EQ(s.min_ms, 0.001);
  EXPECT_DOUBLE_EQ(s.max_ms, 0.1);
  EXPECT_NEAR(s.mean_ms, 0.0505, 1e-12);
  EXPECT_NEAR(s.p99_ms, 0.1, 0.0011);  // the 99th of 100 values, to one bin
  h.add(5 * kNsPerS);                  // past the range: counted, max exact
  EXPECT_DOUBLE_EQ(h.summary().max_ms, 5000.0);
  h.clear();
  EXPECT_EQ(h.count(), 0);
}

TEST(DeadlineMonitor, CountsMissesRunsAndWindows) {
  DeadlineMonitor m(20 * kNsPerMs);
  std::int64_t t = 0;
  const bool missed[] = {false, true, true, false, true, false};
  for (bool miss : missed) {
    m.record(t, t + 2 * kNsPerMs, miss);
    t += 20 * kNsPerMs + (miss ? kNsPerMs : 0);
  }
  const auto total = m.total();
  EXPECT_EQ(total.cycles, 6);
  EXPECT_EQ(total.misses, 3);
  EXPECT_EQ(total.max_consecutive_misses, 2);
  EXPECT_EQ(total.consecutive_misses, 0);
  EXPECT_EQ(total.period.count, 5);
  EXPECT_NEAR(total.period.max_ms, 21.0, 1e-9);
  EXPECT_NEAR(total.jitter.max_ms, 1.0, 1e-9);
  EXPECT_NEAR(total.compute.mean_ms, 2.0, 1e-9);
  m.reset_window();
  EXPECT_EQ(m.window().compute.count, 0);
  EXPECT_EQ(m.window().misses, 3);  // counters run since start
  EXPECT_EQ(m.total().compute.count, 6);
}

TEST(DeadlineMonitor, AMissWhoseWorkFitInAPeriodStartedLate) {
  DeadlineMonitor m(20 * kNsPerMs);
  m.record(0, 5 * kNsPerMs, false);
  // Woken 17 ms late, 5 ms of work: missed, though the work fit (the machine's fault).
  m.record(37 * kNsPerMs, 42 * kNsPerMs, true);
  // On time, 25 ms of work: the controller's own overrun.
  m.record(60 * kNsPerMs, 85 * kNsPerMs, true);
  // Exactly one period of work, late: still the start's fault.
  m.record(95 * kNsPerMs, 115 * kNsPerMs, true);
  const auto total = m.total();
  EXPECT_EQ(total.misses, 3);
  EXPECT_EQ(total.late_start_misses, 2);
  EXPECT_EQ(m.late_start_misses(), 2);
  EXPECT_EQ(m.window().late_start_misses, 2);
}

TEST(LatestValue, ReaderGetsNewestAndNothingTwice) {
  LatestValue<int> v;
  EXPECT_FALSE(v.update());
  v.write(1);
  v.write(2);
  EXPECT_TRUE(v.update());
  EXPECT_EQ(v.front(), 2);
  EXPECT_FALSE(v.update());
  EXPECT_EQ(v.front(), 2);
  v.write(3);
  EXPECT_TRUE(v.update());
  EXPECT_EQ(v.front(), 3);
}

TEST(LatestValue, NoTornReadsUnderConcurrency) {
  struct Pair {
    long a, b;
  };
  LatestValue<Pair> v;
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (long i = 1; i <= 200000; ++i) v.write(Pair{i, -i});
    done = true;
  });
  long last = 0, reads = 0;
  while (true) {
    const bool finished = done.load();
    if (v.update()) {
      const Pair p = v.front();
      ASSERT_EQ(p.a, -p.b);
      ASSERT_GE(p.a, last);  // never older than what was seen
      last = p.a;
      ++reads;
    } else if (finished) {
      break;
    }
  }
  writer.join();
  EXPECT_GT(reads, 0);
  EXPECT_EQ(last, 200000);  // the newest value always arrives
}

TEST(SpscRing, FifoAndFull) {
  SpscRing<int, 4> r;
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(r.push(i));
  EXPECT_FALSE(r.push(99));
  int x = -1;
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(r.pop(&x));
    EXPECT_EQ(x, i);
  }
  EXPECT_FALSE(r.pop(&x));
}

TEST(CommandGate, FiniteAndInsideLimitsOnly) {
  CommandGate g({0, 0}, {10, 20});
  const float ok[] = {0, 20, 10, 0};
  EXPECT_TRUE(g.pass(ok, 4));
  const float nan[] = {1, std::numeric_limits<float>::quiet_NaN()};
  EXPECT_FALSE(g.pass(nan, 2));
  const float inf[] = {std::numeric_limits<float>::infinity(), 1};
  EXPECT_FALSE(g.pass(inf, 2));
  const float high[] = {1, 21};
  EXPECT_FALSE(g.pass(high, 2));
  const float low[] = {-0.001f, 1};
  EXPECT_FALSE(g.pass(low, 2));
}
