// mppid-gpu-timing: time one full CUDA update (state and plan up, sample, roll out, weigh,
// update, plan down) with steady_clock around RolloutBackend::update(), and print JSON.
//   mppid-gpu-timing [--iters N] [--warmup N] [--no-grid] [--period-us P] [--scene test|bench]
//                    [--field none|both|only] [--map-every N] [--set mppi.cuda.FIELD=VALUE]... CASE...
//   CASE = task:K[:T]
// --set mppi.cuda.FIELD=VALUE: the backend's launch settings (mppi/gpu/cuda_settings.hpp, as a
// task file's `mppi.cuda` section: kernel, chunk_steps, warps, noise, controls, lanes, grid,
// pdl, graph), e.g. --set mppi.cuda.kernel=lanes --set mppi.cuda.grid=host.
// --period-us P: one update every P us on an absolute grid (the daemon's 20,000 at 50 Hz), the
// GPU and this thread idle in between, instead of back to back: the tail an idle GPU adds.
// --scene test (default): the parity tests' scenario (test/gpu/scenarios.hpp: 32 obstacles, the
// obstacle grid built from the plan); --no-grid: every search scans all 32 cylinders.
// --field both: the test scene's trees also as a distance field (scenarios.hpp add_field: 0.2 m
// cells, 180 x 120 x 24, 1.0 MB) beside the cylinders; only: the field without the cylinders
// (a sensed forest); --map-every N: a new map (a new stamp: the cells copied to the device
// again) every N updates, as a 10 Hz mapper gives a 50 Hz loop at N = 5 (default 0: one map).
// --scene bench: mppid-bench's (the task file's settings, the offline forest with the 32
// obstacles nearest the start, the plan after 20 cycles of the controller): the update alone
// where mppid-bench times the whole Controller::iterate, so the two can be compared.
// Forest tasks build the obstacle grid on the device, inside update() (mppi.cuda.grid=host:
// the host's grid, built once here, as the optimizer would).
// e.g. mppid-gpu-timing quadrotor_forest:16384 team9_forest:6000 team3_forest:1200
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"
#include "mppi/gpu/cuda_backend.hpp"
#include "mppi/offline/offline.hpp"
#include "scenarios.hpp"

namespace {

struct Result {
  std::string task;
  int k = 0, t = 0;
  double median_us = 0, p99_us = 0, mean_us = 0, min_us = 0, max_us = 0;
  float ess = 0, min_cost = 0;
  std::size_t device_bytes = 0;
};

// Updates of `backend` from x0 with params, the plan starting from plan0 (and put back every 50
// updates: the problem stays stationary).
template <class T>
Result time_updates(mppi::RolloutBackend<T>& backend, const float* x0, typename T::Params params,
                    const std::vector<float>& plan0, int iters, int warmup, int period_us, int map_every = 0) {
  std::vector<float> plan = plan0;
  mppi::UpdateStats stats;
  std::vector<double> us;
  us.reserve(static_cast<std::size_t>(iters));
  auto release = std::chrono::steady_clock::now();
  for (int n = 0; n < warmup + iters; ++n) {
    if (n % 50 == 0) plan = plan0;
    if constexpr (T::kUsesPath) {
      if (map_every > 0 && n % map_every == 0) ++params.cost.field.stamp;
    }
    if (period_us > 0) {
      release += std::chrono::microseconds(period_us);
      std::this_thread::sleep_until(release);
    }
    const auto t0 = std::chrono::steady_clock::now();
    backend.update(x0, params, static_cast<std::uint32_t>(n), plan.data(), &stats);
    const auto t1 = std::chrono::steady_clock::now();
    if (n >= warmup) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  std::sort(us.begin(), us.end());
  Result r;
  r.median_us = us[us.size() / 2];
  r.p99_us = us[std::min(us.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(us.size())))];
  double sum = 0;
  for (double v : us) sum += v;
  r.mean_us = sum / static_cast<double>(us.size());
  r.min_us = us.front();
  r.max_us = us.back();
  r.ess = stats.ess;
  r.min_cost = stats.min_cost;
  r.device_bytes = backend.device_bytes();
  return r;
}

// The parity tests' scenario.
template <class T>
Result time_test_scene(int k, int t, const mppi::CudaSettings& cuda, int iters, int warmup, bool grid, int period_us,
                       const std::string& field, int map_every) {
  auto sc = mppi::gpu_test::make_scenario<T>(k, t);
  auto backend = mppi::make_cuda_backend<T>(sc.settings, cuda);
  const auto plan = mppi::gpu_test::initial_plan(sc.settings);
  auto cells = std::make_unique<mppi::DistanceFieldGrid>();
  if constexpr (T::kUsesPath) {
    if (field != "none") mppi::gpu_test::add_field(sc, cells.get(), field == "both");
    if (grid) mppi::gpu_test::prepare(sc, plan);  // the host's obstacle grid (unless built on the device)
    else sc.params.cost.obstacle_reach = 0.0f;    // no grid on either side: every search scans the set
  }
  return time_updates<T>(*backend, sc.x0.data(), sc.params, plan, iters, warmup, period_us, map_every);
}

// mppid-bench's scene, through the controller mppid-bench times.
template <class T>
Result time_bench_scene(const std::string& task, int k, int t, const std::vector<std::string>& sets, int iters,
                        int warmup, int period_us) {
  std::vector<std::string> overrides = {"backend=cuda", "mppi.rollouts=" + std::to_string(k),
                                        "mppi.horizon=" + std::to_string(t)};
  overrides.insert(overrides.end(), sets.begin(), sets.end());
  const auto cfg = mppi::app::load_config(mppi::app::default_config_path(task), overrides);
  auto c = mppi::app::make_controller(cfg);
  auto* tc = dynamic_cast<mppi::TaskController<T>*>(c.get());
  if (tc == nullptr) throw std::runtime_error(task + ": not an MPPI controller");
  const auto scene = mppi::offline::bench_scenario(*c, 32, 32);
  c->set_inputs(scene.inputs);
  std::vector<float> u(static_cast<std::size_t>(c->nu()));
  for (int i = 0; i < 20; ++i) c->iterate(scene.x0.data(), u.data());
  auto& backend = tc->optimizer().backend();
  // The parameters as the optimizer hands them over: prepared on the host unless the backend
  // prepares them itself.
  const auto& params = backend.prepares_params() ? tc->params() : tc->optimizer().prepared_params();
  return time_updates<T>(backend, scene.x0.data(), params, tc->plan(), iters, warmup, period_us);
}

}  // namespace

namespace {

struct Options {
  int iters = 1000, warmup = 50, period_us = 0, map_every = 0;
  bool grid = true;
  std::string field = "none";
  std::string scene = "test";
  std::vector<std::string> sets;  // "mppi.cuda.FIELD=VALUE"
  YAML::Node cuda{YAML::NodeType::Map};  // the same as the mppi.cuda section
  std::vector<std::string> cases;
};

// The command line; 0 to go on, else the exit status.
int parse(int argc, char** argv, Options* o) {
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--iters" && a + 1 < argc) o->iters = std::atoi(argv[++a]);
    else if (arg == "--warmup" && a + 1 < argc) o->warmup = std::atoi(argv[++a]);
    else if (arg == "--no-grid") o->grid = false;
    else if (arg == "--period-us" && a + 1 < argc) o->period_us = std::atoi(argv[++a]);
    else if (arg == "--scene" && a + 1 < argc) o->scene = argv[++a];
    else if (arg == "--field" && a + 1 < argc) o->field = argv[++a];
    else if (arg == "--map-every" && a + 1 < argc) o->map_every = std::atoi(argv[++a]);
    else if (arg == "--set" && a + 1 < argc) o->sets.push_back(argv[++a]);
    else if (arg == "--help" || arg == "-h") {
      std::printf("usage: mppid-gpu-timing [--iters N] [--warmup N] [--no-grid] [--period-us P] [--scene test|bench] "
                  "[--field none|both|only] [--map-every N] [--set mppi.cuda.FIELD=VALUE]... task:K[:T]...\n");
      return -1;
    } else o->cases.push_back(arg);
  }
  if (o->cases.empty()) o->cases = {"quadrotor_forest:16384", "team9_forest:6000", "team3_forest:1200"};
  if (o->iters < 1) o->iters = 1;
  if (o->scene != "test" && o->scene != "bench") {
    std::fprintf(stderr, "mppid-gpu-timing: --scene: test or bench, got %s\n", o->scene.c_str());
    return 2;
  }
  if (o->field != "none" && o->field != "both" && o->field != "only") {
    std::fprintf(stderr, "mppid-gpu-timing: --field: none, both or only, got %s\n", o->field.c_str());
    return 2;
  }
  const std::string prefix = "mppi.cuda.";
  for (const auto& set : o->sets) {
    const auto eq = set.find('=');
    if (set.rfind(prefix, 0) != 0 || eq == std::string::npos || eq == prefix.size()) {
      std::fprintf(stderr, "mppid-gpu-timing: --set %s: expected mppi.cuda.FIELD=VALUE\n", set.c_str());
      return 2;
    }
    o->cuda[set.substr(prefix.size(), eq - prefix.size())] = YAML::Load(set.substr(eq + 1));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const int rc = parse(argc, argv, &o); rc != 0) return rc < 0 ? 0 : rc;
  std::string why;
  if (!mppi::cuda_device_available(&why)) {
    std::fprintf(stderr, "mppid-gpu-timing: no CUDA device: %s\n", why.c_str());
    return 2;
  }
  // The launch settings asked for (every task: the same fields), to label the run.
  mppi::CudaSettings asked;
  try {
    asked = mppi::app::read_cuda_settings(o.cuda, o.cases.empty() ? "" : o.cases.front().substr(0, o.cases.front().find(':')));
  } catch (const mppi::app::ConfigError& e) {
    std::fprintf(stderr, "mppid-gpu-timing: %s\n", e.what());
    return 2;
  }
  char date[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  std::printf("{\n  \"device\": \"%s\",\n  \"date\": \"%s\",\n  \"cuda_graph\": %s,\n  \"iterations\": %d,\n"
              "  \"warmup\": %d,\n  \"period_us\": %d,\n  \"scene\": \"%s\",\n  \"obstacles\": 32,\n  \"obstacle_grid\": %s,\n  \"field\": \"%s\",\n  \"map_every\": %d,\n  \"cuda\": \"%s\",\n  \"results\": [",
              mppi::cuda_device_name().c_str(), date, asked.graph ? "true" : "false", o.iters, o.warmup, o.period_us,
              o.scene.c_str(), o.grid ? "true" : "false", o.field.c_str(), o.map_every, mppi::describe(asked).c_str());
  bool first = true;
  int status = 0;
  for (const auto& c : o.cases) {
    const auto p1 = c.find(':');
    const std::string name = c.substr(0, p1);
    const auto p2 = p1 == std::string::npos ? std::string::npos : c.find(':', p1 + 1);
    const int k = p1 == std::string::npos ? 1024 : std::atoi(c.substr(p1 + 1, p2 - p1 - 1).c_str());
    const int t = p2 == std::string::npos ? 100 : std::atoi(c.substr(p2 + 1).c_str());
    Result r;
    try {
      const bool known = mppi::visit_task(name, [&](auto tag) {
        using T = typename decltype(tag)::type;
        r = o.scene == "bench"
                ? time_bench_scene<T>(name, k, t, o.sets, o.iters, o.warmup, o.period_us)
                : time_test_scene<T>(k, t, mppi::app::read_cuda_settings(o.cuda, name), o.iters, o.warmup, o.grid,
                                     o.period_us, o.field, o.map_every);
        r.task = name;
        r.k = k;
        r.t = t;
      });
      if (!known) throw std::runtime_error("unknown task " + name);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "mppid-gpu-timing: %s: %s\n", c.c_str(), e.what());
      status = 1;
      continue;
    }
    std::printf("%s\n    {\"task\": \"%s\", \"rollouts\": %d, \"horizon\": %d, \"median_us\": %.1f, \"p99_us\": %.1f, "
                "\"mean_us\": %.1f, \"min_us\": %.1f, \"max_us\": %.1f, \"ess\": %.1f, \"device_bytes\": %zu}",
                first ? "" : ",", r.task.c_str(), r.k, r.t, r.median_us, r.p99_us, r.mean_us, r.min_us, r.max_us,
                static_cast<double>(r.ess), r.device_bytes);
    std::fflush(stdout);
    first = false;
  }
  std::printf("\n  ]\n}\n");
  return status;
}
