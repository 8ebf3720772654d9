// mppid-mapper's map: rays clear and mark cells, the window rolls, and the signed distance
// field is exact on the grid and within a cell of the truth for a tree the camera saw.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "mapper/local_map.hpp"
#include "sim/rng.hpp"
#include "sim/sensors.hpp"

namespace {

mapper::MapSettings small() {
  mapper::MapSettings s;
  s.size = {8.0, 8.0, 4.0};  // 32 x 32 x 16 cells
  return s;
}

// A small map centred at (0, 0, 2): x, y in [-4, 4), z in [0, 4).
mapper::LocalMap small_map() {
  mapper::LocalMap m(small());
  const double c[3] = {0.0, 0.0, 2.0};
  m.recentre(c);
  return m;
}

// The map's value at a world point (the cell it falls in), in metres.
double at(const mapper::LocalMap& m, const std::vector<std::int16_t>& mm, double x, double y, double z) {
  const double p[3] = {x, y, z};
  const int i = m.index_of(p);
  EXPECT_GE(i, 0) << x << " " << y << " " << z;
  return i < 0 ? std::numeric_limits<double>::quiet_NaN() : 1e-3 * mm[static_cast<std::size_t>(i)];
}

TEST(LocalMap, ARayClearsWhatItCrossesAndMarksWhereItEnds) {
  mapper::LocalMap m = small_map();
  const double o[3] = {0.1, 0.1, 2.1}, e[3] = {2.6, 0.1, 2.1};
  for (int k = 0; k < 3; ++k) m.integrate_ray(o, e, true);
  EXPECT_TRUE(m.occupied(m.index_of(e)));
  const double mid[3] = {1.3, 0.1, 2.1}, beyond[3] = {3.1, 0.1, 2.1};
  EXPECT_TRUE(m.known(m.index_of(mid)));
  EXPECT_FALSE(m.occupied(m.index_of(mid)));
  EXPECT_FALSE(m.known(m.index_of(beyond)));
  std::vector<std::int16_t> mm;
  m.compute_distance(&mm);
  // Centre to centre k cells along x, less half a cell: the distance to the cell's face.
  EXPECT_NEAR(at(m, mm, 2.6, 0.1, 2.1), -0.125, 1e-3);
  EXPECT_NEAR(at(m, mm, 2.35, 0.1, 2.1), 0.125, 1e-3);
  EXPECT_NEAR(at(m, mm, 1.6, 0.1, 2.1), 0.875, 1e-3);
  EXPECT_NEAR(at(m, mm, 2.6, 1.1, 2.6), (std::sqrt(16.0 + 4.0) - 0.5) * 0.25, 1e-3);
  EXPECT_NEAR(at(m, mm, -3.9, 0.1, 2.1), small().max_distance, 1e-3);  // saturated
}

TEST(LocalMap, RepeatedMissesClearAnOccupiedCell) {
  mapper::LocalMap m = small_map();
  const double o[3] = {0.1, 0.1, 2.1}, e[3] = {2.6, 0.1, 2.1}, far[3] = {3.6, 0.1, 2.1};
  m.integrate_ray(o, e, true);
  ASSERT_TRUE(m.occupied(m.index_of(e)));
  for (int k = 0; k < 3; ++k) m.integrate_ray(o, far, false);
  EXPECT_FALSE(m.occupied(m.index_of(e)));
  EXPECT_TRUE(m.known(m.index_of(far)));
}

TEST(LocalMap, TheWindowRollsWithTheWorldAndForgetsWhatLeftIt) {
  mapper::LocalMap m = small_map();
  const double o[3] = {0.1, 0.1, 2.1}, e[3] = {2.6, 0.1, 2.1};
  m.integrate_ray(o, e, true);
  const double ahead[3] = {2.0, 0.0, 2.0};  // two metres on: eight cells
  m.recentre(ahead);
  ASSERT_GE(m.index_of(e), 0);
  EXPECT_TRUE(m.occupied(m.index_of(e)));  // the same world cell, still marked
  EXPECT_NEAR(m.origin()[0], 2.0 - 4.0, 1e-9);
  const double away[3] = {20.0, 0.0, 2.0};
  m.recentre(away);
  EXPECT_EQ(m.index_of(e), -1);
  m.recentre(ahead);
  EXPECT_FALSE(m.known(m.index_of(e)));  // left the window: forgotten
}

TEST(LocalMap, DistanceTransformIsExactOnTheGrid) {
  mapper::MapSettings s = small();
  s.max_distance = 30.0;
  mapper::LocalMap m(s);
  sim::Rng rng(11, 0);
  for (int k = 0; k < 25; ++k) {  // single hit rays from the centre to random cells
    const double o[3] = {0.05, 0.05, 0.05};
    const double e[3] = {rng.uniform(-3.9, 3.9), rng.uniform(-3.9, 3.9), rng.uniform(-1.9, 1.9)};
    m.integrate_ray(o, e, true);
  }
  std::vector<int> occ;
  for (int i = 0; i < m.cells(); ++i)
    if (m.occupied(i)) occ.push_back(i);
  ASSERT_GT(occ.size(), 10u);
  std::vector<std::int16_t> mm;
  m.compute_distance(&mm);
  const int nx = m.nx(), ny = m.ny();
  for (int i = 0; i < m.cells(); i += 7) {
    const int x = i % nx, y = (i / nx) % ny, z = i / (nx * ny);
    double best = std::numeric_limits<double>::infinity();
    for (int j = 0; j < m.cells(); ++j) {
      if (m.occupied(j) == m.occupied(i)) continue;  // to the nearest cell of the other kind
      const int a = j % nx, b = (j / nx) % ny, c = j / (nx * ny);
      best = std::min(best, std::sqrt(double((a - x) * (a - x) + (b - y) * (b - y) + (c - z) * (c - z))));
    }
    const double want = (m.occupied(i) ? -1.0 : 1.0) * (best - 0.5) * 0.25;
    ASSERT_NEAR(1e-3 * mm[static_cast<std::size_t>(i)], want, 1.1e-3) << i;
  }
}

TEST(LocalMap, ATreeTheCameraSawReadsItsTrueDistanceWithinAboutACell) {
  std::vector<sim::Obstacle> trees(1);
  trees[0].x = 5.0;
  trees[0].y = 0.3;
  trees[0].radius = 0.4;
  trees[0].height = 8.0;
  sim::RayWorld world(&trees, 0.0);
  sim::DepthCameraSpec spec;  // the defaults: 160 x 120, noise and dropouts on
  const sim::DepthCamera cam(spec);
  sim::Rng rng(2, 0);
  sim::Frame f;
  mapper::MapSettings s;  // the defaults: 0.25 m, 32 x 32 x 8 m
  mapper::LocalMap m(s);
  sim::Pose pose;
  pose.p = {0.0, 0.0, 2.0};
  m.recentre(pose.p.data());
  for (int k = 0; k < 5; ++k) {
    cam.capture(world, pose, rng, &f);
    m.begin_frame(pose.p.data());
    for (std::size_t i = 0; i < f.x.size(); ++i) {
      const double e[3] = {pose.p[0] + f.x[i], pose.p[1] + f.y[i], pose.p[2] + f.z[i]};
      m.add_point(e, f.hit[i] != 0);
    }
    m.end_frame();
  }
  std::vector<std::int16_t> mm;
  m.compute_distance(&mm);
  // Centre to centre less half a cell: off by up to sqrt(3)/2 of a cell at either end, and
  // the half cell (0.34 m at 0.25 m cells); typically much less.
  const double kCell = 0.3;
  // Points on the camera's side of the trunk, at flight altitude and near the ground.
  for (const auto& p : {std::array<double, 3>{3.0, 0.3, 2.0}, {4.0, 1.3, 2.0}, {4.2, -0.7, 1.0}, {2.0, 0.0, 3.0},
                        {3.5, 0.3, 0.6}}) {
    const double truth = std::hypot(p[0] - 5.0, p[1] - 0.3) - 0.4;
    EXPECT_NEAR(at(m, mm, p[0], p[1], p[2]), truth, kCell) << p[0] << " " << p[1] << " " << p[2];
  }
  int spurious = 0;  // occupied cells that hold no part of the trunk (noise, the ground)
  for (int i = 0; i < m.cells(); ++i) {
    if (!m.occupied(i)) continue;
    const int x = i % m.nx(), y = (i / m.nx()) % m.ny(), z = i / (m.nx() * m.ny());
    const double cx = m.origin()[0] + (x + 0.5) * 0.25, cy = m.origin()[1] + (y + 0.5) * 0.25;
    const double cz = m.origin()[2] + (z + 0.5) * 0.25;
    if (std::hypot(cx - 5.0, cy - 0.3) > 0.4 + 0.3 || cz < s.floor_z - 0.25) ++spurious;  // off the trunk
  }
  EXPECT_EQ(spurious, 0);
  // The ground (below floor_z) is no obstacle: far from the tree, the field saturates.
  EXPECT_NEAR(at(m, mm, 2.0, -4.0, 0.2), std::min(s.max_distance, std::hypot(3.0, 4.3) - 0.4), kCell);
}

}  // namespace
