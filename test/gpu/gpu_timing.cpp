// mppid-gpu-timing: time one full CUDA update (state and plan up, sample, roll out, weigh,
// update, plan down) with steady_clock around RolloutBackend::update(), and print JSON.
//   mppid-gpu-timing [--iters N] [--warmup N] [--no-grid] [--period-us P] CASE...   CASE = task:K[:T]
// --period-us P: one update every P us on an absolute grid (the daemon's 20,000 at 50 Hz), the
// GPU and this thread idle in between, instead of back to back: the tail an idle GPU adds.
// The forest tasks run with the obstacle grid the optimizer builds each cycle (Task::prepare
// from the plan), as in the daemon; --no-grid: every search scans all 32 cylinders.
// e.g. mppid-gpu-timing quadrotor_forest:16384 team9_forest:6000 team3_forest:1200
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <string>
#include <thread>
#include <vector>

#include "mppi/gpu/cuda_backend.hpp"
#include "scenarios.hpp"

namespace {

struct Result {
  std::string task;
  int k = 0, t = 0;
  double median_us = 0, p99_us = 0, mean_us = 0, min_us = 0, max_us = 0;
  float ess = 0, min_cost = 0;
  std::size_t device_bytes = 0;
};

template <class T>
Result time_case(const std::string& name, int k, int t, int iters, int warmup, bool grid, int period_us) {
  auto sc = mppi::gpu_test::make_scenario<T>(k, t);
  auto backend = mppi::make_cuda_backend<T>(sc.settings);
  auto plan = mppi::gpu_test::initial_plan(sc.settings);
  if (grid) mppi::gpu_test::prepare(sc, plan);  // the obstacle grid, as the optimizer builds it
  const auto plan0 = plan;
  mppi::UpdateStats stats;
  std::vector<double> us;
  us.reserve(static_cast<std::size_t>(iters));
  auto release = std::chrono::steady_clock::now();
  for (int n = 0; n < warmup + iters; ++n) {
    if (n % 50 == 0) plan = plan0;  // keep the problem stationary
    if (period_us > 0) {
      release += std::chrono::microseconds(period_us);
      std::this_thread::sleep_until(release);
    }
    const auto t0 = std::chrono::steady_clock::now();
    backend->update(sc.x0.data(), sc.params, static_cast<std::uint32_t>(n), plan.data(), &stats);
    const auto t1 = std::chrono::steady_clock::now();
    if (n >= warmup) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  std::sort(us.begin(), us.end());
  Result r;
  r.task = name;
  r.k = k;
  r.t = t;
  r.median_us = us[us.size() / 2];
  r.p99_us = us[std::min(us.size() - 1, static_cast<std::size_t>(0.99 * static_cast<double>(us.size())))];
  double sum = 0;
  for (double v : us) sum += v;
  r.mean_us = sum / static_cast<double>(us.size());
  r.min_us = us.front();
  r.max_us = us.back();
  r.ess = stats.ess;
  r.min_cost = stats.min_cost;
  r.device_bytes = backend->device_bytes();
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  int iters = 1000, warmup = 50, period_us = 0;
  bool grid = true;
  std::vector<std::string> cases;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--iters" && a + 1 < argc) iters = std::atoi(argv[++a]);
    else if (arg == "--warmup" && a + 1 < argc) warmup = std::atoi(argv[++a]);
    else if (arg == "--no-grid") grid = false;
    else if (arg == "--period-us" && a + 1 < argc) period_us = std::atoi(argv[++a]);
    else if (arg == "--help" || arg == "-h") {
      std::printf("usage: mppid-gpu-timing [--iters N] [--warmup N] [--no-grid] [--period-us P] task:K[:T]...\n");
      return 0;
    } else cases.push_back(arg);
  }
  if (cases.empty()) cases = {"quadrotor_forest:16384", "team9_forest:6000", "team3_forest:1200"};
  if (iters < 1) iters = 1;
  std::string why;
  if (!mppi::cuda_device_available(&why)) {
    std::fprintf(stderr, "mppid-gpu-timing: no CUDA device: %s\n", why.c_str());
    return 2;
  }
  const char* graph = std::getenv("MPPID_CUDA_GRAPH");
  // The kernel choices set from the environment (cuda_backend_impl.cuh), to label the run.
  std::string env;
  for (const char* k : {"MPPID_CUDA_KERNEL", "MPPID_CUDA_CHUNK", "MPPID_CUDA_WARPS", "MPPID_CUDA_NOISE", "MPPID_CUDA_LANES"})
    if (const char* v = std::getenv(k)) env += std::string(env.empty() ? "" : " ") + k + "=" + v;
  char date[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  std::printf("{\n  \"device\": \"%s\",\n  \"date\": \"%s\",\n  \"cuda_graph\": %s,\n  \"iterations\": %d,\n"
              "  \"warmup\": %d,\n  \"period_us\": %d,\n  \"obstacles\": 32,\n  \"obstacle_grid\": %s,\n  \"env\": \"%s\",\n  \"results\": [",
              mppi::cuda_device_name().c_str(), date, graph != nullptr && std::string(graph) == "0" ? "false" : "true",
              iters, warmup, period_us, grid ? "true" : "false", env.c_str());
  bool first = true;
  int status = 0;
  for (const auto& c : cases) {
    const auto p1 = c.find(':');
    const std::string name = c.substr(0, p1);
    const auto p2 = p1 == std::string::npos ? std::string::npos : c.find(':', p1 + 1);
    const int k = p1 == std::string::npos ? 1024 : std::atoi(c.substr(p1 + 1, p2 - p1 - 1).c_str());
    const int t = p2 == std::string::npos ? 100 : std::atoi(c.substr(p2 + 1).c_str());
    Result r;
    try {
      const bool known = mppi::visit_task(name, [&](auto tag) {
        using T = typename decltype(tag)::type;
        r = time_case<T>(name, k, t, iters, warmup, grid, period_us);
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
