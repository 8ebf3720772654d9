// mppid-bench: the project's public speed figure. Times one full MPPI iteration as the
// controller sees it (state in, sample, roll out, weight, plan out) for each configuration
// and prints one JSON object per configuration: median and p99 in microseconds, the memory
// allocated at start-up, heap allocations per iteration, and the machine.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "alloc_counter.hpp"
#include "mppi/app/config.hpp"
#include "mppi/offline/offline.hpp"
#ifdef MPPID_HAVE_CUDA
#include "mppi/gpu/cuda_backend.hpp"
#endif

namespace {

std::string cpu_name() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

// The 1-minute load average (/proc/loadavg), to judge how quiet the machine was.
double load_average() {
  std::ifstream f("/proc/loadavg");
  double load = -1.0;
  f >> load;
  return load;
}

std::string task_for(const std::string& model) {
  if (model == "quadrotor") return "quadrotor_forest";
  if (model == "quadrotor_rate") return "quadrotor_rate_forest";
  if (model == "cartpole") return "cartpole_swingup";
  if (model == "racecar") return "racecar_ellipse";
  if (model == "team3") return "team3_forest";
  if (model == "team9") return "team9_forest";
  return model;  // a task name
}

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  return out;
}

std::vector<int> parse_list(const std::string& text) {
  std::vector<int> out;
  for (const auto& item : split(text)) out.push_back(std::stoi(item));
  return out;
}

// The rollout fan's cost (daemon.rollouts, tools/view), measured beside the plain cycle in
// one run: blocks of `every` cycles alternate between plain and fanned (the first cycle of a
// fanned block keeps its rollouts, then a fan of top + random is rebuilt), so both see the
// same machine. JSON fields: the cycle that keeps (its compute: the command's path), the
// rebuild (after the command, off its path), and the mean per cycle of each kind of block,
// in wall time and in the CPU time of the whole process (all its threads: with
// OMP_WAIT_POLICY=PASSIVE, as the daemon runs, that is the work done, which other load on the
// machine does not change the way it changes wall time).
struct FanCost {
  double plain_mean_us = 0, fanned_mean_us = 0, plain_median_us = 0, kept_median_us = 0, rebuild_median_us = 0;
  double plain_cpu_mean_us = 0, fanned_cpu_mean_us = 0, kept_cpu_median_us = 0, plain_cpu_median_us = 0;
  std::size_t allocations = 0;  // heap allocations over the timed cycles
};

double process_cpu_us() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e6 + static_cast<double>(ts.tv_nsec) * 1e-3;
}

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

FanCost measure_fan(mppi::Controller& c, const float* x0, int iterations, int every, int top, int random) {
  mppi::RolloutFan fan;
  fan.reserve(top + random, c.vehicles(), c.horizon());
  std::vector<float> u(static_cast<std::size_t>(c.nu()));
  std::vector<double> plain, kept, rebuild, plain_cpu, kept_cpu;
  double plain_sum = 0, fanned_sum = 0, plain_cpu_sum = 0, fanned_cpu_sum = 0;
  int plain_n = 0, fanned_n = 0;
  plain.reserve(static_cast<std::size_t>(iterations));
  kept.reserve(static_cast<std::size_t>(iterations));
  rebuild.reserve(static_cast<std::size_t>(iterations));
  plain_cpu.reserve(static_cast<std::size_t>(iterations));
  kept_cpu.reserve(static_cast<std::size_t>(iterations));
  const std::size_t count0 = mppi::testing::allocation_count();
  for (int i = 0; i < iterations; ++i) {
    const bool fanned_block = (i / every) % 2 == 1, first = i % every == 0;
    const double c0 = process_cpu_us();
    const auto t0 = std::chrono::steady_clock::now();
    if (fanned_block && first) c.keep_rollouts();
    c.iterate(x0, u.data());
    const auto t1 = std::chrono::steady_clock::now();
    const double c1 = process_cpu_us();
    if (fanned_block && first) c.fan(top, random, &fan);
    const auto t2 = std::chrono::steady_clock::now();
    const double c2 = process_cpu_us();
    const double cycle = std::chrono::duration<double, std::micro>(t1 - t0).count();
    const double total = std::chrono::duration<double, std::micro>(t2 - t0).count();
    if (fanned_block) {
      fanned_sum += total;
      fanned_cpu_sum += c2 - c0;
      ++fanned_n;
      if (first) {
        kept.push_back(cycle);
        kept_cpu.push_back(c1 - c0);
        rebuild.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
      }
    } else {
      plain_sum += total;
      plain_cpu_sum += c2 - c0;
      ++plain_n;
      plain.push_back(cycle);
      plain_cpu.push_back(c1 - c0);
    }
  }
  FanCost f;
  f.allocations = mppi::testing::allocation_count() - count0;
  f.plain_mean_us = plain_n > 0 ? plain_sum / plain_n : 0.0;
  f.fanned_mean_us = fanned_n > 0 ? fanned_sum / fanned_n : 0.0;
  f.plain_median_us = median_of(plain);
  f.kept_median_us = median_of(kept);
  f.rebuild_median_us = median_of(rebuild);
  f.plain_cpu_mean_us = plain_n > 0 ? plain_cpu_sum / plain_n : 0.0;
  f.fanned_cpu_mean_us = fanned_n > 0 ? fanned_cpu_sum / fanned_n : 0.0;
  f.plain_cpu_median_us = median_of(plain_cpu);
  f.kept_cpu_median_us = median_of(kept_cpu);
  return f;
}

std::string escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    o += c;
  }
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Time one full MPPI iteration (median, p99) for each configuration; prints JSON"};
  std::string model = "quadrotor", backend = "cpu", rollouts = "1024", threads = "2", config, simd = "auto",
              obstacles = "32";
  int horizon = 100, iterations = 1000, warmup = 20, fan_every = 0, fan_top = 16, fan_random = 16;
  bool json = false;
  app.add_option("--model", model, "quadrotor | quadrotor_rate | cartpole | racecar | team3 | team9 | a task name");
  app.add_option("--backend", backend, "cpu | cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--rollouts", rollouts, "K, or a comma list");
  app.add_option("--horizon", horizon, "T");
  app.add_option("--threads", threads, "CPU threads, or a comma list");
  app.add_option("--iterations", iterations, "timed iterations per configuration");
  app.add_option("--warmup", warmup, "untimed iterations first");
  app.add_option("--obstacles", obstacles,
                 "obstacles the controller is told about (forest tasks: the nearest of the scene), or a comma list; "
                 "the scene is the 4 m forest (48 cylinders), widened when a count exceeds it");
  app.add_option("--simd", simd,
                 "CPU backend's SIMD target: auto | off (one sample at a time) | sse4 | avx2 | avx3 | neon, or a "
                 "comma list (targets this CPU lacks are skipped with a note)");
  app.add_option("--config", config, "settings file (default: the task's)");
  app.add_option("--fan-every", fan_every,
                 "also time the rollout fan (tools/view): plain and fanned blocks of this many cycles alternate; "
                 "10 = the daemon's 5 Hz at 50 Hz (0: off)");
  app.add_option("--fan-top", fan_top, "the fan's lowest-cost rollouts");
  app.add_option("--fan-random", fan_random, "the fan's random others");
  app.add_flag("--json", json, "one JSON object per line (the default output; kept for scripts)");
  CLI11_PARSE(app, argc, argv);

  const std::string task = task_for(model);
  if (config.empty()) config = mppi::app::default_config_path(task);
  const auto ks = parse_list(rollouts);
  const auto ns = backend == "cpu" ? parse_list(threads) : std::vector<int>{0};
  const auto obstacle_counts = parse_list(obstacles);
  const int scene_obstacles = *std::max_element(obstacle_counts.begin(), obstacle_counts.end());
  const auto simds = backend == "cpu" ? split(simd) : std::vector<std::string>{"auto"};
  std::string gpu;
#ifdef MPPID_HAVE_CUDA
  if (backend == "cuda") gpu = mppi::cuda_device_name();
#endif
  int measured = 0;  // rows printed
  try {
    for (int k : ks) {
      for (int n : ns) {
       for (int obstacle_count : obstacle_counts) {
        for (const auto& target : simds) {
        std::vector<std::string> sets = {"backend=" + backend, "mppi.rollouts=" + std::to_string(k),
                                         "mppi.horizon=" + std::to_string(horizon),
                                         "mppi.threads=" + std::to_string(n), "mppi.simd=" + target};
        const auto cfg = mppi::app::load_config(config, sets);
        const std::size_t bytes0 = mppi::testing::allocated_bytes();
        std::unique_ptr<mppi::Controller> c;
        try {
          c = mppi::app::make_controller(cfg);
        } catch (const mppi::app::ConfigError& e) {
          std::cerr << "mppid-bench: skipping simd=" << target << ": " << e.what() << std::endl;
          continue;
        }
        const auto scenario = mppi::offline::bench_scenario(*c, obstacle_count, scene_obstacles);
        c->set_inputs(scenario.inputs);
        std::vector<float> u(static_cast<std::size_t>(c->nu()));
        std::vector<double> us(static_cast<std::size_t>(iterations));
        for (int i = 0; i < warmup; ++i) c->iterate(scenario.x0.data(), u.data());
        const std::size_t startup_bytes = mppi::testing::allocated_bytes() - bytes0;
        const std::size_t count0 = mppi::testing::allocation_count();
        for (int i = 0; i < iterations; ++i) {
          const auto t0 = std::chrono::steady_clock::now();
          c->iterate(scenario.x0.data(), u.data());
          us[i] = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
        }
        const double allocs = static_cast<double>(mppi::testing::allocation_count() - count0) / iterations;
        std::string fan_json;
        if (fan_every > 0) {
          const FanCost f = measure_fan(*c, scenario.x0.data(), iterations, fan_every, fan_top, fan_random);
          std::ostringstream o;
          o << ",\"fan\":{\"every\":" << fan_every << ",\"top\":" << fan_top << ",\"random\":" << fan_random
            << ",\"plain_median_us\":" << f.plain_median_us << ",\"kept_median_us\":" << f.kept_median_us
            << ",\"rebuild_median_us\":" << f.rebuild_median_us << ",\"plain_mean_us\":" << f.plain_mean_us
            << ",\"fanned_mean_us\":" << f.fanned_mean_us
            << ",\"kept_cycle_growth_pct\":" << 100.0 * (f.kept_median_us / f.plain_median_us - 1.0)
            << ",\"mean_growth_pct\":" << 100.0 * (f.fanned_mean_us / f.plain_mean_us - 1.0)
            << ",\"plain_cpu_median_us\":" << f.plain_cpu_median_us << ",\"kept_cpu_median_us\":" << f.kept_cpu_median_us
            << ",\"plain_cpu_mean_us\":" << f.plain_cpu_mean_us << ",\"fanned_cpu_mean_us\":" << f.fanned_cpu_mean_us
            << ",\"kept_cycle_cpu_growth_pct\":" << 100.0 * (f.kept_cpu_median_us / f.plain_cpu_median_us - 1.0)
            << ",\"mean_cpu_growth_pct\":" << 100.0 * (f.fanned_cpu_mean_us / f.plain_cpu_mean_us - 1.0)
            << ",\"allocations\":" << f.allocations << "}";
          fan_json = o.str();
        }
        std::sort(us.begin(), us.end());
        const double median = us[us.size() / 2];
        const double p99 = us[std::min(us.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(us.size())))];
        std::cout << "{\"task\":\"" << task << "\",\"backend\":\"" << c->backend() << "\",\"rollouts\":" << k
                  << ",\"horizon\":" << horizon << ",\"threads\":" << n << ",\"iterations\":" << iterations
                  << ",\"median_us\":" << median << ",\"p99_us\":" << p99 << ",\"min_us\":" << us.front()
                  << ",\"startup_host_bytes\":" << startup_bytes << ",\"device_bytes\":" << c->device_bytes()
                  << ",\"allocations_per_iteration\":" << allocs << ",\"obstacles\":" << scenario.inputs.obstacles.count
                  << ",\"weighting\":\"" << mppi::to_string(cfg.mppi.weighting) << "\""
                  << ",\"simd\":\"" << target << "\",\"forest_size\":" << scenario.forest.size() << fan_json
                  << ",\"machine\":{\"cpu\":\"" << escape(cpu_name()) << "\",\"cores\":" << std::thread::hardware_concurrency()
                  << ",\"gpu\":\"" << escape(gpu) << "\",\"load_average\":" << load_average() << "}}" << std::endl;
        ++measured;
        }
       }
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "mppid-bench: " << e.what() << std::endl;
    return 1;
  }
  // Every configuration skipped (a CUDA backend without a GPU, SIMD targets this CPU lacks):
  // no figure, so no success either.
  if (measured == 0) {
    std::cerr << "mppid-bench: nothing measured: every configuration was skipped (see above)" << std::endl;
    return 1;
  }
  return 0;
}
