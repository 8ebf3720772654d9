// Google Benchmark per model, per cost and for the noise: the pieces one rollout step is
// made of, on the host; and BM_Rollouts/<task>/<target>: the CPU backend's rollouts of
// every task on one thread for each SIMD target this CPU runs and the scalar code,
// reported per sample-step (the counter per_sample_step, in seconds of CPU time; a team's
// sample-step steps every vehicle).
// `build/bin/mppid-microbench --benchmark_format=json` for JSON.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/costs/field_of_cylinders.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/offline/offline.hpp"
#include "mppi/params.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"
#include "mppi/tasks.hpp"

namespace {

using namespace mppi;

template <class Model>
std::vector<float> state_near_hover();

template <>
std::vector<float> state_near_hover<Quadrotor>() {
  std::vector<float> x(Quadrotor::kNx, 0.01f);
  x[Quadrotor::PZ] = 2.0f;
  for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = 3168.4f;
  return x;
}
template <>
std::vector<float> state_near_hover<QuadrotorRate>() {
  std::vector<float> x(QuadrotorRate::kNx, 0.01f);
  x[QuadrotorRate::QW] = 1.0f;
  return x;
}
template <>
std::vector<float> state_near_hover<Cartpole>() { return std::vector<float>(Cartpole::kNx, 0.1f); }
template <>
std::vector<float> state_near_hover<Racecar>() {
  std::vector<float> x(Racecar::kNx, 0.05f);
  x[Racecar::VX] = 5.0f;
  return x;
}

template <class Model>
void BM_ModelStep(benchmark::State& st) {
  const typename Model::Params p{};
  auto x = state_near_hover<Model>();
  std::vector<float> u(Model::kNu, 0.0f);
  if constexpr (std::is_same_v<Model, Quadrotor>) u.assign(4, 3168.4f);
  if constexpr (std::is_same_v<Model, QuadrotorRate>) u[0] = 9.81f;
  for (auto _ : st) {
    Model::step(p, x.data(), u.data(), 1e-4f);
    benchmark::DoNotOptimize(x.data());
  }
}
BENCHMARK(BM_ModelStep<Quadrotor>);
BENCHMARK(BM_ModelStep<QuadrotorRate>);
BENCHMARK(BM_ModelStep<Cartpole>);
BENCHMARK(BM_ModelStep<Racecar>);

// The forest cost of one vehicle against N obstacles.
void BM_ForestCost(benchmark::State& st) {
  ForestCost<Quadrotor>::Params p{};
  p.obstacles.count = static_cast<int>(st.range(0));
  for (int i = 0; i < p.obstacles.count; ++i)
    p.obstacles.items[i] = Cylinder{4.0f + static_cast<float>(i), static_cast<float>(i % 5) - 2.0f, 0.4f, 0.0f, 0.0f};
  auto x = state_near_hover<Quadrotor>();
  std::uint32_t crashed = 0;
  for (auto _ : st) {
    bool hit = false;
    benchmark::DoNotOptimize(ForestCost<Quadrotor>::vehicle(p, 0, x.data(), 0.5f, &hit));
    crashed |= hit;
  }
  benchmark::DoNotOptimize(crashed);
}
BENCHMARK(BM_ForestCost)->Arg(0)->Arg(16)->Arg(32)->Arg(64);

// The same vehicle with the local map (costs/distance_field.hpp): the trees of BM_ForestCost/32
// as the default map (0.2 m cells, 160 x 160 x 32 around the vehicle, 1.6 MB), alone (arg 0:
// a sensed forest) or beside the 32 cylinders (arg 32). Positions walk through the map so the
// corners come from memory, not from one cache line.
void BM_ForestCostField(benchmark::State& st) {
  ForestCost<Quadrotor>::Params p{};
  ObstacleSet trees;
  trees.count = 32;
  for (int i = 0; i < trees.count; ++i)
    trees.items[i] = Cylinder{4.0f + static_cast<float>(i), static_cast<float>(i % 5) - 2.0f, 0.4f, 0.0f, 0.0f};
  if (st.range(0) > 0) p.obstacles = trees;
  auto grid = std::make_unique<DistanceFieldGrid>();
  const float origin[3] = {-16.0f, -16.0f, 0.0f};
  fill_from_cylinders(trees, 8.0f, origin, 0.2f, 160, 160, 32, 6.0f, grid.get());
  p.field = grid->view(1);
  auto x = state_near_hover<Quadrotor>();
  std::uint32_t crashed = 0, i = 0;
  for (auto _ : st) {
    x[Quadrotor::PX] = -15.0f + 0.37f * static_cast<float>(i % 80);
    x[Quadrotor::PY] = -10.0f + 0.53f * static_cast<float>((i / 80) % 40);
    ++i;
    bool hit = false;
    benchmark::DoNotOptimize(ForestCost<Quadrotor>::vehicle(p, 0, x.data(), 0.5f, &hit));
    crashed |= hit;
  }
  benchmark::DoNotOptimize(crashed);
}
BENCHMARK(BM_ForestCostField)->Arg(0)->Arg(32);

void BM_TrackingCost(benchmark::State& st) {
  TrackingCost<QuadrotorRate>::Params p{};
  p.reference.kind = Reference::kCircle;
  p.reference.radius = 5.0f;
  p.reference.speed = 3.0f;
  auto x = state_near_hover<QuadrotorRate>();
  for (auto _ : st) {
    bool hit = false;
    benchmark::DoNotOptimize(TrackingCost<QuadrotorRate>::vehicle(p, 0, x.data(), 0.5f, &hit));
  }
}
BENCHMARK(BM_TrackingCost);

// Four standard normals from the counter-based stream (one Philox4x32-10 call, Box-Muller).
void BM_Noise4(benchmark::State& st) {
  const NoiseKey key{1, 2};
  float out[4];
  std::uint32_t k = 0;
  for (auto _ : st) {
    gaussian4(key, k++, 7, 0, out);
    benchmark::DoNotOptimize(out);
  }
}
BENCHMARK(BM_Noise4);

// One sample-step of the quadrotor forest task as the CPU backend runs it: perturb,
// advance, cost (16 obstacles), control cost.
void BM_QuadrotorForestSampleStep(benchmark::State& st) {
  using T = QuadrotorForest;
  T::Params p{};
  p.cost.goal[0][0] = 40.0f;
  p.cost.goal[0][2] = 2.0f;
  p.cost.obstacles.count = 16;
  for (int i = 0; i < 16; ++i)
    p.cost.obstacles.items[i] = Cylinder{4.0f + 2.0f * static_cast<float>(i), static_cast<float>(i % 5) - 2.0f, 0.4f, 0, 0};
  SamplerConstants<4> c{};
  for (int j = 0; j < 4; ++j) {
    c.noise_std[j] = 85.0f;
    c.r[j] = 0.003f;
    c.u_min[j] = 0.0f;
    c.u_max[j] = 6000.0f;
    c.u_nominal[j] = 3168.4f;
  }
  const float plan[4] = {3168.4f, 3168.4f, 3168.4f, 3168.4f};
  auto x = state_near_hover<Quadrotor>();
  const NoiseKey key{1, 2};
  std::uint32_t i = 0;
  for (auto _ : st) {
    float u[4], du[4];
    std::uint32_t crashed = 0;
    perturb<4>(c, key, 0, i++, plan, u, du);
    T::advance(p, x.data(), u, 0.02f, 1, crashed);
    float q = T::running(p, x.data(), 0.02f, &crashed) + control_cost<4>(c, plan, du);
    benchmark::DoNotOptimize(q);
    if (i % 64 == 0) x = state_near_hover<Quadrotor>();
  }
}
BENCHMARK(BM_QuadrotorForestSampleStep);

// The per-cycle obstacle culling (ObstacleGrid::build): N cylinders of the 4 m forest,
// widened as needed, the path of a plan flying 12 m along x, reach 8 m, 1 m cells.
void BM_ObstacleGridBuild(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  std::vector<Cylinder> forest;
  for (float e = 0.0f; static_cast<int>(forest.size()) < n; e += 4.0f)
    forest = offline::make_forest(4.0f, 36.0f + e, -12.0f - e, 12.0f + e, 4.0f, 1, {{0.0f, 0.0f}});
  std::sort(forest.begin(), forest.end(), [](const Cylinder& a, const Cylinder& b) {
    return std::hypot(a.x, a.y) - a.radius < std::hypot(b.x, b.y) - b.radius;
  });
  ObstacleSet set;
  set.count = n;
  for (int i = 0; i < n; ++i) set.items[i] = forest[static_cast<std::size_t>(i)];
  std::vector<float> path;
  for (int i = 0; i <= 100; ++i) {
    path.push_back(0.12f * static_cast<float>(i));
    path.push_back(0.0f);
  }
  auto grid = std::make_unique<ObstacleGrid>();
  for (auto _ : st) {
    grid->build(set, path.data(), 101, 2.0f, 8.0f, 1.0f);
    benchmark::DoNotOptimize(grid->first);
  }
  st.counters["cells"] = grid->nx * grid->ny;
  st.counters["listed"] = grid->listed;
  st.counters["refs_per_cell"] = static_cast<double>(grid->first[grid->nx * grid->ny]) / (grid->nx * grid->ny);
}
BENCHMARK(BM_ObstacleGridBuild)->Arg(48)->Arg(64)->Arg(200)->Arg(256)->Unit(benchmark::kMicrosecond);

// ---- The CPU backend's rollouts, per task and SIMD target ---------------------------------

// What the forest cost knows in BM_Rollouts: the cylinders (as flown today), the same trees
// only as the default local map (a sensed forest), or both.
enum class Known { kCylinders, kField, kBoth };

// K rollouts of T steps of a task from its settings file and offline scenario (forest tasks:
// the 48 obstacles nearest the start, culled from the plan's path as the optimizer does; with
// a field, those trees, 8 m tall, as the default map: 0.2 m cells, 160 x 160 x 32 around the start).
template <class T>
struct RolloutBench {
  static constexpr int K = 256, kHorizon = 100;
  typename T::Params params{};
  MppiSettings settings;
  SamplerConstants<T::kNu> sampler{};
  std::vector<float> x0, plan, cost, du, weights, path;
  std::vector<unsigned char> crashed;
  cpu::Batch<T> batch;
  std::unique_ptr<DistanceFieldGrid> field;

  explicit RolloutBench(const std::string& task, Known known = Known::kCylinders) {
    auto cfg = app::load_config(app::default_config_path(task),
                                {"mppi.rollouts=" + std::to_string(K), "mppi.horizon=" + std::to_string(kHorizon),
                                 "mppi.simd=off", "backend=cpu"});
    settings = cfg.mppi;
    for (const auto& [key, value] : cfg.params) set_task_param<T>(params, key, value);
    auto c = app::make_controller(cfg);
    auto sc = offline::default_scenario(*c, 4.0f, 1);
    auto forest = sc.forest;
    std::sort(forest.begin(), forest.end(), [&](const Cylinder& a, const Cylinder& b) {
      return std::hypot(a.x - sc.x0[0], a.y - sc.x0[1]) - a.radius < std::hypot(b.x - sc.x0[0], b.y - sc.x0[1]) - b.radius;
    });
    sc.inputs.obstacles.count = std::min<int>(48, static_cast<int>(forest.size()));
    for (int i = 0; i < sc.inputs.obstacles.count; ++i) sc.inputs.obstacles.items[i] = forest[static_cast<std::size_t>(i)];
    if constexpr (std::is_same_v<typename T::Cost, ForestCost<typename T::Vehicle>>) {
      for (int j = 0; j < T::kVehicles; ++j)
        for (int d = 0; d < 3; ++d) params.cost.goal[j][d] = sc.inputs.goals[j][d];
      params.cost.obstacles = sc.inputs.obstacles;
      if (known != Known::kCylinders) {
        field = std::make_unique<DistanceFieldGrid>();
        const float origin[3] = {sc.x0[0] - 16.0f, sc.x0[1] - 16.0f, 0.0f};
        fill_from_cylinders(sc.inputs.obstacles, 8.0f, origin, 0.2f, 160, 160, 32, 6.0f, field.get());
        params.cost.field = field->view(1);
        if (known == Known::kField) params.cost.obstacles.count = 0;
      }
    } else if constexpr (std::is_same_v<typename T::Cost, TrackingCost<typename T::Vehicle>>) {
      params.cost.reference = sc.inputs.reference;
    }
    x0 = sc.x0;
    plan.resize(static_cast<std::size_t>(kHorizon) * T::kNu);
    for (int i = 0; i < kHorizon; ++i)
      std::copy(settings.u_init.begin(), settings.u_init.end(), plan.begin() + i * T::kNu);
    path.resize(static_cast<std::size_t>(kHorizon + 1) * T::kVehicles * 2);
    T::prepare(params, x0.data(), plan.data(), kHorizon, settings.dt, settings.substeps, path.data());
    sampler = make_sampler_constants<T::kNu>(settings);
    cost.resize(static_cast<std::size_t>(kHorizon) * K);
    du.resize(static_cast<std::size_t>(kHorizon) * T::kNu * K);
    weights.resize(K);
    crashed.resize(K);
    batch.params = &params;
    batch.x0 = x0.data();
    batch.plan = plan.data();
    batch.sampler = &sampler;
    batch.key = NoiseKey{1, 0};
    batch.horizon = kHorizon;
    batch.stride = K;
    batch.dt = settings.dt;
    batch.substeps = settings.substeps;
    batch.inv_lambda = 1.0f / settings.lambda;
    batch.cost = cost.data();
    batch.du = du.data();
    batch.crashed = crashed.data();
    batch.weights = weights.data();
  }
};

template <class T>
void BM_Rollouts(benchmark::State& st, const std::string& task, simd::Target target, Known known) {
  RolloutBench<T> b(task, known);
  const cpu::KernelOps<T> ops =
      target == simd::Target::kScalar ? cpu::kernel_ops<T, cpu::ScalarLanes>() : *cpu::kernels_for<T>(target);
  std::uint32_t cycle = 0;
  for (auto _ : st) {
    b.batch.key.cycle = cycle++;
    ops.rollouts(b.batch, 0, RolloutBench<T>::K);
    benchmark::DoNotOptimize(b.cost.data());
  }
  // Seconds per sample-step (the console prints e.g. "10.3n", ns).
  st.counters["per_sample_step"] =
      benchmark::Counter(static_cast<double>(RolloutBench<T>::K) * RolloutBench<T>::kHorizon,
                         benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  st.SetLabel(std::string(simd::name(target)) + ", " + std::to_string(ops.lanes) + " lanes");
}

void register_rollouts() {
  std::vector<simd::Target> targets = {simd::Target::kScalar};
  for (simd::Target t : {simd::Target::kSse4, simd::Target::kAvx2, simd::Target::kAvx3, simd::Target::kNeon})
    if (simd::supported(t)) targets.push_back(t);
  for (const auto& name : task_names()) {
    visit_task(name, [&](auto tag) {
      using T = typename decltype(tag)::type;
      for (simd::Target t : targets)
        benchmark::RegisterBenchmark(("BM_Rollouts/" + name + "/" + simd::name(t)).c_str(), BM_Rollouts<T>, name, t,
                                     Known::kCylinders)
            ->Unit(benchmark::kMillisecond);
    });
  }
  // The forest with the local map: the sensed forest (the field alone) and both.
  for (simd::Target t : targets) {
    for (Known k : {Known::kField, Known::kBoth})
      benchmark::RegisterBenchmark(("BM_Rollouts/quadrotor_forest+" + std::string(k == Known::kField ? "field" : "field+cylinders") +
                                    "/" + simd::name(t)).c_str(),
                                   BM_Rollouts<QuadrotorForest>, "quadrotor_forest", t, k)
          ->Unit(benchmark::kMillisecond);
  }
}

}  // namespace

int main(int argc, char** argv) {
  register_rollouts();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
