// The race car (core/include/mppi/models/racecar.hpp, Appendix D) against hand calculations and physics (paper-notes Sec. 4).
// Expected values are computed here from the paper's equations (in double precision,
// independently of the model code), never copied from the code's output.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "../fixtures.hpp"
#include "integration_check.hpp"
#include "mppi/models/racecar.hpp"

namespace mppi {
namespace {

using testing::check_integrator;
using testing::derivative_of;
using testing::state_with;
using RC = Racecar;

TEST(Racecar, StraightDrivingHasNoLateralForce) {
  const RC::Params p;
  const auto x = state_with<RC>({{RC::PSI, 0.4f}, {RC::VX, 5.0f}, {RC::FX, 30.0f}});
  const auto dx = derivative_of<RC>(p, x, {0.0f, 30.0f});
  EXPECT_NEAR(dx[RC::X], 5.0 * std::cos(0.4), 1e-5);
  EXPECT_NEAR(dx[RC::Y], 5.0 * std::sin(0.4), 1e-5);
  EXPECT_EQ(dx[RC::PSI], 0.0f);
  EXPECT_EQ(dx[RC::BETA], 0.0f);
  EXPECT_FLOAT_EQ(dx[RC::VX], 30.0f / 21.0f);  // Fx / M
  EXPECT_EQ(dx[RC::VY], 0.0f);
  EXPECT_EQ(dx[RC::R], 0.0f);
  EXPECT_EQ(dx[RC::DELTA], 0.0f);
  EXPECT_EQ(dx[RC::FX], 0.0f);
}

TEST(Racecar, BrushTireShape) {
  const RC::Params p;  // C = 1200, mu = 0.55
  const float fz = 100.0f;
  // xi = 1 with no longitudinal force; gamma = atan(3 * 0.55 * 100 / 1200) = atan(0.1375)
  //    = 0.136643 rad; saturated force mu xi Fz = 55 N.
  const double gamma = std::atan(3.0 * 0.55 * 100.0 / 1200.0);
  EXPECT_NEAR(gamma, 0.136643, 1e-6);
  EXPECT_EQ(RC::lateral_force(p, 0.0f, fz, 0.0f), 0.0f);
  for (float a : {0.01f, 0.05f, 0.1f, 0.13f, 0.2f, 0.5f, 1.0f}) {
    const float f = RC::lateral_force(p, a, fz, 0.0f);
    EXPECT_FLOAT_EQ(RC::lateral_force(p, -a, fz, 0.0f), -f) << "odd at " << a;
    EXPECT_LT(f, 0.0f) << "opposes the slip at " << a;
    EXPECT_LE(std::fabs(f), 55.0f * (1 + 1e-6f));
  }
  // Linear region: slope -C at the origin (central difference).
  const double slope = (RC::lateral_force(p, 1e-4f, fz, 0.0f) - RC::lateral_force(p, -1e-4f, fz, 0.0f)) / 2e-4;
  EXPECT_NEAR(slope, -1200.0, 12.0);
  // Monotone towards saturation.
  float prev = 0.0f;
  for (int i = 1; i <= 100; ++i) {
    const float f = RC::lateral_force(p, static_cast<float>(gamma * i / 100.0), fz, 0.0f);
    EXPECT_LE(f, prev + 1e-3f) << i;
    prev = f;
  }
  // Saturated beyond gamma: -mu xi Fz sgn(alpha), with xi < 1 under a longitudinal force:
  // Fx = 30 N: xi = sqrt(55^2 - 30^2) / 55 = sqrt(2125) / 55 = 0.838148.
  EXPECT_FLOAT_EQ(RC::lateral_force(p, 0.3f, fz, 0.0f), -55.0f);
  EXPECT_FLOAT_EQ(RC::lateral_force(p, -0.3f, fz, 0.0f), 55.0f);
  EXPECT_NEAR(RC::lateral_force(p, 0.5f, fz, 30.0f), -55.0 * 0.838148, 1e-3);
  EXPECT_NEAR(RC::lateral_force(p, -0.5f, fz, -30.0f), 55.0 * 0.838148, 1e-3);
  // Continuous at gamma (the brush curve reaches -mu xi Fz with zero slope there).
  for (float fx : {0.0f, 30.0f}) {
    const double xi = std::sqrt(55.0 * 55.0 - fx * fx) / 55.0;
    const double g = std::atan(3.0 * xi * 55.0 / 1200.0);
    const float below = RC::lateral_force(p, static_cast<float>(g - 1e-4), fz, fx);
    const float above = RC::lateral_force(p, static_cast<float>(g + 1e-4), fz, fx);
    EXPECT_NEAR(below, above, 1e-2) << "fx " << fx;
    EXPECT_NEAR(above, -55.0 * xi, 1e-3) << "fx " << fx;
  }
}

TEST(Racecar, SteeringAndDriveTrackTheirSetpoints) {
  const RC::Params p;
  auto x = state_with<RC>({{RC::VX, 3.0f}, {RC::DELTA, 0.1f}, {RC::FX, 20.0f}});
  const auto dx = derivative_of<RC>(p, x, {0.3f, 5.0f});
  EXPECT_FLOAT_EQ(dx[RC::DELTA], 10.0f * (0.3f - 0.1f));  // towards delta_des
  EXPECT_FLOAT_EQ(dx[RC::FX], 10.0f * (5.0f - 20.0f));
  // Integrating: delta converges to delta_des.
  for (int i = 0; i < 2000; ++i) RC::step(p, x.data(), std::vector<float>{0.3f, 5.0f}.data(), 1e-3f);
  EXPECT_NEAR(x[RC::DELTA], 0.3f, 1e-3f);
  // Steering left (delta > 0) at speed turns the car left (positive yaw rate).
  EXPECT_GT(x[RC::R], 0.0f);
}

TEST(Integration, EulerConvergesToRk4Racecar) {
  const auto x = state_with<RC>({{RC::VX, 5.0f}, {RC::BETA, 0.01f}, {RC::R, 0.1f}, {RC::DELTA, 0.02f}, {RC::FX, 10.0f}});
  check_integrator<RC>(RC::Params{}, x, {0.05f, 20.0f}, "racecar");
}

}  // namespace
}  // namespace mppi
