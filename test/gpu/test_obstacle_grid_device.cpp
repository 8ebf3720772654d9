// The obstacle grid as the CUDA backend builds it each cycle, on the device
// (gpu/src/obstacle_grid.cuh): its search returns the full scan's float everywhere, for static
// and moving cylinders and for cells coarsened past an overflow; its lists are never longer
// than the host build's for the same cells; where the host builds no grid, neither does it.
// Skips without a CUDA device.
#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "../core/grid_fixtures.hpp"
#include "mppi/costs/obstacles.hpp"
#include "cuda_skip.hpp"
#include "mppi/gpu/cuda_backend.hpp"

namespace mppi {
namespace {

using testing::expect_exact;
using testing::forest;
using testing::path;

// Cell by cell, the device's list is a subset of the host's (both in index order).
void expect_lists_within_host(const ObstacleGrid& dev, const ObstacleGrid& host) {
  ASSERT_EQ(dev.nx, host.nx);
  ASSERT_EQ(dev.ny, host.ny);
  EXPECT_EQ(dev.x0, host.x0);
  EXPECT_EQ(dev.y0, host.y0);
  EXPECT_EQ(dev.inv_cell, host.inv_cell);
  for (int c = 0; c < dev.nx * dev.ny; ++c) {
    int h = host.first[c];
    for (int r = dev.first[c]; r < dev.first[c + 1]; ++r) {
      while (h < host.first[c + 1] && host.refs[h] != dev.refs[r]) ++h;
      ASSERT_LT(h, host.first[c + 1]) << "cell " << c << ": cylinder " << int{dev.refs[r]} << " not in the host's list";
    }
  }
  EXPECT_LE(dev.first[dev.nx * dev.ny], host.first[host.nx * host.ny]);
}

TEST(CudaObstacleGrid, SearchIsTheFullScanEverywhere) {
  SKIP_WITHOUT_CUDA();
  for (int moving : {0, 3}) {
    const ObstacleSet set = forest(200, 10, moving, 5);
    const auto xy = path(12.0f, 101);
    const ObstacleGrid dev = build_obstacle_grid_on_device(set, xy.data(), 101, 2.0f, 8.0f, 1.0f);
    ObstacleGrid host;
    host.build(set, xy.data(), 101, 2.0f, 8.0f, 1.0f);
    ASSERT_GT(dev.nx, 0);
    expect_lists_within_host(dev, host);
    EXPECT_GT(dev.listed, 10);
    EXPECT_LE(dev.listed, host.listed);
    const int inside = expect_exact(set, dev, 2.0f, 9);
    EXPECT_GT(inside, 5000) << "the test must probe the grid, not only the fallback";
  }
}

// Fast cylinders sweep long segments: the lists of the finest cells overflow kMaxRefs and the
// build moves to coarser ones, on the host and on the device, both exact.
TEST(CudaObstacleGrid, CoarserCellsWhenTheListsOverflow) {
  SKIP_WITHOUT_CUDA();
  ObstacleSet set = forest(256, 16, 1, 11);
  for (int i = 0; i < set.count; ++i) {
    set.items[i].vx *= 4.0f;
    set.items[i].vy *= 4.0f;
  }
  const auto xy = path(40.0f, 101);
  ObstacleGrid host;
  host.build(set, xy.data(), 101, 4.0f, 8.0f, 0.25f);
  const ObstacleGrid dev = build_obstacle_grid_on_device(set, xy.data(), 101, 4.0f, 8.0f, 0.25f);
  ASSERT_GT(dev.nx, 0);
  EXPECT_LE(dev.first[dev.nx * dev.ny], ObstacleGrid::kMaxRefs);
  EXPECT_GE(dev.nx, host.nx) << "the device's lists are never longer, so it never needs coarser cells";
  const ObstacleGridLayout layout = ObstacleGridLayout::plan(set, xy.data(), 101, 4.0f, 8.0f, 0.25f);
  ASSERT_GT(layout.attempts, 1);
  EXPECT_LT(host.nx, layout.attempt[0].cx) << "the host must have overflowed its first cells for this test";
  expect_exact(set, dev, 4.0f, 3);
}

TEST(CudaObstacleGrid, NoGridWhereTheHostBuildsNone) {
  SKIP_WITHOUT_CUDA();
  const ObstacleSet set = forest(60, 6, 0, 8);
  const auto xy = path(12.0f, 51);
  EXPECT_EQ(build_obstacle_grid_on_device(set, xy.data(), 51, 2.0f, 0.0f, 1.0f).nx, 0);  // reach 0
  EXPECT_EQ(build_obstacle_grid_on_device(ObstacleSet{}, xy.data(), 51, 2.0f, 8.0f, 1.0f).nx, 0);
  ObstacleSet bad = set;
  bad.items[5].x = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(build_obstacle_grid_on_device(bad, xy.data(), 51, 2.0f, 8.0f, 1.0f).nx, 0);
}

}  // namespace
}  // namespace mppi
