// The LCM transport in-process (memq://): raw decode with garbage and wrong types counted,
// the loop publishing through it, parameter updates over the channel, a prompt stop on a
// quiet bus, and the real controller behind it. Waits poll a condition with a deadline;
// no sleep is an assertion.
#include <cstdint>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>

#include "../rt/fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/transport/lcm_transport.hpp"
#include "source_dir.hpp"

using namespace mppi;
using mppi::test::FakeClock;
using mppi::test::FakeController;
using transport::Mode;

namespace {

// What left the process on the command and status channels, decoded as a peer would.
struct Listener {
  std::mutex mu;
  std::vector<mppi_lcm::command_t> commands;
  std::vector<mppi_lcm::controller_status_t> statuses;
  void on_command(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::command_t* m) {
    std::lock_guard<std::mutex> l(mu);
    commands.push_back(*m);
  }
  void on_status(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::controller_status_t* m) {
    std::lock_guard<std::mutex> l(mu);
    statuses.push_back(*m);
  }
  std::size_t n_commands() {
    std::lock_guard<std::mutex> l(mu);
    return commands.size();
  }
  bool any_nonfinite() {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& c : commands)
      for (float v : c.u)
        if (!std::isfinite(v)) return true;
    return false;
  }
};

mppi_lcm::vehicle_state_t state_msg(std::int64_t seq, float fill = 0.0f) {
  mppi_lcm::vehicle_state_t m{};
  // Sampled now on this host's wall clock, as the simulator and the bridge stamp it (the
  // loop measures a state's age from it).
  m.utime = m.sample_utime = rt::wall_utime();
  m.seq = seq;
  m.model = mppi_lcm::vehicle_state_t::MODEL_QUADROTOR;
  m.vehicle_count = 1;
  m.nx = 16;
  m.n = 16;
  m.x.assign(16, fill);
  m.x[2] = 1.0f;
  for (int i = 12; i < 16; ++i) m.x[static_cast<std::size_t>(i)] = 3168.4f;
  return m;
}

// The loop on a fake clock behind the memq transport. It ages a state from its receipt on
// that clock (daemon.latency.state_time: receive): a state's wall-clock time in flight inside
// this process, long on a loaded machine under a sanitizer, is no part of what these tests
// check (test/rt/test_inbox_time.cpp and test_latency.cpp test the sample-time age), and with
// it a state received between two cycles is fresh by construction.
struct LcmRig {
  explicit LcmRig(Controller* c = nullptr) : tx("memq://", {}, &clock, 4096), inbox(expect()) {
    tx.lcm().subscribe("MPPI_COMMAND", &Listener::on_command, &listener);
    tx.lcm().subscribe("MPPI_STATUS", &Listener::on_status, &listener);
    EXPECT_EQ(tx.self_test(), "");
    controller = c ? c : &fake;
    daemon::LoopSettings settings;
    settings.latency.use_sample_time = false;
    loop = std::make_unique<daemon::ControlLoop>(controller, &clock, &tx, &inbox, settings);
    tx.start(&inbox);
  }
  ~LcmRig() { tx.stop(); }
  static transport::Inbox::Expect expect() {
    transport::Inbox::Expect e;
    e.nx = 16;
    e.model = 1;
    return e;
  }
  template <class Msg>
  void send(const std::string& channel, const Msg& m) {
    tx.lcm().publish(channel, &m);
  }
  void send_state(std::int64_t seq, float fill = 0.0f) { send("MPPI_STATE", state_msg(seq, fill)); }
  void cycle() { ASSERT_TRUE(loop->step_realtime(stop)); }

  FakeClock clock;
  FakeController fake{&clock};
  Controller* controller = nullptr;
  transport::LcmTransport tx;
  transport::Inbox inbox;
  Listener listener;
  std::unique_ptr<daemon::ControlLoop> loop;
  std::atomic<bool> stop{false};
};

}  // namespace

TEST(LcmTransport, SelfTestLoopsBackOnMemq) {
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 64);
  EXPECT_EQ(tx.self_test(), "");
}

// rollouts_t (tools/view's fan) leaves as it was given, within the room reserved at start-up;
// a larger one is refused, never grown into.
TEST(LcmTransport, RolloutsGoOutWhole) {
  test::FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 64);
  std::vector<mppi_lcm::rollouts_t> got;
  struct Sink {
    std::vector<mppi_lcm::rollouts_t>* got;
    void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::rollouts_t* m) { got->push_back(*m); }
  } sink{&got};
  tx.lcm().subscribe("MPPI_ROLLOUTS", &Sink::on, &sink);
  tx.reserve_rollouts(2, 2 * 3 * 3);
  const int index[2] = {7, 3};
  const float cost[2] = {1.5f, 2.5f}, weight[2] = {0.75f, 0.25f};
  const unsigned char crashed[2] = {0, 1};
  float xyz[18];
  for (int i = 0; i < 18; ++i) xyz[i] = 0.5f * static_cast<float>(i);
  transport::RolloutsView v;
  v.seq = 4;
  v.cycle = 9;
  v.total = 64;
  v.vehicles = 1;
  v.steps = 3;
  v.dt = 0.02f;
  v.lambda = 10.0f;
  v.count = 2;
  v.top = 1;
  v.index = index;
  v.cost = cost;
  v.weight = weight;
  v.crashed = crashed;
  v.xyz = xyz;
  ASSERT_TRUE(tx.publish_rollouts(v));
  tx.lcm().handleTimeout(100);
  ASSERT_EQ(got.size(), 1u);
  const auto& m = got[0];
  EXPECT_EQ(m.seq, 4);
  EXPECT_EQ(m.cycle, 9);
  EXPECT_EQ(m.total, 64);
  EXPECT_EQ(m.temperature, 10.0f);
  EXPECT_EQ(m.top, 1);
  EXPECT_EQ(m.index, (std::vector<std::int32_t>{7, 3}));
  EXPECT_EQ(m.weight, (std::vector<float>{0.75f, 0.25f}));
  EXPECT_EQ(m.crashed, (std::vector<std::int8_t>{0, 1}));
  ASSERT_EQ(m.npos, 18);
  EXPECT_EQ(m.pos, std::vector<float>(xyz, xyz + 18));
  v.steps = 4;  // 24 floats: more than reserved
  EXPECT_FALSE(tx.publish_rollouts(v));
}

TEST(LcmTransport, BadUrlIsAnError) {
  FakeClock clock;
  EXPECT_THROW(transport::LcmTransport("nosuchprovider://x", {}, &clock, 64), std::runtime_error);
}

TEST(LcmTransport, GarbageAndWrongTypeOnTheStateChannelAreCounted) {
  LcmRig r;
  const char junk[] = "\x13\x37 definitely not an LCM message";
  r.tx.lcm().publish("MPPI_STATE", junk, sizeof(junk));
  mppi_lcm::command_t wrong{};  // a valid message of the wrong type
  wrong.n = 0;
  r.send("MPPI_STATE", wrong);
  // A valid state, truncated by one byte.
  auto m = state_msg(1);
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  r.tx.lcm().publish("MPPI_STATE", buf.data(), static_cast<unsigned>(buf.size() - 1));
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.rejected_undecodable.load() == 3; }));
  EXPECT_EQ(r.inbox.counters.states.load(), 0);
  r.cycle();
  EXPECT_EQ(r.fake.iterations, 0);  // nothing valid arrived: failsafe, no optimizer run
  // A good state after the garbage is accepted and answered.
  r.send_state(2);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 1; }));
  r.cycle();
  ASSERT_TRUE(test::eventually([&] { return r.listener.n_commands() == 2; }));
  // The status follows the command (a mode change forces one).
  ASSERT_TRUE(test::eventually([&] {
    std::lock_guard<std::mutex> l(r.listener.mu);
    return !r.listener.statuses.empty();
  }));
  std::lock_guard<std::mutex> l(r.listener.mu);
  EXPECT_EQ(r.listener.commands[0].mode, mppi_lcm::command_t::MODE_FAILSAFE);
  EXPECT_EQ(r.listener.commands[1].mode, mppi_lcm::command_t::MODE_NORMAL);
  EXPECT_EQ(r.listener.commands[1].state_seq, 2);
  EXPECT_EQ(r.listener.commands[1].kind, mppi_lcm::command_t::KIND_MOTOR_SPEEDS);
}

TEST(LcmTransport, NanStateOverLcmIsRejectedAndNoNanLeaves) {
  LcmRig r;
  r.send_state(1);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 1; }));
  r.send_state(2, std::numeric_limits<float>::quiet_NaN());
  r.send_state(3, std::numeric_limits<float>::infinity());
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.rejected_nan.load() == 2; }));
  for (int k = 0; k < 51; ++k) r.cycle();
  ASSERT_TRUE(test::eventually([&] { return r.listener.n_commands() == 51; }));
  EXPECT_FALSE(r.listener.any_nonfinite());
  ASSERT_TRUE(test::eventually([&] {
    std::lock_guard<std::mutex> l(r.listener.mu);
    return !r.listener.statuses.empty() && r.listener.statuses.back().rejected_nan == 2;
  }));
  std::lock_guard<std::mutex> l(r.listener.mu);
  EXPECT_EQ(r.listener.commands[0].state_seq, 1);
}

TEST(LcmTransport, OutOfOrderAndDuplicateOverLcmAreCounted) {
  LcmRig r;
  for (std::int64_t s : {10, 10, 9, 11, 8, 11}) r.send_state(s);
  ASSERT_TRUE(test::eventually([&] {
    return r.inbox.counters.states.load() + r.inbox.counters.rejected_duplicate.load() +
               r.inbox.counters.rejected_out_of_order.load() == 6;
  }));
  EXPECT_EQ(r.inbox.counters.states.load(), 2);
  EXPECT_EQ(r.inbox.counters.rejected_duplicate.load(), 2);
  EXPECT_EQ(r.inbox.counters.rejected_out_of_order.load(), 2);
  r.cycle();
  ASSERT_TRUE(test::eventually([&] { return r.listener.n_commands() == 1; }));
  std::lock_guard<std::mutex> l(r.listener.mu);
  EXPECT_EQ(r.listener.commands[0].state_seq, 11);
}

TEST(LcmTransport, InvalidParameterUpdateIsRejectedAndReported) {
  LcmRig r;
  mppi_lcm::param_update_t p{};
  p.seq = 1;
  p.key = "cost.w_xy";
  p.value = -5.0;
  r.send("MPPI_PARAMS", p);
  p.seq = 2;
  p.key = "cost.w_xy";
  p.value = 7.0;
  r.send("MPPI_PARAMS", p);
  ASSERT_TRUE(test::eventually([&] { return !r.inbox.params.empty(); }));
  r.send_state(1);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 1; }));
  for (int k = 0; k < 50; ++k) r.cycle();
  EXPECT_EQ(r.loop->counters().params_rejected.load(), 1);
  EXPECT_EQ(r.loop->counters().params_applied.load(), 1);
  ASSERT_EQ(r.fake.params_set.size(), 1u);
  EXPECT_EQ(r.fake.params_set[0].second, 7.0);
  EXPECT_EQ(r.fake.mid_cycle_changes, 0);
  ASSERT_TRUE(test::eventually([&] {
    std::lock_guard<std::mutex> l(r.listener.mu);
    return !r.listener.statuses.empty() && r.listener.statuses.back().rejected_params == 1;
  }));
}

TEST(LcmTransport, StopReturnsPromptlyOnAQuietBus) {
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 64, 20);
  transport::Inbox inbox(LcmRig::expect());
  tx.start(&inbox);
  const auto t0 = std::chrono::steady_clock::now();
  tx.stop();
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0).count();
  // The receive thread wakes every receive_timeout (20 ms) to see the stop: a hang would be the
  // failure, so the bound leaves room for a loaded 2-core VM's stalls (up to 28 ms).
  EXPECT_LT(ms, 1000);
}

// The real controller (the forest task's MPPI on the CPU) behind the LCM transport: each
// state that arrives over memq is answered by a normal command, finite and inside the limits,
// that names it (LcmRig: on the fake clock every state is fresh, whatever the load).
TEST(LcmTransport, RealQuadrotorControllerOverMemq) {
  app::AppConfig cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                        {"mppi.rollouts=64", "mppi.horizon=20", "mppi.threads=1"});
  auto controller = app::make_controller(cfg);
  LcmRig r(controller.get());
  for (int k = 1; k <= 20; ++k) {
    r.send_state(k);
    ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == k; }));
    r.cycle();
  }
  ASSERT_TRUE(test::eventually([&] { return r.listener.n_commands() == 20; }));
  EXPECT_EQ(r.loop->counters().stale_cycles.load(), 0);
  EXPECT_EQ(r.loop->counters().commands_normal.load(), 20);
  EXPECT_FALSE(r.listener.any_nonfinite());
  std::lock_guard<std::mutex> l(r.listener.mu);
  for (std::size_t i = 0; i < r.listener.commands.size(); ++i) {
    const auto& c = r.listener.commands[i];
    EXPECT_EQ(c.mode, mppi_lcm::command_t::MODE_NORMAL);
    EXPECT_EQ(c.state_seq, static_cast<std::int64_t>(i + 1)) << "each command answers its state";
    ASSERT_EQ(c.n, 4);
    for (float v : c.u) {
      EXPECT_GE(v, 0.0f);
      EXPECT_LE(v, 6000.0f);
    }
  }
}

// A simulator's side of lock-step: publish state k, then tick k, wait for the command
// answering state k, step. The pace is the ticks' alone: the loop answers each tick at once,
// exactly once, and never waits on a clock (its clock is a fake that records every wait), so
// a simulator runs as fast as the two can exchange messages. The wall time of the 100 steps
// (2 s of sim time) is recorded, not asserted: a sanitizer on a loaded machine is slower.
TEST(LcmTransport, LockstepOverLcmAnswersEachTickFasterThanRealTime) {
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 4096);
  transport::Inbox inbox(LcmRig::expect());
  Listener listener;
  tx.lcm().subscribe("MPPI_COMMAND", &Listener::on_command, &listener);
  FakeClock fclock;
  FakeController fake(&fclock);
  daemon::LoopSettings s;
  s.lockstep = true;
  daemon::ControlLoop loop(&fake, &clock, &tx, &inbox, s);
  tx.start(&inbox);
  std::atomic<bool> stop{false};
  std::thread runner([&] { loop.run(stop); });
  const auto t0 = std::chrono::steady_clock::now();
  for (int k = 1; k <= 100; ++k) {
    auto m = state_msg(k);
    m.sample_utime = k * 20000;
    tx.lcm().publish("MPPI_STATE", &m);
    mppi_lcm::sim_clock_t tick{};
    tick.seq = k;
    tick.step = k;
    tick.sim_utime = k * 20000;
    tx.lcm().publish("MPPI_SIM_CLOCK", &tick);
    ASSERT_TRUE(test::eventually([&] { return listener.n_commands() == static_cast<std::size_t>(k); })) << "step " << k;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  stop = true;
  runner.join();
  tx.stop();
  RecordProperty("wall_ms_for_2s_of_sim", static_cast<int>(secs * 1000.0));
  EXPECT_TRUE(clock.sleeps.empty()) << "the lock-step loop waited on its clock";
  std::lock_guard<std::mutex> l(listener.mu);
  ASSERT_EQ(listener.commands.size(), 100u);  // exactly one per tick
  for (std::size_t i = 0; i < listener.commands.size(); ++i) {
    EXPECT_EQ(listener.commands[i].state_seq, static_cast<std::int64_t>(i + 1));
    EXPECT_EQ(listener.commands[i].mode, mppi_lcm::command_t::MODE_NORMAL);
  }
  EXPECT_EQ(loop.counters().repeated_ticks.load(), 0);
  EXPECT_EQ(loop.timing_total().misses, 0);
}

TEST(Settings, TheCudaSectionIsWhatTheCudaBackendFliesWith) {
  const std::string file = mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml";
  const app::AppConfig c = app::load_config(file, {"cuda.mppi.rollouts=16384", "cuda.cost.w_z=200"});
  ASSERT_NE(c.cuda, nullptr);
  EXPECT_EQ(c.for_backend("cuda").mppi.rollouts, 16384);
  // The CPU backend flies the file's settings, or its cpu_targets entry for this machine's
  // SIMD target (a sanitizer build or an AVX2 machine takes cpu_targets.avx2): never cuda's.
  const std::string entry = c.variant_for("cpu");
  EXPECT_EQ(c.for_backend("cpu").mppi.rollouts,
            entry.empty() ? c.mppi.rollouts : c.cpu_targets.at(entry.substr(entry.find('.') + 1))->mppi.rollouts);
  EXPECT_NE(c.for_backend("cpu").mppi.rollouts, 16384);
  EXPECT_NE(c.mppi.rollouts, 16384);
  bool has_wz = false;
  for (const auto& [k, v] : c.for_backend("cuda").params) has_wz = has_wz || (k == "cost.w_z" && v == 200.0);
  EXPECT_TRUE(has_wz);
  // A command-line --set wins over the section, on either backend.
  const app::AppConfig d = app::load_config(file, {"cuda.mppi.rollouts=16384", "mppi.rollouts=512"});
  EXPECT_EQ(d.for_backend("cuda").mppi.rollouts, 512);
  EXPECT_EQ(d.for_backend("cpu").mppi.rollouts, 512);
}

// A live update rebuilds the controller from with_mppi(settings): the CUDA backend must get
// them too, not the cuda: section's (found on the H100: live updates were silently ignored by
// a CUDA controller whose task file has a cuda: section).
TEST(Settings, WithMppiReachesTheCudaSectionToo) {
  const std::string file = mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml";
  const app::AppConfig c = app::load_config(file, {"cuda.mppi.rollouts=16384"});
  ASSERT_NE(c.cuda, nullptr);
  MppiSettings s = c.for_backend("cuda").mppi;
  s.rollouts = 256;
  s.horizon = 45;
  const app::AppConfig n = c.with_mppi(s);
  EXPECT_EQ(n.for_backend("cuda").mppi.rollouts, 256);
  EXPECT_EQ(n.for_backend("cuda").mppi.horizon, 45);
  EXPECT_EQ(n.for_backend("cpu").mppi.rollouts, 256);
  EXPECT_EQ(n.for_backend("cuda").params, c.for_backend("cuda").params);  // model/cost kept
  EXPECT_EQ(c.for_backend("cuda").mppi.rollouts, 16384);                 // the original untouched
}
