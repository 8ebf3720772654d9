// The tracking references (core/include/mppi/costs/reference.hpp): velocity is the
// derivative of position; a hold stands still; the ramp from rest, the phase, the end at rest
// and the straight line that the mission tool asks for. The same closed-form values are
// checked on the Python mirror the mission tool and the harness score with
// (test/mission/test_reference.py), so the two cannot drift apart.
#include <gtest/gtest.h>

#include <cmath>
#include <initializer_list>

#include "mppi/costs/reference.hpp"

namespace mppi {
namespace {

// eval's velocity against the central difference of its positions at the times ts.
void expect_velocity_is_the_derivative(const Reference& r, std::initializer_list<float> ts, double tol) {
  for (float t : ts) {
    const float h = 1e-3f;
    float p1[3], p2[3], p0[3], v[3], unused[3];
    r.eval(t - h, p1, unused);
    r.eval(t + h, p2, unused);
    r.eval(t, p0, v);
    for (int d = 0; d < 3; ++d)
      EXPECT_NEAR(v[d], (static_cast<double>(p2[d]) - p1[d]) / (2.0 * h), tol)
          << "kind " << r.kind << " t " << t << " axis " << d;
  }
}

TEST(Reference, VelocityIsTheDerivativeOfPosition) {
  for (int kind : {Reference::kCircle, Reference::kFigureEight}) {
    Reference r;
    r.kind = kind;
    r.center[0] = 0.5f;
    r.center[1] = -1.0f;
    r.center[2] = 2.0f;
    r.radius = 2.0f;
    r.speed = 1.5f;
    // Central difference: truncation ~h^2 |x'''| / 6 ~ 1e-6; rounding ~ulp(2) / h ~ 2.4e-4.
    expect_velocity_is_the_derivative(r, {0.0f, 0.37f, 1.2f, 3.3f, 7.9f}, 1e-3);
    // The circle runs at the given speed.
    if (kind == Reference::kCircle) {
      float p[3], v[3];
      r.eval(0.9f, p, v);
      EXPECT_NEAR(std::hypot(v[0], v[1]), 1.5, 1e-5);
      EXPECT_NEAR(std::hypot(p[0] - 0.5, p[1] + 1.0), 2.0, 1e-5);
    }
  }
  // Hold: fixed point, zero velocity.
  Reference hold;
  hold.center[0] = 3.0f;
  float p[3], v[3];
  hold.eval(5.0f, p, v);
  EXPECT_EQ(p[0], 3.0f);
  EXPECT_EQ(p[2], 1.0f);
  EXPECT_EQ(v[0], 0.0f);
  EXPECT_EQ(v[1], 0.0f);
}

Reference circle(float ramp, float phase) {
  Reference r;
  r.kind = Reference::kCircle;
  r.center[0] = -5.0f;
  r.center[2] = 2.0f;
  r.radius = 5.0f;
  r.speed = 3.0f;
  r.ramp = ramp;
  r.phase = phase;
  return r;
}

TEST(ReferenceRamp, ACircleStartsAtRestAtItsPhaseAndReachesItsSpeedAfterTheRamp) {
  const Reference r = circle(3.0f, 0.0f);
  float p[3], v[3];
  r.eval(-1.0f, p, v);  // before the epoch: at rest at the start point
  EXPECT_NEAR(p[0], 0.0f, 1e-6f);
  EXPECT_NEAR(p[1], 0.0f, 1e-6f);
  EXPECT_EQ(v[0], 0.0f);
  EXPECT_EQ(v[1], 0.0f);
  r.eval(1.5f, p, v);  // halfway up the ramp: half the speed, a quarter of the ramp's distance
  EXPECT_NEAR(std::hypot(v[0], v[1]), 1.5f, 1e-5f);
  r.eval(3.0f, p, v);  // the ramp covers speed * ramp / 2 = 4.5 m of arc: 0.9 rad
  EXPECT_NEAR(std::atan2(p[1], p[0] + 5.0f), 0.9f, 1e-5f);
  EXPECT_NEAR(std::hypot(v[0], v[1]), 3.0f, 1e-5f);
  r.eval(5.0f, p, v);  // then the full speed: 0.9 + 2 s * 0.6 rad/s
  EXPECT_NEAR(std::atan2(p[1], p[0] + 5.0f), 2.1f, 1e-5f);
}

TEST(ReferenceRamp, ThePhasePlacesTheStart) {
  const Reference r = circle(2.0f, 1.0f);
  float p[3], v[3];
  r.eval(0.0f, p, v);
  EXPECT_NEAR(p[0], -5.0f + 5.0f * std::cos(1.0f), 1e-5f);
  EXPECT_NEAR(p[1], 5.0f * std::sin(1.0f), 1e-5f);
}

TEST(ReferenceRamp, WithoutARampTheCurveIsAsItWasBeforeEitherExisted) {
  const Reference r = circle(0.0f, 0.0f);
  for (float t : {-2.0f, 0.0f, 1.3f, 8.0f}) {
    float p[3], v[3];
    r.eval(t, p, v);
    EXPECT_NEAR(p[0], -5.0f + 5.0f * std::cos(0.6f * t), 1e-5f) << t;
    EXPECT_NEAR(p[1], 5.0f * std::sin(0.6f * t), 1e-5f) << t;
  }
}

TEST(ReferenceRamp, ACurveWithAnEndRampsDownToRestWhereItsLapsEnd) {
  Reference r = circle(3.0f, 0.0f);
  r.end_s = static_cast<float>(2.0 * 2.0 * M_PI * 5.0 / 3.0) + 3.0f;  // two laps and the two ramps
  float p[3], v[3];
  r.eval(r.end_s - 1.5f, p, v);
  EXPECT_NEAR(std::hypot(v[0], v[1]), 1.5f, 1e-4f);
  r.eval(r.end_s, p, v);
  EXPECT_NEAR(p[0], 0.0f, 2e-4f);  // back where it began
  EXPECT_NEAR(p[1], 0.0f, 2e-4f);
  EXPECT_EQ(v[0], 0.0f);
  float q[3];
  r.eval(r.end_s + 4.0f, q, v);
  EXPECT_EQ(q[0], p[0]);
  EXPECT_EQ(v[1], 0.0f);
}

TEST(ReferenceLine, RampsUpCruisesRampsDownAndStopsAtItsEnd) {
  Reference r;
  r.kind = Reference::kLine;
  r.center[2] = r.end[2] = 2.0f;
  r.end[0] = 10.0f;
  r.speed = 2.0f;
  r.ramp = 2.0f;  // 10 m at 2 m/s with a 2 s ramp each way: done at 10 / 2 + 2 = 7 s
  float p[3], v[3];
  r.eval(-0.5f, p, v);
  EXPECT_EQ(p[0], 0.0f);
  EXPECT_EQ(v[0], 0.0f);
  r.eval(1.0f, p, v);
  EXPECT_NEAR(p[0], 0.5f, 1e-5f);
  EXPECT_NEAR(v[0], 1.0f, 1e-5f);
  r.eval(3.5f, p, v);
  EXPECT_NEAR(p[0], 5.0f, 1e-5f);
  EXPECT_NEAR(v[0], 2.0f, 1e-5f);
  r.eval(6.0f, p, v);
  EXPECT_NEAR(p[0], 9.5f, 1e-5f);
  EXPECT_NEAR(v[0], 1.0f, 1e-5f);
  r.eval(9.0f, p, v);
  EXPECT_NEAR(p[0], 10.0f, 1e-6f);
  EXPECT_EQ(v[0], 0.0f);
  EXPECT_EQ(p[1], 0.0f);
  EXPECT_EQ(p[2], 2.0f);
}

TEST(ReferenceLine, AShortLinePeaksBelowItsSpeed) {
  Reference r;
  r.kind = Reference::kLine;
  r.end[0] = 2.0f;
  r.speed = 4.0f;
  r.ramp = 2.0f;  // 2 m < 4 m/s * 2 s: peaks at 2 m / 2 s = 1 m/s, done at 2 / 1 + 2 = 4 s
  float p[3], v[3];
  r.eval(2.0f, p, v);
  EXPECT_NEAR(p[0], 1.0f, 1e-5f);
  EXPECT_NEAR(v[0], 1.0f, 1e-5f);
  r.eval(4.0f, p, v);
  EXPECT_NEAR(p[0], 2.0f, 1e-5f);
  EXPECT_EQ(v[0], 0.0f);
}

TEST(ReferenceRamp, VelocityIsTheDerivativeOfPositionOnEveryKindWithARamp) {
  for (int kind : {Reference::kCircle, Reference::kFigureEight, Reference::kLine}) {
    Reference r = circle(1.5f, 0.7f);
    r.kind = kind;
    r.end[0] = 6.0f;
    r.end[1] = 3.0f;
    r.end_s = 6.0f;
    expect_velocity_is_the_derivative(r, {0.4f, 1.2f, 3.3f, 5.1f, 5.9f}, 2e-3);
  }
}

}  // namespace
}  // namespace mppi
