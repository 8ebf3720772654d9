// Settings shared by the core tests: the 16-state quadrotor forest task around hover.
#pragma once

#include "mppi/models/quadrotor.hpp"
#include "mppi/settings.hpp"

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

}  // namespace mppi::testing
