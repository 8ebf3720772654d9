// A flight scenario, loaded from a YAML file of config/scenarios/: the plant (model, number
// of vehicles, its own parameters), the world (start, goals, obstacles, forest generator),
// the reference, and the simulator's timing, delay, wind and noise. The seed turns the
// generators (forest, moving obstacles, wind, noise) into one fixed world.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace sim {

using Vec3 = std::array<double, 3>;

struct Obstacle {
  double x = 0.0, y = 0.0, radius = 0.0;
  double vx = 0.0, vy = 0.0;  // m/s; moving obstacles bounce inside the arena
  double height = 10.0;       // m above the ground: what the sensors see; collisions above it miss
};

struct ForestSpec {
  bool enabled = false;
  double spacing = 4.0;             // m, mean distance between neighbouring trees
  double jitter = 0.35;             // fraction of the spacing each tree moves off its grid point
  double radius = 0.3;              // m, mean trunk radius
  double radius_jitter = 0.1;       // m, +- uniform
  double x_min = 4.0, x_max = 36.0; // m, corridor along x
  double y_min = -8.0, y_max = 8.0; // m, corridor across
  double clear_radius = 2.5;        // m, kept free around the start and goal points
  double height = 10.0;             // m, every tree's (the sensors see their tops)
};

struct MovingSpec {
  int count = 0;
  double speed = 3.0;   // m/s, random direction
  double radius = 0.3;  // m
};

struct WindSpec {
  Vec3 mean{0.0, 0.0, 0.0};  // m/s
  double gust_std = 0.0;     // m/s, stationary std of each axis (Ornstein-Uhlenbeck)
  double gust_tau = 2.0;     // s, correlation time
};

struct NoiseSpec {
  // Standard deviations of the noise added to the published state (the truth is clean).
  double position = 0.0;  // m
  double velocity = 0.0;  // m/s
  double attitude = 0.0;  // rad (quaternion models: small-angle, renormalised)
  double rate = 0.0;      // rad/s
  double other = 0.0;     // any remaining state (motor speeds, cart-pole, car)
};

struct DepthCameraSpec {
  bool enabled = false;
  double hfov_deg = 87.0, vfov_deg = 58.0;  // RealSense D435 depth
  int width = 160, height = 120;            // the D435's 848 x 480 decimated
  double min_range = 0.2, max_range = 10.0; // m
  double rate_hz = 30.0;
  double noise = 0.002;     // 1/m: range error standard deviation = noise * range^2 (stereo)
  double dropout = 0.02;    // probability a pixel has no value (not sent)
  double latency = 0.03;    // s from capture to publish
  Vec3 offset{0.1, 0.0, 0.0};  // m, body frame
  double pitch_deg = 0.0;      // down-tilt of the optical axis
};

struct LidarSpec {
  bool enabled = false;
  int beams = 16;                           // a VLP-16 class unit
  double min_elevation_deg = -15.0, max_elevation_deg = 15.0;
  int azimuth_steps = 900;                  // per revolution (0.4 deg)
  double min_range = 0.3, max_range = 30.0; // m
  double rate_hz = 10.0;
  double noise = 0.03;                      // m, range standard deviation
  double latency = 0.0;                     // s
  Vec3 offset{0.0, 0.0, 0.1};
};

// Sensors on vehicle 0 (sim/sensors.hpp), published as point_cloud_t. With
// publish_obstacles false the trees exist only in the world: the controller gets no
// obstacles_t and knows only what a mapper makes of the sensors (docs/sensing.md).
struct SensingSpec {
  bool publish_obstacles = true;
  DepthCameraSpec depth_camera;
  LidarSpec lidar;
};

struct ReferenceSpec {
  std::string kind = "none";  // none | hold | waypoint | circle | figure_eight
  Vec3 center{0.0, 0.0, 2.0};
  double radius = 0.0;
  double speed = 0.0;
  double yaw = 0.0;
};

struct Scenario {
  std::string name;
  std::string task;       // controller config: config/tasks/<task>.yaml
  std::string model;      // quadrotor | quadrotor_rate | quadrotor_rate_body | cartpole | racecar
  int vehicles = 1;
  std::map<std::string, double> params;  // plant parameters by name (core's field tables)
  std::vector<double> initial_state;     // one vehicle's state; empty: model default
  double max_motor_speed = 8000.0;       // rpm, the plant's motor saturation (quadrotor)
  double max_thrust = 40.0;              // N, quadrotor_rate saturation
  double max_body_rate = 10.0;           // rad/s, quadrotor_rate saturation
  double rate_gain = 20.0;               // 1/s, quadrotor_rate_body: the autopilot's P rate loop
  // The rate-controlled plants: the thrust produced per newton commanded (motors or a thrust
  // map off by this factor, which the controller is not told; 1: as commanded).
  double thrust_gain = 1.0;

  // Timing.
  double physics_hz = 1000.0;
  double state_hz = 50.0;
  double actuation_delay = 0.0;     // s, command applied this long after it reaches the plant
  // Lock-step: what a command pays before it reaches the plant, counted from its state's
  // time: < 0 "measured" (the wall time from the state's publish to the command's receipt,
  // as in real time), else these seconds. --ideal charges nothing.
  double controller_latency = -1.0;
  double duration = 30.0;           // s of simulated time
  double lockstep_timeout = 5.0;    // s wall clock for one command
  double startup_timeout = 30.0;    // s wall clock for the first command
  double obstacles_hz = 10.0;       // obstacle and reference messages
  // > 0: with no command for this long (s, simulated time), the plant gets its failsafe
  // command (Plant::failsafe: level and hold altitude, or hover) until the next one, as an
  // autopilot's offboard-loss failsafe (COM_OF_LOSS_T) would; 0: the last command stays
  // applied (the default).
  double command_timeout = 0.0;
  int max_published_obstacles = 64; // nearest ones when there are more

  // World.
  Vec3 start{0.0, 0.0, 2.0};
  Vec3 goal{40.0, 0.0, 2.0};
  double team_spacing = 2.0;   // m across y between team members (start and goal)
  double goal_radius = 1.0;    // m
  bool stop_at_goal = true;
  bool stop_on_collision = true;
  double ground_z = 0.0;       // m; below is a ground collision (quadrotors)
  double vehicle_radius = 0.15;
  double arena_margin = 5.0;   // m around the corridor, where moving obstacles bounce
  double track_limit = 0.0;    // cart-pole: |x| beyond is a crash (0: none)
  double off_track = 0.0;      // race car: |ellipse residual| beyond is a crash (0: none)
  ForestSpec forest;
  MovingSpec moving;
  std::vector<Obstacle> fixed_obstacles;
  ReferenceSpec reference;
  WindSpec wind;
  NoiseSpec noise;
  SensingSpec sensing;

  std::uint64_t seed = 1;
  std::vector<Obstacle> obstacles;  // generated: fixed + forest + moving

  // Goal of vehicle v (team members are spread across y).
  Vec3 goal_of(int v) const;
  Vec3 start_of(int v) const;
};

// Loads and validates; throws std::runtime_error naming the file and the bad field.
Scenario load_scenario(const std::string& path, std::uint64_t seed);
// The same from YAML text (`label` names it in errors): what the fuzz target feeds.
Scenario load_scenario_text(const std::string& text, const std::string& label, std::uint64_t seed);

// The `sensing:` block of any YAML file (a scenario's, a mission's: config/missions), parsed
// and validated as a scenario's is; the file's other keys are not read.
SensingSpec load_sensing(const std::string& path);

// The forest and moving obstacles for this seed (deterministic).
void generate_obstacles(Scenario& s);

}  // namespace sim
