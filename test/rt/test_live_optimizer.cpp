// Live optimizer updates (mppi.* while the daemon runs) on the fake clock: the checks and
// their messages, the plan resampling, the swap between two cycles with the plan and the
// task state carried over (scripted controllers), the builder thread under a cycling loop,
// and the real quadrotor controller continuing bit for bit across a rebuild.
#include <cstdint>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "mppi/settings_table.hpp"
#include "source_dir.hpp"

using namespace mppi;
using daemon::LiveOptimizer;
using mppi::test::FakeClock;
using mppi::test::FakeController;
using mppi::test::RecordingTransport;
using transport::Mode;

namespace {

transport::ParamUpdate update(const char* key, double v, std::int64_t seq = 0) {
  transport::ParamUpdate p;
  std::strncpy(p.key, key, sizeof(p.key) - 1);
  p.value = v;
  p.seq = seq;
  return p;
}

MppiSettings quad_settings() {
  MppiSettings s;
  s.rollouts = 256;
  s.horizon = 50;
  s.sigma = {100, 100, 100, 100};
  s.u_min = {0, 0, 0, 0};
  s.u_max = {6000, 6000, 6000, 6000};
  s.u_init = {3000, 3000, 3000, 3000};
  s.chunk_rollouts = 64;
  return s;
}

daemon::LiveSettings limits() {
  daemon::LiveSettings l;
  l.max_horizon = 200;
  l.max_rollouts = 8192;
  l.max_threads = 2;
  return l;
}

// A control loop with a live optimizer, on a fake clock, publishing into memory (members are
// destroyed in reverse: the loop first).
struct LiveLoopParts {
  FakeClock clock;
  RecordingTransport tx;
  std::unique_ptr<LiveOptimizer> live;
  std::unique_ptr<transport::Inbox> inbox;
  std::unique_ptr<daemon::ControlLoop> loop;
};

// A loop around fake controllers built by a live-update factory (commands base + 10 n + i,
// the first controller's base 1000, every rebuilt one 5000).
struct LiveRig : LiveLoopParts {
  explicit LiveRig(LiveOptimizer::Mode mode, std::function<void()> on_build = {}) {
    daemon::LoopSettings s;
    s.latency.compensate = false;  // the plan is shifted only by the cycles themselves
    auto first = std::make_unique<FakeController>(&clock, 10, 1000.0f);
    live = std::make_unique<LiveOptimizer>(
        std::move(first),
        [this, on_build](const MppiSettings& m) {
          if (on_build) on_build();
          auto f = std::make_unique<FakeController>(&clock, m.horizon, 5000.0f);
          f->use_settings(m);
          ++built;
          return f;
        },
        limits(), mode);
    inbox = std::make_unique<transport::Inbox>(expect());
    loop = std::make_unique<daemon::ControlLoop>(live->current(), &clock, &tx, inbox.get(), s);
    loop->set_live_optimizer(live.get());
  }
  static transport::Inbox::Expect expect() {
    transport::Inbox::Expect e;
    e.nx = 16;
    e.model = 1;
    return e;
  }
  void fresh_cycle() {
    auto& st = inbox->state_buffer();
    test::shape_state(st, ++seq);
    st.recv_ns = clock.now_ns();
    st.sample_utime = clock.now_ns() / 1000;
    for (int i = 0; i < 16; ++i) st.x[i] = 1.0f;
    inbox->offer_state();
    ASSERT_TRUE(loop->step_realtime(run));
  }
  FakeController& fake() { return static_cast<FakeController&>(loop->controller()); }

  std::atomic<bool> run{false};
  std::atomic<int> built{0};
  std::int64_t seq = 0;
};

}  // namespace

TEST(LiveUpdate, ChecksEveryFieldAndNamesItWithTheReason) {
  const auto lim = limits();
  auto apply = [&](const char* key, double v, MppiSettings* s) {
    return daemon::apply_live_update(s, key, v, 4, lim);
  };
  MppiSettings s = quad_settings();
  EXPECT_EQ(apply("mppi.rollouts", 512, &s), "");
  EXPECT_EQ(s.rollouts, 512);
  EXPECT_EQ(apply("mppi.horizon", 80, &s), "");
  EXPECT_EQ(apply("mppi.lambda", 0.5, &s), "");
  EXPECT_EQ(apply("mppi.nu", 2.0, &s), "");
  EXPECT_EQ(apply("mppi.sigma", 50.0, &s), "");
  EXPECT_EQ(s.sigma, (std::vector<float>{50, 50, 50, 50}));
  EXPECT_EQ(apply("mppi.sigma[2]", 70.0, &s), "");
  EXPECT_EQ(s.sigma, (std::vector<float>{50, 50, 70, 50}));
  EXPECT_EQ(apply("mppi.threads", 1, &s), "");
  EXPECT_EQ(apply("mppi.seed", 77, &s), "");
  EXPECT_EQ(s.seed, 77u);
  EXPECT_EQ(apply("mppi.dt", 0.01, &s), "");
  EXPECT_FLOAT_EQ(s.dt, 0.01f);

  const MppiSettings before = s;
  EXPECT_EQ(apply("mppi.rollouts", 0, &s), "mppi.rollouts: must be >= 1, got 0");
  EXPECT_EQ(apply("mppi.rollouts", 12.5, &s), "mppi.rollouts: must be an integer, got 12.5");
  EXPECT_EQ(apply("mppi.rollouts", 10000, &s), "mppi.rollouts: must be <= 8192 (daemon.live.max_rollouts), got 10000");
  EXPECT_EQ(apply("mppi.horizon", 201, &s), "mppi.horizon: must be <= 200 (daemon.live.max_horizon), got 201");
  EXPECT_EQ(apply("mppi.horizon", 1, &s), "mppi.horizon: must be >= 2, got 1");
  EXPECT_EQ(apply("mppi.threads", 3, &s), "mppi.threads: must be <= 2 (the CPUs this process may use), got 3");
  EXPECT_EQ(apply("mppi.lambda", -1, &s), "mppi.lambda: must be > 0");
  EXPECT_EQ(apply("mppi.nu", 0.5, &s), "mppi.nu: must be >= 1");
  EXPECT_EQ(apply("mppi.lambda", std::nan(""), &s), "mppi.lambda: must be finite");
  EXPECT_EQ(apply("mppi.sigma[4]", 1.0, &s), "mppi.sigma[4]: the channel index must be in [0, 3]");
  EXPECT_EQ(apply("mppi.sigma", 0.0, &s), "mppi.sigma: every value must be > 0");
  EXPECT_EQ(apply("mppi.smoothing_window", 4, &s), "mppi.smoothing_window: must be odd and >= 1");
  // A value valid alone that breaks another field: both named.
  EXPECT_EQ(apply("mppi.rollouts", 32, &s),
            "mppi.rollouts: makes the settings invalid: mppi.chunk_rollouts: must lie in [0, rollouts]");
  EXPECT_NE(apply("mppi.u_max", 7000, &s).find("mppi.u_max: not tunable at run time"), std::string::npos);
  EXPECT_NE(apply("mppi.simd", 1, &s).find("not tunable at run time"), std::string::npos);
  EXPECT_NE(apply("mppi.bogus", 1, &s).find("mppi.bogus: unknown field"), std::string::npos);
  EXPECT_NE(apply("mppi.sigma[2", 1, &s).find("mppi.sigma[2: unknown field"), std::string::npos);  // not closed
  EXPECT_EQ(apply("mppi.sigma[x]", 1, &s), "mppi.sigma[x]: the channel index must be in [0, 3]");
  EXPECT_EQ(apply("mppi.sigma[]", 1, &s), "mppi.sigma[]: the channel index must be in [0, 3]");
  // Nothing refused changed anything.
  EXPECT_EQ(s.rollouts, before.rollouts);
  EXPECT_EQ(s.horizon, before.horizon);
  EXPECT_EQ(s.lambda, before.lambda);
  EXPECT_EQ(s.sigma, before.sigma);
  EXPECT_EQ(s.threads, before.threads);
}

// The live and fixed keys are the optimizer table's (mppi/settings.hpp): every live row
// takes a live update (or names a range, never "not tunable"), every fixed row is refused
// naming it, and an unknown key lists exactly the table's live keys.
TEST(LiveUpdate, TheLiveKeysAreTheOptimizerTablesLiveRows) {
  const auto lim = limits();
  const MppiSettings base = quad_settings();
  std::vector<std::string> live;
  int rows = 0;
  visit_settings(base, [&](const SettingSpec& r, const auto&) {
    ++rows;
    MppiSettings s = base;
    const std::string key = std::string("mppi.") + r.name;
    const std::string err = daemon::apply_live_update(&s, key, 3, 4, lim);
    if (r.live == LiveBound::kFixed) {
      EXPECT_EQ(err.rfind(key + ": not tunable at run time", 0), 0u) << err;
      return;
    }
    live.push_back(r.name);
    EXPECT_EQ(err.find("not tunable"), std::string::npos) << err;
    EXPECT_EQ(err.find("unknown field"), std::string::npos) << err;
  });
  EXPECT_EQ(rows, 20);
  EXPECT_EQ(live, (std::vector<std::string>{"rollouts", "horizon", "dt", "substeps", "lambda", "nu",
                                            "control_cost_scale", "smoothing_window", "threads", "chunk_rollouts",
                                            "min_rollouts", "sigma", "seed"}));
  MppiSettings s = base;
  const std::string unknown = daemon::apply_live_update(&s, "mppi.bogus", 1, 4, lim);
  EXPECT_EQ(unknown, "mppi.bogus: unknown field (tunable at run time: " + live_setting_names() + ")");
  for (const std::string& name : live) EXPECT_NE(live_setting_names().find(name), std::string::npos) << name;
  EXPECT_NE(live_setting_names().find("sigma[j]"), std::string::npos);  // a list row: its channels too
  EXPECT_EQ(live_setting_names().find("u_min"), std::string::npos);
  // The row's live bound: the table's constant, daemon.live's limits.
  EXPECT_EQ(daemon::apply_live_update(&s, "mppi.substeps", 1001, 4, lim), "mppi.substeps: must be <= 1000, got 1001");
  EXPECT_EQ(daemon::apply_live_update(&s, "mppi.chunk_rollouts", 8193, 4, lim),
            "mppi.chunk_rollouts: must be <= 8192 (daemon.live.max_rollouts), got 8193");
  EXPECT_EQ(daemon::apply_live_update(&s, "mppi.seed", -1, 4, lim), "mppi.seed: must be an integer in [0, 9007199254740992]");
}

// The loop's daemon.* keys: the daemon table's live rows are routed to the loop (answered
// with their own reasons), every other row is refused naming the live rows.
TEST(LiveUpdate, TheLoopsLiveKeysAreTheDaemonTablesLiveRows) {
  LiveRig r(LiveOptimizer::Mode::kSynchronous);
  std::vector<std::pair<std::string, bool>> keys;
  const daemon::DaemonSettings defaults;
  daemon::visit_daemon_settings(defaults, [&](const daemon::DaemonKey& k, const auto&) {
    keys.emplace_back(std::string("daemon.") + k.path, k.live);
  });
  std::int64_t seq = 0;
  for (const auto& [key, is_live] : keys) {
    r.inbox->offer_param(update(key.c_str(), 0.0, ++seq));
    if (seq % 32 == 0) r.fresh_cycle();  // the inbox queues 64
  }
  r.fresh_cycle();
  ASSERT_EQ(r.tx.param_results.size(), keys.size());
  const std::string refusal = ": not tunable at run time (tunable: " + daemon::live_daemon_keys() + ")";
  EXPECT_EQ(daemon::live_daemon_keys(),
            "daemon.state_timeout_ms, daemon.failsafe_timeout_ms, daemon.identify, daemon.restart_estimates");
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const auto& got = r.tx.param_results[i];
    EXPECT_STREQ(got.key, keys[i].first.c_str());
    const std::string reason = got.reason;
    if (keys[i].second)
      EXPECT_EQ(reason.find("not tunable"), std::string::npos) << reason;
    else
      EXPECT_EQ(reason, (keys[i].first + refusal).substr(0, sizeof(got.reason) - 1));
  }
}

TEST(LiveUpdate, ResampleKeepsTheStepsAndFillsWithUInit) {
  const float fill[2] = {-1, -2};
  std::vector<float> in;
  for (int i = 0; i < 5; ++i) in.insert(in.end(), {static_cast<float>(i), static_cast<float>(10 + i)});
  std::vector<float> out(16);
  daemon::resample_plan(in.data(), 5, 0.02, out.data(), 8, 0.02, 2, fill);  // longer
  EXPECT_EQ(out, (std::vector<float>{0, 10, 1, 11, 2, 12, 3, 13, 4, 14, -1, -2, -1, -2, -1, -2}));
  out.assign(6, 0.0f);
  daemon::resample_plan(in.data(), 5, 0.02, out.data(), 3, 0.02, 2, fill);  // shorter
  EXPECT_EQ(out, (std::vector<float>{0, 10, 1, 11, 2, 12}));
  // Half the step: each old step covers two new ones; double: every other old step.
  out.assign(20, 0.0f);
  daemon::resample_plan(in.data(), 5, 0.02, out.data(), 10, 0.01, 2, fill);
  EXPECT_EQ(out, (std::vector<float>{0, 10, 0, 10, 1, 11, 1, 11, 2, 12, 2, 12, 3, 13, 3, 13, 4, 14, 4, 14}));
  out.assign(8, 0.0f);
  daemon::resample_plan(in.data(), 5, 0.02, out.data(), 4, 0.04, 2, fill);
  // (a midpoint on an old boundary takes the later step; past the old end, u_init)
  EXPECT_EQ(out, (std::vector<float>{1, 11, 3, 13, -1, -2, -1, -2}));
}

TEST(LiveUpdate, SwapHappensBetweenCyclesWithThePlanAndTaskStateCarriedOver) {
  LiveRig r(LiveOptimizer::Mode::kSynchronous);
  // A goal through the inbox, as mppid gets it (the loop sets the controller's inputs).
  auto& ref = r.inbox->reference_buffer();
  ref.seq = 1;
  ref.vehicle_count = 1;
  ref.goals[0][0] = 42.0f;
  r.inbox->offer_reference();
  for (int k = 0; k < 5; ++k) r.fresh_cycle();
  FakeController* old = &r.fake();
  ASSERT_EQ(old->iterations, 5);
  // The old plan after cycle 5, shifted once: 1000 + 50 + (i + 1), then u_init.
  const std::vector<float> old_plan = old->plan();
  r.inbox->offer_param(update("mppi.horizon", 15, 7));
  r.inbox->offer_param(update("mppi.rollouts", 64, 8));
  const std::size_t before = r.tx.commands.size();
  r.fresh_cycle();
  FakeController& now = r.fake();
  ASSERT_NE(&now, old);
  EXPECT_EQ(r.built.load(), 1);  // both updates in one build
  EXPECT_EQ(now.horizon(), 15);
  EXPECT_EQ(now.settings().rollouts, 64);
  EXPECT_EQ(now.adopted_from, old);
  EXPECT_FLOAT_EQ(now.inputs.goals[0][0], 42.0f);
  // The new controller's first warm start: the old plan's 10 steps, then u_init.
  ASSERT_EQ(now.plan_at_iterate.size(), 60u);
  for (int i = 0; i < 15; ++i)
    for (int j = 0; j < 4; ++j)
      EXPECT_FLOAT_EQ(now.plan_at_iterate[static_cast<std::size_t>(i * 4 + j)],
                      i < 10 ? old_plan[static_cast<std::size_t>(i * 4 + j)] : 3000.0f)
          << "step " << i;
  // The cycle that swapped ran the new controller: its command is the new one's.
  ASSERT_EQ(r.tx.commands.size(), before + 1);
  EXPECT_EQ(r.tx.commands.back().mode, Mode::kNormal);
  EXPECT_FLOAT_EQ(r.tx.commands.back().u[0], 5000.0f + 10.0f);
  // Each update answered: applied, from the cycle that ran with it (index 5, the sixth).
  ASSERT_EQ(r.tx.param_results.size(), 2u);
  for (const auto& res : r.tx.param_results) {
    EXPECT_TRUE(res.applied);
    EXPECT_EQ(res.cycle, 5);
    EXPECT_STREQ(res.reason, "");
  }
  EXPECT_EQ(r.tx.param_results[0].update_seq, 7);
  EXPECT_STREQ(r.tx.param_results[1].key, "mppi.rollouts");
  EXPECT_EQ(r.loop->counters().params_applied.load(), 2);
  // The status reports the new size; the plan message the new horizon.
  for (int k = 0; k < 60; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.statuses.back().horizon, 15);
  EXPECT_EQ(r.tx.statuses.back().rollouts, 64);
  EXPECT_EQ(r.tx.plans.back().horizon, 15);
  EXPECT_EQ(now.mid_cycle_changes, 0);
  EXPECT_FALSE(r.tx.any_nonfinite());
}

TEST(LiveUpdate, InvalidValuesAreRefusedOnTheReplyChannelAndValidOnesInTheBatchApply) {
  LiveRig r(LiveOptimizer::Mode::kSynchronous);
  r.fresh_cycle();
  r.inbox->offer_param(update("mppi.rollouts", 0, 1));
  r.inbox->offer_param(update("mppi.lambda", 2.0, 2));
  r.inbox->offer_param(update("mppi.u_min", 0, 3));
  r.inbox->offer_param(update("mppi.horizon", 1e6, 4));
  r.inbox->offer_param(update("cost.w_xy", 5.0, 5));  // the controller's own (applied by the loop)
  r.fresh_cycle();
  ASSERT_EQ(r.tx.param_results.size(), 5u);
  auto find = [&](std::int64_t seq) {
    for (const auto& res : r.tx.param_results)
      if (res.update_seq == seq) return res;
    ADD_FAILURE() << "no answer to update " << seq;
    return transport::ParamResult{};
  };
  EXPECT_FALSE(find(1).applied);
  EXPECT_STREQ(find(1).reason, "mppi.rollouts: must be >= 1, got 0");
  EXPECT_TRUE(find(2).applied);
  EXPECT_FALSE(find(3).applied);
  EXPECT_NE(std::string(find(3).reason).find("mppi.u_min: not tunable at run time"), std::string::npos);
  EXPECT_FALSE(find(4).applied);
  EXPECT_STREQ(find(4).reason, "mppi.horizon: must be <= 200 (daemon.live.max_horizon), got 1000000");
  EXPECT_TRUE(find(5).applied);
  for (const auto& res : r.tx.param_results) EXPECT_EQ(res.cycle, 1);
  EXPECT_EQ(r.fake().settings().lambda, 2.0f);
  EXPECT_EQ(r.fake().settings().rollouts, 8);  // unchanged: refused
  EXPECT_EQ(r.loop->counters().params_rejected.load(), 3);
  EXPECT_EQ(r.loop->counters().params_applied.load(), 2);
  for (int k = 0; k < 60; ++k) r.fresh_cycle();
  EXPECT_EQ(r.tx.statuses.back().rejected_params, 3);
}

TEST(LiveUpdate, WithoutALiveOptimizerMppiIsRefusedOnTheReplyChannel) {
  FakeClock clock;
  RecordingTransport tx;
  FakeController ctl(&clock);
  transport::Inbox inbox(LiveRig::expect());
  daemon::ControlLoop loop(&ctl, &clock, &tx, &inbox, {});
  std::atomic<bool> run{false};
  inbox.offer_param(update("mppi.rollouts", 512, 3));
  ASSERT_TRUE(loop.step_realtime(run));
  ASSERT_EQ(tx.param_results.size(), 1u);
  EXPECT_FALSE(tx.param_results[0].applied);
  EXPECT_EQ(tx.param_results[0].update_seq, 3);
  EXPECT_NE(std::string(tx.param_results[0].reason).find("mppi.rollouts: optimizer settings are fixed"),
            std::string::npos);
}

// The builder thread builds while the loop keeps cycling; the new controller takes over
// exactly at a cycle boundary, and the answer names that cycle.
TEST(LiveUpdate, BuilderThreadSwapsInAtACycleBoundaryWhileTheLoopCycles) {
  std::atomic<bool> release{false};
  LiveRig r(LiveOptimizer::Mode::kBuilderThread, [&] {
    // The build waits until the loop has cycled on during it (no timing assumption).
    while (!release.load()) std::this_thread::yield();
  });
  for (int k = 0; k < 3; ++k) r.fresh_cycle();
  r.inbox->offer_param(update("mppi.horizon", 12, 1));
  for (int k = 0; k < 10; ++k) r.fresh_cycle();  // the build is held: the old controller runs on
  EXPECT_EQ(r.built.load(), 0);
  release = true;
  r.live->wait_idle();  // built and ready
  int cycles = 0;
  while (r.tx.param_results.empty() && cycles < 10) {
    r.fresh_cycle();
    ++cycles;
  }
  ASSERT_EQ(r.tx.param_results.size(), 1u);
  const auto& res = r.tx.param_results[0];
  EXPECT_TRUE(res.applied);
  ASSERT_EQ(res.cycle, 13);  // the first cycle after the build was ready
  for (int k = 0; k < 5; ++k) r.fresh_cycle();
  // Commands of cycles before `res.cycle` came from the old controller, from it on the new.
  ASSERT_EQ(r.tx.commands.size(), 19u);
  for (std::size_t n = 0; n < r.tx.commands.size(); ++n) {
    const float u = r.tx.commands[n].u[0];
    if (static_cast<std::int64_t>(n) < res.cycle)
      EXPECT_LT(u, 5000.0f) << "cycle " << n;
    else
      EXPECT_GE(u, 5000.0f) << "cycle " << n;
  }
  EXPECT_EQ(r.fake().horizon(), 12);
  EXPECT_EQ(r.fake().mid_cycle_changes, 0);
}

// The real quadrotor controller: a rebuild with a new thread count (the CPU backend's plan
// is bit-identical for any thread count) continues the run exactly, noise counter and plan
// carried over; a rebuild with new rollouts really changes the optimizer.
TEST(LiveUpdate, RealControllerContinuesBitForBitAcrossARebuild) {
  const app::AppConfig cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                              {"mppi.rollouts=128", "mppi.horizon=30", "mppi.threads=2"});
  auto factory = [cfg](const MppiSettings& s) {
    return app::make_controller(cfg.with_mppi(s));
  };
  struct Run : LiveLoopParts {
    std::atomic<bool> stop{false};
  };
  auto make = [&](Run* run) {
    run->live = std::make_unique<LiveOptimizer>(app::make_controller(cfg), factory, limits(),
                                                LiveOptimizer::Mode::kSynchronous);
    run->inbox = std::make_unique<transport::Inbox>(LiveRig::expect());
    run->loop = std::make_unique<daemon::ControlLoop>(run->live->current(), &run->clock, &run->tx, run->inbox.get(),
                                                      daemon::LoopSettings{});
    run->loop->set_live_optimizer(run->live.get());
    auto& obs = run->inbox->obstacles_buffer();
    obs.count = 20;
    for (int i = 0; i < 20; ++i) obs.items[i] = Cylinder{3.0f + static_cast<float>(i % 5), static_cast<float>(i / 5) - 2.0f, 0.3f, 0, 0};
    run->inbox->offer_obstacles();
  };
  auto step = [](Run* run, int k) {
    auto& st = run->inbox->state_buffer();
    test::shape_state(st, k + 1);
    st.recv_ns = run->clock.now_ns();
    st.sample_utime = run->clock.now_ns() / 1000;
    for (int i = 0; i < 16; ++i) st.x[i] = 0.0f;
    st.x[0] = 0.05f * static_cast<float>(k);
    st.x[2] = 2.0f;
    for (int i = 12; i < 16; ++i) st.x[i] = 3168.4f;
    run->inbox->offer_state();
    return run->loop->step_realtime(run->stop);
  };
  Run a, b, c;
  make(&a);
  make(&b);
  make(&c);
  for (int k = 0; k < 40; ++k) {
    if (k == 15) {
      b.inbox->offer_param(update("mppi.threads", 1, 1));
      c.inbox->offer_param(update("mppi.rollouts", 256, 1));
    }
    ASSERT_TRUE(step(&a, k));
    ASSERT_TRUE(step(&b, k));
    ASSERT_TRUE(step(&c, k));
  }
  ASSERT_EQ(b.tx.param_results.size(), 1u);
  EXPECT_TRUE(b.tx.param_results[0].applied);
  EXPECT_EQ(b.live->current_threads(), 1);
  EXPECT_EQ(c.loop->controller().settings().rollouts, 256);
  EXPECT_EQ(a.loop->controller().noise_cycle(), b.loop->controller().noise_cycle());
  ASSERT_EQ(a.tx.commands.size(), 40u);
  ASSERT_EQ(b.tx.commands.size(), 40u);
  int differ_c = 0;
  for (std::size_t n = 0; n < 40; ++n) {
    EXPECT_EQ(a.tx.commands[n].mode, Mode::kNormal);
    EXPECT_EQ(std::memcmp(a.tx.commands[n].u, b.tx.commands[n].u, 4 * sizeof(float)), 0) << "cycle " << n;
    if (std::memcmp(a.tx.commands[n].u, c.tx.commands[n].u, 4 * sizeof(float)) != 0) {
      ++differ_c;
      EXPECT_GE(n, 15u) << "the runs differ before the update";
    }
  }
  EXPECT_GT(differ_c, 0);  // 256 rollouts are not 128
  EXPECT_FALSE(c.tx.any_nonfinite());
}
