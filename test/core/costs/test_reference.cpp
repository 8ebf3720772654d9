// The tracking references (core/include/mppi/costs/reference.hpp): velocity is the
// derivative of position; a hold stands still.
#include <gtest/gtest.h>

#include <cmath>

#include "mppi/costs/reference.hpp"

namespace mppi {
namespace {

TEST(Reference, VelocityIsTheDerivativeOfPosition) {
  for (int kind : {Reference::kCircle, Reference::kFigureEight}) {
    Reference r;
    r.kind = kind;
    r.center[0] = 0.5f;
    r.center[1] = -1.0f;
    r.center[2] = 2.0f;
    r.radius = 2.0f;
    r.speed = 1.5f;
    for (float t : {0.0f, 0.37f, 1.2f, 3.3f, 7.9f}) {
      const float h = 1e-3f;
      float p1[3], p2[3], p0[3], v[3], v_unused[3];
      r.eval(t - h, p1, v_unused);
      r.eval(t + h, p2, v_unused);
      r.eval(t, p0, v);
      for (int d = 0; d < 3; ++d) {
        const double fd = (static_cast<double>(p2[d]) - p1[d]) / (2.0 * h);
        // Central difference: truncation ~h^2 |x'''| / 6 ~ 1e-6; rounding ~ulp(2) / h ~ 2.4e-4.
        EXPECT_NEAR(v[d], fd, 1e-3) << "kind " << kind << " t " << t << " axis " << d;
      }
    }
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

}  // namespace
}  // namespace mppi
