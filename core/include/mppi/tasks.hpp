// The named tasks mppid can run, and a visitor that turns a name into its type, so every
// program (daemon, bench, offline runner, tests) instantiates tasks from one list.
#pragma once

#include <string>
#include <type_traits>
#include <vector>

#include "mppi/costs/ellipse.hpp"
#include "mppi/costs/forest.hpp"
#include "mppi/costs/swingup.hpp"
#include "mppi/costs/tracking.hpp"
#include "mppi/models/cartpole.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"
#include "mppi/models/racecar.hpp"
#include "mppi/task.hpp"

namespace mppi {

using CartpoleSwingup = Task<Cartpole, SwingupCost>;
using RacecarEllipse = Task<Racecar, EllipseCost>;
using QuadrotorForest = Task<Quadrotor, ForestCost<Quadrotor>>;
using QuadrotorTrack = Task<Quadrotor, TrackingCost<Quadrotor>>;
using RateQuadrotorForest = Task<QuadrotorRate, ForestCost<QuadrotorRate>>;
using RateQuadrotorTrack = Task<QuadrotorRate, TrackingCost<QuadrotorRate>>;
using Team3Forest = Task<Quadrotor, ForestCost<Quadrotor>, 3>;
using Team9Forest = Task<Quadrotor, ForestCost<Quadrotor>, 9>;

// One of the named tasks above (the CPU backend has SIMD kernels for exactly these; the
// list in core/CMakeLists.txt matches it).
template <class T>
constexpr bool kNamedTask =
    std::is_same_v<T, CartpoleSwingup> || std::is_same_v<T, RacecarEllipse> || std::is_same_v<T, QuadrotorForest> ||
    std::is_same_v<T, QuadrotorTrack> || std::is_same_v<T, RateQuadrotorForest> ||
    std::is_same_v<T, RateQuadrotorTrack> || std::is_same_v<T, Team3Forest> || std::is_same_v<T, Team9Forest>;

template <class T>
struct TaskTag {
  using type = T;
};

// Calls f(TaskTag<T>{}) for the task named `name`; false if there is none.
template <class F>
bool visit_task(const std::string& name, F&& f) {
  if (name == "cartpole_swingup") return f(TaskTag<CartpoleSwingup>{}), true;
  if (name == "racecar_ellipse") return f(TaskTag<RacecarEllipse>{}), true;
  if (name == "quadrotor_forest") return f(TaskTag<QuadrotorForest>{}), true;
  if (name == "quadrotor_track") return f(TaskTag<QuadrotorTrack>{}), true;
  if (name == "quadrotor_rate_forest") return f(TaskTag<RateQuadrotorForest>{}), true;
  if (name == "quadrotor_rate_track") return f(TaskTag<RateQuadrotorTrack>{}), true;
  if (name == "team3_forest") return f(TaskTag<Team3Forest>{}), true;
  if (name == "team9_forest") return f(TaskTag<Team9Forest>{}), true;
  return false;
}

inline std::vector<std::string> task_names() {
  return {"cartpole_swingup", "racecar_ellipse", "quadrotor_forest", "quadrotor_track",
          "quadrotor_rate_forest", "quadrotor_rate_track", "team3_forest", "team9_forest"};
}

}  // namespace mppi
