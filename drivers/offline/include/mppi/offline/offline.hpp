// Offline closed loop: a controller flies a scenario against the task's model integrated
// with RK4 at a finer step (the plant), with no transport and no clock. Used by the
// closed-loop tests and by mppid-offline.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "mppi/controller.hpp"

namespace mppi::offline {

struct Scenario {
  std::string name;
  float duration = 10.0f;           // s
  std::vector<float> x0;            // initial task state
  TaskInputs inputs;                // goals, reference; obstacles are refreshed each cycle
  std::vector<Cylinder> forest;     // every obstacle of the world
  int nearest_obstacles = 16;       // how many of the nearest the controller is told about
  int plant_substeps = 10;          // RK4 steps per control step
  float goal_tolerance = 1.0f;      // m
  float vehicle_radius = 0.15f;     // m, for the plant's collision check
};

struct Result {
  int nx = 0, nu = 0, vehicles = 1;
  std::vector<float> t;           // s, one entry per control cycle
  std::vector<float> x;           // state at t (nx per entry)
  std::vector<float> u;           // command applied from t (nu per entry)
  std::vector<float> ess;
  bool collided = false;
  float collision_time = -1.0f;
  bool reached = false;             // every vehicle within goal_tolerance of its goal
  float time_to_goal = -1.0f;
  float min_clearance = 1e9f;       // m, to any obstacle surface
  float tracking_rmse = -1.0f;      // m, tracking tasks
  float mean_speed = 0.0f;          // m/s over the run (distance / time)
  float max_angle_error_late = -1.0f;  // cart-pole: max |theta - pi| from 4 s to the end
  bool nonfinite = false;           // a non-finite command or state was seen
  bool success = false;             // the task's own bar (see fly())
};

// Flies `scenario` with `controller` (its own model parameters are the plant's unless
// `plant_params` overrides "model.NAME" values).
Result fly(Controller& controller, const Scenario& scenario,
           const std::vector<std::pair<std::string, double>>& plant_params = {});

// The paper's forests: one cylinder per `spacing` x `spacing` cell, jittered inside it,
// radius 0.3-0.5 m, clear of the start and goal areas. A seed names a forest.
std::vector<Cylinder> make_forest(float x_min, float x_max, float y_min, float y_max, float spacing,
                                  std::uint64_t seed, const std::vector<std::array<float, 2>>& keep_clear);

// Scenarios for the four systems of the paper (and tracking for both quadrotor models).
Scenario forest_scenario(const Controller& c, float spacing, std::uint64_t seed);
Scenario cartpole_scenario(const Controller& c);
Scenario ellipse_scenario(const Controller& c);
Scenario tracking_scenario(const Controller& c, int kind, float radius, float speed);

// Picks the scenario that goes with the controller's task.
Scenario default_scenario(const Controller& c, float spacing, std::uint64_t seed);

// The speed benchmarks' scene (mppid-bench, mppid-gpu-timing --scene bench): the default
// scenario, its forest widened (same 4 m spacing and seed) until it holds `scene_obstacles`
// cylinders, and the controller told about the `obstacles` nearest the start, nearest first
// (as the daemon sends them).
Scenario bench_scenario(const Controller& c, int obstacles, int scene_obstacles);

// JSON object with the result's scores.
std::string to_json(const Scenario& s, const Result& r);

}  // namespace mppi::offline
