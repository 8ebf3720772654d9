// mppid-mapper: sensor frames (point_cloud_t) in, the local distance field (local_map_t) out.
//   mppid-mapper [--config FILE] [--set key=value ...] [--lcm-url URL] [--sensor-lcm-url URL]
//                [--channel-prefix P] [--stats FILE] [--sensed FILE]
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "mapper/node.hpp"
#include "mppi/cli/program.hpp"

namespace {

constexpr const char* kName = "mppid-mapper";

struct Args {
  std::string config, url, sensor_url, prefix, stats, sensed;
  std::vector<std::string> sets;
};

void add_options(CLI::App& app, Args* a) {
  app.add_option("--config", a->config, "Settings (config/mapper/mapper.yaml: map.resolution, map.size, rate_hz, ...)");
  app.add_option("--set", a->sets, "One setting, e.g. map.resolution=0.2, rate_hz=20, inputs=[MPPI_DEPTH] (repeatable)")
      ->allow_extra_args(false);
  app.add_option("--lcm-url", a->url, "The maps go out on this bus (default: the settings' lcm_url, else LCM's default)");
  app.add_option("--sensor-lcm-url", a->sensor_url,
                 "The sensors' frames on this bus (default: the settings' sensor_lcm_url, else the maps' bus)");
  app.add_option("--channel-prefix", a->prefix, "Prefix of the input and output channels");
  app.add_option("--stats", a->stats, "On exit, write frames, maps and update timings (JSON) there");
  app.add_option("--sensed", a->sensed, "Append each map's newly occupied (x, y) columns there (JSON lines)");
}

// The sensors' bus when it is not the maps' (nullptr: the same bus).
std::unique_ptr<lcm::LCM> open_bus(const std::string& url, const std::string& maps_url) {
  if (url.empty() || url == maps_url) return nullptr;
  auto bus = std::make_unique<lcm::LCM>(url);
  if (!bus->good()) throw std::runtime_error("LCM init failed for url '" + url + "'");
  return bus;
}

void write_stats(const std::string& stats, const std::string& path) {
  std::fprintf(stderr, "%s: %s\n", kName, stats.c_str());
  if (path.empty()) return;
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw std::runtime_error("cannot write " + path);
  std::fprintf(f, "%s\n", stats.c_str());
  std::fclose(f);
}

int run(const Args& args) {
  mapper::NodeSettings s = mapper::load_settings(args.config, args.sets);
  for (auto& ch : s.inputs) ch = args.prefix + ch;
  s.output = args.prefix + s.output;
  const std::string url = args.url.empty() ? s.lcm_url : args.url;
  lcm::LCM lcm(url);
  if (!lcm.good()) throw std::runtime_error("LCM init failed for url '" + url + "'");
  const std::unique_ptr<lcm::LCM> sensor_bus = open_bus(args.sensor_url.empty() ? s.sensor_lcm_url : args.sensor_url, url);
  mapper::MapperNode node(s, &lcm, sensor_bus ? sensor_bus.get() : &lcm);
  std::FILE* sensed = nullptr;
  if (!args.sensed.empty()) {
    sensed = std::fopen(args.sensed.c_str(), "w");
    if (sensed == nullptr) throw std::runtime_error("cannot write " + args.sensed);
    node.record_sensed(sensed);
  }
  const volatile std::sig_atomic_t* stop = mppi::cli::stop_on_signals();
  std::fprintf(stderr, "%s: %d x %d x %d cells of %g m -> %s at %g Hz\n", kName, node.map().nx(), node.map().ny(),
               node.map().nz(), node.map().resolution(), s.output.c_str(), s.rate_hz);
  node.run(stop);
  if (sensed != nullptr) std::fclose(sensed);
  write_stats(node.stats_json(), args.stats);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  CLI::App app{"mppid-mapper: sensor frames (point_cloud_t) in, the local distance field (local_map_t) out", kName};
  add_options(app, &args);
  if (const std::optional<int> rc = mppi::cli::parse(app, argc, argv)) return *rc;
  return mppi::cli::run_reporting(kName, [&] { return run(args); });
}
