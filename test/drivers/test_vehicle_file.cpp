// Vehicle files (config/vehicles/*.yaml): read into a task's settings, and every way a task
// file and its vehicle file can disagree refused at start with both named.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/app/vehicle.hpp"
#include "source_dir.hpp"

using mppi::app::ConfigError;
using mppi::app::load_config;
using mppi::app::load_vehicle;

namespace {

const std::string kRoot = mppi::testing::source_dir();
const std::string kRateTask = kRoot + "/config/tasks/quadrotor_rate_track.yaml";
const std::string kShipped = kRoot + "/config/vehicles/sim_rate_1kg.yaml";

// A vehicle file in a fresh temporary folder.
std::string vehicle_file(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / ("mppid_vehicle_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::ofstream(path) << text;
  return path.string();
}

const char* kHeavy = R"(name: heavy
model: quadrotor_rate
mass: 1.3
drag: 0.1
limits: {max_thrust: 30.0, max_body_rate: [8, 8, 4]}
rate_response: {tau: [0.06, 0.07, 0.1], gain: [0.9, 1.1, 0.8], delay: 0.012}
estimate_lag: 0.025
)";

// The error a config load throws, or "" when it loads.
std::string load_error(const std::string& file, const std::vector<std::string>& sets) {
  try {
    load_config(file, sets);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return {};
}

double daemon_delay_ms(const mppi::app::AppConfig& c) { return c.root["daemon"]["latency"]["actuation_delay_ms"].as<double>(); }

}  // namespace

TEST(VehicleFile, TheRateTasksFlyTheShippedVehicle) {
  const auto c = load_config(kRateTask);
  ASSERT_NE(c.vehicle, nullptr);
  EXPECT_EQ(c.vehicle->name, "sim_rate_1kg");
  EXPECT_FLOAT_EQ(c.mppi.u_init[0], 9.81f);  // `hover`: mass x gravity of the vehicle
  EXPECT_FLOAT_EQ(c.mppi.u_nominal[0], 9.81f);
  EXPECT_EQ(c.mppi.u_init[1], 0.0f);
}

TEST(VehicleFile, AnotherVehicleSetsTheModelTheHoverAndTheActuationDelay) {
  const std::string v = vehicle_file("heavy.yaml", kHeavy);
  const auto c = load_config(kRateTask, {"vehicle=" + v});
  EXPECT_EQ(c.vehicle->name, "heavy");
  EXPECT_FLOAT_EQ(c.mppi.u_init[0], 1.3f * 9.81f);
  const auto value = [&](const std::string& k) {
    for (const auto& [key, x] : c.params)
      if (key == k) return x;
    return -1.0;
  };
  EXPECT_DOUBLE_EQ(value("model.mass"), 1.3);
  EXPECT_DOUBLE_EQ(value("model.drag"), 0.1);
  EXPECT_DOUBLE_EQ(value("model.rate_tau_y"), 0.07);
  EXPECT_DOUBLE_EQ(value("model.rate_gain_z"), 0.8);
  EXPECT_DOUBLE_EQ(daemon_delay_ms(c), 12.0);
  // How far the autopilot's estimate trails the vehicle: the act-time prediction's.
  EXPECT_DOUBLE_EQ(c.root["daemon"]["latency"]["estimate_lag_ms"].as<double>(), 25.0);
  // The controller built from it flies that mass.
  EXPECT_FLOAT_EQ(mppi::app::make_controller(load_config(kRateTask, {"vehicle=" + v, "mppi.rollouts=16"}))->mass(), 1.3f);
}

TEST(VehicleFile, AValueTheTaskAlsoGivesDifferentlyIsRefusedNamingBoth) {
  const std::string err = load_error(kRateTask, {"model.mass=1.2"});
  EXPECT_NE(err.find("model.mass"), std::string::npos) << err;
  EXPECT_NE(err.find("--set model.mass gives 1.2"), std::string::npos) << err;
  EXPECT_NE(err.find("sim_rate_1kg.yaml gives 1"), std::string::npos) << err;
  // The same value is no disagreement.
  EXPECT_EQ(load_error(kRateTask, {"model.mass=1.0"}), "");
  // The delay against the task's daemon section.
  const std::string v = vehicle_file("heavy.yaml", kHeavy);
  const std::string d = load_error(kRateTask, {"vehicle=" + v, "daemon.latency.actuation_delay_ms=5"});
  EXPECT_NE(d.find("daemon.latency.actuation_delay_ms"), std::string::npos) << d;
  EXPECT_NE(d.find(v), std::string::npos) << d;
}

TEST(VehicleFile, LimitsHoverAndModelMustFitTheVehicle) {
  const std::string beyond = load_error(kRateTask, {"mppi.u_max=[30, 6, 6, 3]"});
  EXPECT_NE(beyond.find("mppi.u_min/u_max[0]"), std::string::npos) << beyond;
  EXPECT_NE(beyond.find("quadrotor_rate_track.yaml flies [0, 30]"), std::string::npos) << beyond;
  EXPECT_NE(beyond.find("limits it to [0, 25]"), std::string::npos) << beyond;
  const std::string hover = load_error(kRateTask, {"mppi.u_init=[12, 0, 0, 0]"});
  EXPECT_NE(hover.find("mppi.u_init[0]"), std::string::npos) << hover;
  EXPECT_NE(hover.find("not the hover of the vehicle file"), std::string::npos) << hover;
  const std::string model = load_error(kRoot + "/config/tasks/quadrotor_forest.yaml", {"vehicle=" + kShipped});
  EXPECT_NE(model.find("flies the quadrotor model"), std::string::npos) << model;
  EXPECT_NE(model.find("describes a quadrotor_rate"), std::string::npos) << model;
  const std::string channel = load_error(kRateTask, {"mppi.u_init=[hover, hover, 0, 0]"});
  EXPECT_NE(channel.find("mppi.u_init[1]"), std::string::npos) << channel;
}

TEST(VehicleFile, ABadFileIsRefusedNamingTheFileAndTheField) {
  const auto error_of = [](const std::string& text) {
    const std::string path = vehicle_file("bad.yaml", text);
    try {
      load_vehicle(path);
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      return std::string(e.what());
    }
    return std::string("loaded");
  };
  const std::string good = "name: a\nmodel: quadrotor_rate\nmass: 1\nlimits: {max_thrust: 20, max_body_rate: 6}\n";
  EXPECT_EQ(error_of(good), "loaded");
  EXPECT_NE(error_of(good + "colour: red\n").find("colour: unknown field"), std::string::npos);
  EXPECT_NE(error_of("name: a\nmodel: quadrotor_rate\nlimits: {max_thrust: 20, max_body_rate: 6}\n").find("mass"),
            std::string::npos);
  EXPECT_NE(error_of(good + "rate_response: {tau: [0.05, 0.05]}\n").find("rate_response.tau"), std::string::npos);
  EXPECT_NE(error_of(good + "hover_thrust: 1.5\n").find("hover_thrust: must be in"), std::string::npos);
  EXPECT_NE(error_of("name: a\nmodel: hexacopter\nmass: 1\n").find("model: must be"), std::string::npos);
  EXPECT_NE(error_of(good + "params: {mass: 2}\n").find("params.mass"), std::string::npos);
  EXPECT_NE(load_error(kRateTask, {"vehicle=/nonexistent/v.yaml"}).find("cannot open"), std::string::npos);
}
