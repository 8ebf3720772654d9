// mppid-offline: fly one task's scenario in an offline closed loop (no transport, no clock)
// and write the score and the trajectory. The offline main job and a tuning tool.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "mppi/app/config.hpp"
#include "mppi/offline/offline.hpp"

namespace {

// score.json, obstacles.csv and trajectory.csv in folder `out`.
void write_files(const std::string& out, const std::string& json, const mppi::offline::Scenario& scenario,
                 const mppi::offline::Result& result) {
  std::filesystem::create_directories(out);
  std::ofstream(out + "/score.json") << json << "\n";
  std::ofstream obs(out + "/obstacles.csv");
  obs << "x,y,radius\n";
  for (const auto& c : scenario.forest) obs << c.x << "," << c.y << "," << c.radius << "\n";
  std::ofstream tr(out + "/trajectory.csv");
  tr << "t";
  for (int i = 0; i < result.nx; ++i) tr << ",x" << i;
  for (int i = 0; i < result.nu; ++i) tr << ",u" << i;
  tr << ",ess\n";
  for (std::size_t n = 0; n < result.t.size(); ++n) {
    tr << result.t[n];
    for (int i = 0; i < result.nx; ++i) tr << "," << result.x[n * result.nx + i];
    for (int i = 0; i < result.nu; ++i) tr << "," << result.u[n * result.nu + i];
    tr << "," << result.ess[n] << "\n";
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Fly an mppid task offline against its model integrated with RK4"};
  std::string task = "quadrotor_forest", config, out, backend;
  std::vector<std::string> sets, plant;
  std::uint64_t seed = 1;
  float spacing = 4.0f, duration = 0.0f;
  int threads = -1;
  app.add_option("--task", task, "task name (its settings: config/tasks/TASK.yaml)");
  app.add_option("--config", config, "settings file (default: the task's)");
  app.add_option("--set", sets, "override a setting, e.g. --set mppi.rollouts=512");
  app.add_option("--plant", plant, "plant parameter differing from the model, e.g. --plant model.mass=0.3");
  app.add_option("--seed", seed, "forest seed");
  app.add_option("--spacing", spacing, "forest mean spacing, m")->check(CLI::Range(1.0f, 20.0f));
  app.add_option("--duration", duration, "override the scenario's duration, s");
  app.add_option("--backend", backend, "cpu | cuda | auto");
  app.add_option("--threads", threads, "CPU backend threads (0 = all)");
  app.add_option("--out", out, "folder for score.json, trajectory.csv, obstacles.csv");
  CLI11_PARSE(app, argc, argv);

  try {
    if (config.empty()) config = mppi::app::default_config_path(task);
    if (!backend.empty()) sets.push_back("backend=" + backend);
    if (threads >= 0) sets.push_back("mppi.threads=" + std::to_string(threads));
    const auto cfg = mppi::app::load_config(config, sets);
    auto controller = mppi::app::make_controller(cfg);
    auto scenario = mppi::offline::default_scenario(*controller, spacing, seed);
    if (duration > 0.0f) scenario.duration = duration;
    std::vector<std::pair<std::string, double>> plant_params;
    for (const auto& p : plant) {
      const auto eq = p.find('=');
      if (eq == std::string::npos) throw std::invalid_argument("--plant: expected model.NAME=value, got " + p);
      plant_params.emplace_back(p.substr(0, eq), std::stod(p.substr(eq + 1)));
    }
    const auto t0 = std::chrono::steady_clock::now();
    const auto result = mppi::offline::fly(*controller, scenario, plant_params);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::string json = mppi::offline::to_json(scenario, result);
    json.pop_back();
    json += ",\"task\":\"" + cfg.task + "\",\"backend\":\"" + controller->backend() + "\",\"rollouts\":" +
            std::to_string(cfg.mppi.rollouts) + ",\"horizon\":" + std::to_string(cfg.mppi.horizon) +
            ",\"seed\":" + std::to_string(seed) + ",\"wall_s\":" + std::to_string(wall) + "}";
    std::cout << json << std::endl;
    if (!out.empty()) write_files(out, json, scenario, result);
    return result.success ? 0 : 3;
  } catch (const mppi::app::ConfigError& e) {
    std::cerr << "mppid-offline: bad settings: " << e.what() << std::endl;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "mppid-offline: " << e.what() << std::endl;
    return 1;
  }
}
