// mppid-sim: the SITL simulator process.
//   mppid-sim --scenario FILE [--seed S] [--lockstep | --realtime] [--lcm-url URL] [--out DIR]
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>

#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace {

void on_signal(int) { sim::request_stop(); }

int usage(const char* why) {
  if (why != nullptr) std::fprintf(stderr, "mppid-sim: %s\n", why);
  std::fprintf(stderr,
               "usage: mppid-sim --scenario FILE [--seed S] [--lockstep | --realtime] [--lcm-url URL]\n"
               "                 [--out DIR] [--channel-prefix P] [--duration S] [--quiet]\n"
               "                 [--ideal | --latency measured|SECONDS] [--sensor-lcm-url URL]\n"
               "  --lockstep   wait for the command answering each state (deterministic, fast); the\n"
               "               command acts after the controller's measured latency + the delay\n"
               "  --ideal      lock-step without the controller's latency (algorithm studies)\n"
               "  --latency    lock-step latency charged: measured (default) or fixed seconds\n"
               "  --realtime   pace the physics to the wall clock (the default)\n"
               "  --out DIR    where world.json, truth.jsonl and sim_summary.json go (default .)\n"
               "  --sensor-lcm-url URL  the sensors' frames (point_cloud_t) on this bus (default: --lcm-url's)\n"
               "exit status: 0 run completed (see sim_summary.json for its outcome), 1 error,\n"
               "             2 usage, 3 controller stopped answering (lock-step), 4 interrupted\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenario_path, prefix;
  unsigned long long seed = 1;
  double duration = -1.0;
  bool lockstep = false, realtime = false;
  sim::RunOptions opt;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> const char* {
      if (i + 1 >= argc) return nullptr;
      return argv[++i];
    };
    if (a == "--scenario") {
      const char* v = value();
      if (v == nullptr) return usage("--scenario needs a file");
      scenario_path = v;
    } else if (a == "--seed") {
      const char* v = value();
      char* end = nullptr;
      if (v == nullptr) return usage("--seed needs a number");
      seed = std::strtoull(v, &end, 10);
      if (*end != '\0') return usage("--seed needs a number");
    } else if (a == "--lockstep") {
      lockstep = true;
    } else if (a == "--realtime") {
      realtime = true;
    } else if (a == "--lcm-url") {
      const char* v = value();
      if (v == nullptr) return usage("--lcm-url needs a URL");
      opt.lcm_url = v;
    } else if (a == "--sensor-lcm-url") {
      const char* v = value();
      if (v == nullptr) return usage("--sensor-lcm-url needs a URL");
      opt.sensor_lcm_url = v;
    } else if (a == "--out") {
      const char* v = value();
      if (v == nullptr) return usage("--out needs a directory");
      opt.out_dir = v;
    } else if (a == "--channel-prefix") {
      const char* v = value();
      if (v == nullptr) return usage("--channel-prefix needs a string");
      prefix = v;
    } else if (a == "--duration") {
      const char* v = value();
      if (v == nullptr) return usage("--duration needs seconds");
      duration = std::atof(v);
    } else if (a == "--ideal") {
      opt.ideal = true;
    } else if (a == "--latency") {
      const char* v = value();
      if (v == nullptr) return usage("--latency needs 'measured' or seconds");
      if (std::strcmp(v, "measured") == 0) {
        opt.controller_latency = -1.0;
      } else {
        char* end = nullptr;
        opt.controller_latency = std::strtod(v, &end);
        if (*end != '\0' || !(opt.controller_latency >= 0.0 && opt.controller_latency < 10.0))
          return usage("--latency needs 'measured' or seconds in [0, 10)");
      }
    } else if (a == "--quiet") {
      opt.quiet = true;
    } else if (a == "-h" || a == "--help") {
      usage(nullptr);
      return 0;
    } else {
      return usage(("unknown argument " + a).c_str());
    }
  }
  if (scenario_path.empty()) return usage("--scenario is required");
  if (lockstep && realtime) return usage("--lockstep and --realtime exclude each other");
  if (opt.ideal && opt.controller_latency > -2.0) return usage("--ideal and --latency exclude each other");
  opt.lockstep = lockstep;
  if (!prefix.empty()) {
    auto& c = opt.channels;
    for (std::string* ch : {&c.state, &c.command, &c.obstacles, &c.reference, &c.clock, &c.depth, &c.lidar}) *ch = prefix + *ch;
  }

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  try {
    sim::Scenario s = sim::load_scenario(scenario_path, seed);
    if (duration > 0.0) s.duration = duration;
    if (opt.controller_latency > -2.0) s.controller_latency = opt.controller_latency;
    return sim::run_simulation(s, opt);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mppid-sim: %s\n", e.what());
    return 1;
  }
}
