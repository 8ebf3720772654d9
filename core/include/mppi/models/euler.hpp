// One explicit Euler step of a model from its derivative: every model's step(), the
// integrator of the rollouts (the plants integrate with RK4, mppi/rk4.hpp).
#pragma once

#include "mppi/hd.hpp"

namespace mppi {

template <class Model, class V>
MPPI_HD void euler_step(const typename Model::Params& p, V* x, const V* u, float dt) {
  V dx[Model::kNx];
  Model::derivative(p, x, u, dx);
  for (int i = 0; i < Model::kNx; ++i) x[i] += dt * dx[i];
}

}  // namespace mppi
