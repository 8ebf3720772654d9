// Google Benchmark per model, per cost and for the noise: the pieces one rollout step is
// made of, on the host. `build/bin/mppid-microbench --benchmark_format=json` for JSON.
#include <benchmark/benchmark.h>

#include <vector>

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

}  // namespace

BENCHMARK_MAIN();
