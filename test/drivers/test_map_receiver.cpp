// Local maps on a receive thread of their own (LcmTransport's maps' instance): the states'
// instance never takes a map, states and maps published at once from two threads are all
// taken and counted while the loop cycles with the real forest cost reading the map in place,
// and the replay's single-thread mode keeps maps on the states' queue. Over memq:// (one queue
// per LCM instance). Built into driver_tests, which tools/sanitize.sh runs under TSan: the
// checks here are counts; waits poll a condition with a deadline; no sleep is an assertion.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>

#include "../rt/fakes.hpp"
#include "../support/local_map.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/tasks.hpp"
#include "mppi/transport/lcm_transport.hpp"
#include "mppi_lcm/controller_status_t.hpp"
#include "mppi_lcm/local_map_t.hpp"
#include "mppi_lcm/vehicle_state_t.hpp"
#include "source_dir.hpp"

using namespace mppi;
using mppi::test::FakeClock;

namespace {

constexpr std::int64_t kT0 = 1'000'000'000;  // us

mppi_lcm::vehicle_state_t state_msg(std::int64_t seq) {
  mppi_lcm::vehicle_state_t m{};
  m.utime = m.sample_utime = kT0 + 20'000 * seq;
  m.seq = seq;
  m.model = 1, m.vehicle_count = 1, m.nx = 16, m.n = 16;
  m.x.assign(16, 0.0f);
  m.x[2] = 1.5f;
  for (int i = 12; i < 16; ++i) m.x[static_cast<std::size_t>(i)] = 3168.4f;
  return m;
}

// A 40 x 40 x 10 map at 0.2 m (32 kB of cells: several memq messages' worth of copying). Its
// utime is past every state's, so no interleaving of the two streams makes it stale.
mppi_lcm::local_map_t map_msg(std::int64_t seq, std::int16_t fill_mm) {
  return mppi::test::local_map_msg({{-4.0f, -4.0f, 0.0f}, 0.2f, 40, 40, 10}, seq, kT0 + 100'000'000 + seq, fill_mm);
}

template <class Msg>
void publish(lcm::LCM& lcm, const char* channel, const Msg& m) {
  lcm.publish(channel, &m);
}

struct LastStatus {
  std::mutex mu;
  mppi_lcm::controller_status_t last{};
  std::int64_t n = 0;
  void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::controller_status_t* m) {
    std::lock_guard<std::mutex> l(mu);
    last = *m;
    ++n;
  }
  mppi_lcm::controller_status_t get() {
    std::lock_guard<std::mutex> l(mu);
    return last;
  }
};

TEST(MapReceiver, TheStatesInstanceTakesNoMapAndTheMapsOneNoState) {
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 64);
  tx.open_map_receiver();
  EXPECT_EQ(tx.self_test(), "") << "both instances loop back";
  transport::Inbox inbox(test::map_expect());
  tx.start(&inbox);
  ASSERT_NE(&tx.map_lcm(), &tx.lcm()) << "maps have an instance of their own";
  const auto map = map_msg(1, 1500);
  publish(tx.lcm(), "MPPI_LOCAL_MAP", map);         // on the states' instance: nobody takes it
  publish(tx.map_lcm(), "MPPI_STATE", state_msg(1));  // on the maps' instance: nobody takes it
  publish(tx.lcm(), "MPPI_STATE", state_msg(2));
  publish(tx.map_lcm(), "MPPI_LOCAL_MAP", map);
  ASSERT_TRUE(test::eventually([&] { return inbox.counters.states.load() == 1 && inbox.counters.maps.load() == 1; }));
  tx.stop();
  ASSERT_TRUE(inbox.state.update());
  EXPECT_EQ(inbox.state.front().seq, 2);
  EXPECT_EQ(inbox.counters.maps_rejected(), 0);
  EXPECT_EQ(inbox.counters.rejected_undecodable.load(), 0);
}

// Two publishers at once (states on the states' instance, maps on the maps'), each waiting
// until its last message was taken before the next, so every message is offered; the loop
// cycles on its own thread all along, the real forest cost reading the inbox's front map in
// place while the maps' thread fills another slot.
TEST(MapReceiver, StatesAndMapsAtOnceAreAllTakenWhileTheLoopCycles) {
  constexpr int kStates = 300, kMaps = 30;
  const auto cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                                    {"mppi.rollouts=32", "mppi.horizon=10", "mppi.threads=1"});
  const auto controller = app::make_controller(cfg);
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 4096);
  transport::Inbox inbox(test::map_expect());
  LastStatus status;
  tx.lcm().subscribe("MPPI_STATUS", &LastStatus::on, &status);
  daemon::LoopSettings settings;
  settings.latency.use_sample_time = false;  // fresh by receipt on the fake clock
  settings.status_hz = settings.rate_hz;
  daemon::ControlLoop loop(controller.get(), &clock, &tx, &inbox, settings);
  tx.start(&inbox);

  std::atomic<bool> stop{false}, publishing{true};
  std::thread cycles([&] {
    while (publishing.load()) ASSERT_TRUE(loop.step_realtime(stop));
  });
  std::thread maps([&] {
    for (int k = 1; k <= kMaps; ++k) {
      publish(tx.map_lcm(), "MPPI_LOCAL_MAP", map_msg(k, static_cast<std::int16_t>(500 + 50 * k)));
      ASSERT_TRUE(test::eventually([&] { return inbox.counters.maps.load() + inbox.counters.maps_rejected() == k; }));
    }
  });
  for (int k = 1; k <= kStates; ++k) {
    publish(tx.lcm(), "MPPI_STATE", state_msg(k));
    ASSERT_TRUE(test::eventually([&] { return inbox.counters.states.load() == k; }));
  }
  maps.join();
  publishing = false;
  cycles.join();

  EXPECT_EQ(inbox.counters.states.load(), kStates);
  EXPECT_EQ(inbox.counters.maps.load(), kMaps);
  EXPECT_EQ(inbox.counters.maps_rejected(), 0);
  EXPECT_EQ(inbox.counters.rejected_undecodable.load(), 0);
  // One more cycle takes the newest map (if the loop had not) and reports the counts.
  publish(tx.lcm(), "MPPI_STATE", state_msg(kStates + 1));
  ASSERT_TRUE(test::eventually([&] { return inbox.counters.states.load() == kStates + 1; }));
  const std::int64_t statuses = [&] {
    std::lock_guard<std::mutex> l(status.mu);
    return status.n;
  }();
  ASSERT_TRUE(loop.step_realtime(stop));
  ASSERT_TRUE(test::eventually([&] {
    std::lock_guard<std::mutex> l(status.mu);
    return status.n > statuses;
  }));
  tx.stop();
  EXPECT_EQ(status.get().maps_accepted, kMaps);
  EXPECT_EQ(status.get().maps_rejected, 0);
  const DistanceField& field = dynamic_cast<TaskController<QuadrotorForest>&>(*controller).params().cost.field;
  ASSERT_TRUE(field.present());
  EXPECT_FLOAT_EQ(field.distance(0.1f, 0.1f, 1.1f), (500 + 50 * kMaps) * 1e-3f) << "the newest map in the cost";
}

// The replay's mode: maps on the states' instance and thread, one queue in publish order.
TEST(MapReceiver, OnTheStatesThreadMapsShareTheStatesQueue) {
  FakeClock clock;
  transport::LcmTransport tx("memq://", {}, &clock, 64);
  tx.set_map_thread(transport::LcmTransport::MapThread::kStateThread);
  transport::Inbox inbox(test::map_expect());
  tx.start(&inbox);
  EXPECT_EQ(&tx.map_lcm(), &tx.lcm());
  const auto map = map_msg(1, 1500);
  publish(tx.lcm(), "MPPI_LOCAL_MAP", map);
  publish(tx.lcm(), "MPPI_STATE", state_msg(1));
  ASSERT_TRUE(test::eventually([&] { return inbox.counters.states.load() == 1; }));
  EXPECT_EQ(inbox.counters.maps.load(), 1) << "handled before the state published after it";
  tx.stop();
}

}  // namespace
