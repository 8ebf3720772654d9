// mppid-sensors (sim/sensor_node.hpp): for the same pose and seed its frames are the
// simulator's (SensorRig's); stamped with the truth's sample time and out their latency
// later; every kind of bad truth refused and counted, and nothing captured before the world.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <mppi_lcm/obstacles_t.hpp>
#include <mppi_lcm/point_cloud_t.hpp>
#include <mppi_lcm/vehicle_state_t.hpp>
#include <vector>

#include "sim/scenario.hpp"
#include "sim/sensor_node.hpp"
#include "sim/sensor_rig.hpp"
#include "source_dir.hpp"

namespace {

constexpr std::int64_t kT0 = 1'790'000'000'000'000;  // a wall-clock time, us

struct Sink {
  std::vector<mppi_lcm::point_cloud_t> got;
  void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::point_cloud_t* m) { got.push_back(*m); }
};

void drain(lcm::LCM& lc) {
  while (lc.handleTimeout(0) > 0) {
  }
}

sim::Scenario sensed(double latency) {
  sim::Scenario s = sim::load_scenario_text(
      "task: quadrotor_forest\nplant: {model: quadrotor}\nsensing:\n"
      "  depth_camera: {width: 32, height: 24, rate_hz: 30, latency: " + std::to_string(latency) + "}\n"
      "  lidar: {beams: 4, azimuth_steps: 64, rate_hz: 10, latency: 0}\n",
      "t.yaml", 7);
  for (double y : {-1.0, 0.5, 3.0}) s.obstacles.push_back({5.0, y, 0.4, 0.0, 0.0, 10.0});
  s.obstacles.push_back({0.0, 6.0, 0.3, 0.0, 0.0, 10.0});
  return s;
}

mppi_lcm::obstacles_t world_of(const std::vector<sim::Obstacle>& trees) {
  mppi_lcm::obstacles_t m{};
  for (const auto& o : trees) {
    mppi_lcm::cylinder_t c{};
    c.x = static_cast<float>(o.x);
    c.y = static_cast<float>(o.y);
    c.radius = static_cast<float>(o.radius);
    m.cylinders.push_back(c);
  }
  m.n = static_cast<std::int32_t>(m.cylinders.size());
  return m;
}

// A truth as ap_truth.py publishes it: the rate quadrotor's 13 states, ENU / FLU -> ENU.
std::vector<std::uint8_t> truth(const sim::Pose& p, std::int64_t sample_us, std::int8_t model = 2) {
  mppi_lcm::vehicle_state_t m{};
  m.utime = m.sample_utime = sample_us;
  m.model = model;
  m.vehicle_count = 1;
  m.nx = 13;
  m.n = 13;
  m.x.assign(13, 0.0f);
  for (int i = 0; i < 3; ++i) m.x[static_cast<std::size_t>(i)] = static_cast<float>(p.p[static_cast<std::size_t>(i)]);
  for (int i = 0; i < 4; ++i) m.x[static_cast<std::size_t>(6 + i)] = static_cast<float>(p.q[static_cast<std::size_t>(i)]);
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  return buf;
}

sim::Pose yawed(double x, double y, double z, double yaw) {
  sim::Pose p;
  p.p = {x, y, z};
  p.q = {std::cos(yaw / 2), 0.0, 0.0, std::sin(yaw / 2)};
  return p;
}

struct NodeUnderTest {
  sim::Scenario s;
  lcm::LCM lc{"memq://"};
  Sink depth, lidar;
  std::unique_ptr<sim::SensorNode> node;
  explicit NodeUnderTest(double latency) : s(sensed(latency)) {
    lc.subscribe("MPPI_DEPTH", &Sink::on, &depth);
    lc.subscribe("MPPI_LIDAR", &Sink::on, &lidar);
    node = std::make_unique<sim::SensorNode>(s, sim::SensorNodeSettings{}, &lc, &lc, [] { return kT0; });
  }
};

TEST(SensorNode, GivesTheSimulatorsFramesForTheSamePoseAndSeed) {
  // The pose a float carries exactly: the truth goes through vehicle_state_t's floats.
  const sim::Pose body = yawed(0.5, 0.25, 2.0, 0.25);
  sim::Scenario s = sensed(0.03);
  lcm::LCM sim_bus("memq://");
  Sink sim_depth, sim_lidar;
  sim_bus.subscribe("MPPI_DEPTH", &Sink::on, &sim_depth);
  sim_bus.subscribe("MPPI_LIDAR", &Sink::on, &sim_lidar);
  sim::SensorRig rig(s, &sim_bus, "MPPI_DEPTH", "MPPI_LIDAR");
  rig.step(0.0, body, s.obstacles, kT0);
  rig.step(0.03, body, s.obstacles, kT0);
  drain(sim_bus);

  NodeUnderTest t(0.03);
  t.node->on_world(world_of(s.obstacles));
  const sim::Pose sent = sim::Pose{body.p, {static_cast<float>(body.q[0]), 0.0, 0.0, static_cast<float>(body.q[3])}};
  const auto msg = truth(sent, kT0);
  ASSERT_TRUE(t.node->on_truth(msg.data(), msg.size(), kT0 + 500));
  t.node->publish_due(kT0 + 30'000);
  drain(t.lc);
  ASSERT_EQ(sim_depth.got.size(), 1u);
  ASSERT_EQ(t.depth.got.size(), 1u);
  ASSERT_EQ(t.lidar.got.size(), 1u);
  for (auto [a, b] : {std::pair{&sim_depth.got[0], &t.depth.got[0]}, std::pair{&sim_lidar.got[0], &t.lidar.got[0]}}) {
    EXPECT_EQ(b->utime, kT0);
    EXPECT_EQ(a->utime, b->utime);
    EXPECT_EQ(a->sensor, b->sensor);
    ASSERT_EQ(a->n, b->n);
    EXPECT_GT(b->n, 0);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(a->position[i], b->position[i], 1e-6);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(a->orientation[i], b->orientation[i], 1e-6);
    int hits = 0;
    for (std::size_t i = 0; i < a->x.size(); ++i) {
      // The same rays, the same noise and dropouts (the seed's stream): the same points, but
      // for the pose's float rounding.
      ASSERT_EQ(a->hit[i], b->hit[i]) << i;
      EXPECT_NEAR(a->x[i], b->x[i], 1e-4);
      EXPECT_NEAR(a->y[i], b->y[i], 1e-4);
      EXPECT_NEAR(a->z[i], b->z[i], 1e-4);
      hits += b->hit[i];
    }
    EXPECT_GT(hits, 0);
  }
}

TEST(SensorNode, StampsFramesWithTheTruthsTimeAndSendsThemTheirLatencyLater) {
  NodeUnderTest t(0.03);
  t.node->on_world(world_of(t.s.obstacles));
  // Truths at 50 Hz for 0.2 s; the camera's 30 Hz falls on them at 0, 40, 80, 100, 140, 180, 200 ms.
  std::vector<std::int64_t> stamps;
  for (int k = 0; k <= 10; ++k) {
    const std::int64_t ts = kT0 + 20'000 * k;
    const auto msg = truth(yawed(0.0, 0.0, 2.0, 1.5707963705062866), ts);  // facing +y (north)
    ASSERT_TRUE(t.node->on_truth(msg.data(), msg.size(), ts + 1'000));
    t.node->publish_due(ts + 1'000);
    drain(t.lc);
    if (t.depth.got.size() > stamps.size()) stamps.push_back(ts);
    const std::int64_t due = t.node->next_publish_us();
    if (due != std::numeric_limits<std::int64_t>::max()) {
      t.node->publish_due(due - 1);
      drain(t.lc);
      EXPECT_EQ(t.depth.got.size(), stamps.size());  // not a microsecond early
    }
  }
  t.node->publish_due(kT0 + 1'000'000);
  drain(t.lc);
  std::vector<std::int64_t> want;
  for (int ms : {0, 40, 80, 100, 140, 180, 200}) want.push_back(kT0 + 1000 * ms);
  ASSERT_EQ(t.depth.got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(t.depth.got[i].utime, want[i]);
    EXPECT_EQ(t.depth.got[i].seq, static_cast<std::int64_t>(i));
  }
  // The camera 0.1 m ahead of the body along its x, which faces +y: the sensor at (0, 0.1, 2).
  const auto& f = t.depth.got[0];
  EXPECT_NEAR(f.position[0], 0.0, 1e-6);
  EXPECT_NEAR(f.position[1], 0.1, 1e-6);
  // The tree at (0, 6), radius 0.3, stands straight ahead: the centre pixels' returns are
  // its near face, 5.6 m from the camera (the camera's noise: 0.002 x 5.6^2 = 0.06 m).
  double best = 1e9;
  for (std::size_t i = 0; i < f.x.size(); ++i)
    if (f.hit[i] != 0 && std::fabs(f.y[i]) < 0.2 && std::fabs(f.z[i]) < 0.2) best = std::min<double>(best, f.x[i]);
  EXPECT_NEAR(best, 5.6, 0.2);
}

TEST(SensorNode, RefusesAndCountsBadTruths) {
  NodeUnderTest t(0.0);
  const sim::Pose ok = yawed(0, 0, 2, 0);
  auto before = truth(ok, kT0);
  EXPECT_FALSE(t.node->on_truth(before.data(), before.size(), kT0));  // no world yet
  EXPECT_EQ(t.node->counters().before_world, 1);
  t.node->on_world(world_of(t.s.obstacles));
  sim::Pose nan = ok;
  nan.p[0] = std::numeric_limits<double>::quiet_NaN();
  sim::Pose unnormal = ok;
  unnormal.q = {2.0, 0.0, 0.0, 0.0};
  const auto bad_nan = truth(nan, kT0 + 1000), bad_q = truth(unnormal, kT0 + 1000);
  const auto stale = truth(ok, kT0 - 200'000), future = truth(ok, kT0 + 200'000);
  const auto other_model = truth(ok, kT0 + 1000, 1);
  const auto truncated = [&] {
    auto m = truth(ok, kT0 + 1000);
    m.pop_back();
    return m;
  }();
  for (const auto* m : {&bad_nan, &bad_q, &stale, &future, &other_model, &truncated})
    EXPECT_FALSE(t.node->on_truth(m->data(), m->size(), kT0));
  const auto good = truth(ok, kT0 + 2000);
  EXPECT_TRUE(t.node->on_truth(good.data(), good.size(), kT0));
  const auto again = truth(ok, kT0 + 2000);
  EXPECT_FALSE(t.node->on_truth(again.data(), again.size(), kT0));  // not newer
  const auto& n = t.node->counters();
  EXPECT_EQ(n.not_finite, 2);
  EXPECT_EQ(n.stale, 2);
  EXPECT_EQ(n.layout, 1);
  EXPECT_EQ(n.undecodable, 1);
  EXPECT_EQ(n.out_of_order, 1);
  EXPECT_EQ(n.taken, 1);
  t.node->publish_due(kT0 + 2000);
  drain(t.lc);
  EXPECT_EQ(t.depth.got.size(), 1u);  // the good one's frame only
  mppi_lcm::obstacles_t broken = world_of(t.s.obstacles);
  broken.cylinders[0].radius = -1.0f;
  t.node->on_world(broken);
  EXPECT_EQ(t.node->counters().bad_worlds, 1);
}

TEST(SensorNode, TakesTheWorldAndTheTruthFromTheBus) {
  NodeUnderTest t(0.0);
  const auto world = world_of(t.s.obstacles);
  t.lc.publish("MPPI_WORLD", &world);
  drain(t.lc);
  const auto msg = truth(yawed(0, 0, 2, 0), kT0);
  t.lc.publish("SIM_TRUTH", msg.data(), static_cast<unsigned>(msg.size()));
  drain(t.lc);
  t.node->publish_due(kT0);
  drain(t.lc);
  EXPECT_EQ(t.node->counters().worlds, 1);
  EXPECT_EQ(t.node->counters().taken, 1);
  EXPECT_EQ(t.depth.got.size(), 1u);
  EXPECT_EQ(t.lidar.got.size(), 1u);
}

TEST(SensorNode, ReadsAMissionsSensingBlockAsTheSimulatorReadsAScenarios) {
  const auto m = sim::load_sensing(mppi::testing::source_dir() + "/config/missions/rate_forest_sensed.yaml");
  const auto s = sim::load_scenario(mppi::testing::source_dir() + "/config/scenarios/forest_4m_sensed.yaml", 1);
  EXPECT_FALSE(m.publish_obstacles);
  ASSERT_TRUE(m.depth_camera.enabled);
  EXPECT_FALSE(m.lidar.enabled);
  const auto& a = m.depth_camera;
  const auto& b = s.sensing.depth_camera;  // the sensed forest's camera: the same
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_DOUBLE_EQ(a.hfov_deg, b.hfov_deg);
  EXPECT_DOUBLE_EQ(a.max_range, b.max_range);
  EXPECT_DOUBLE_EQ(a.latency, b.latency);
  EXPECT_DOUBLE_EQ(a.rate_hz, b.rate_hz);
  EXPECT_DOUBLE_EQ(a.offset[0], b.offset[0]);
}

}  // namespace
