// The named tasks as the SIMD and cross-machine plan tests set them up: settings and
// parameters from config/tasks/ (the file's noise seed), the start of the offline scenario of
// seed 1 and its 48 obstacles nearest the start (as the daemon sends them), a TaskController
// on a given backend.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"
#include "mppi/offline/offline.hpp"
#include "mppi/params.hpp"
#include "mppi/tasks.hpp"

namespace mppi::testing {

struct TaskSetup {
  app::AppConfig cfg;
  offline::Scenario scenario;
};

inline TaskSetup setup(const std::string& task, int rollouts, int horizon, int threads = 2) {
  TaskSetup s;
  s.cfg = app::load_config(app::default_config_path(task),
                           {"mppi.rollouts=" + std::to_string(rollouts), "mppi.horizon=" + std::to_string(horizon),
                            "mppi.threads=" + std::to_string(threads), "mppi.simd=off", "backend=cpu"});
  auto c = app::make_controller(s.cfg);
  s.scenario = offline::default_scenario(*c, 4.0f, 1);
  auto forest = s.scenario.forest;
  const float x0 = s.scenario.x0[0], y0 = s.scenario.x0[1];
  std::sort(forest.begin(), forest.end(), [&](const Cylinder& a, const Cylinder& b) {
    return std::hypot(a.x - x0, a.y - y0) - a.radius < std::hypot(b.x - x0, b.y - y0) - b.radius;
  });
  auto& obs = s.scenario.inputs.obstacles;
  obs.count = std::min<int>(48, static_cast<int>(forest.size()));
  for (int i = 0; i < obs.count; ++i) obs.items[i] = forest[static_cast<std::size_t>(i)];
  return s;
}

template <class T>
typename T::Params params_of(const TaskSetup& s) {
  typename T::Params p{};
  for (const auto& [key, value] : s.cfg.params) {
    const std::string error = set_task_param<T>(p, key, value);
    if (!error.empty()) throw std::invalid_argument(key + ": " + error);
  }
  return p;
}

template <class T>
std::unique_ptr<TaskController<T>> controller(const TaskSetup& s, std::unique_ptr<RolloutBackend<T>> backend) {
  auto c = std::make_unique<TaskController<T>>(s.cfg.task, s.cfg.mppi, params_of<T>(s), std::move(backend));
  c->set_inputs(s.scenario.inputs);
  return c;
}

// Named tasks, as types, with their names.
template <class T>
struct Named {
  using Task = T;
  const char* name;
};
template <class F>
void for_each_task(F&& f) {
  f(Named<CartpoleSwingup>{"cartpole_swingup"});
  f(Named<RacecarEllipse>{"racecar_ellipse"});
  f(Named<QuadrotorForest>{"quadrotor_forest"});
  f(Named<QuadrotorTrack>{"quadrotor_track"});
  f(Named<RateQuadrotorForest>{"quadrotor_rate_forest"});
  f(Named<RateQuadrotorTrack>{"quadrotor_rate_track"});
  f(Named<Team3Forest>{"team3_forest"});
  f(Named<Team9Forest>{"team9_forest"});
}

inline std::vector<std::string> task_names() {
  std::vector<std::string> names;
  for_each_task([&](auto named) { names.emplace_back(named.name); });
  return names;
}

}  // namespace mppi::testing
