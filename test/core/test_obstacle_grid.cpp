// Obstacle culling (costs/obstacles.hpp, ObstacleGrid): the grid's search returns the same
// float as the full scan at every point and time, inside the grid and out, for static and
// moving cylinders; it drops the cylinders no point of the region can see; its lists are
// short in a dense forest; it refuses what it cannot index (and stays exact).
#include <cstdint>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "mppi/costs/obstacles.hpp"
#include "mppi/optimizer.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/tasks.hpp"
#include "../core/fixtures.hpp"
#include "grid_fixtures.hpp"

namespace mppi {
namespace {

using testing::expect_exact;
using testing::forest;
using testing::path;
using testing::same_bits;

TEST(ObstacleGrid, SearchIsTheFullScanEverywhere) {
  for (int moving : {0, 3}) {
    const ObstacleSet set = forest(200, 10, moving, 5);
    ASSERT_EQ(set.count, 200);
    const auto xy = path(12.0f, 101);
    ObstacleGrid grid;
    grid.build(set, xy.data(), 101, 2.0f, 8.0f, 1.0f);
    ASSERT_GT(grid.nx, 0);
    const int inside = expect_exact(set, grid, 2.0f, 9);
    EXPECT_GT(inside, 5000) << "the test must probe the grid, not only the fallback";
    EXPECT_LT(inside, 40000) << "and the fallback outside it";
  }
}

TEST(ObstacleGrid, CullsWhatTheRegionCannotSeeAndListsFew) {
  const ObstacleSet set = forest(200, 10, 0, 6);
  const auto xy = path(12.0f, 101);
  ObstacleGrid grid;
  grid.build(set, xy.data(), 101, 2.0f, 8.0f, 1.0f);
  ASSERT_GT(grid.nx, 0);
  // The region spans x in [-8, 20]: the cylinders beyond x ~ 30 cannot be nearest to it.
  EXPECT_LT(grid.listed, 100) << "of 200";
  EXPECT_GT(grid.listed, 10);
  const int cells = grid.nx * grid.ny;
  const double mean = static_cast<double>(grid.first[cells]) / cells;
  int longest = 0;
  for (int c = 0; c < cells; ++c) longest = std::max(longest, grid.first[c + 1] - grid.first[c]);
  // In a 4 m forest a cell of 1 m has its nearest cylinder within a few metres.
  EXPECT_LT(mean, 8.0) << "cylinders per cell";
  EXPECT_LT(longest, 24);
  // The same forest with 48 or 200 cylinders: the cells near the path list the same ones.
  const ObstacleSet small = forest(48, 10, 0, 6);
  ObstacleGrid g48;
  g48.build(small, xy.data(), 101, 2.0f, 8.0f, 1.0f);
  ASSERT_EQ(g48.nx, grid.nx);
  const int centre = (grid.ny / 2) * grid.nx + grid.nx / 2;
  EXPECT_EQ(grid.first[centre + 1] - grid.first[centre], g48.first[centre + 1] - g48.first[centre]);
}

TEST(ObstacleGrid, NoGridWhenNothingToIndexAndStillExact) {
  const ObstacleSet set = forest(200, 10, 3, 7);
  const auto xy = path(12.0f, 101);
  ObstacleGrid grid;
  grid.build(set, xy.data(), 101, 2.0f, 0.0f, 1.0f);  // reach 0: culling off
  EXPECT_EQ(grid.nx, 0);
  expect_exact(set, grid, 2.0f, 1);
  grid.build(ObstacleSet{}, xy.data(), 101, 2.0f, 8.0f, 1.0f);  // no obstacles
  EXPECT_EQ(grid.nx, 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float bad[4] = {nan, 0.0f, 0.0f, std::numeric_limits<float>::infinity()};
  grid.build(set, bad, 2, 2.0f, 8.0f, 1.0f);  // no finite point
  EXPECT_EQ(grid.nx, 0);
  // A huge region gets larger cells (kMaxSide per side), still exact.
  const float far[4] = {-500.0f, -500.0f, 500.0f, 500.0f};
  grid.build(set, far, 2, 2.0f, 8.0f, 1.0f);
  ASSERT_GT(grid.nx, 0);
  EXPECT_LE(grid.nx, ObstacleGrid::kMaxSide);
  expect_exact(set, grid, 2.0f, 2);
}

TEST(ObstacleGrid, NonFinitePointsAndCylinders) {
  ObstacleSet set = forest(60, 6, 0, 8);
  const auto xy = path(12.0f, 51);
  ObstacleGrid grid;
  grid.build(set, xy.data(), 51, 2.0f, 8.0f, 1.0f);
  ASSERT_GT(grid.nx, 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(same_bits(grid.nearest_surface(set, nan, 1.0f, 0.5f), set.nearest_surface(nan, 1.0f, 0.5f)));
  EXPECT_TRUE(same_bits(grid.nearest_surface(set, 1e30f, 1.0f, 0.5f), set.nearest_surface(1e30f, 1.0f, 0.5f)));
  // A cylinder with a non-finite field gives no bounds to cull with: no grid (the daemon
  // never sends one); the search stays the scan.
  for (int field = 0; field < 2; ++field) {
    ObstacleSet bad = set;
    if (field == 0) bad.items[5].x = nan;
    else bad.items[9].radius = std::numeric_limits<float>::infinity();
    grid.build(bad, xy.data(), 51, 2.0f, 8.0f, 1.0f);
    EXPECT_EQ(grid.nx, 0);
    expect_exact(bad, grid, 2.0f, 4);
  }
}

// The optimizer prepares the grid from the plan's path each cycle, and the update is the
// one without culling, bit for bit (scalar and SIMD).
TEST(ObstacleGrid, CulledUpdateEqualsUnculled) {
  for (const char* simd : {"off", "auto"}) {
    MppiSettings s = testing::quadrotor_settings(128, 50, 10.0f, 150.0f, 2);
    s.simd = simd;
    QuadrotorForest::Params p{};
    p.cost.goal[0][0] = 30.0f;
    p.cost.goal[0][2] = 2.0f;
    p.cost.obstacles = forest(200, 10, 4, 3);
    auto unculled = p;
    unculled.cost.obstacle_reach = 0.0f;
    Mppi<QuadrotorForest> a(s, std::make_unique<CpuBackend<QuadrotorForest>>(s));
    Mppi<QuadrotorForest> b(s, std::make_unique<CpuBackend<QuadrotorForest>>(s));
    std::vector<float> x(Quadrotor::kNx, 0.0f);
    x[Quadrotor::PZ] = 2.0f;
    x[Quadrotor::VX] = 3.0f;
    for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = Quadrotor::hover_speed(Quadrotor::Params{});
    float ua[4], ub[4];
    for (int cycle = 0; cycle < 3; ++cycle) {
      a.iterate(x.data(), p, ua);
      b.iterate(x.data(), unculled, ub);
      EXPECT_GT(a.prepared_params().cost.obstacle_grid.nx, 0);
      EXPECT_LT(a.prepared_params().cost.obstacle_grid.listed, 200);
      EXPECT_EQ(b.prepared_params().cost.obstacle_grid.nx, 0);
      ASSERT_EQ(a.plan(), b.plan()) << simd << " cycle " << cycle;
      EXPECT_EQ(a.backend().rollout_costs(), b.backend().rollout_costs());
    }
  }
}

}  // namespace
}  // namespace mppi
