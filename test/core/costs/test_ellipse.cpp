// The race car on the ellipse (core/include/mppi/costs/ellipse.hpp, Sec. VI.B): the paper's
// q = 100 d^2 + (vx - 7)^2 and the optional line, edge, track-limit and drift terms, by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mppi/costs/ellipse.hpp"
#include "mppi/models/racecar.hpp"

namespace mppi {
namespace {

using RC = Racecar;

// A car on the major axis at residual d: x = 13 sqrt(1 + d), y = 0.
std::vector<float> car_at(double d, float vx, float vy) {
  std::vector<float> x(RC::kNx, 0.0f);
  x[RC::X] = static_cast<float>(13.0 * std::sqrt(1.0 + d));
  x[RC::VX] = vx;
  x[RC::VY] = vy;
  return x;
}

TEST(EllipseCost, PaperCostByHandAndExtrasOffByDefault) {
  const EllipseCost::Params c;
  bool crash = false;
  // d = 0.2, vx = 5: 100 * 0.04 + (5 - 7)^2 = 8; a wild vy and |d| costs nothing more.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 5.0f, -4.0f).data(), 0.0f, &crash), 8.0f, 1e-3f);
  EXPECT_FALSE(crash);
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(2.0, 7.0f, 0.0f).data(), 0.0f, &crash), 400.0f, 0.05f);
  EXPECT_FALSE(crash) << "the paper's cost has no track limit";
}

TEST(EllipseCost, LineEdgeTrackLimitAndDriftByHand) {
  EllipseCost::Params c;
  c.w_track = 10.0f;
  c.line = 0.2f;
  c.edge = 0.3f;
  c.w_edge = 100.0f;
  c.track_limit = 0.5f;
  c.w_crash = 1000.0f;
  c.drift = 0.25f;
  c.w_drift = 10.0f;
  bool crash = false;
  // On the line at target speed, sliding less than the drift angle: nothing to pay.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 7.0f, -1.5f).data(), 0.0f, &crash), 0.0f, 1e-3f);
  EXPECT_FALSE(crash);
  // d = 0.4: track 10 * 0.2^2 = 0.4, edge 100 * 0.1^2 = 1.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.4, 7.0f, 0.0f).data(), 0.0f, &crash), 1.4f, 1e-3f);
  EXPECT_FALSE(crash);
  // Inside, d = -0.4: track 10 * 0.6^2 = 3.6, edge on |d| too: 1.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(-0.4, 7.0f, 0.0f).data(), 0.0f, &crash), 4.6f, 1e-3f);
  EXPECT_FALSE(crash);
  // d = 0.6, past the limit: crashed, pays w_crash on top (track 0.16 * 10, edge 100 * 0.09).
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.6, 7.0f, 0.0f).data(), 0.0f, &crash), 1000.0f + 1.6f + 9.0f, 1e-2f);
  EXPECT_TRUE(crash);
  crash = false;
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(-0.55, 7.0f, 0.0f).data(), 0.0f, &crash),
              1000.0f + 10.0f * 0.75f * 0.75f + 100.0f * 0.25f * 0.25f, 1e-2f);
  EXPECT_TRUE(crash) << "off the inside edge";
  crash = false;
  // Sliding: vx = 4, vy = -3 (either side): |vy| - 0.25 * 4 = 2 over, 10 * 4 = 40.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 4.0f, -3.0f).data(), 0.0f, &crash), 9.0f + 40.0f, 1e-3f);
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 4.0f, 3.0f).data(), 0.0f, &crash), 9.0f + 40.0f, 1e-3f);
  // A crab: vx = 0, vy = 5: the whole vy is over.
  EXPECT_NEAR(EllipseCost::vehicle(c, 0, car_at(0.2, 0.0f, 5.0f).data(), 0.0f, &crash), 49.0f + 250.0f, 1e-3f);
  EXPECT_FALSE(crash);
}

TEST(EllipseCost, RacingLineStadiumByHand) {
  EllipseCost::Params c;
  c.w_track = 0.0f;  // only the line term (vx = 7 = target speed)
  c.w_line = 3.0f;
  c.line_radius = 7.0f;
  c.line_half = 2.5f;
  auto at = [](float px, float py) {
    std::vector<float> x(RC::kNx, 0.0f);
    x[RC::X] = px;
    x[RC::Y] = py;
    x[RC::VX] = 7.0f;
    return x;
  };
  bool crash = false;
  auto q = [&](float px, float py) { return EllipseCost::vehicle(c, 0, at(px, py).data(), 0.0f, &crash); };
  EXPECT_NEAR(q(9.5f, 0.0f), 0.0f, 1e-4f);    // the end's apex, 7 m beyond the centre (2.5, 0)
  EXPECT_NEAR(q(-9.5f, 0.0f), 0.0f, 1e-4f);   // the other end
  EXPECT_NEAR(q(0.0f, 7.0f), 0.0f, 1e-4f);    // on the straight
  EXPECT_NEAR(q(1.0f, -8.0f), 3.0f, 1e-4f);   // 1 m outside the straight
  EXPECT_NEAR(q(-2.0f, 6.0f), 3.0f, 1e-4f);   // 1 m inside it
  EXPECT_NEAR(q(5.5f, 4.0f), 3.0f * 4.0f, 1e-4f);    // (3, 4) from the centre: 5 m, 2 m inside
  EXPECT_NEAR(q(-8.5f, -8.0f), 3.0f * 9.0f, 1e-4f);  // (6, 8) from (-2.5, 0): 10 m, 3 m outside
  EXPECT_FALSE(crash);
  c.w_line = 0.0f;
  EXPECT_EQ(q(-8.5f, -8.0f), 0.0f) << "off by default";
}

}  // namespace
}  // namespace mppi
