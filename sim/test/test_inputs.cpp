// The simulator's inputs: scenario files (a bad one ends in std::runtime_error naming the
// file and where, never a yaml-cpp error naming nothing) and command_t from the bus
// (decoded by the checked decoder, then checked against the plant). The inputs
// fuzz_scenario and fuzz_sim_command found are in test/fuzz/regressions/.
#include <cstdint>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "mppi/transport/lcm_decode.hpp"
#include "sim/command_input.hpp"
#include "sim/plant.hpp"
#include "sim/scenario.hpp"
#include "source_dir.hpp"

namespace {

std::string source(const std::string& rel) { return mppi::testing::source_dir() + "/" + rel; }

std::string scenario_error(const std::string& text) {
  try {
    sim::load_scenario_text(text, "t.yaml", 1);
  } catch (const YAML::Exception& e) {
    ADD_FAILURE() << "a yaml-cpp error escaped: " << e.what();
    return {};
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  ADD_FAILURE() << "accepted:\n" << text;
  return {};
}

const char* kMinimal = "task: quadrotor_forest\nplant: {model: quadrotor}\n";

mppi_lcm::command_t command(int n, std::int8_t kind, float value) {
  mppi_lcm::command_t c{};
  c.seq = 1;
  c.state_seq = 1;
  c.kind = kind;
  c.n = n;
  c.u.assign(static_cast<std::size_t>(n), value);
  return c;
}

}  // namespace

TEST(ScenarioInput, AListOrMapAsAKeyNamesWhere) {
  std::ifstream f(source("test/fuzz/regressions/fuzz_scenario/top_level_key_is_a_map.yaml"));
  const std::string found((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(found.empty());
  EXPECT_EQ(scenario_error(found), "t.yaml: scenario: keys must be plain names (line 19)");
  EXPECT_EQ(scenario_error(std::string(kMinimal) + "world: {? [1, 2]: 3}\n"),
            "t.yaml: world: keys must be plain names (line 3)");
  EXPECT_EQ(scenario_error("task: quadrotor_forest\nplant: {model: quadrotor, params: {? [mass]: 1}}\n"),
            "t.yaml: plant.params: keys must be plain names (line 2)");
  EXPECT_NO_THROW(sim::load_scenario_text(kMinimal, "t.yaml", 1));
}

// fuzz_scenario: a forest y_range of [-8, 8.8e89] kept the generator walking lattice rows
// for ever (a 10 s timeout under the fuzzer); a moving-obstacle count of 2e9 would too.
TEST(ScenarioInput, WorldsTooLargeToGenerateAreRefused) {
  std::ifstream f(source("test/fuzz/regressions/fuzz_scenario/forest_y_range_1e89_never_ends.yaml"));
  const std::string found((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(found.empty());
  EXPECT_NE(scenario_error(found).find("t.yaml: world.forest: x_range, y_range and spacing make"), std::string::npos);
  const std::string forest = std::string(kMinimal) + "world: {forest: {spacing: 0.001}}\n";
  EXPECT_NE(scenario_error(forest).find("lattice points; at most 20000"), std::string::npos);
  EXPECT_EQ(scenario_error(std::string(kMinimal) + "world: {moving: {count: 2000000000}}\n"),
            "t.yaml: world.moving.count: must be 0..1024");
  EXPECT_EQ(scenario_error(std::string(kMinimal) + "world: {forest: {x_range: [0, .inf]}}\n"),
            "t.yaml: world.forest: every value must be finite");
  // Every shipped forest stays well inside the bound.
  for (const char* name : {"forest_3m", "team9_moving"})
    EXPECT_NO_THROW(sim::load_scenario(source(std::string("config/scenarios/") + name + ".yaml"), 1)) << name;
}

// fuzz_sim_command: n < 0 threw std::length_error out of the simulator's LCM handler (the
// typed subscription decoded with the generated decoder). Now the checked decoder refuses it.
TEST(CommandInput, NegativeCountIsUndecodable) {
  std::ifstream f(source("test/fuzz/regressions/fuzz_sim_command/command_negative_count_throws"), std::ios::binary);
  const std::vector<char> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(b.empty());
  mppi_lcm::command_t m{};
  EXPECT_NO_THROW(EXPECT_FALSE(mppi::transport::decode_message(b.data(), b.size(), &m)));
}

TEST(CommandInput, ShapeKindAndFiniteAgainstThePlant) {
  const sim::Scenario s = sim::load_scenario(source("config/scenarios/rate_forest_4m.yaml"), 1);
  const auto plant = sim::make_plant(s);  // rate quadrotor: 4 values, KIND_THRUST_RATES (2)
  std::vector<float> u;
  EXPECT_EQ(sim::check_command(command(4, 2, 1.0f), *plant, &u), sim::CommandCheck::kAccepted);
  EXPECT_EQ(sim::check_command(command(4, 3, 1.0f), *plant, &u), sim::CommandCheck::kAccepted);  // KIND_GENERIC
  EXPECT_EQ(sim::check_command(command(4, 1, 1.0f), *plant, &u), sim::CommandCheck::kWrongShape);
  EXPECT_EQ(sim::check_command(command(3, 2, 1.0f), *plant, &u), sim::CommandCheck::kWrongShape);
  mppi_lcm::command_t lying = command(4, 2, 1.0f);
  lying.u.resize(5);  // n says 4, the array holds 5
  EXPECT_EQ(sim::check_command(lying, *plant, &u), sim::CommandCheck::kWrongShape);
  EXPECT_EQ(sim::check_command(command(4, 2, std::numeric_limits<float>::quiet_NaN()), *plant, &u),
            sim::CommandCheck::kNonFinite);
  // Accepted commands come back clamped to the plant's limits.
  ASSERT_EQ(sim::check_command(command(4, 2, 1e9f), *plant, &u), sim::CommandCheck::kAccepted);
  EXPECT_FLOAT_EQ(u[0], static_cast<float>(s.max_thrust));
  EXPECT_FLOAT_EQ(u[1], static_cast<float>(s.max_body_rate));
}

// Plant::failsafe (timing.command_timeout): a rate quadrotor tilted 30 degrees and rolling
// is levelled within a second and keeps its altitude; the same plant on its plain hover
// command stays tilted and sinks.
TEST(Failsafe, RateQuadrotorLevelsAndHoldsAltitude) {
  for (const char* model : {"quadrotor_rate", "quadrotor_rate_body"}) {
    sim::Scenario s = sim::load_scenario(source("config/scenarios/soak_circle.yaml"), 1);
    s.model = model;
    auto tilted = [&] {
      auto p = sim::make_plant(s);
      std::vector<float> u = p->hover();
      u[1] = 3.0f;  // roll at 3 rad/s for ~0.17 s: ~30 degrees
      const double wind[3] = {0, 0, 0};
      for (int i = 0; i < 175; ++i) p->step(u.data(), wind, 1e-3);
      return p;
    };
    const double wind[3] = {0, 0, 0};
    auto held = tilted();
    const float z0 = held->state()[2];
    for (int i = 0; i < 1000; ++i) {
      std::vector<float> u = held->failsafe();
      held->step(u.data(), wind, 1e-3);
    }
    auto hovered = tilted();
    for (int i = 0; i < 1000; ++i) {
      std::vector<float> u = hovered->hover();
      hovered->step(u.data(), wind, 1e-3);
    }
    const auto& x = held->state();
    const float tilt_cos = 1.0f - 2.0f * (x[7] * x[7] + x[8] * x[8]);  // body z . world z
    EXPECT_GT(tilt_cos, std::cos(0.05f)) << model;                       // within 3 degrees of level
    EXPECT_NEAR(x[2], z0, 0.15f) << model;
    const auto& y = hovered->state();
    EXPECT_LT(1.0f - 2.0f * (y[7] * y[7] + y[8] * y[8]), std::cos(0.3f)) << model;  // still tilted
    EXPECT_LT(y[2], z0 - 0.05f) << model;
  }
}
