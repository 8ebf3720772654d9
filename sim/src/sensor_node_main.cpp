// mppid-sensors: the simulator's sensors for a vehicle flown by an autopilot's SITL (sim/sensor_node.hpp).
//   mppid-sensors --sensing FILE [--seed S] --lcm-url URL [--sensor-lcm-url URL] [--stats FILE] [--set k=v]
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <memory>
#include <stdexcept>
#include <string>

#include "sim/scenario.hpp"
#include "sim/sensor_node.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

int usage(const char* why) {
  if (why != nullptr) std::fprintf(stderr, "mppid-sensors: %s\n", why);
  std::fprintf(stderr,
               "usage: mppid-sensors --sensing FILE [--seed S] [--lcm-url URL] [--sensor-lcm-url URL]\n"
               "                     [--tree-height M] [--max-truth-age S] [--stats FILE]\n"
               "  --sensing FILE       a YAML file whose sensing: block names the sensors (a mission's)\n"
               "  --lcm-url URL        the world (obstacles_t on MPPI_WORLD) comes on this bus\n"
               "  --sensor-lcm-url URL the truth (vehicle_state_t on SIM_TRUTH) comes and the frames\n"
               "                       (point_cloud_t on MPPI_DEPTH, MPPI_LIDAR) go on this one (default: --lcm-url)\n"
               "  --stats FILE         on exit: the truths taken and refused, the frames, their cost (JSON)\n");
  return 2;
}

struct Args {
  std::string sensing, lcm_url, sensor_url, stats;
  unsigned long long seed = 1;
  sim::SensorNodeSettings settings;
};

// 0: parsed; else the exit status.
int parse(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "-h" || k == "--help") return usage(nullptr), 3;
    if (i + 1 >= argc) return usage((k + " needs a value").c_str());
    const std::string v = argv[++i];
    char* end = nullptr;
    if (k == "--sensing") {
      a->sensing = v;
    } else if (k == "--seed") {
      a->seed = std::strtoull(v.c_str(), &end, 10);
      if (*end != '\0') return usage("--seed needs a number");
    } else if (k == "--lcm-url") {
      a->lcm_url = v;
    } else if (k == "--sensor-lcm-url") {
      a->sensor_url = v;
    } else if (k == "--stats") {
      a->stats = v;
    } else if (k == "--tree-height" || k == "--max-truth-age") {
      const double d = std::strtod(v.c_str(), &end);
      if (*end != '\0' || !(d > 0.0 && d < 1000.0)) return usage((k + " needs a positive number").c_str());
      (k == "--tree-height" ? a->settings.tree_height : a->settings.max_truth_age) = d;
    } else {
      return usage(("unknown argument " + k).c_str());
    }
  }
  return a->sensing.empty() ? usage("--sensing is required") : 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (const int rc = parse(argc, argv, &a); rc != 0) return rc == 3 ? 0 : rc;
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    sim::Scenario s;
    s.seed = a.seed;
    s.ground_z = 0.0;
    s.sensing = sim::load_sensing(a.sensing);
    if (!s.sensing.depth_camera.enabled && !s.sensing.lidar.enabled)
      throw std::runtime_error(a.sensing + ": sensing: names no sensor (depth_camera, lidar)");
    lcm::LCM in(a.lcm_url);
    std::unique_ptr<lcm::LCM> sensors = a.sensor_url.empty() ? nullptr : std::make_unique<lcm::LCM>(a.sensor_url);
    if (!in.good() || (sensors && !sensors->good())) throw std::runtime_error("LCM init failed");
    sim::SensorNode node(s, a.settings, &in, sensors ? sensors.get() : &in, nullptr);
    std::printf("{\"event\": \"ready\"}\n");
    std::fflush(stdout);
    node.run(&g_stop);
    if (!a.stats.empty()) {
      std::FILE* f = std::fopen(a.stats.c_str(), "w");
      if (f == nullptr) throw std::runtime_error("cannot write " + a.stats);
      node.write_stats(f);
      std::fclose(f);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mppid-sensors: %s\n", e.what());
    return 1;
  }
  return 0;
}
