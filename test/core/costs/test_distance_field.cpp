// The local distance field (core/include/mppi/costs/distance_field.hpp) and the forest cost
// reading it (forest.hpp): the interpolation against fields whose values are known in closed
// form, the outside, the shapes a map may not have, and the cost with and without a field.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "mppi/costs/distance_field.hpp"
#include "mppi/costs/field_of_cylinders.hpp"
#include "mppi/costs/forest.hpp"
#include "mppi/models/quadrotor.hpp"

namespace mppi {
namespace {

using Q = Quadrotor;
using Cost = ForestCost<Quadrotor>;

// A grid whose cells hold a * x + b * y + c * z + e (mm) at their centres: trilinear
// interpolation reproduces an affine field exactly, so every inside point has a known value.
std::unique_ptr<DistanceFieldGrid> affine_grid(float res, int nx, int ny, int nz) {
  auto g = std::make_unique<DistanceFieldGrid>();
  g->origin[0] = -2.0f;
  g->origin[1] = 1.0f;
  g->origin[2] = 0.0f;
  g->resolution = res;
  g->nx = nx;
  g->ny = ny;
  g->nz = nz;
  g->n_cells = nx * ny * nz;
  g->max_distance = 8.0f;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) g->distance_mm[i + nx * (j + ny * k)] = static_cast<std::int16_t>(100 * i - 30 * j + 7 * k + 50);
  return g;
}

// The affine field at a point, in metres, from its cell-centre coordinates (clamped as the
// lookup clamps them).
double affine_at(const DistanceFieldGrid& g, double x, double y, double z) {
  auto c = [&](double p, double o, int n) { return std::clamp((p - o) / g.resolution - 0.5, 0.0, n - 1.0); };
  return (100.0 * c(x, g.origin[0], g.nx) - 30.0 * c(y, g.origin[1], g.ny) + 7.0 * c(z, g.origin[2], g.nz) + 50.0) * 1e-3;
}

TEST(DistanceField, ReadsTheCellsAtTheirCentresAndInterpolatesAnAffineFieldExactly) {
  const auto g = affine_grid(0.25f, 12, 9, 5);
  const DistanceField f = g->view(1);
  ASSERT_TRUE(f.present());
  // Cell (3, 4, 2)'s centre: its own value.
  const float cx = -2.0f + 3.5f * 0.25f, cy = 1.0f + 4.5f * 0.25f, cz = 2.5f * 0.25f;
  EXPECT_FLOAT_EQ(f.distance(cx, cy, cz), (300 - 120 + 14 + 50) * 1e-3f);
  // Everywhere inside, the half cells along the faces included (clamped: the face's cells).
  std::vector<float> xs = {-1.99f, -1.3f, -0.77f, 0.4f, 0.99f}, ys = {1.01f, 1.6f, 2.9f, 3.24f},
                     zs = {0.01f, 0.3f, 0.62f, 1.24f};
  for (float x : xs)
    for (float y : ys)
      for (float z : zs) EXPECT_NEAR(f.distance(x, y, z), affine_at(*g, x, y, z), 2e-6) << x << " " << y << " " << z;
}

TEST(DistanceField, OutsideTheBoxOrNotFiniteReadsMaxDistance) {
  const auto g = affine_grid(0.25f, 12, 9, 5);  // box [-2, 1) x [1, 3.25) x [0, 1.25)
  const DistanceField f = g->view(1);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const auto& p : std::vector<std::vector<float>>{{-2.01f, 2.0f, 0.5f},
                                                       {1.0f, 2.0f, 0.5f},  // the far face is outside
                                                       {0.0f, 0.99f, 0.5f},
                                                       {0.0f, 3.25f, 0.5f},
                                                       {0.0f, 2.0f, -0.01f},
                                                       {0.0f, 2.0f, 1.25f},
                                                       {nan, 2.0f, 0.5f},
                                                       {0.0f, inf, 0.5f},
                                                       {0.0f, 2.0f, -inf}})
    EXPECT_EQ(f.distance(p[0], p[1], p[2]), 8.0f) << p[0] << " " << p[1] << " " << p[2];
  EXPECT_NE(f.distance(0.99f, 3.24f, 1.24f), 8.0f);  // the last cell is inside
}

TEST(DistanceField, ATwoCellSideInterpolatesBetweenItsTwoCells) {
  const auto g = affine_grid(0.5f, 2, 2, 2);
  const DistanceField f = g->view(1);
  // Between the centres (x = -1.75 and -1.25): halfway is the mean of 50 and 150 mm.
  EXPECT_NEAR(f.distance(-1.5f, 1.25f, 0.25f), 0.100, 1e-6);
  EXPECT_NEAR(f.distance(-1.01f, 1.25f, 0.25f), 0.150, 1e-6);  // clamped at the last centre
}

TEST(DistanceField, ShapesAMapMayNotHave) {
  struct Case {
    const char* what;
    float origin0, resolution, max_distance;
    int nx, ny, nz;
    std::int64_t n_cells;
    const char* expect;  // substring of the reason, nullptr: valid
  };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<Case> cases = {
      {"valid", 0.0f, 0.2f, 5.0f, 160, 160, 32, 160 * 160 * 32, nullptr},
      {"at capacity", 0.0f, 0.2f, 5.0f, 256, 256, 16, 256 * 256 * 16, nullptr},
      {"over capacity", 0.0f, 0.2f, 5.0f, 256, 256, 17, 256 * 256 * 17, "kMaxCells"},
      {"overflowing sides", 0.0f, 0.2f, 5.0f, 1 << 16, 1 << 16, 1 << 16, 0, "kMaxCells"},
      {"count mismatch", 0.0f, 0.2f, 5.0f, 10, 10, 10, 999, "n_cells"},
      {"zero resolution", 0.0f, 0.0f, 5.0f, 10, 10, 10, 1000, "resolution"},
      {"negative resolution", 0.0f, -0.2f, 5.0f, 10, 10, 10, 1000, "resolution"},
      {"NaN resolution", 0.0f, nan, 5.0f, 10, 10, 10, 1000, "resolution"},
      {"NaN origin", nan, 0.2f, 5.0f, 10, 10, 10, 1000, "origin"},
      {"NaN max distance", 0.0f, 0.2f, nan, 10, 10, 10, 1000, "max_distance"},
      {"zero max distance", 0.0f, 0.2f, 0.0f, 10, 10, 10, 1000, "max_distance"},
      {"max distance past int16 mm", 0.0f, 0.2f, 40.0f, 10, 10, 10, 1000, "max_distance"},
      {"one cell thick", 0.0f, 0.2f, 5.0f, 10, 10, 1, 100, "2 cells"},
      {"negative side", 0.0f, 0.2f, 5.0f, -10, -10, 10, 1000, "2 cells"},
  };
  for (const Case& c : cases) {
    const float origin[3] = {c.origin0, 0.0f, 0.0f};
    const char* why = DistanceFieldGrid::invalid_shape(origin, c.resolution, c.nx, c.ny, c.nz, c.max_distance, c.n_cells);
    if (c.expect == nullptr) {
      EXPECT_EQ(why, nullptr) << c.what << ": " << why;
    } else {
      ASSERT_NE(why, nullptr) << c.what;
      EXPECT_NE(std::string(why).find(c.expect), std::string::npos) << c.what << ": " << why;
    }
  }
}

// ---- The forest cost with a field ----------------------------------------------------

Cost::Params forest_params() {
  Cost::Params c{};
  c.goal[0][0] = 20.0f;
  c.goal[0][2] = 1.5f;
  return c;
}

ObstacleSet three_trees() {
  ObstacleSet set;
  set.count = 3;
  set.items[0] = Cylinder{4.0f, 0.0f, 0.5f, 0.0f, 0.0f};
  set.items[1] = Cylinder{7.0f, 2.0f, 0.3f, 0.0f, 0.0f};
  set.items[2] = Cylinder{9.0f, -1.5f, 0.4f, 0.0f, 0.0f};
  return set;
}

std::unique_ptr<DistanceFieldGrid> field_of(const ObstacleSet& set, float height, float res) {
  auto g = std::make_unique<DistanceFieldGrid>();
  const float origin[3] = {0.0f, -5.0f, 0.0f};
  const int n = static_cast<int>(std::lround(12.0f / res));
  EXPECT_TRUE(fill_from_cylinders(set, height, origin, res, n, static_cast<int>(std::lround(10.0f / res)),
                                  static_cast<int>(std::lround(4.0f / res)), 6.0f, g.get()));
  return g;
}

float cost_at(const Cost::Params& c, float x, float y, float z, bool* crash) {
  std::vector<float> s(16, 0.0f);
  s[Q::PX] = x;
  s[Q::PY] = y;
  s[Q::PZ] = z;
  *crash = false;
  return Cost::vehicle(c, 0, s.data(), 0.0f, crash);
}

TEST(ForestCostField, NoFieldIsTheCylinderCostBitForBit) {
  // The default parameters carry no field, and a field-less copy of parameters that had one
  // costs what parameters that never had one do.
  auto plain = forest_params();
  plain.obstacles = three_trees();
  EXPECT_FALSE(plain.field.present());
  const auto g = field_of(three_trees(), 3.0f, 0.2f);
  auto had = plain;
  had.field = g->view(7);
  had.field = DistanceField{};
  for (float x = 0.5f; x < 11.0f; x += 0.37f) {
    bool a = false, b = false;
    const float qa = cost_at(plain, x, 0.3f, 1.5f, &a), qb = cost_at(had, x, 0.3f, 1.5f, &b);
    EXPECT_EQ(std::memcmp(&qa, &qb, sizeof qa), 0) << x;
    EXPECT_EQ(a, b);
  }
}

TEST(ForestCostField, TheFieldAloneCostsWhatTheKnownCylindersCost) {
  // The same trees, once as cylinders and once as a 0.2 m field of trees 3 m tall, below
  // their tops: the obstacle term agrees to the field's interpolation error, and the crash
  // term agrees away from the surface.
  auto known = forest_params();
  known.obstacles = three_trees();
  auto sensed = forest_params();
  const auto g = field_of(three_trees(), 3.0f, 0.2f);
  sensed.field = g->view(1);
  int compared = 0, crashes = 0;
  for (float x = 1.0f; x < 11.0f; x += 0.13f) {
    for (float y : {-1.5f, -0.4f, 0.0f, 0.45f, 2.0f, 3.1f}) {
      bool ck = false, cs = false;
      const float qk = cost_at(known, x, y, 1.5f, &ck), qs = cost_at(sensed, x, y, 1.5f, &cs);
      const float dk = three_trees().nearest_surface(x, y, 0.0f);
      const float ds = g->view(1).distance(x, y, 1.5f);
      // The field samples the exact distance: within 3 cm near the surfaces, and nowhere more
      // than 3 cm farther than the truth; up to half a cell nearer on the ridges between two
      // trees (the min of two distances has a crease there, which interpolation cuts below).
      if (dk > -0.1f) {
        EXPECT_LT(ds - dk, 0.03f) << x << " " << y;
        EXPECT_GT(ds - dk, -0.1f) << x << " " << y;
        if (dk < 0.5f) {
          EXPECT_NEAR(ds, dk, 0.03f) << x << " " << y;
        }
      }
      if (std::fabs(dk - known.vehicle_radius) > 0.05f) {
        EXPECT_EQ(ck, cs) << x << " " << y;
        // The obstacle term's slope is at most 350 * 0.25 per metre (2 d / 12 exp(-d^2 / 12) <= 0.25).
        EXPECT_NEAR(qs, qk, 350.0f * 0.25f * 0.1f) << x << " " << y;
        ++compared;
        crashes += ck;
      }
    }
  }
  EXPECT_GT(compared, 300);
  EXPECT_GT(crashes, 5);  // some points inside the trees
}

TEST(ForestCostField, AboveTheTreesTheFieldIsFreeWhereTheCylindersAreNot) {
  // The field knows the trees' height: over a 3 m tree at 4.5 m nothing is hit; the
  // cylinder model (infinite height) says crash.
  auto known = forest_params();
  known.obstacles = three_trees();
  auto sensed = forest_params();
  const auto g = field_of(three_trees(), 3.0f, 0.2f);
  sensed.field = g->view(1);
  bool ck = false, cs = false;
  cost_at(known, 4.0f, 0.0f, 3.9f, &ck);
  cost_at(sensed, 4.0f, 0.0f, 3.9f, &cs);
  EXPECT_TRUE(ck);
  EXPECT_FALSE(cs);
  EXPECT_NEAR(g->view(1).distance(4.0f, 0.0f, 3.9f), 0.9f, 0.03f);
  cost_at(sensed, 4.0f, 0.0f, 2.5f, &cs);
  EXPECT_TRUE(cs);  // inside the trunk, below the top
}

TEST(ForestCostField, BothTheNearerOfTheCylindersAndTheField) {
  // A known cylinder the map has not seen, and a sensed tree the cylinders lack: each
  // counts where it is the nearer.
  auto both = forest_params();
  both.obstacles.count = 1;
  both.obstacles.items[0] = three_trees().items[0];  // (4, 0), known only
  ObstacleSet sensed_only;
  sensed_only.count = 1;
  sensed_only.items[0] = three_trees().items[1];  // (7, 2), sensed only
  const auto g = field_of(sensed_only, 3.0f, 0.2f);
  both.field = g->view(1);
  bool crash = false;
  cost_at(both, 4.0f, 0.2f, 1.5f, &crash);
  EXPECT_TRUE(crash);
  cost_at(both, 7.0f, 2.1f, 1.5f, &crash);
  EXPECT_TRUE(crash);
  cost_at(both, 5.5f, -2.0f, 1.5f, &crash);
  EXPECT_FALSE(crash);
  // Far from both, the obstacle term is the nearer one's: exp(-d^2 / 12) at d = 4.5 - 0.5 = 4
  // from the known tree at (4, 0) vs ~4.5 m from the sensed one.
  auto cyl_only = forest_params();
  cyl_only.obstacles = both.obstacles;
  bool c1 = false, c2 = false;
  EXPECT_NEAR(cost_at(both, 0.0f, 0.0f, 1.5f, &c1), cost_at(cyl_only, 0.0f, 0.0f, 1.5f, &c2), 1e-4f);
}

TEST(ForestCostField, AFieldWithNoCylindersStillPaysTheObstacleTerm) {
  auto sensed = forest_params();
  auto none = forest_params();
  const auto g = field_of(three_trees(), 3.0f, 0.2f);
  sensed.field = g->view(1);
  bool c1 = false, c2 = false;
  const float qs = cost_at(sensed, 3.0f, 0.0f, 1.5f, &c1), qn = cost_at(none, 3.0f, 0.0f, 1.5f, &c2);
  // 0.5 m from the tree: 350 exp(-0.25 / 12) ~ 342.8 more.
  EXPECT_NEAR(qs - qn, 350.0f * std::exp(-0.25f / 12.0f), 2.0f);
}

}  // namespace
}  // namespace mppi
