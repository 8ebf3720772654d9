// The local map (local_map_t) into the daemon: the decoder and the inbox's checks, a table of
// the maps it must refuse (each counted, the last good map kept), and over memq:// the loop
// putting the map into the forest task's cost, reporting it in its status, and keeping the
// last map when no newer one comes. Waits poll a condition with a deadline; no sleep is an
// assertion.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "../rt/fakes.hpp"
#include "../support/local_map.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/tasks.hpp"
#include "mppi/transport/lcm_decode.hpp"
#include "mppi/transport/lcm_transport.hpp"
#include "source_dir.hpp"

using namespace mppi;
using mppi::test::FakeClock;

namespace {

// A 20 x 10 x 5 map at 0.25 m from (-1, -1.25, 0), every cell `fill` mm.
mppi_lcm::local_map_t map_msg(std::int64_t seq, std::int64_t utime, std::int16_t fill = 3000) {
  return mppi::test::local_map_msg({{-1.0f, -1.25f, 0.0f}, 0.25f, 20, 10, 5}, seq, utime, fill);
}

std::vector<std::uint8_t> bytes_of(const mppi_lcm::local_map_t& m) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

constexpr std::int64_t kT0 = 1'000'000'000;  // us

TEST(LocalMapIntake, NoSlotUnlessExpectedAndAValidMapIsTaken) {
  FakeClock clock;
  transport::LcmDecoder decoder(&clock);
  transport::Inbox none(transport::Inbox::Expect{});
  EXPECT_EQ(none.map, nullptr);
  const auto b = bytes_of(map_msg(1, kT0));
  decoder.local_map(b.data(), b.size(), &none);  // ignored: the inbox takes no maps
  EXPECT_EQ(none.counters.maps.load() + none.counters.maps_rejected(), 0);

  transport::Inbox in(test::map_expect());
  ASSERT_NE(in.map, nullptr);
  decoder.local_map(b.data(), b.size(), &in);
  EXPECT_EQ(in.counters.maps.load(), 1);
  ASSERT_TRUE(in.map->update());
  const transport::LocalMapInput& m = in.map->front();
  EXPECT_EQ(m.seq, 1);
  EXPECT_EQ(m.grid.nx, 20);
  EXPECT_EQ(m.grid.n_cells, 1000);
  EXPECT_EQ(m.grid.distance_mm[999], 3000);
  const DistanceField f = m.grid.view(1);
  EXPECT_FLOAT_EQ(f.distance(0.0f, 0.0f, 0.5f), 3.0f);
}

// Each bad map against a good one taken first (seq 10, utime kT0 - 1 s, before any state),
// then a state sampled at kT0 + 0.1 s: counted under its reason, and the slot still holds the
// good map.
TEST(LocalMapIntake, BadMapsAreRefusedCountedAndTheLastGoodOneKept) {
  using Counter = std::atomic<std::int64_t> transport::InboxCounters::*;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  struct Case {
    const char* what;
    std::function<void(mppi_lcm::local_map_t&)> spoil;
    Counter counter;
  };
  const std::vector<Case> cases = {
      {"NaN origin", [&](auto& m) { m.origin[1] = nan; }, &transport::InboxCounters::maps_rejected_invalid},
      {"NaN resolution", [&](auto& m) { m.resolution = nan; }, &transport::InboxCounters::maps_rejected_invalid},
      {"zero resolution", [](auto& m) { m.resolution = 0.0f; }, &transport::InboxCounters::maps_rejected_invalid},
      {"negative resolution", [](auto& m) { m.resolution = -0.25f; }, &transport::InboxCounters::maps_rejected_invalid},
      {"infinite max distance", [](auto& m) { m.max_distance = std::numeric_limits<float>::infinity(); },
       &transport::InboxCounters::maps_rejected_invalid},
      {"n_cells is not nx * ny * nz", [](auto& m) { m.nz = 4; }, &transport::InboxCounters::maps_rejected_invalid},
      {"a side of one cell", [](auto& m) { m.nx = 1, m.ny = 200, m.nz = 5; },
       &transport::InboxCounters::maps_rejected_invalid},
      {"larger than the capacity",
       [](auto& m) {
         m.nx = 1024, m.ny = 1024, m.nz = 2;
         m.n_cells = m.nx * m.ny * m.nz;
         m.distance_mm.assign(static_cast<std::size_t>(m.n_cells), 1000);
       },
       &transport::InboxCounters::maps_rejected_invalid},
      {"seq repeated", [](auto& m) { m.seq = 10; }, &transport::InboxCounters::maps_rejected_out_of_order},
      {"seq going back", [](auto& m) { m.seq = 9; }, &transport::InboxCounters::maps_rejected_out_of_order},
      {"utime going back", [](auto& m) { m.utime = kT0 - 1'000'001; }, &transport::InboxCounters::maps_rejected_out_of_order},
      {"utime negative", [](auto& m) { m.utime = -1; }, &transport::InboxCounters::maps_rejected_time},
      {"older than the timeout behind the newest state",
       [](auto& m) { m.utime = kT0 - 700'000; }, &transport::InboxCounters::maps_rejected_stale},
  };
  for (const Case& c : cases) {
    FakeClock clock;
    transport::LcmDecoder decoder(&clock);
    transport::Inbox in(test::map_expect());
    const auto good = bytes_of(map_msg(10, kT0 - 1'000'000, 2500));
    decoder.local_map(good.data(), good.size(), &in);
    // The newest state: sampled at kT0 + 0.1 s (a map from before kT0 - 0.4 s is stale).
    mppi_lcm::vehicle_state_t s{};
    s.utime = s.sample_utime = kT0 + 100'000;
    s.seq = 1, s.model = 1, s.vehicle_count = 1, s.nx = 16, s.n = 16;
    s.x.assign(16, 0.0f);
    std::vector<std::uint8_t> sb(static_cast<std::size_t>(s.getEncodedSize()));
    s.encode(sb.data(), 0, static_cast<int>(sb.size()));
    decoder.state(sb.data(), sb.size(), &in);
    ASSERT_EQ(in.counters.states.load(), 1) << c.what;
    auto bad = map_msg(11, kT0 + 50'000, 100);
    c.spoil(bad);
    const auto b = bytes_of(bad);
    decoder.local_map(b.data(), b.size(), &in);
    EXPECT_EQ((in.counters.*c.counter).load(), 1) << c.what;
    EXPECT_EQ(in.counters.maps_rejected(), 1) << c.what;
    EXPECT_EQ(in.counters.maps.load(), 1) << c.what;
    ASSERT_TRUE(in.map->update()) << c.what;
    EXPECT_EQ(in.map->front().seq, 10) << c.what;
    EXPECT_EQ(in.map->front().grid.distance_mm[0], 2500) << c.what;
    EXPECT_FALSE(in.map->update()) << c.what << ": nothing newer was published";
  }
}

TEST(LocalMapIntake, GarbageAndCountsTheBytesDoNotBackAreUndecodable) {
  FakeClock clock;
  transport::LcmDecoder decoder(&clock);
  transport::Inbox in(test::map_expect());
  auto b = bytes_of(map_msg(1, kT0));
  decoder.local_map(b.data(), b.size() - 2, &in);  // truncated: the count is not backed
  const std::uint8_t junk[7] = {1, 2, 3, 4, 5, 6, 7};
  decoder.local_map(junk, sizeof junk, &in);
  b[8 + 8 + 8 + 12 + 4 + 4 + 4 + 4 + 4] = 0x7f;  // n_cells' high byte: 2^30 cells the bytes lack
  decoder.local_map(b.data(), b.size(), &in);
  EXPECT_EQ(in.counters.maps_undecodable.load(), 2);
  EXPECT_EQ(in.counters.maps_rejected_invalid.load(), 1);  // 2^30 > kMaxCells: refused before decoding
  EXPECT_EQ(in.counters.maps.load(), 0);
  EXPECT_FALSE(in.map->update());
}

TEST(LocalMapIntake, APublisherRestartAfterAQuietSpellIsTaken) {
  FakeClock clock;
  transport::LcmDecoder decoder(&clock);
  transport::Inbox::Expect e = test::map_expect();
  e.restart_after_ns = 100'000'000;
  transport::Inbox in(e);
  const auto first = bytes_of(map_msg(500, kT0));
  decoder.local_map(first.data(), first.size(), &in);
  clock.advance(150'000'000);  // quiet for 150 ms
  const auto restarted = bytes_of(map_msg(1, kT0 + 150'000));
  decoder.local_map(restarted.data(), restarted.size(), &in);
  EXPECT_EQ(in.counters.maps.load(), 2);
  EXPECT_EQ(in.counters.maps_rejected(), 0);
}

TEST(LocalMapSettings, ForestTasksTakeMapsByDefaultAndTheSectionIsChecked) {
  EXPECT_TRUE(daemon::parse_daemon_settings(YAML::Node(), "quadrotor_forest", 4).local_map);
  EXPECT_FALSE(daemon::parse_daemon_settings(YAML::Node(), "quadrotor_track", 4).local_map);
  const auto d = daemon::parse_daemon_settings(
      YAML::Load("{map: {enabled: false, timeout_ms: 250}, channels: {local_map: MAP_IN}}"), "quadrotor_forest", 4);
  EXPECT_FALSE(d.local_map);
  EXPECT_EQ(d.loop.map_timeout_ns, 250'000'000);
  EXPECT_EQ(d.channels.local_map, "MAP_IN");
  EXPECT_THROW(daemon::parse_daemon_settings(YAML::Load("{map: {timeout_ms: 0}}"), "quadrotor_forest", 4),
               app::ConfigError);
  EXPECT_THROW(daemon::parse_daemon_settings(YAML::Load("{map: {size: 3}}"), "quadrotor_forest", 4), app::ConfigError);
}

// ---- Over memq://, the loop and the real forest controller ---------------------------------

struct Statuses {
  std::mutex mu;
  std::vector<mppi_lcm::controller_status_t> all;
  void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::controller_status_t* m) {
    std::lock_guard<std::mutex> l(mu);
    all.push_back(*m);
  }
  mppi_lcm::controller_status_t last() {
    std::lock_guard<std::mutex> l(mu);
    return all.empty() ? mppi_lcm::controller_status_t{} : all.back();
  }
  std::size_t size() {
    std::lock_guard<std::mutex> l(mu);
    return all.size();
  }
};

struct MapRig {
  MapRig()
      : cfg(app::load_config(mppi::testing::source_dir() + "/config/tasks/quadrotor_forest.yaml",
                             {"mppi.rollouts=64", "mppi.horizon=20", "mppi.threads=1"})),
        controller(app::make_controller(cfg)),
        tx("memq://", {}, &clock, 4096),
        inbox(test::map_expect()) {
    tx.lcm().subscribe("MPPI_STATUS", &Statuses::on, &statuses);
    daemon::LoopSettings settings;
    settings.latency.use_sample_time = false;  // fresh by receipt on the fake clock (test_lcm_transport.cpp)
    settings.status_hz = settings.rate_hz;     // a status every cycle
    loop = std::make_unique<daemon::ControlLoop>(controller.get(), &clock, &tx, &inbox, settings);
    tx.start(&inbox);
  }
  ~MapRig() { tx.stop(); }
  void send_state(std::int64_t seq, std::int64_t sample_utime) {
    mppi_lcm::vehicle_state_t m{};
    m.utime = m.sample_utime = sample_utime;
    m.seq = seq;
    m.model = 1, m.vehicle_count = 1, m.nx = 16, m.n = 16;
    m.x.assign(16, 0.0f);
    m.x[2] = 1.5f;
    for (int i = 12; i < 16; ++i) m.x[static_cast<std::size_t>(i)] = 3168.4f;
    tx.lcm().publish("MPPI_STATE", &m);
  }
  // Maps have an LCM instance of their own (each memq:// instance is a queue of its own).
  void send_map(const mppi_lcm::local_map_t& m) { tx.map_lcm().publish("MPPI_LOCAL_MAP", &m); }
  const DistanceField& field() {
    return dynamic_cast<TaskController<QuadrotorForest>&>(*controller).params().cost.field;
  }
  void cycle() { ASSERT_TRUE(loop->step_realtime(stop)); }

  app::AppConfig cfg;
  std::unique_ptr<Controller> controller;
  FakeClock clock;
  transport::LcmTransport tx;
  transport::Inbox inbox;
  Statuses statuses;
  std::unique_ptr<daemon::ControlLoop> loop;
  std::atomic<bool> stop{false};
};

TEST(LocalMapLoop, TheMapReachesTheForestCostAndTheStatusAndBadOnesLeaveIt) {
  MapRig r;
  std::int64_t seq = 0;
  r.send_state(++seq, kT0);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 1; }));
  r.cycle();
  EXPECT_FALSE(r.field().present()) << "no map yet";
  r.send_map(map_msg(1, kT0, 1200));
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.maps.load() == 1; }));
  r.send_state(++seq, kT0 + 20'000);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 2; }));
  r.cycle();
  ASSERT_TRUE(r.field().present());
  EXPECT_EQ(r.field().nx, 20);
  EXPECT_FLOAT_EQ(r.field().distance(0.0f, 0.0f, 0.5f), 1.2f);
  EXPECT_EQ(r.field().cells, r.inbox.map->front().grid.distance_mm) << "the cost reads the inbox's map in place";
  const std::uint64_t stamp = r.field().stamp;
  EXPECT_EQ(r.loop->counters().commands_normal.load(), 2);

  // A bad map: refused, counted, and the cost keeps the good one.
  auto bad = map_msg(2, kT0 + 30'000, 100);
  bad.resolution = std::numeric_limits<float>::quiet_NaN();
  r.send_map(bad);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.maps_rejected() == 1; }));
  r.send_state(++seq, kT0 + 40'000);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 3; }));
  r.cycle();
  EXPECT_EQ(r.field().stamp, stamp);
  EXPECT_FLOAT_EQ(r.field().distance(0.0f, 0.0f, 0.5f), 1.2f);
  ASSERT_TRUE(test::eventually([&] { return r.statuses.last().maps_rejected == 1; }));
  const auto st = r.statuses.last();
  EXPECT_EQ(st.maps_accepted, 1);
  EXPECT_NEAR(st.map_age_ms, 40.0f, 1e-3f);  // the state at kT0 + 40 ms, the map at kT0
  EXPECT_EQ(st.map_stale_cycles, 0);

  // A new good map replaces it (a new stamp: the GPU's copy follows).
  r.send_map(map_msg(3, kT0 + 50'000, 800));
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.maps.load() == 2; }));
  r.send_state(++seq, kT0 + 60'000);
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == 4; }));
  r.cycle();
  EXPECT_NE(r.field().stamp, stamp);
  EXPECT_FLOAT_EQ(r.field().distance(0.0f, 0.0f, 0.5f), 0.8f);
}

TEST(LocalMapLoop, AMapNoNewerOneReplacesIsKeptAndItsStaleCyclesCounted) {
  MapRig r;
  r.send_map(map_msg(1, kT0, 1500));
  ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.maps.load() == 1; }));
  // States 0.1 s apart: the map passes its 0.5 s timeout after the fifth.
  for (int k = 1; k <= 8; ++k) {
    r.send_state(k, kT0 + 100'000 * k);
    ASSERT_TRUE(test::eventually([&] { return r.inbox.counters.states.load() == k; }));
    r.cycle();
    ASSERT_TRUE(r.field().present()) << "cycle " << k << ": the cost keeps the last map";
  }
  EXPECT_EQ(r.loop->counters().map_stale_cycles.load(), 3);  // ages 0.6, 0.7, 0.8 s
  EXPECT_EQ(r.loop->counters().commands_normal.load(), 8);
  ASSERT_TRUE(test::eventually([&] { return r.statuses.last().map_stale_cycles == 3; }));
  EXPECT_NEAR(r.statuses.last().map_age_ms, 800.0f, 1e-3f);
}

}  // namespace
