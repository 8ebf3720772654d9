// The work sizer (work_sizer.hpp): fed scripted compute times, it shrinks the rollout count
// when a window's p99 passes the target, grows it back when there is room, stays inside the
// floor and the ceiling, holds on a steady load inside the band and on a load proportional
// to the count; replay's pin and the ceiling of a live update; its settings. Then the loop on
// a fake clock whose compute is charged per rollout: the commands keep their rate while the
// count shrinks under a slow machine and grows back on a quiet one.
#include <gtest/gtest.h>
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/daemon/work_sizer.hpp"

using namespace mppi;
using mppi::test::FakeClock;
using mppi::test::FakeController;
using mppi::test::RecordingTransport;

namespace {

constexpr std::int64_t kMs = rt::kNsPerMs;
constexpr std::int64_t kPeriod = 20 * kMs;  // 50 Hz: the target 12 ms, the growth bound 7 ms

daemon::WorkSizerSettings on() {
  daemon::WorkSizerSettings s;
  s.enabled = true;
  return s;  // target 0.6, grow_below 0.35, floor 512, window 50, x0.5 / x1.25
}

// A sizer and a controller of K = 4096 (quantum 16) it sizes; step() runs one update of
// `compute_ns` as the loop does.
struct Sized {
  explicit Sized(daemon::WorkSizerSettings s = on(), int k = 4096) : sizer(s, kPeriod) {
    ctl.set_rollouts(k);
    ctl.quantum = 16;
  }
  int step(std::int64_t compute_ns) {
    sizer.before_update(ctl);
    const int ran = ctl.active_rollouts();
    sizer.after_update(compute_ns);
    return ran;
  }
  // The count the next update runs.
  int next() {
    sizer.before_update(ctl);
    return ctl.active_rollouts();
  }
  FakeClock clock;
  FakeController ctl{&clock};
  daemon::WorkSizer sizer;
};

// The log lines the sizer writes, through a ring buffer on the default logger.
struct LogCapture {
  LogCapture() : sink(std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(64)), was(spdlog::default_logger()) {
    spdlog::set_default_logger(std::make_shared<spdlog::logger>("work", sink));
  }
  ~LogCapture() { spdlog::set_default_logger(was); }
  std::vector<std::string> lines() { return sink->last_formatted(); }
  std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> sink;
  std::shared_ptr<spdlog::logger> was;
};

TEST(WorkSizer, StartsAtTheCeilingAndHoldsASteadyLoadInsideTheBand) {
  Sized s;
  for (int i = 0; i < 1000; ++i) EXPECT_EQ(s.step(i % 2 ? 7 * kMs : 12 * kMs), 4096);  // 7 and 12 ms: in the band
  EXPECT_EQ(s.sizer.changes(), 0);
  EXPECT_EQ(s.ctl.active_changes, 0);  // never even set: it was at the count already
}

TEST(WorkSizer, ShrinksAtTheFirstCycleThatPutsTheWindowsP99OverTheTarget) {
  Sized s;
  LogCapture log;
  for (int i = 0; i < 20; ++i) s.step(9 * kMs);
  EXPECT_EQ(s.next(), 4096);
  s.step(12 * kMs + 1);  // a window of 50: one cycle over the target is its p99
  EXPECT_EQ(s.next(), 2048);
  EXPECT_EQ(s.sizer.changes(), 1);
  ASSERT_FALSE(log.lines().empty());
  EXPECT_NE(log.lines().back().find("work: 4096 -> 2048 rollouts"), std::string::npos) << log.lines().back();
  EXPECT_NE(log.lines().back().find("over the target 12.00 ms"), std::string::npos) << log.lines().back();
}

TEST(WorkSizer, AWindowOf100ShrinksAtItsSecondCycleOverTheTarget) {
  daemon::WorkSizerSettings w = on();
  w.window = 100;  // p99 of 100: the 99th, so two samples over the target put it over
  Sized s(w);
  s.step(30 * kMs);
  for (int i = 0; i < 50; ++i) s.step(5 * kMs);
  EXPECT_EQ(s.next(), 4096);
  s.step(30 * kMs);
  EXPECT_EQ(s.next(), 2048);
}

TEST(WorkSizer, GrowsBackByWholeWindowsBelowTheBoundAndNeverPastTheCeiling) {
  Sized s;
  s.step(15 * kMs);
  ASSERT_EQ(s.next(), 2048);
  std::vector<int> sizes;
  for (int w = 0; w < 10; ++w) {
    for (int i = 0; i < 49; ++i) s.step(3 * kMs);
    EXPECT_EQ(s.next(), sizes.empty() ? 2048 : sizes.back()) << "a window not yet whole: no change";
    s.step(3 * kMs);
    sizes.push_back(s.next());
  }
  // x1.25, rounded up to the quantum of 16, then the ceiling.
  EXPECT_EQ(sizes, (std::vector<int>{2560, 3200, 4000, 4096, 4096, 4096, 4096, 4096, 4096, 4096}));
  EXPECT_EQ(s.sizer.changes(), 5);
}

TEST(WorkSizer, AWindowWithAnyCycleAtTheGrowthBoundDoesNotGrow) {
  Sized s;
  s.step(15 * kMs);
  for (int i = 0; i < 49; ++i) s.step(3 * kMs);
  s.step(7 * kMs);  // the p99 of the window: not below 7 ms
  EXPECT_EQ(s.next(), 2048);
  for (int i = 0; i < 50; ++i) s.step(6 * kMs);
  EXPECT_EQ(s.next(), 2560);
}

TEST(WorkSizer, NeverBelowTheFloor) {
  Sized s;
  for (int i = 0; i < 500; ++i) s.step(40 * kMs);  // a machine that cannot keep up at any count
  EXPECT_EQ(s.next(), 512);
  EXPECT_EQ(s.sizer.changes(), 3);  // 2048, 1024, 512
  // A floor that is no multiple of the quantum, and a ceiling below the floor.
  daemon::WorkSizerSettings w = on();
  w.floor = 700;
  Sized odd(w);
  for (int i = 0; i < 500; ++i) odd.step(40 * kMs);
  EXPECT_EQ(odd.next(), 700);
  Sized small(on(), 300);
  for (int i = 0; i < 500; ++i) small.step(40 * kMs);
  EXPECT_EQ(small.next(), 300);
  EXPECT_EQ(small.sizer.changes(), 0);
}

// Compute proportional to the count (with +-10 % of jitter from a fixed sequence), for
// per-rollout costs across the range: the count settles and never moves again, and where it
// settles its compute is inside the band or it is at the floor or the ceiling.
TEST(WorkSizer, AProportionalLoadSettlesWithoutSwinging) {
  for (double us_per_rollout = 0.5; us_per_rollout < 40.0; us_per_rollout *= 1.37) {
    Sized s;
    std::uint32_t r = 12345u;
    std::int64_t changes_at_half = 0;
    int reversals = 0, last_dir = 0, last = 4096;
    for (int i = 0; i < 4000; ++i) {
      r = r * 1664525u + 1013904223u;
      const double jitter = 0.9 + 0.2 * static_cast<double>(r >> 8) / 16777216.0;
      const int n = s.step(static_cast<std::int64_t>(us_per_rollout * 1e3 * s.next() * jitter));
      if (n != last) {
        const int dir = n > last ? 1 : -1;
        reversals += last_dir != 0 && dir != last_dir;
        last_dir = dir;
        last = n;
      }
      if (i == 2000) changes_at_half = s.sizer.changes();
    }
    const std::string at = "us per rollout " + std::to_string(us_per_rollout);
    EXPECT_EQ(s.sizer.changes(), changes_at_half) << at << ": still changing";
    EXPECT_LE(reversals, 1) << at;
    const double mean_ms = us_per_rollout * 1e-3 * s.next();
    EXPECT_TRUE(0.9 * mean_ms <= 12.0 || s.next() == 512) << at << ": settled at " << s.next();
    EXPECT_TRUE(1.1 * mean_ms >= 7.0 || s.next() == 4096) << at << ": settled at " << s.next();
  }
}

TEST(WorkSizer, OffItPinsMppiRollouts) {
  daemon::WorkSizerSettings w = on();
  w.enabled = false;
  Sized s(w);
  s.ctl.set_active_rollouts(100);  // whatever ran before
  for (int i = 0; i < 200; ++i) EXPECT_EQ(s.step(40 * kMs), 4096);
  EXPECT_EQ(s.sizer.changes(), 0);
}

TEST(WorkSizer, AControllerWithoutRolloutsIsLeftAlone) {
  Sized s;
  s.ctl.quantum = 0;  // DDP: Controller::rollout_quantum() 0
  for (int i = 0; i < 200; ++i) EXPECT_EQ(s.step(40 * kMs), 4096);
  EXPECT_EQ(s.sizer.changes(), 0);
  EXPECT_EQ(s.ctl.active_changes, 0);
}

TEST(WorkSizer, ReplaysPinnedCountsWithoutDeciding) {
  Sized s;
  s.sizer.pin(1000);
  for (int i = 0; i < 200; ++i) EXPECT_EQ(s.step(40 * kMs), 1000);
  s.sizer.pin(9000);  // at most the ceiling
  EXPECT_EQ(s.step(40 * kMs), 4096);
  EXPECT_EQ(s.sizer.changes(), 0);
  s.sizer.pin(0);  // deciding again, from where it was
  s.step(40 * kMs);
  EXPECT_EQ(s.next(), 2048);
}

TEST(WorkSizer, FollowsTheCeilingOfALiveUpdate) {
  Sized s;
  s.step(15 * kMs);
  ASSERT_EQ(s.next(), 2048);
  s.ctl.set_rollouts(1024);  // a controller built with mppi.rollouts = 1024 swapped in
  EXPECT_EQ(s.next(), 1024);
  for (int i = 0; i < 500; ++i) s.step(1 * kMs);
  EXPECT_EQ(s.next(), 1024);
  s.ctl.set_rollouts(8192);
  EXPECT_EQ(s.next(), 1024);  // kept, then grown by windows
  for (int i = 0; i < 50; ++i) s.step(1 * kMs);
  EXPECT_EQ(s.next(), 1280);
}

// ---- settings ------------------------------------------------------------------------

daemon::DaemonSettings parse(const std::string& yaml) {
  return daemon::parse_daemon_settings(YAML::Load(yaml), "quadrotor_forest", 4);
}

std::string error_of(const std::string& yaml) {
  try {
    parse(yaml);
  } catch (const app::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(WorkSizerSettings, OnByDefaultForTheDaemonOffForALoop) {
  EXPECT_TRUE(parse("{}").loop.work.enabled);
  EXPECT_TRUE(daemon::parse_daemon_settings(YAML::Node(), "quadrotor_forest", 4).loop.work.enabled);
  EXPECT_FALSE(daemon::LoopSettings{}.work.enabled);
  const auto d = parse("work: {enabled: false, target: 0.5, grow_below: 0.3, floor: 256, window: 100, shrink: 0.75, "
                       "grow: 1.5}");
  EXPECT_FALSE(d.loop.work.enabled);
  EXPECT_DOUBLE_EQ(d.loop.work.target, 0.5);
  EXPECT_DOUBLE_EQ(d.loop.work.grow_below, 0.3);
  EXPECT_EQ(d.loop.work.floor, 256);
  EXPECT_EQ(d.loop.work.window, 100);
  EXPECT_DOUBLE_EQ(d.loop.work.shrink, 0.75);
  EXPECT_DOUBLE_EQ(d.loop.work.grow, 1.5);
}

TEST(WorkSizerSettings, BadValuesNameTheField) {
  EXPECT_EQ(error_of("work: {target: 0}"), "daemon.work.target: must be in [0.01, 1], got 0");
  EXPECT_EQ(error_of("work: {target: nan}").rfind("daemon.work.target:", 0), 0u);
  EXPECT_EQ(error_of("work: {floor: 0}"), "daemon.work.floor: must be in [1, 67108864], got 0");
  EXPECT_EQ(error_of("work: {window: 2.5}"), "daemon.work.window: must be a whole number, got 2.5");
  EXPECT_EQ(error_of("work: {shrink: 1}"), "daemon.work.shrink: must be in [0.1, 0.95], got 1");
  EXPECT_EQ(error_of("work: {grow: 1}"), "daemon.work.grow: must be in [1.05, 4], got 1");
  EXPECT_EQ(error_of("work: {grow_below: 0.5}"), "daemon.work.grow_below: must be below work.target / work.grow (0.48), got 0.5");
  EXPECT_EQ(error_of("work: {enabled: maybe}"), "daemon.work.enabled: cannot read 'maybe'");
  EXPECT_EQ(error_of("work: {floors: 3}"), "daemon.work.floors: unknown field");
  EXPECT_EQ(error_of("work: 5"), "daemon.work: expected a map");
  EXPECT_EQ(error_of("work: {floor: [1]}"), "daemon.work.floor: expected a scalar");
}

// ---- the loop ------------------------------------------------------------------------

// A real-time loop on a fake clock, its controller's compute charged per active rollout: 6 us
// (24.6 ms at K = 4096, past the 20 ms period) for the first 300 cycles, then 1 us (a quiet
// machine). One command a cycle throughout; the count shrinks within the first cycles to one
// whose compute fits, holds there, and grows back to K once there is room.
TEST(WorkSizerLoop, TheCommandStreamKeepsItsRateWhileTheCountFollowsTheMachine) {
  daemon::LoopSettings ls;
  ls.work = on();
  ls.status_hz = 1.0;
  FakeClock clock;
  RecordingTransport tx;
  FakeController ctl{&clock};
  ctl.set_rollouts(4096);
  ctl.quantum = 16;
  std::int64_t per_rollout_ns = 6000;
  ctl.compute_ns = [&](int) { return per_rollout_ns * ctl.active_rollouts(); };
  transport::Inbox::Expect e;
  e.nx = 16;
  e.vehicles = 1;
  e.model = 1;
  e.restart_after_ns = 100 * kMs;
  transport::Inbox inbox(e);
  daemon::ControlLoop loop(&ctl, &clock, &tx, &inbox, ls);
  std::atomic<bool> run{false};
  auto cycles = [&](int n) {
    for (int i = 0; i < n; ++i) {
      auto& s = inbox.state_buffer();
      mppi::test::shape_state(s, static_cast<std::int64_t>(tx.commands.size()) + 1);
      s.recv_ns = clock.now_ns();
      s.sample_utime = clock.now_ns() / 1000;
      for (int j = 0; j < 16; ++j) s.x[j] = 1.0f;
      inbox.offer_state();
      ASSERT_TRUE(loop.step_realtime(run));
    }
  };
  cycles(300);
  ASSERT_EQ(tx.commands.size(), 300u);
  const auto misses_slow = loop.timing_total().misses;
  EXPECT_LE(misses_slow, 1) << "the first cycle over the period shrinks the count";
  // Settled: 1280 rollouts (7.7 ms: in the band) after 2048 (12.3 ms) and 1024 (6.1 ms).
  EXPECT_EQ(tx.commands.back().rollouts, 1280);
  EXPECT_EQ(tx.commands.back().mode, transport::Mode::kNormal);
  for (std::size_t i = 150; i < 300; ++i) EXPECT_EQ(tx.commands[i].rollouts, 1280) << "cycle " << i;

  per_rollout_ns = 1000;  // the machine is quiet again
  cycles(400);
  ASSERT_EQ(tx.commands.size(), 700u);
  EXPECT_EQ(loop.timing_total().misses, misses_slow);
  EXPECT_EQ(tx.commands.back().rollouts, 4096);
  // Every command answered its own state in its own cycle, one per period.
  for (std::size_t i = 0; i < tx.commands.size(); ++i)
    EXPECT_EQ(tx.commands[i].state_seq, static_cast<std::int64_t>(i) + 1) << "cycle " << i;
  for (std::size_t i = 4; i < clock.sleeps.size(); ++i)  // past the first cycles' miss
    EXPECT_EQ(clock.sleeps[i] - clock.sleeps[i - 1], kPeriod) << "release " << i;
  // The sizes in order: down, down, up to the band; then up by windows to K.
  std::vector<int> sizes{tx.commands.front().rollouts};
  for (const auto& c : tx.commands)
    if (c.rollouts != sizes.back()) sizes.push_back(c.rollouts);
  EXPECT_EQ(sizes, (std::vector<int>{4096, 2048, 1024, 1280, 1600, 2000, 2512, 3152, 3952, 4096}));
  ASSERT_FALSE(tx.statuses.empty());
  EXPECT_EQ(tx.statuses.back().rollouts, 4096);
  EXPECT_EQ(tx.statuses.back().rollouts_active, 4096);
  EXPECT_EQ(tx.statuses.back().work_size_changes, static_cast<std::int64_t>(sizes.size()) - 1);
  EXPECT_EQ(loop.work_sizer().changes(), static_cast<std::int64_t>(sizes.size()) - 1);
  EXPECT_EQ(ctl.mid_cycle_changes, 0);
}

}  // namespace
