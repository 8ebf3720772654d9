// Unit tests of the simulator's library: the RK4 integrator, the plants, the scenarios.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "mppi/models/quadrotor.hpp"
#include "sim/plant.hpp"
#include "mppi/rk4.hpp"
#include "sim/scenario.hpp"
#include "source_dir.hpp"

namespace {

struct Decay {
  static constexpr int kNx = 1;
  [[maybe_unused]] static constexpr int kNu = 1;  // the model interface; unused by rk4
  struct Params {
    float k = 1.0f;
  };
  static void derivative(const Params& p, const float* x, const float*, float* dx) { dx[0] = -p.k * x[0]; }
};

TEST(Rk4, FourthOrderOnExponentialDecay) {
  // Halving the step must cut the error by about 2^4.
  double err[2];
  for (int k = 0; k < 2; ++k) {
    const int n = 10 << k;
    float x = 1.0f;
    const float u = 0.0f;
    for (int i = 0; i < n; ++i) mppi::rk4_model<Decay>(Decay::Params{2.0f}, &x, &u, 1.0f / static_cast<float>(n));
    err[k] = std::fabs(static_cast<double>(x) - std::exp(-2.0));
  }
  EXPECT_GT(err[0] / err[1], 10.0);
  EXPECT_LT(err[1], 1e-5);
}

TEST(Rk4, FreeFallMatchesClosedForm) {
  mppi::Quadrotor::Params p;
  float x[mppi::Quadrotor::kNx] = {};
  x[mppi::Quadrotor::PZ] = 10.0f;
  const float u[4] = {0, 0, 0, 0};
  for (int i = 0; i < 1000; ++i) mppi::rk4_model<mppi::Quadrotor>(p, x, u, 1e-3f);
  EXPECT_NEAR(x[mppi::Quadrotor::PZ], 10.0f - 0.5f * 9.81f, 1e-3f);
  EXPECT_NEAR(x[mppi::Quadrotor::VZ], -9.81f, 1e-3f);
}

std::string scenario(const char* name) { return mppi::testing::source_dir() + "/config/scenarios/" + name + ".yaml"; }

TEST(Plant, QuadrotorHoversOnItsHoverCommand) {
  const sim::Scenario s = sim::load_scenario(scenario("forest_4m"), 1);
  auto plant = sim::make_plant(s);
  const auto u = plant->hover();
  const double wind[3] = {0, 0, 0};
  for (int i = 0; i < 5000; ++i) plant->step(u.data(), wind, 1e-3);
  double p[3];
  plant->position(0, p);
  EXPECT_NEAR(p[2], 2.0, 1e-3);
  EXPECT_NEAR(plant->speed(0), 0.0, 1e-3);
}

TEST(Plant, HeavierPlantSinksOnTheControllersHover) {
  sim::Scenario s = sim::load_scenario(scenario("forest_4m"), 1);
  s.params["mass"] = 0.3;
  auto plant = sim::make_plant(s);
  std::vector<float> u(4, mppi::Quadrotor::hover_speed(mppi::Quadrotor::Params{}));
  const double wind[3] = {0, 0, 0};
  for (int i = 0; i < 1000; ++i) plant->step(u.data(), wind, 1e-3);
  double p[3];
  plant->position(0, p);
  EXPECT_LT(p[2], 1.8);
}

TEST(Plant, SaturatesAndRejectsNonFinite) {
  const sim::Scenario s = sim::load_scenario(scenario("forest_4m"), 1);
  auto plant = sim::make_plant(s);
  float u[4] = {-5.0f, 1e6f, 3000.0f, 3000.0f};
  EXPECT_TRUE(plant->saturate(u));
  EXPECT_EQ(u[0], 0.0f);
  EXPECT_EQ(u[1], 8000.0f);
  u[2] = std::nanf("");
  EXPECT_FALSE(plant->saturate(u));
}

TEST(Plant, UnknownParameterIsAnError) {
  sim::Scenario s = sim::load_scenario(scenario("forest_4m"), 1);
  s.params["mas"] = 0.3;
  EXPECT_THROW(sim::make_plant(s), std::runtime_error);
}

TEST(Scenario, EveryFileLoads) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(mppi::testing::source_dir() + "/config/scenarios")) {
    if (e.path().extension() != ".yaml") continue;
    EXPECT_NO_THROW({
      const auto s = sim::load_scenario(e.path().string(), 1);
      (void)sim::make_plant(s);
    }) << e.path();
    ++n;
  }
  EXPECT_GE(n, 10);
}

TEST(Scenario, SeedNamesTheForest) {
  const auto a = sim::load_scenario(scenario("forest_3m"), 5).obstacles;
  const auto b = sim::load_scenario(scenario("forest_3m"), 5).obstacles;
  const auto c = sim::load_scenario(scenario("forest_3m"), 6).obstacles;
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].x, b[i].x);
  EXPECT_TRUE(a.size() != c.size() || a[0].x != c[0].x);
}

TEST(Scenario, MovingObstaclesHaveTheirSpeed) {
  const auto s = sim::load_scenario(scenario("team3_moving"), 2);
  int moving = 0;
  for (const auto& o : s.obstacles) {
    if (o.vx == 0.0 && o.vy == 0.0) continue;
    ++moving;
    EXPECT_NEAR(std::hypot(o.vx, o.vy), 3.0, 1e-9);
  }
  EXPECT_EQ(moving, 8);
}

}  // namespace

namespace {

sim::Scenario rate_body() {
  sim::Scenario s = sim::load_scenario(scenario("rate_forest_4m_body"), 1);
  s.forest.enabled = false;
  s.obstacles.clear();
  return s;
}

TEST(RateBodyPlant, HoversOnItsHoverThrust) {
  const auto s = rate_body();
  auto plant = sim::make_plant(s);
  ASSERT_EQ(plant->nx(), 13);
  const auto u = plant->hover();
  const double wind[3] = {0, 0, 0};
  for (int i = 0; i < 3000; ++i) plant->step(u.data(), wind, 1e-3);
  double p[3];
  plant->position(0, p);
  EXPECT_NEAR(p[2], 2.0, 2e-3);
  EXPECT_NEAR(plant->state()[6], 1.0f, 1e-5f);  // level: q = identity
}

TEST(RateBodyPlant, TracksARateSetpointAndTiltsTheThrust) {
  const auto s = rate_body();
  auto plant = sim::make_plant(s);
  auto u = plant->hover();
  u[1] = 1.0f;  // roll rate 1 rad/s
  const double wind[3] = {0, 0, 0};
  for (int i = 0; i < 300; ++i) plant->step(u.data(), wind, 1e-3);
  const auto& x = plant->state();
  EXPECT_NEAR(x[10], 1.0f, 0.1f);  // the P loop through the motor lag has settled
  // Positive roll about x tilts the body z axis towards -y: the thrust pushes along -y.
  for (int i = 0; i < 300; ++i) plant->step(plant->hover().data(), wind, 1e-3);
  EXPECT_LT(plant->state()[4], 0.0f);
  // The published quaternion's body z axis is R_WB's third column from the Euler angles.
  const float qw = x[6], qx = x[7], qy = x[8], qz = x[9];
  const float bz = 1.0f - 2.0f * (qx * qx + qy * qy);
  EXPECT_GT(bz, 0.9f);
  EXPECT_NEAR(qw * qw + qx * qx + qy * qy + qz * qz, 1.0f, 1e-5f);
}

}  // namespace

namespace {

// plant.thrust_gain: the rate plants produce that much of the thrust commanded (a motor
// constant the controller is not told), so their own hover command no longer holds them.
TEST(RatePlants, ThrustGainScalesTheThrustTheyProduce) {
  for (const char* name : {"rate_track_circle", "rate_forest_4m_body"}) {
    sim::Scenario s = sim::load_scenario(scenario(name), 1);
    s.forest.enabled = false;
    s.obstacles.clear();
    s.thrust_gain = 0.9;
    auto plant = sim::make_plant(s);
    auto u = plant->hover();
    ASSERT_TRUE(plant->saturate(u.data()));
    EXPECT_NEAR(u[0], 0.9 * plant->hover()[0], 1e-4) << name;
    const double wind[3] = {0, 0, 0};
    for (int i = 0; i < 500; ++i) plant->step(u.data(), wind, 1e-3);
    EXPECT_NEAR(plant->state()[5], -0.1 * 9.81 * 0.5, 0.05) << name;  // 0.5 s at -0.1 g
  }
}

}  // namespace
