// Settings and states shared by the core tests: the 16-state quadrotor forest task around
// hover, the rate quadrotor's state, a team of three.
#pragma once

#include <initializer_list>
#include <utility>
#include <vector>

#include "mppi/costs/forest.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"
#include "mppi/settings.hpp"
#include "mppi/task.hpp"
#include "mppi/tasks.hpp"

namespace mppi::testing {

// K rollouts of T steps, noise sigma rpm on each motor (nu = 2), the control cost measured
// from hover and scaled by 0.01 as in config/tasks/quadrotor_forest.yaml.
inline MppiSettings quadrotor_settings(int k, int t, float lambda, float sigma, int threads = 0) {
  MppiSettings s;
  s.rollouts = k;
  s.horizon = t;
  s.lambda = lambda;
  s.nu = 2.0f;
  const float hover = Quadrotor::hover_speed(Quadrotor::Params{});
  s.sigma.assign(4, sigma);
  s.u_min.assign(4, 0.0f);
  s.u_max.assign(4, 6000.0f);
  s.u_init.assign(4, hover);
  s.u_nominal.assign(4, hover);
  s.control_cost_scale = 0.01f;
  s.threads = threads;
  return s;
}

// The same on 2 threads of one SIMD target (`simd`: "off", "avx2", ...), 30 steps, with a
// weighting: the optimizer tests run over every target this machine has.
inline MppiSettings quadrotor_simd_settings(const char* simd, int k, Weighting w = Weighting::kCostToGo) {
  MppiSettings s = quadrotor_settings(k, 30, 10.0f, 150.0f, 2);
  s.simd = simd;
  s.weighting = w;
  return s;
}

// A model's state: `base` (zero if none) with the named entries set, e.g.
// state_with<Racecar>({{Racecar::VX, 5.0f}, {Racecar::FX, 30.0f}}).
template <class Model>
std::vector<float> state_with(std::initializer_list<std::pair<int, float>> set, std::vector<float> base = {}) {
  if (base.empty()) base.assign(Model::kNx, 0.0f);
  for (const auto& [i, v] : set) base[static_cast<std::size_t>(i)] = v;
  return base;
}

// A model's state derivative at (x, u).
template <class Model>
std::vector<float> derivative_of(const typename Model::Params& p, const std::vector<float>& x,
                                 const std::vector<float>& u) {
  std::vector<float> dx(Model::kNx, 0.0f);
  Model::derivative(p, x.data(), u.data(), dx.data());
  return dx;
}

// The 16-state quadrotor at rest 2 m up, its motors at hover speed.
inline std::vector<float> quad_hover_state(const Quadrotor::Params& p) {
  std::vector<float> x(Quadrotor::kNx, 0.0f);
  x[Quadrotor::PZ] = 2.0f;
  for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = Quadrotor::hover_speed(p);
  return x;
}

// The rate quadrotor at rest 2 m up with attitude quaternion (qw, qx, qy, qz), as given.
inline std::vector<float> rate_state(float qw = 1, float qx = 0, float qy = 0, float qz = 0) {
  using QR = QuadrotorRate;
  std::vector<float> x(QR::kNx, 0.0f);
  x[QR::PZ] = 2.0f;
  x[QR::QW] = qw;
  x[QR::QX] = qx;
  x[QR::QY] = qy;
  x[QR::QZ] = qz;
  return x;
}

using QuadrotorTeam3 = Task<Quadrotor, ForestCost<Quadrotor>, 3>;

// The forest task's parameters with two trunks ahead, the goal 20 m on at 2 m up.
inline QuadrotorForest::Params forest_with_two_trunks() {
  QuadrotorForest::Params p{};
  p.cost.goal[0][0] = 20.0f;
  p.cost.goal[0][2] = 2.0f;
  p.cost.obstacles.count = 2;
  p.cost.obstacles.items[0] = Cylinder{4.0f, 0.5f, 0.5f, 0.0f, 0.0f};
  p.cost.obstacles.items[1] = Cylinder{7.0f, -1.0f, 0.4f, 0.0f, 0.0f};
  return p;
}

// The 16-state quadrotor z m up, flying 1 m/s forward, its motors at hover speed.
inline std::vector<float> cruising_state(float z = 2.0f) {
  std::vector<float> x = quad_hover_state(Quadrotor::Params{});
  x[Quadrotor::PZ] = z;
  x[Quadrotor::VX] = 1.0f;
  return x;
}

}  // namespace mppi::testing
