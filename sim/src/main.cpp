// mppid-sim: the SITL simulator process.
//   mppid-sim --scenario FILE [--seed S] [--lockstep | --realtime] [--lcm-url URL] [--out DIR]
#include <optional>
#include <string>

#include "mppi/cli/program.hpp"
#include "sim/scenario.hpp"
#include "sim/simulator.hpp"

namespace {

constexpr const char* kName = "mppid-sim";

struct Args {
  std::string scenario, prefix, latency;
  unsigned long long seed = 1;
  double duration = -1.0;  // <= 0: the scenario's
  bool lockstep = false, realtime = false;
  sim::RunOptions run;
};

// --latency: the word measured, or seconds in [0, 10).
CLI::Validator latency_charge() {
  const CLI::Validator seconds = mppi::cli::in_half_open(0.0, 10.0);
  return CLI::Validator([seconds](std::string& v) { return v == "measured" ? std::string() : seconds(v); },
                        "measured|SECONDS");
}

void add_options(CLI::App& app, Args* a) {
  app.add_option("--scenario", a->scenario, "Scenario file (config/scenarios/*.yaml)")->required();
  app.add_option("--seed", a->seed, "Seed of the scenario's randomness (obstacles, noise, wind)")->capture_default_str();
  auto* lockstep = app.add_flag("--lockstep", a->lockstep,
                                "Wait for the command answering each state (deterministic, fast); the command "
                                "acts after the controller's measured latency + the delay");
  app.add_flag("--realtime", a->realtime, "Pace the physics to the wall clock (the default)")->excludes(lockstep);
  auto* ideal = app.add_flag("--ideal", a->run.ideal, "Lock-step without the controller's latency (algorithm studies)");
  app.add_option("--latency", a->latency, "Lock-step latency charged: measured or fixed seconds in [0, 10) (default: the scenario's "
                 "timing.controller_latency, else measured)")
      ->check(latency_charge())
      ->excludes(ideal);
  app.add_option("--lcm-url", a->run.lcm_url, "LCM URL (default: LCM's)");
  app.add_option("--sensor-lcm-url", a->run.sensor_lcm_url,
                 "The sensors' frames (point_cloud_t) on this bus (default: --lcm-url's)");
  app.add_option("--out", a->run.out_dir, "Where world.json, truth.jsonl and sim_summary.json go")
      ->capture_default_str();
  app.add_option("--channel-prefix", a->prefix, "Prefix of every LCM channel (several flights on one bus)");
  app.add_option("--duration", a->duration, "Seconds simulated (default: the scenario's)");
  app.add_flag("--quiet", a->run.quiet, "No line on stderr at the end of the run");
  app.footer(
      "Exit status: 0 run completed (see sim_summary.json for its outcome), 1 error, 2 usage,\n"
      "3 controller stopped answering (lock-step), 4 interrupted.");
}

// What the options change in the run (the scenario's own values are changed in main()).
void finish_run_options(Args* a) {
  a->run.lockstep = a->lockstep;
  if (!a->latency.empty()) a->run.controller_latency = a->latency == "measured" ? -1.0 : std::stod(a->latency);
  if (!a->prefix.empty()) {
    auto& c = a->run.channels;
    for (std::string* ch : {&c.state, &c.command, &c.obstacles, &c.reference, &c.clock, &c.depth, &c.lidar})
      *ch = a->prefix + *ch;
  }
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  CLI::App app{"mppid-sim: the SITL simulator (plants, scenarios, lock-step clock, truth log)", kName};
  add_options(app, &a);
  if (const std::optional<int> rc = mppi::cli::parse(app, argc, argv)) return *rc;
  finish_run_options(&a);
  mppi::cli::stop_on_signals(sim::request_stop);
  return mppi::cli::run_reporting(kName, [&] {
    sim::Scenario s = sim::load_scenario(a.scenario, a.seed);
    if (a.duration > 0.0) s.duration = a.duration;
    if (a.run.controller_latency > -2.0) s.controller_latency = a.run.controller_latency;
    return sim::run_simulation(s, a.run);
  });
}
