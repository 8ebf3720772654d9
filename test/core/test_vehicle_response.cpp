// The rate model's per-axis response (gain, time constant), the hover controls of the
// quadrotor models, and a controller whose mass changes at run time (the daemon's mass
// estimate): its control cost's nominal, warm start and plan follow the hover.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "fixtures.hpp"
#include "mppi/controller.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

using QR = QuadrotorRate;

std::vector<float> level_rate_state() {
  std::vector<float> x(QR::kNx, 0.0f);
  x[QR::PZ] = 2.0f;
  x[QR::QW] = 1.0f;
  return x;
}

TEST(RateResponse, EachAxisFollowsItsOwnGainAndTimeConstant) {
  QR::Params p;
  p.rate_tau_x = 0.04f;
  p.rate_tau_y = 0.08f;
  p.rate_tau_z = 0.2f;
  p.rate_gain_x = 0.9f;
  p.rate_gain_y = 1.2f;
  p.rate_gain_z = 0.5f;
  auto x = level_rate_state();
  x[QR::WX] = 0.1f;
  x[QR::WY] = -0.3f;
  const float u[4] = {9.81f, 1.0f, -2.0f, 0.6f};
  float dx[QR::kNx];
  QR::derivative(p, x.data(), u, dx);
  EXPECT_FLOAT_EQ(dx[QR::WX], (0.9f * 1.0f - 0.1f) / 0.04f);
  EXPECT_FLOAT_EQ(dx[QR::WY], (1.2f * -2.0f + 0.3f) / 0.08f);
  EXPECT_FLOAT_EQ(dx[QR::WZ], (0.5f * 0.6f) / 0.2f);
  // Held long enough (10 time constants of the slowest), each rate settles at gain x setpoint.
  const float dt = 1e-4f;
  for (int i = 0; i < 20000; ++i) QR::step(p, x.data(), u, dt);
  EXPECT_NEAR(x[QR::WX], 0.9f, 1e-3f);
  EXPECT_NEAR(x[QR::WY], -2.4f, 1e-3f);
  EXPECT_NEAR(x[QR::WZ], 0.3f, 1e-3f);
}

TEST(RateResponse, DefaultsAreTheFirstOrderLagOfBefore) {
  // Unit gains and 50 ms on every axis: the derivative is exactly (u - w) / 0.05 as the
  // model was before the per-axis response (the task files' flights do not change).
  const QR::Params p;
  auto x = level_rate_state();
  x[QR::WZ] = 0.25f;
  const float u[4] = {9.81f, 0.7f, -0.4f, 1.1f};
  float dx[QR::kNx];
  QR::derivative(p, x.data(), u, dx);
  const float k = 1.0f / 0.05f;
  EXPECT_EQ(dx[QR::WX], k * (0.7f - 0.0f));
  EXPECT_EQ(dx[QR::WY], k * (-0.4f - 0.0f));
  EXPECT_EQ(dx[QR::WZ], k * (1.1f - 0.25f));
}

TEST(Hover, TheHoverControlHoldsEachQuadrotorAndScalesWithMass) {
  QR::Params rp;
  rp.mass = 1.3f;
  float u[4];
  QR::hover_control(rp, u);
  EXPECT_FLOAT_EQ(u[QR::THRUST], 1.3f * 9.81f);
  EXPECT_EQ(u[QR::RATE_X], 0.0f);
  auto x = level_rate_state();
  float dx[QR::kNx];
  QR::derivative(rp, x.data(), u, dx);
  EXPECT_NEAR(dx[QR::VZ], 0.0f, 1e-5f);
  QR::scale_hover(1.2f, u);  // 20 % heavier: 20 % more thrust
  EXPECT_FLOAT_EQ(u[QR::THRUST], 1.2f * 1.3f * 9.81f);

  Quadrotor::Params qp;
  float m[4];
  Quadrotor::hover_control(qp, m);
  for (float w : m) EXPECT_FLOAT_EQ(w, Quadrotor::hover_speed(qp));
  Quadrotor::scale_hover(1.21f, m);  // thrust ~ speed^2: 1.1 x the speed holds 1.21 x the mass
  qp.mass *= 1.21f;
  for (float w : m) EXPECT_NEAR(w, Quadrotor::hover_speed(qp), 1e-2f);
}

// A CPU controller of the 16-state forest task, small.
std::unique_ptr<TaskController<QuadrotorForest>> forest_controller() {
  const MppiSettings s = testing::quadrotor_settings(64, 20, 1000.0f, 60.0f, 1);
  return std::make_unique<TaskController<QuadrotorForest>>("quadrotor_forest", s, QuadrotorForest::Params{},
                                                           std::make_unique<CpuBackend<QuadrotorForest>>(s));
}

TEST(MassAtRunTime, TheNominalWarmStartAndPlanFollowTheHoverOfTheNewMass) {
  auto c = forest_controller();
  const float m0 = c->mass();
  const float hover0 = Quadrotor::hover_speed(Quadrotor::Params{});
  ASSERT_FLOAT_EQ(m0, 0.25f);
  std::vector<float> plan = c->plan();
  plan[0] = hover0 + 100.0f;  // a plan with something in it
  c->set_plan(plan.data());
  ASSERT_TRUE(c->set_mass(1.2f * m0));
  EXPECT_FLOAT_EQ(c->mass(), 1.2f * m0);
  const float hover1 = hover0 * std::sqrt(1.2f);
  // The plan moved by the change of hover, inside the limits.
  EXPECT_NEAR(c->plan()[0], hover0 + 100.0f + (hover1 - hover0), 0.05f);
  EXPECT_NEAR(c->plan()[5], hover1, 0.05f);
  // The warm start appends the new hover.
  c->shift(3);
  const auto& p = c->plan();
  EXPECT_NEAR(p[p.size() - 1], hover1, 0.05f);
  // A change below half a percent of the mass leaves them where they are.
  ASSERT_TRUE(c->set_mass(1.2f * m0 * 1.003f));
  c->shift(1);
  EXPECT_NEAR(c->plan()[c->plan().size() - 1], hover1, 0.05f);
}

TEST(MassAtRunTime, AHeavierModelPlansMoreThrustAroundItsOwnHover) {
  // From hover, both controllers hold: the heavier one's update stays near its own hover
  // rather than being pulled to the nominal one's (the control cost's nominal followed).
  auto light = forest_controller();
  auto heavy = forest_controller();
  heavy->set_mass(1.2f * heavy->mass());
  TaskInputs in;
  in.goals[0][2] = 2.0f;
  light->set_inputs(in);
  heavy->set_inputs(in);
  std::vector<float> x(Quadrotor::kNx, 0.0f);
  x[Quadrotor::PZ] = 2.0f;
  float ul[4], uh[4];
  for (int i = 0; i < 30; ++i) {
    for (int m = 0; m < 4; ++m) x[Quadrotor::M1 + m] = Quadrotor::hover_speed(Quadrotor::Params{});
    light->iterate(x.data(), ul);
    Quadrotor::Params hp;
    hp.mass = heavy->mass();
    for (int m = 0; m < 4; ++m) x[Quadrotor::M1 + m] = Quadrotor::hover_speed(hp);
    heavy->iterate(x.data(), uh);
  }
  Quadrotor::Params hp;
  hp.mass = heavy->mass();
  const float mean_l = (ul[0] + ul[1] + ul[2] + ul[3]) / 4.0f, mean_h = (uh[0] + uh[1] + uh[2] + uh[3]) / 4.0f;
  EXPECT_NEAR(mean_l, Quadrotor::hover_speed(Quadrotor::Params{}), 60.0f);
  EXPECT_NEAR(mean_h, Quadrotor::hover_speed(hp), 60.0f);
}

}  // namespace
}  // namespace mppi
