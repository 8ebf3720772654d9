// mppid-mapper's node over memq://: a simulated depth frame in, a valid local_map_t out.
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>
#include <mppi_lcm/local_map_t.hpp>
#include <mppi_lcm/point_cloud_t.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include "mapper/node.hpp"
#include "sim/rng.hpp"
#include "sim/sensors.hpp"
#include "source_dir.hpp"

namespace {

struct MapSink {
  std::vector<mppi_lcm::local_map_t> maps;
  void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::local_map_t* m) { maps.push_back(*m); }
};

mppi_lcm::point_cloud_t depth_frame(const std::vector<sim::Obstacle>& trees, const sim::Pose& pose) {
  sim::RayWorld world(&trees, 0.0);
  sim::DepthCameraSpec spec;
  sim::Rng rng(4, 0);
  sim::Frame f;
  sim::DepthCamera(spec).capture(world, pose, rng, &f);
  mppi_lcm::point_cloud_t m;
  m.utime = 123456789;
  m.seq = 7;
  m.sensor = mppi_lcm::point_cloud_t::SENSOR_DEPTH_CAMERA;
  for (int i = 0; i < 3; ++i) m.position[i] = static_cast<float>(pose.p[static_cast<std::size_t>(i)]);
  for (int i = 0; i < 4; ++i) m.orientation[i] = static_cast<float>(pose.q[static_cast<std::size_t>(i)]);
  m.min_range = static_cast<float>(spec.min_range);
  m.max_range = static_cast<float>(spec.max_range);
  m.n = static_cast<std::int32_t>(f.x.size());
  m.x = f.x;
  m.y = f.y;
  m.z = f.z;
  m.hit = f.hit;
  return m;
}

// A mapper node on memq:// recording what it senses, and the maps it publishes.
struct MapperRig {
  lcm::LCM lc{"memq://"};
  mapper::MapperNode node{mapper::load_settings("", {}), &lc};
  std::FILE* sensed = std::tmpfile();
  MapSink sink;
  MapperRig() {
    node.record_sensed(sensed);
    lc.subscribe("MPPI_LOCAL_MAP", &MapSink::on, &sink);
  }
  ~MapperRig() { std::fclose(sensed); }
  // The frame in, the map it makes out (false if either did not happen).
  bool map(const mppi_lcm::point_cloud_t& frame) {
    lc.publish("MPPI_DEPTH", &frame);
    const std::size_t before = sink.maps.size();
    return lc.handleTimeout(100) == 1 && node.publish() && lc.handleTimeout(100) == 1 && sink.maps.size() == before + 1;
  }
};

// The map's distance at a world point [m].
double distance_at(const mppi_lcm::local_map_t& m, double x, double y, double z) {
  const int i = static_cast<int>((x - m.origin[0]) / m.resolution), j = static_cast<int>((y - m.origin[1]) / m.resolution),
            k = static_cast<int>((z - m.origin[2]) / m.resolution);
  return 1e-3 * m.distance_mm[static_cast<std::size_t>(i + m.nx * (j + m.ny * k))];
}

TEST(MapperNode, PublishesAValidLocalMapFromASimulatedDepthFrame) {
  MapperRig rig;
  ASSERT_TRUE(rig.lc.good());
  ASSERT_NE(rig.sensed, nullptr);
  auto& node = rig.node;
  auto& sink = rig.sink;
  std::FILE* sensed = rig.sensed;
  EXPECT_FALSE(node.publish());  // nothing seen yet: nothing to say

  std::vector<sim::Obstacle> trees(1);
  trees[0].x = 6.0;
  trees[0].y = -1.0;
  trees[0].radius = 0.3;
  sim::Pose pose;
  pose.p = {10.0, -1.0, 2.0};
  pose.q = {0.0, 0.0, 0.0, 1.0};  // yawed 180 deg: looking along -x, at the tree
  const auto frame = depth_frame(trees, pose);
  ASSERT_TRUE(rig.map(frame));
  ASSERT_EQ(sink.maps.size(), 1u);

  const auto& m = sink.maps[0];
  EXPECT_EQ(m.utime, frame.utime);
  EXPECT_EQ(m.seq, 0);
  EXPECT_FLOAT_EQ(m.resolution, 0.25f);
  EXPECT_EQ(m.nx, 128);
  EXPECT_EQ(m.ny, 128);
  EXPECT_EQ(m.nz, 32);
  EXPECT_EQ(m.n_cells, m.nx * m.ny * m.nz);
  ASSERT_EQ(m.distance_mm.size(), static_cast<std::size_t>(m.n_cells));
  EXPECT_FLOAT_EQ(m.max_distance, 5.0f);
  // Centred on the sensor, on the grid.
  EXPECT_NEAR(m.origin[0], 10.0 - 16.0, 0.25);
  EXPECT_NEAR(m.origin[2], 2.0 - 4.0, 0.25);
  // Between the vehicle and the tree, 2 m before its surface: ~2 m.
  const auto cell = [&](double x, double y, double z) { return distance_at(m, x, y, z); };
  EXPECT_NEAR(cell(8.3, -1.0, 2.0), 2.0, 0.25);
  EXPECT_LT(cell(6.0, -1.0, 2.0), 0.0);  // inside the trunk
  EXPECT_NEAR(cell(20.0, 10.0, 2.0), 5.0, 1e-3);  // behind the camera: unknown, free, saturated
  EXPECT_FALSE(node.publish());  // no new frame since

  // What was sensed: the tree's columns, the first time they were occupied, nothing else.
  std::rewind(sensed);
  char line[65536];
  ASSERT_NE(std::fgets(line, sizeof line, sensed), nullptr);
  const std::string rec = line;
  EXPECT_NE(rec.find("\"t\":0.000"), std::string::npos) << rec;
  EXPECT_NE(rec.find("\"sensor\":[10.000,-1.000,2.000]"), std::string::npos) << rec;
  int columns = 0;
  for (std::size_t at = rec.find("[", rec.find("columns")) + 1; (at = rec.find('[', at)) != std::string::npos; ++at) {
    double x = 0, y = 0;
    ASSERT_EQ(std::sscanf(rec.c_str() + at, "[%lf,%lf]", &x, &y), 2);
    EXPECT_LT(std::hypot(x - 6.0, y + 1.0), 0.3 + 0.4) << x << " " << y;
    ++columns;
  }
  EXPECT_GE(columns, 2);
  EXPECT_EQ(std::fgets(line, sizeof line, sensed), nullptr);  // one map, one line
}

// A camera tilted 45 degrees down (a fast forward flight's attitude) sees a trunk 4 m ahead
// only at its foot: the trunk is in the map, but not where the vehicle flies, so it is not yet
// "sensed"; seen level, it is.
TEST(MapperNode, ATrunkSeenOnlyAtItsFootIsNotSensedAtTheFlightHeight) {
  MapperRig rig;
  ASSERT_NE(rig.sensed, nullptr);
  std::vector<sim::Obstacle> trees(1);
  trees[0].x = 4.0;
  trees[0].radius = 0.3;
  sim::Pose pose;
  pose.p = {0.0, 0.0, 2.0};
  const double half = 0.5 * 45.0 * M_PI / 180.0;
  pose.q = {std::cos(half), 0.0, std::sin(half), 0.0};  // pitched 45 deg down, looking along +x
  ASSERT_TRUE(rig.map(depth_frame(trees, pose)));
  const auto nearest = [&](double z) {  // along the trunk's near side, at height z
    double d = 1e9;
    for (double x = 3.3; x < 4.0; x += 0.05) d = std::min(d, distance_at(rig.sink.maps.back(), x, 0.0, z));
    return d;
  };
  EXPECT_LT(nearest(0.6), 0.0);  // the foot: occupied
  EXPECT_GT(nearest(2.0), 0.2);  // at the flight height: not seen, free
  std::fflush(rig.sensed);
  EXPECT_EQ(std::ftell(rig.sensed), 0L);  // nothing sensed where the vehicle flies

  pose.q = {1.0, 0.0, 0.0, 0.0};  // level
  auto level = depth_frame(trees, pose);
  level.utime += 100000;
  ASSERT_TRUE(rig.map(level));
  std::rewind(rig.sensed);
  char line[65536];
  ASSERT_NE(std::fgets(line, sizeof line, rig.sensed), nullptr);
  EXPECT_NE(std::string(line).find("\"t\":0.100"), std::string::npos) << line;
}

TEST(MapperNode, CountsAndIgnoresUndecodableFrames) {
  lcm::LCM lc("memq://");
  mapper::MapperNode node(mapper::load_settings("", {}), &lc);
  const unsigned char junk[70] = {1, 2, 3};
  lc.publish("MPPI_DEPTH", junk, sizeof junk);
  ASSERT_EQ(lc.handleTimeout(100), 1);
  EXPECT_FALSE(node.publish());
  EXPECT_NE(node.stats_json().find("\"undecodable\":1"), std::string::npos);
}

TEST(MapperSettings, OverridesApplyAndUnknownKeysFail) {
  const auto s = mapper::load_settings(mppi::testing::source_dir() + "/config/mapper/mapper.yaml",
                                       {"map.resolution=0.2", "rate_hz=20", "inputs=[MPPI_LIDAR]"});
  EXPECT_DOUBLE_EQ(s.map.resolution, 0.2);
  EXPECT_DOUBLE_EQ(s.rate_hz, 20.0);
  ASSERT_EQ(s.inputs.size(), 1u);
  EXPECT_EQ(s.inputs[0], "MPPI_LIDAR");
  EXPECT_THROW(mapper::load_settings("", {"map.resolutio=0.2"}), std::runtime_error);
  EXPECT_THROW(mapper::load_settings("", {"rate_hz=0"}), std::runtime_error);
}

TEST(MapperSettings, TheBusesAreSettingsTheDefaultsLcmsAndTheMapsOnes) {
  const auto d = mapper::load_settings(mppi::testing::source_dir() + "/config/mapper/mapper.yaml", {});
  EXPECT_EQ(d.lcm_url, "") << "LCM's default bus";
  EXPECT_EQ(d.sensor_lcm_url, "") << "the maps' bus";
  const auto s = mapper::load_settings("", {"lcm_url=udpm://239.255.76.67:7667?ttl=0", "sensor_lcm_url=memq://"});
  EXPECT_EQ(s.lcm_url, "udpm://239.255.76.67:7667?ttl=0");
  EXPECT_EQ(s.sensor_lcm_url, "memq://");
  EXPECT_THROW(mapper::load_settings("", {"lcm_ur=memq://"}), std::runtime_error);
}

}  // namespace

namespace {

TEST(MapperNode, ACountTheBytesDoNotBackIsUndecodable) {
  mppi_lcm::point_cloud_t m;
  m.n = 2;
  m.x = {1, 2};
  m.y = {0, 0};
  m.z = {0, 0};
  m.hit = {1, 0};
  std::vector<unsigned char> buf(static_cast<std::size_t>(m.getEncodedSize()));
  ASSERT_EQ(m.encode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  mppi_lcm::point_cloud_t out;
  ASSERT_TRUE(mapper::decode_cloud(buf.data(), buf.size(), &out));
  EXPECT_EQ(out.n, 2);
  EXPECT_EQ(out.hit[1], 0);
  // n sits after the fingerprint, utime, seq, sensor, position, orientation and the ranges.
  const std::size_t at = 8 + 8 + 8 + 1 + 12 + 16 + 4 + 4;
  ASSERT_EQ(buf[at + 3], 2);
  for (const int lie : {0x7F, 0xFF}) {  // 2^31 - 1 points, or a negative count
    auto bad = buf;
    bad[at] = static_cast<unsigned char>(lie);
    EXPECT_FALSE(mapper::decode_cloud(bad.data(), bad.size(), &out));
  }
  EXPECT_FALSE(mapper::decode_cloud(buf.data(), buf.size() - 1, &out));  // truncated
}

}  // namespace
