// mppid-sensors: the simulator's sensors for a vehicle flown by an autopilot's SITL (sim/sensor_node.hpp).
//   mppid-sensors --sensing FILE [--seed S] --lcm-url URL [--sensor-lcm-url URL] [--stats FILE]
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "mppi/cli/program.hpp"
#include "sim/scenario.hpp"
#include "sim/sensor_node.hpp"

namespace {

constexpr const char* kName = "mppid-sensors";

struct Args {
  std::string sensing, lcm_url, sensor_url, stats;
  unsigned long long seed = 1;
  sim::SensorNodeSettings settings;
};

void add_options(CLI::App& app, Args* a) {
  app.add_option("--sensing", a->sensing, "A YAML file whose sensing: block names the sensors (a mission's)")
      ->required();
  app.add_option("--seed", a->seed, "Seed of the sensors' noise")->capture_default_str();
  app.add_option("--lcm-url", a->lcm_url, "The world (obstacles_t on MPPI_WORLD) comes on this bus");
  app.add_option("--sensor-lcm-url", a->sensor_url,
                 "The truth (vehicle_state_t on SIM_TRUTH) comes and the frames (point_cloud_t on MPPI_DEPTH, "
                 "MPPI_LIDAR) go on this one (default: --lcm-url)");
  app.add_option("--tree-height", a->settings.tree_height, "Height of the world's trees, m")
      ->check(mppi::cli::in_open(0.0, 1000.0))
      ->capture_default_str();
  app.add_option("--max-truth-age", a->settings.max_truth_age, "A truth older than this behind the wall clock is stale, s")
      ->check(mppi::cli::in_open(0.0, 1000.0))
      ->capture_default_str();
  app.add_option("--stats", a->stats, "On exit: the truths taken and refused, the frames, their cost (JSON)");
}

// The mission's sensors, as the simulator would carry them.
sim::Scenario sensing_scenario(const Args& a) {
  sim::Scenario s;
  s.seed = a.seed;
  s.ground_z = 0.0;
  s.sensing = sim::load_sensing(a.sensing);
  if (!s.sensing.depth_camera.enabled && !s.sensing.lidar.enabled)
    throw std::runtime_error(a.sensing + ": sensing: names no sensor (depth_camera, lidar)");
  return s;
}

void write_stats(const sim::SensorNode& node, const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw std::runtime_error("cannot write " + path);
  node.write_stats(f);
  std::fclose(f);
}

int run(const Args& a, const volatile std::sig_atomic_t* stop) {
  const sim::Scenario s = sensing_scenario(a);
  lcm::LCM in(a.lcm_url);
  std::unique_ptr<lcm::LCM> sensors = a.sensor_url.empty() ? nullptr : std::make_unique<lcm::LCM>(a.sensor_url);
  if (!in.good() || (sensors && !sensors->good())) throw std::runtime_error("LCM init failed");
  sim::SensorNode node(s, a.settings, &in, sensors ? sensors.get() : &in, nullptr);
  std::printf("{\"event\": \"ready\"}\n");
  std::fflush(stdout);
  node.run(stop);
  if (!a.stats.empty()) write_stats(node, a.stats);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  CLI::App app{"mppid-sensors: the simulator's depth camera and LiDAR for a vehicle an autopilot's SITL flies",
               kName};
  add_options(app, &a);
  if (const std::optional<int> rc = mppi::cli::parse(app, argc, argv)) return *rc;
  const volatile std::sig_atomic_t* stop = mppi::cli::stop_on_signals();
  return mppi::cli::run_reporting(kName, [&] { return run(a, stop); });
}
