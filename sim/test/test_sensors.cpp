// The simulator's sensors: a ray against a cylinder of finite height and the ground, the
// azimuth bins against testing every tree, the camera's and the LiDAR's frames, the mount.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <lcm/lcm-cpp.hpp>
#include <mppi_lcm/point_cloud_t.hpp>
#include <stdexcept>

#include "sim/rng.hpp"
#include "sim/scenario.hpp"
#include "sim/sensor_rig.hpp"
#include "sim/sensors.hpp"

namespace {

using sim::Obstacle;
constexpr double kInf = std::numeric_limits<double>::infinity();

Obstacle tree(double x, double y, double r, double h) {
  Obstacle o;
  o.x = x;
  o.y = y;
  o.radius = r;
  o.height = h;
  return o;
}

TEST(RayCylinder, HitsTheSideAtTheNearSurface) {
  const double o[3] = {0, 0, 1}, d[3] = {1, 0, 0};
  EXPECT_NEAR(sim::ray_cylinder(o, d, tree(5, 0, 0.5, 3), 0.0, 100.0), 4.5, 1e-12);
  // Off-centre: the chord's near end, sqrt(r^2 - y^2) before the centre.
  const double o2[3] = {0, 0.3, 1};
  EXPECT_NEAR(sim::ray_cylinder(o2, d, tree(5, 0, 0.5, 3), 0.0, 100.0), 5.0 - 0.4, 1e-12);
}

TEST(RayCylinder, PassesOverItsTopAndBesideIt) {
  const double d[3] = {1, 0, 0};
  const double over[3] = {0, 0, 3.5}, beside[3] = {0, 0.6, 1};
  EXPECT_EQ(sim::ray_cylinder(over, d, tree(5, 0, 0.5, 3), 0.0, 100.0), kInf);
  EXPECT_EQ(sim::ray_cylinder(beside, d, tree(5, 0, 0.5, 3), 0.0, 100.0), kInf);
  const double back[3] = {-1, 0, 0}, o[3] = {0, 0, 1};
  EXPECT_EQ(sim::ray_cylinder(o, back, tree(5, 0, 0.5, 3), 0.0, 100.0), kInf);  // behind the origin
}

TEST(RayCylinder, ComesDownThroughTheTopCap) {
  const double s = 1.0 / std::sqrt(5.0);
  // From (3, 0, 4) toward (5, 0, 3): meets the side's line at x = 4.5 above the top (z 3.25),
  // then the cap (z = 3) at x = 5, sqrt(5) along the ray.
  const double o[3] = {3, 0, 4}, d[3] = {2 * s, 0, -s};
  EXPECT_NEAR(sim::ray_cylinder(o, d, tree(5, 0, 0.5, 3), 0.0, 100.0), std::sqrt(5.0), 1e-9);
  // Straight down from above the trunk.
  const double above[3] = {5.1, 0, 10}, down[3] = {0, 0, -1};
  EXPECT_NEAR(sim::ray_cylinder(above, down, tree(5, 0, 0.5, 3), 0.0, 100.0), 7.0, 1e-12);
  // On a raised ground, the tree stands on it: top at 1 + 3.
  EXPECT_NEAR(sim::ray_cylinder(above, down, tree(5, 0, 0.5, 3), 1.0, 100.0), 6.0, 1e-12);
}

TEST(RayCylinder, RespectsTheRangeAndAnOriginInside) {
  const double o[3] = {0, 0, 1}, d[3] = {1, 0, 0};
  EXPECT_EQ(sim::ray_cylinder(o, d, tree(5, 0, 0.5, 3), 0.0, 4.4), kInf);
  const double inside[3] = {5, 0.1, 1};
  EXPECT_EQ(sim::ray_cylinder(inside, d, tree(5, 0, 0.5, 3), 0.0, 100.0), 0.0);
}

TEST(RayGround, HitsThePlaneBelowOnly) {
  const double s = 1.0 / std::sqrt(2.0);
  const double o[3] = {0, 0, 2}, down[3] = {s, 0, -s}, up[3] = {s, 0, s};
  EXPECT_NEAR(sim::ray_ground(o, down, 0.0, 100.0), 2.0 * std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(sim::ray_ground(o, down, 0.5, 100.0), 1.5 * std::sqrt(2.0), 1e-12);
  EXPECT_EQ(sim::ray_ground(o, up, 0.0, 100.0), kInf);
  EXPECT_EQ(sim::ray_ground(o, down, 0.0, 2.0), kInf);
}

TEST(RayWorld, AzimuthBinsFindWhatTestingEveryTreeFinds) {
  sim::Rng rng(7, 0);
  std::vector<Obstacle> trees;
  for (int i = 0; i < 60; ++i)
    trees.push_back(tree(rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(0.1, 0.6), rng.uniform(1.0, 6.0)));
  trees.push_back(tree(0.2, 0.0, 0.5, 1.5));  // around the origin, below it: seen looking down
  sim::RayWorld world(&trees, 0.0);
  const double origin[3] = {0.0, 0.0, 2.0};
  world.prepare(origin, 12.0);
  int hits = 0;
  for (int k = 0; k < 20000; ++k) {
    const double z = rng.uniform(-1, 1), a = rng.uniform(0, 6.283185307179586), r = std::sqrt(1 - z * z);
    const double d[3] = {r * std::cos(a), r * std::sin(a), z};
    double brute = sim::ray_ground(origin, d, 0.0, 12.0);
    for (const auto& t : trees) brute = std::min(brute, sim::ray_cylinder(origin, d, t, 0.0, 12.0));
    const double got = world.cast(d, 12.0);
    if (std::isfinite(brute)) ++hits;
    ASSERT_EQ(std::isfinite(got), std::isfinite(brute)) << k;
    if (std::isfinite(brute)) {
      ASSERT_NEAR(got, brute, 1e-9) << k;
    }
  }
  EXPECT_GT(hits, 5000);  // the ground and the trees were met
}

TEST(Mount, PitchDownTiltsTheOpticalAxisDown) {
  sim::Pose body;
  body.p = {1, 2, 3};
  // Yawed 90 deg: the body's x is the world's y.
  body.q = {std::cos(M_PI / 4), 0, 0, std::sin(M_PI / 4)};
  const sim::Pose cam = sim::mounted(body, {0.1, 0.0, 0.0}, 30.0 * M_PI / 180.0);
  EXPECT_NEAR(cam.p[0], 1.0, 1e-12);
  EXPECT_NEAR(cam.p[1], 2.1, 1e-12);
  const double x[3] = {1, 0, 0};
  double w[3];
  cam.rotate(x, w);
  EXPECT_NEAR(w[0], 0.0, 1e-12);
  EXPECT_NEAR(w[1], std::cos(M_PI / 6), 1e-12);
  EXPECT_NEAR(w[2], -0.5, 1e-12);
}

TEST(DepthCamera, SeesTheTreeAheadTheGroundBelowAndMissesAbove) {
  sim::DepthCameraSpec spec;
  spec.width = 40;
  spec.height = 30;
  spec.noise = 0.0;
  spec.dropout = 0.0;
  const sim::DepthCamera cam(spec);
  std::vector<Obstacle> trees{tree(5, 0, 1.0, 8.0)};
  sim::RayWorld world(&trees, 0.0);
  sim::Pose pose;
  pose.p = {0, 0, 2};
  sim::Rng rng(1, 0);
  sim::Frame f;
  cam.capture(world, pose, rng, &f);
  ASSERT_EQ(f.x.size(), 40u * 30u);  // every ray, the misses too
  int ground = 0, tree_hits = 0, misses = 0;
  for (std::size_t i = 0; i < f.x.size(); ++i) {
    const double r = std::sqrt(f.x[i] * f.x[i] + f.y[i] * f.y[i] + f.z[i] * f.z[i]);
    if (f.hit[i] == 0) {
      ++misses;
      EXPECT_NEAR(r, spec.max_range, 1e-4);
      continue;
    }
    const double wz = 2.0 + f.z[i];
    const double dx = f.x[i] - 5.0, dy = f.y[i];
    if (std::fabs(wz) < 1e-4)
      ++ground;
    else if (std::fabs(std::sqrt(dx * dx + dy * dy) - 1.0) < 1e-4)
      ++tree_hits;
    else
      ADD_FAILURE() << "a return on neither the ground nor the tree at " << f.x[i] << " " << f.y[i] << " " << f.z[i];
  }
  EXPECT_GT(ground, 100);
  EXPECT_GT(tree_hits, 50);
  EXPECT_GT(misses, 100);
}

TEST(DepthCamera, DropsPixelsAtItsRateAndAddsRangeNoise) {
  sim::DepthCameraSpec spec;
  spec.dropout = 0.25;
  spec.noise = 0.01;
  const sim::DepthCamera cam(spec);
  std::vector<Obstacle> trees{tree(4, 0, 3.0, 20.0)};  // fills the view: every ray hits it, 1-2 m away
  sim::RayWorld world(&trees, 0.0);
  sim::Pose pose;
  pose.p = {0, 0, 2};
  sim::Rng rng(3, 0);
  sim::Frame f;
  cam.capture(world, pose, rng, &f);
  const double kept = static_cast<double>(f.x.size()) / (spec.width * spec.height);
  EXPECT_NEAR(kept, 0.75, 0.02);
  double err2 = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < f.x.size(); ++i) {
    if (f.hit[i] == 0) continue;
    const double dx = f.x[i] - 4.0, dy = f.y[i];
    err2 += std::pow(std::sqrt(dx * dx + dy * dy) - 3.0, 2);
    ++n;
  }
  ASSERT_GT(n, 1000);
  // 0.01 r^2 at r ~ 1..2 m: a few centimetres, not zero.
  EXPECT_GT(std::sqrt(err2 / n), 0.005);
  EXPECT_LT(std::sqrt(err2 / n), 0.06);
}

TEST(Lidar, BeamsBelowTheHorizonMeetTheGroundAtTheirRange) {
  sim::LidarSpec spec;
  spec.noise = 0.0;
  const sim::Lidar lidar(spec);
  std::vector<Obstacle> none;
  sim::RayWorld world(&none, 0.0);
  sim::Pose pose;
  pose.p = {0, 0, 2};
  sim::Rng rng(1, 0);
  sim::Frame f;
  lidar.capture(world, pose, rng, &f);
  ASSERT_EQ(f.x.size(), static_cast<std::size_t>(spec.beams * spec.azimuth_steps));
  int ground = 0;
  for (std::size_t i = 0; i < f.x.size(); ++i) {
    if (f.hit[i] == 0) {
      EXPECT_NEAR(std::sqrt(f.x[i] * f.x[i] + f.y[i] * f.y[i] + f.z[i] * f.z[i]), spec.max_range, 1e-4);
      continue;
    }
    EXPECT_NEAR(f.z[i], -2.0, 1e-4);
    ++ground;
  }
  // Beams at -15, -13, ..., -5 deg reach the ground within 30 m (2 / sin(5 deg) = 22.9 m);
  // -3 deg (38 m) and -1 deg do not.
  EXPECT_EQ(ground, 6 * spec.azimuth_steps);
}

TEST(SensingScenario, ParsesTheSensorsAndRejectsUnknownKeys) {
  const std::string base = "task: quadrotor_forest\nplant: {model: quadrotor}\n";
  const auto s = sim::load_scenario_text(
      base + "sensing: {publish_obstacles: false, depth_camera: {width: 64, height: 48, latency: 0.05}}\n", "t.yaml", 1);
  EXPECT_FALSE(s.sensing.publish_obstacles);
  EXPECT_TRUE(s.sensing.depth_camera.enabled);
  EXPECT_EQ(s.sensing.depth_camera.width, 64);
  EXPECT_DOUBLE_EQ(s.sensing.depth_camera.latency, 0.05);
  EXPECT_FALSE(s.sensing.lidar.enabled);
  EXPECT_THROW(sim::load_scenario_text(base + "sensing: {lidar: {beam: 16}}\n", "t.yaml", 1), std::runtime_error);
  EXPECT_THROW(sim::load_scenario_text(base + "sensing: {depth_camera: {hfov_deg: 180}}\n", "t.yaml", 1),
               std::runtime_error);
  const auto f = sim::load_scenario_text(
      base + "world: {forest: {height: 4.5, x_range: [4, 26], y_range: [-8, 8]}}\n", "t.yaml", 3);
  ASSERT_FALSE(f.obstacles.empty());
  for (const auto& o : f.obstacles) EXPECT_DOUBLE_EQ(o.height, 4.5);
}

}  // namespace

namespace {

struct CloudSink {
  std::vector<mppi_lcm::point_cloud_t> got;
  void on(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::point_cloud_t* m) { got.push_back(*m); }
};

TEST(SensorRig, CapturesAtItsRateAndPublishesItsLatencyLaterStampedWithTheCapture) {
  sim::Scenario s = sim::load_scenario_text(
      "task: quadrotor_forest\nplant: {model: quadrotor}\n"
      "sensing: {depth_camera: {width: 8, height: 6, rate_hz: 30, latency: 0.03}, lidar: {beams: 2, azimuth_steps: 8}}\n",
      "t.yaml", 1);
  s.obstacles.push_back(tree(5, 0, 0.5, 8));
  lcm::LCM lc("memq://");
  ASSERT_TRUE(lc.good());
  CloudSink depth, lidar;
  lc.subscribe("D", &CloudSink::on, &depth);
  lc.subscribe("L", &CloudSink::on, &lidar);
  sim::SensorRig rig(s, &lc, "D", "L");
  sim::Pose body;
  body.p = {0, 0, 2};
  for (int k = 0; k <= 100; ++k) {  // 0.1 s at 1 kHz
    rig.step(k * 1e-3, body, s.obstacles, 1000000);
    while (lc.handleTimeout(0) > 0) {
    }
  }
  // Captures at 0, 1/30, 2/30 and 0.1 s; the first three out by 0.1 s (30 ms later).
  ASSERT_EQ(depth.got.size(), 3u);
  for (std::size_t i = 0; i < depth.got.size(); ++i) {
    EXPECT_NEAR(static_cast<double>(depth.got[i].utime - 1000000), 1e6 * static_cast<double>(i) / 30.0, 1001.0);
    EXPECT_EQ(depth.got[i].seq, static_cast<std::int64_t>(i));
    EXPECT_EQ(depth.got[i].sensor, mppi_lcm::point_cloud_t::SENSOR_DEPTH_CAMERA);
    EXPECT_EQ(depth.got[i].n, static_cast<std::int32_t>(depth.got[i].x.size()));
    EXPECT_FLOAT_EQ(depth.got[i].position[0], 0.1f);  // the mount's offset
  }
  ASSERT_EQ(lidar.got.size(), 2u);  // 10 Hz, no latency: t = 0 and 0.1 s
  EXPECT_EQ(lidar.got[1].utime, 1100000);
  EXPECT_EQ(lidar.got[0].n, 16);
}

}  // namespace
