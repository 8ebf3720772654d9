// Realistic settings, parameters and states for every task, shared by the CPU-GPU parity
// tests and the timing tool: the quadrotor near hover with a forest of 32 obstacles and
// the goal ahead, the cart-pole at rest, the race car at 5 m/s on the ellipse, the teams
// spread apart.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "mppi/costs/field_of_cylinders.hpp"
#include "mppi/gpu/cuda_settings.hpp"
#include "mppi/settings.hpp"
#include "mppi/tasks.hpp"

namespace mppi::gpu_test {

template <class T>
struct Scenario {
  MppiSettings settings;
  CudaSettings cuda;  // mppi.cuda: the launch choices (default: the backend's own)
  typename T::Params params{};
  std::vector<float> x0;
};

// A fixed pseudo-random forest: n cylinders in x in [3, 30] m, |y| <= 8 m, radius 0.3 to
// 0.5 m: the nearest starts 2.5 m ahead of a vehicle starting at x = 0.
inline ObstacleSet forest(int n, std::uint32_t seed = 7u) {
  ObstacleSet set;
  std::uint32_t s = seed;
  auto next = [&s] {
    s = s * 1664525u + 1013904223u;
    return static_cast<float>(s >> 8) / 16777216.0f;
  };
  while (set.count < n && set.count < ObstacleSet::kCapacity) {
    Cylinder c;
    c.x = 3.0f + 27.0f * next();
    c.y = -8.0f + 16.0f * next();
    c.radius = 0.3f + 0.2f * next();
    set.items[set.count++] = c;
  }
  return set;
}

inline void quad_mppi(MppiSettings& s, int vehicles, float hover) {
  const int nu = 4 * vehicles;
  // Exploration small enough that a 2 s open-loop rollout rarely flips the vehicle (a
  // flipped rollout is chaotic: ulp-level differences of sinf/expf grow without bound).
  s.lambda = 500.0f;
  s.nu = 1.0f;
  s.sigma.assign(nu, 20.0f);
  s.u_min.assign(nu, 0.0f);
  s.u_max.assign(nu, 6000.0f);
  s.u_init.assign(nu, hover);
  s.u_nominal.assign(nu, hover);
}

template <class T>
Scenario<T> make_scenario(int k, int t);

// K rollouts of T steps; the rest as each scenario sets it.
template <class T>
inline Scenario<T> sized(int k, int t) {
  Scenario<T> sc;
  sc.settings.rollouts = k;
  sc.settings.horizon = t;
  return sc;
}

// The forest scene: the goal 20 m ahead at 2 m height among 32 trees.
template <class Cost>
inline void forest_scene(Cost& cost) {
  cost.goal[0][0] = 20.0f;
  cost.goal[0][2] = 2.0f;
  cost.obstacles = forest(32);
}

// A reference curve at 2 m height, flown at 2 m/s.
inline void track_scene(Reference& r, Reference::Kind kind, float radius) {
  r.kind = kind;
  r.center[2] = 2.0f;
  r.radius = radius;
  r.speed = 2.0f;
}

// One motor-speed quadrotor: K rollouts of T steps, at rest with its motors at hover speed.
template <class T>
inline Scenario<T> quad_scenario(int k, int t) {
  auto sc = sized<T>(k, t);
  const float hover = Quadrotor::hover_speed(Quadrotor::Params{});
  quad_mppi(sc.settings, 1, hover);
  sc.x0.assign(Quadrotor::kNx, 0.0f);
  for (int i = 0; i < 4; ++i) sc.x0[Quadrotor::M1 + i] = hover;
  return sc;
}

template <>
inline Scenario<QuadrotorForest> make_scenario<QuadrotorForest>(int k, int t) {
  auto sc = quad_scenario<QuadrotorForest>(k, t);
  forest_scene(sc.params.cost);
  sc.x0[Quadrotor::PZ] = 2.0f;
  sc.x0[Quadrotor::VX] = 1.0f;
  return sc;
}

template <>
inline Scenario<QuadrotorTrack> make_scenario<QuadrotorTrack>(int k, int t) {
  auto sc = quad_scenario<QuadrotorTrack>(k, t);
  track_scene(sc.params.cost.reference, Reference::kCircle, 2.0f);
  sc.x0[Quadrotor::PX] = 2.0f;
  sc.x0[Quadrotor::PZ] = 2.0f;
  return sc;
}

inline void rate_mppi(MppiSettings& s) {
  const float hover = QuadrotorRate::hover_thrust(QuadrotorRate::Params{});
  s.lambda = 1000.0f;
  s.nu = 1.0f;
  s.sigma = {1.0f, 0.5f, 0.5f, 0.5f};
  s.u_min = {0.0f, -6.0f, -6.0f, -3.0f};
  s.u_max = {25.0f, 6.0f, 6.0f, 3.0f};
  s.u_init = {hover, 0.0f, 0.0f, 0.0f};
  s.u_nominal = s.u_init;
}

inline std::vector<float> rate_hover(float x, float z) {
  std::vector<float> s(QuadrotorRate::kNx, 0.0f);
  s[QuadrotorRate::PX] = x;
  s[QuadrotorRate::PZ] = z;
  s[QuadrotorRate::VX] = 1.0f;
  s[QuadrotorRate::QW] = 1.0f;
  return s;
}

// One rate-controlled quadrotor: K rollouts of T steps, at 2 m height moving at 1 m/s along x.
template <class T>
inline Scenario<T> rate_scenario(int k, int t) {
  auto sc = sized<T>(k, t);
  rate_mppi(sc.settings);
  sc.x0 = rate_hover(0.0f, 2.0f);
  return sc;
}

template <>
inline Scenario<RateQuadrotorForest> make_scenario<RateQuadrotorForest>(int k, int t) {
  auto sc = rate_scenario<RateQuadrotorForest>(k, t);
  forest_scene(sc.params.cost);
  return sc;
}

template <>
inline Scenario<RateQuadrotorTrack> make_scenario<RateQuadrotorTrack>(int k, int t) {
  auto sc = rate_scenario<RateQuadrotorTrack>(k, t);
  track_scene(sc.params.cost.reference, Reference::kFigureEight, 3.0f);
  return sc;
}

template <>
inline Scenario<CartpoleSwingup> make_scenario<CartpoleSwingup>(int k, int t) {
  auto sc = sized<CartpoleSwingup>(k, t);
  auto& s = sc.settings;
  s.dt = 0.01f;  // 1 s horizon at T = 100
  s.lambda = 2000.0f;
  s.nu = 10.0f;
  s.sigma = {5.0f};
  s.u_min = {-30.0f};
  s.u_max = {30.0f};
  s.u_init = {0.0f};
  sc.x0.assign(Cartpole::kNx, 0.0f);  // at rest, pole down
  return sc;
}

template <>
inline Scenario<RacecarEllipse> make_scenario<RacecarEllipse>(int k, int t) {
  auto sc = sized<RacecarEllipse>(k, t);
  auto& s = sc.settings;
  s.lambda = 300.0f;
  s.nu = 2.0f;
  s.sigma = {0.1f, 10.0f};
  s.u_min = {-0.5f, -40.0f};
  s.u_max = {0.5f, 40.0f};
  s.u_init = {0.0f, 0.0f};
  // On the ellipse at (13, 0), heading along it (+y, counter-clockwise), 5 m/s.
  sc.x0.assign(Racecar::kNx, 0.0f);
  sc.x0[Racecar::X] = 13.0f;
  sc.x0[Racecar::PSI] = 1.5707963f;
  sc.x0[Racecar::VX] = 5.0f;
  return sc;
}

template <class T>
Scenario<T> team_scenario(int k, int t) {
  constexpr int m = T::kVehicles;
  auto sc = sized<T>(k, t);
  const float hover = Quadrotor::hover_speed(Quadrotor::Params{});
  quad_mppi(sc.settings, m, hover);
  sc.params.cost.obstacles = forest(32);
  sc.x0.assign(T::kNx, 0.0f);
  // Spread apart on a grid of 3 m in y and 1 m in z.
  for (int j = 0; j < m; ++j) {
    const float y = 3.0f * static_cast<float>(j % 3 - 1);
    const float z = 1.5f + static_cast<float>(j / 3);
    float* x = sc.x0.data() + j * Quadrotor::kNx;
    x[Quadrotor::PY] = y;
    x[Quadrotor::PZ] = z;
    x[Quadrotor::VX] = 1.0f;
    for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = hover;
    sc.params.cost.goal[j][0] = 20.0f;
    sc.params.cost.goal[j][1] = y;
    sc.params.cost.goal[j][2] = z;
  }
  return sc;
}

template <>
inline Scenario<Team3Forest> make_scenario<Team3Forest>(int k, int t) { return team_scenario<Team3Forest>(k, t); }
template <>
inline Scenario<Team9Forest> make_scenario<Team9Forest>(int k, int t) { return team_scenario<Team9Forest>(k, t); }

// The plan every test starts from: u_init with a small, smooth wiggle in time, the same on
// every channel (for a quadrotor: collective thrust only, no torque), inside the limits.
inline std::vector<float> initial_plan(const MppiSettings& s) {
  const int nu = static_cast<int>(s.u_init.size());
  std::vector<float> plan(static_cast<std::size_t>(s.horizon) * nu);
  for (int i = 0; i < s.horizon; ++i)
    for (int j = 0; j < nu; ++j) {
      const float span = s.u_max[j] - s.u_min[j];
      const float v = s.u_init[j] + 0.005f * span * std::sin(0.1f * static_cast<float>(i));
      plan[static_cast<std::size_t>(i) * nu + j] = std::fmin(std::fmax(v, s.u_min[j]), s.u_max[j]);
    }
  return plan;
}

// Task::prepare as the optimizer runs it each cycle, from `plan`: for the forest tasks, the
// obstacle grid over the plan's noise-free path, which both backends then search (without
// it, every search scans every cylinder).
template <class T>
void prepare(Scenario<T>& sc, const std::vector<float>& plan) {
  std::vector<float> path(static_cast<std::size_t>(sc.settings.horizon + 1) * T::kVehicles * 2);
  T::prepare(sc.params, sc.x0.data(), plan.data(), sc.settings.horizon, sc.settings.dt, sc.settings.substeps,
             path.data());
}

// A sensed forest: the scenario's trees as a distance field (3 m tall, so rollouts that climb
// past 3 m fly over them; 0.2 m cells over x [-4, 32] m, |y| <= 12 m, z [0, 4.8] m: 180 x 120 x
// 24 cells, 1.0 MB), in *grid (which must outlive the scenario's use), stamped `stamp`. With
// cylinders_too the cylinders stay beside it (each is then both known and sensed); without,
// the cost knows only the field.
template <class T>
void add_field(Scenario<T>& sc, DistanceFieldGrid* grid, bool cylinders_too, std::uint64_t stamp = 1) {
  const float origin[3] = {-4.0f, -12.0f, 0.0f};
  fill_from_cylinders(sc.params.cost.obstacles, 3.0f, origin, 0.2f, 180, 120, 24, 6.0f, grid);
  sc.params.cost.field = grid->view(stamp);
  if (!cylinders_too) sc.params.cost.obstacles.count = 0;
}

}  // namespace mppi::gpu_test
