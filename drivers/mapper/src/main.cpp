// mppid-mapper: sensor frames (point_cloud_t) in, the local distance field (local_map_t) out.
//   mppid-mapper [--config FILE] [--set key=value ...] [--lcm-url URL] [--sensor-lcm-url URL]
//                [--channel-prefix P]
//                [--stats FILE] [--sensed FILE]
#include <csignal>
#include <cstdio>
#include <exception>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mapper/node.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

int usage(const char* why) {
  if (why != nullptr) std::fprintf(stderr, "mppid-mapper: %s\n", why);
  std::fprintf(stderr,
               "usage: mppid-mapper [--config FILE] [--set key=value ...] [--lcm-url URL] [--sensor-lcm-url URL]\n"
               "                    [--channel-prefix P] [--stats FILE] [--sensed FILE]\n"
               "  --config   settings (config/mapper/mapper.yaml: map.resolution, map.size, rate_hz, ...)\n"
               "  --lcm-url  the maps go out on this bus (default: the settings' lcm_url, else LCM's default)\n"
               "  --sensor-lcm-url  the sensors' frames on this bus (default: the settings' sensor_lcm_url, else\n"
               "             the maps' bus)\n"
               "  --set      one setting, e.g. map.resolution=0.2, rate_hz=20, inputs=[MPPI_DEPTH]\n"
               "  --stats    on exit, write frames, maps and update timings (JSON) there\n"
               "  --sensed   append each map's newly occupied (x, y) columns there (JSON lines)\n");
  return 2;
}

struct Args {
  std::string config, url, sensor_url, prefix, stats, sensed;
  std::vector<std::string> sets;
};

// 0: parsed; else the exit status.
int parse(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "-h" || k == "--help") return usage(nullptr), 1;
    if (i + 1 >= argc) return usage(("missing value for " + k).c_str());
    const std::string v = argv[++i];
    if (k == "--config")
      a->config = v;
    else if (k == "--set")
      a->sets.push_back(v);
    else if (k == "--lcm-url")
      a->url = v;
    else if (k == "--sensor-lcm-url")
      a->sensor_url = v;
    else if (k == "--channel-prefix")
      a->prefix = v;
    else if (k == "--stats")
      a->stats = v;
    else if (k == "--sensed")
      a->sensed = v;
    else
      return usage(("unknown argument " + k).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  if (const int rc = parse(argc, argv, &args); rc != 0) return rc == 1 ? 0 : rc;
  try {
    mapper::NodeSettings s = mapper::load_settings(args.config, args.sets);
    for (auto& ch : s.inputs) ch = args.prefix + ch;
    s.output = args.prefix + s.output;
    const std::string url = args.url.empty() ? s.lcm_url : args.url;
    const std::string sensor_url = args.sensor_url.empty() ? s.sensor_lcm_url : args.sensor_url;
    lcm::LCM lcm(url);
    if (!lcm.good()) throw std::runtime_error("LCM init failed for url '" + url + "'");
    std::unique_ptr<lcm::LCM> sensor_bus;
    if (!sensor_url.empty() && sensor_url != url) {
      sensor_bus = std::make_unique<lcm::LCM>(sensor_url);
      if (!sensor_bus->good()) throw std::runtime_error("LCM init failed for url '" + sensor_url + "'");
    }
    mapper::MapperNode node(s, &lcm, sensor_bus ? sensor_bus.get() : &lcm);
    std::FILE* sensed = nullptr;
    if (!args.sensed.empty()) {
      sensed = std::fopen(args.sensed.c_str(), "w");
      if (sensed == nullptr) throw std::runtime_error("cannot write " + args.sensed);
      node.record_sensed(sensed);
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    std::fprintf(stderr, "mppid-mapper: %d x %d x %d cells of %g m -> %s at %g Hz\n", node.map().nx(), node.map().ny(),
                 node.map().nz(), node.map().resolution(), s.output.c_str(), s.rate_hz);
    node.run(&g_stop);
    if (sensed != nullptr) std::fclose(sensed);
    const std::string stats = node.stats_json();
    std::fprintf(stderr, "mppid-mapper: %s\n", stats.c_str());
    if (!args.stats.empty()) {
      std::FILE* f = std::fopen(args.stats.c_str(), "w");
      if (f == nullptr) throw std::runtime_error("cannot write " + args.stats);
      std::fprintf(f, "%s\n", stats.c_str());
      std::fclose(f);
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mppid-mapper: %s\n", e.what());
    return 1;
  }
}
