#include "sim/scenario.hpp"

#include <cstdint>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <stdexcept>
#include <type_traits>
#include <variant>

#include "sim/rng.hpp"

namespace sim {
namespace {

struct Context {
  std::string file;
  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw std::runtime_error(file + ": " + where + ": " + what);
  }
};

// A map key's name; a list or map as a key is an error naming where it is.
std::string key_name(const Context& c, const YAML::Node& key, const std::string& where) {
  if (!key.IsScalar()) c.fail(where, "keys must be plain names (line " + std::to_string(key.Mark().line + 1) + ")");
  return key.Scalar();
}

// Every section lists the keys it knows, so a typo is an error, not a silent default.
void check_keys(const Context& c, const YAML::Node& n, const std::string& where,
                const std::set<std::string>& known) {
  if (!n) return;
  if (!n.IsMap()) c.fail(where, "expected a mapping");
  for (const auto& kv : n) {
    const auto key = key_name(c, kv.first, where);
    if (known.count(key) == 0) c.fail(where + "." + key, "unknown key");
  }
}

template <class T>
void read(const Context& c, const YAML::Node& n, const std::string& where, const char* key, T& out) {
  if (!n || !n[key]) return;
  try {
    out = n[key].as<T>();
  } catch (const YAML::Exception& e) {
    c.fail(where + "." + key, std::string("bad value: ") + e.what());
  }
}

void read_vec3(const Context& c, const YAML::Node& n, const std::string& where, const char* key, Vec3& out) {
  if (!n || !n[key]) return;
  std::vector<double> v;
  read(c, n, where, key, v);
  if (v.size() != 3) c.fail(where + "." + key, "expected 3 numbers");
  out = {v[0], v[1], v[2]};
}

constexpr double kMaxForestPoints = 20000;

void positive(const Context& c, double v, const std::string& where) {
  if (!(v > 0.0) || !std::isfinite(v)) c.fail(where, "must be > 0");
}

}  // namespace

Vec3 Scenario::goal_of(int v) const {
  const double off = (v - 0.5 * (vehicles - 1)) * team_spacing;
  return {goal[0], goal[1] + off, goal[2]};
}
Vec3 Scenario::start_of(int v) const {
  const double off = (v - 0.5 * (vehicles - 1)) * team_spacing;
  return {start[0], start[1] + off, start[2]};
}

namespace {
// A sensor's key and where its value goes: both sensor blocks are read by one parser.
struct SensorField {
  const char* key;
  std::variant<int*, double*, Vec3*> out;
};

// sensing.<name>: {enabled, fields...}; the section present turns the sensor on (enabled: false
// keeps it off). Every key not in `fields` is an error.
void parse_sensor(const Context& c, const YAML::Node& n, const std::string& w, bool& enabled,
                  std::initializer_list<SensorField> fields) {
  std::set<std::string> known{"enabled"};
  for (const auto& f : fields) known.insert(f.key);
  check_keys(c, n, w, known);
  if (!n) return;
  enabled = true;
  read(c, n, w, "enabled", enabled);
  for (const auto& f : fields) {
    std::visit(
        [&](auto* p) {
          if constexpr (std::is_same_v<decltype(p), Vec3*>)
            read_vec3(c, n, w, f.key, *p);
          else
            read(c, n, w, f.key, *p);
        },
        f.out);
  }
}

// The sensors' common bounds: ranges within 1000 m, a rate up to max_rate_hz.
void check_range_and_rate(const Context& c, const std::string& w, double min_range, double max_range,
                          double rate_hz, int max_rate_hz) {
  if (!(min_range >= 0.0 && max_range > min_range && max_range <= 1000.0))
    c.fail(w, "needs 0 <= min_range < max_range <= 1000");
  if (!(rate_hz > 0.0 && rate_hz <= max_rate_hz))
    c.fail(w + ".rate_hz", "must be in (0, " + std::to_string(max_rate_hz) + "]");
}

void parse_depth_camera(const Context& c, const YAML::Node& n, DepthCameraSpec& d) {
  const std::string w = "sensing.depth_camera";
  parse_sensor(c, n, w, d.enabled,
               {{"hfov_deg", &d.hfov_deg}, {"vfov_deg", &d.vfov_deg}, {"width", &d.width}, {"height", &d.height},
                {"min_range", &d.min_range}, {"max_range", &d.max_range}, {"rate_hz", &d.rate_hz},
                {"noise", &d.noise}, {"dropout", &d.dropout}, {"latency", &d.latency}, {"offset", &d.offset},
                {"pitch_deg", &d.pitch_deg}});
  if (!n) return;
  if (!(d.hfov_deg > 0.0 && d.hfov_deg < 170.0 && d.vfov_deg > 0.0 && d.vfov_deg < 170.0))
    c.fail(w, "hfov_deg and vfov_deg must be in (0, 170)");
  if (d.width < 1 || d.height < 1 || d.width * d.height > 1 << 20) c.fail(w, "width x height must be 1..1048576");
  check_range_and_rate(c, w, d.min_range, d.max_range, d.rate_hz, 500);
  if (!(d.noise >= 0.0 && d.dropout >= 0.0 && d.dropout < 1.0 && d.latency >= 0.0 && d.latency < 10.0))
    c.fail(w, "noise >= 0, dropout in [0, 1), latency in [0, 10) s");
}

void parse_lidar(const Context& c, const YAML::Node& n, LidarSpec& l) {
  const std::string w = "sensing.lidar";
  parse_sensor(c, n, w, l.enabled,
               {{"beams", &l.beams}, {"min_elevation_deg", &l.min_elevation_deg},
                {"max_elevation_deg", &l.max_elevation_deg}, {"azimuth_steps", &l.azimuth_steps},
                {"min_range", &l.min_range}, {"max_range", &l.max_range}, {"rate_hz", &l.rate_hz},
                {"noise", &l.noise}, {"latency", &l.latency}, {"offset", &l.offset}});
  if (!n) return;
  if (l.beams < 1 || l.beams > 256 || l.azimuth_steps < 1 || l.azimuth_steps > 8192)
    c.fail(w, "beams must be 1..256, azimuth_steps 1..8192");
  if (!(l.min_elevation_deg >= -90.0 && l.max_elevation_deg <= 90.0 && l.min_elevation_deg <= l.max_elevation_deg))
    c.fail(w, "elevations must be ordered, within +-90 deg");
  check_range_and_rate(c, w, l.min_range, l.max_range, l.rate_hz, 100);
  if (!(l.noise >= 0.0 && l.latency >= 0.0 && l.latency < 10.0)) c.fail(w, "noise >= 0, latency in [0, 10) s");
}

// sensing: {publish_obstacles, depth_camera: {...}, lidar: {...}}.
void parse_sensing(const Context& c, const YAML::Node& n, SensingSpec& s) {
  check_keys(c, n, "sensing", {"publish_obstacles", "depth_camera", "lidar"});
  if (!n) return;
  read(c, n, "sensing", "publish_obstacles", s.publish_obstacles);
  parse_depth_camera(c, n["depth_camera"], s.depth_camera);
  parse_lidar(c, n["lidar"], s.lidar);
}

Scenario parse_scenario(const Context& c, const YAML::Node& root, std::uint64_t seed);

// The YAML document `load` reads; a YAML error names `label`'s file.
template <class Load>
YAML::Node load_yaml(const Context& c, Load load) {
  try {
    return load();
  } catch (const YAML::Exception& e) {
    c.fail("file", e.what());
  }
}
}  // namespace

Scenario load_scenario(const std::string& path, std::uint64_t seed) {
  const Context c{path};
  return parse_scenario(c, load_yaml(c, [&] { return YAML::LoadFile(path); }), seed);
}

Scenario load_scenario_text(const std::string& text, const std::string& label, std::uint64_t seed) {
  const Context c{label};
  return parse_scenario(c, load_yaml(c, [&] { return YAML::Load(text); }), seed);
}

SensingSpec load_sensing(const std::string& path) {
  const Context c{path};
  const YAML::Node root = load_yaml(c, [&] { return YAML::LoadFile(path); });
  if (!root.IsMap()) c.fail("file", "expected a mapping");
  SensingSpec s;
  parse_sensing(c, root["sensing"], s);
  return s;
}

namespace {
// plant.params: model parameters by name, numbers.
void parse_plant_params(const Context& c, const YAML::Node& params, Scenario& s) {
  if (!params) return;
  if (!params.IsMap()) c.fail("plant.params", "expected a mapping");
  for (const auto& kv : params) {
    const auto key = key_name(c, kv.first, "plant.params");
    try {
      s.params[key] = kv.second.as<double>();
    } catch (const YAML::Exception&) {
      c.fail("plant.params." + key, "expected a number");
    }
  }
}

// A model the simulator has, and a team only of quadrotors.
void check_plant_model(const Context& c, const Scenario& s) {
  if (s.model != "quadrotor" && s.model != "quadrotor_rate" && s.model != "quadrotor_rate_body" &&
      s.model != "cartpole" && s.model != "racecar")
    c.fail("plant.model", "unknown model '" + s.model + "'");
  if (s.vehicles < 1 || s.vehicles > 32) c.fail("plant.vehicles", "must be 1..32");
  if ((s.model == "cartpole" || s.model == "racecar") && s.vehicles != 1)
    c.fail("plant.vehicles", "teams are quadrotors only");
}

void parse_plant(const Context& c, const YAML::Node& plant, Scenario& s) {
  if (!plant) c.fail("plant", "required");
  check_keys(c, plant, "plant",
             {"model", "vehicles", "params", "initial_state", "max_motor_speed", "max_thrust", "max_body_rate",
              "rate_gain", "thrust_gain"});
  read(c, plant, "plant", "model", s.model);
  read(c, plant, "plant", "vehicles", s.vehicles);
  read(c, plant, "plant", "initial_state", s.initial_state);
  read(c, plant, "plant", "max_motor_speed", s.max_motor_speed);
  read(c, plant, "plant", "max_thrust", s.max_thrust);
  read(c, plant, "plant", "max_body_rate", s.max_body_rate);
  read(c, plant, "plant", "rate_gain", s.rate_gain);
  if (!(s.rate_gain > 0.0)) c.fail("plant.rate_gain", "must be > 0");
  read(c, plant, "plant", "thrust_gain", s.thrust_gain);
  if (!(s.thrust_gain > 0.0 && s.thrust_gain <= 10.0)) c.fail("plant.thrust_gain", "must be in (0, 10]");
  parse_plant_params(c, plant["params"], s);
  check_plant_model(c, s);
}

void parse_timing(const Context& c, const YAML::Node& timing, Scenario& s) {
  check_keys(c, timing, "timing",
             {"physics_hz", "state_hz", "actuation_delay", "controller_latency", "duration", "lockstep_timeout",
              "startup_timeout", "obstacles_hz", "command_timeout"});
  read(c, timing, "timing", "physics_hz", s.physics_hz);
  read(c, timing, "timing", "state_hz", s.state_hz);
  read(c, timing, "timing", "actuation_delay", s.actuation_delay);
  if (timing && timing["controller_latency"]) {
    const auto n = timing["controller_latency"];
    if (n.IsScalar() && n.Scalar() == "measured") {
      s.controller_latency = -1.0;
    } else {
      read(c, timing, "timing", "controller_latency", s.controller_latency);
      if (!(s.controller_latency >= 0.0 && s.controller_latency < 10.0))
        c.fail("timing.controller_latency", "must be 'measured' or seconds in [0, 10)");
    }
  }
  read(c, timing, "timing", "duration", s.duration);
  read(c, timing, "timing", "lockstep_timeout", s.lockstep_timeout);
  read(c, timing, "timing", "startup_timeout", s.startup_timeout);
  read(c, timing, "timing", "obstacles_hz", s.obstacles_hz);
  read(c, timing, "timing", "command_timeout", s.command_timeout);
  if (s.physics_hz < 500.0) c.fail("timing.physics_hz", "must be >= 500");
  positive(c, s.state_hz, "timing.state_hz");
  positive(c, s.duration, "timing.duration");
  positive(c, s.lockstep_timeout, "timing.lockstep_timeout");
  positive(c, s.obstacles_hz, "timing.obstacles_hz");
  if (s.actuation_delay < 0.0) c.fail("timing.actuation_delay", "must be >= 0");
  if (!(s.command_timeout >= 0.0) || !std::isfinite(s.command_timeout))
    c.fail("timing.command_timeout", "must be >= 0 (0: off)");
  // The physics step must divide the state period, so every state falls on a step.
  const double ratio = s.physics_hz / s.state_hz;
  if (std::fabs(ratio - std::round(ratio)) > 1e-9)
    c.fail("timing.physics_hz", "must be a whole multiple of timing.state_hz");
}

// world.forest.x_range / y_range: [min, max], left as they are when absent.
void read_range(const Context& c, const YAML::Node& f, const char* key, double& lo, double& hi) {
  std::vector<double> r;
  read(c, f, "world.forest", key, r);
  if (r.empty()) return;
  if (r.size() != 2 || !(r[1] > r[0])) c.fail(std::string("world.forest.") + key, "expected [min, max]");
  lo = r[0];
  hi = r[1];
}

void parse_forest(const Context& c, const YAML::Node& f, ForestSpec& fs) {
  check_keys(c, f, "world.forest",
             {"spacing", "jitter", "radius", "radius_jitter", "x_range", "y_range", "clear_radius", "height"});
  fs.enabled = true;
  read(c, f, "world.forest", "spacing", fs.spacing);
  read(c, f, "world.forest", "jitter", fs.jitter);
  read(c, f, "world.forest", "radius", fs.radius);
  read(c, f, "world.forest", "radius_jitter", fs.radius_jitter);
  read(c, f, "world.forest", "clear_radius", fs.clear_radius);
  read(c, f, "world.forest", "height", fs.height);
  positive(c, fs.height, "world.forest.height");
  read_range(c, f, "x_range", fs.x_min, fs.x_max);
  read_range(c, f, "y_range", fs.y_min, fs.y_max);
  positive(c, fs.spacing, "world.forest.spacing");
  positive(c, fs.radius, "world.forest.radius");
  for (double v : {fs.jitter, fs.radius_jitter, fs.clear_radius, fs.x_min, fs.x_max, fs.y_min, fs.y_max})
    if (!std::isfinite(v)) c.fail("world.forest", "every value must be finite");
  // The generator visits every lattice point and checks each new tree against the others:
  // bound the work (a corridor of 1 km x 100 m at 3 m spacing is ~13,000 points).
  const double points =
      ((fs.x_max - fs.x_min) / fs.spacing + 1.0) * ((fs.y_max - fs.y_min) / (fs.spacing * 0.866) + 1.0);
  if (!(points <= kMaxForestPoints))
    c.fail("world.forest", "x_range, y_range and spacing make " + std::to_string(points) + " lattice points; at most " +
                               std::to_string(static_cast<long>(kMaxForestPoints)));
}

void parse_moving(const Context& c, const YAML::Node& m, MovingSpec& ms) {
  check_keys(c, m, "world.moving", {"count", "speed", "radius"});
  read(c, m, "world.moving", "count", ms.count);
  read(c, m, "world.moving", "speed", ms.speed);
  read(c, m, "world.moving", "radius", ms.radius);
  if (ms.count < 0 || ms.count > 1024) c.fail("world.moving.count", "must be 0..1024");
  if (!std::isfinite(ms.speed) || !std::isfinite(ms.radius)) c.fail("world.moving", "speed and radius must be finite");
}

void parse_fixed_obstacles(const Context& c, const YAML::Node& list, std::vector<Obstacle>& out) {
  for (const auto& o : list) {
    std::vector<double> v;
    try {
      v = o.as<std::vector<double>>();
    } catch (const YAML::Exception&) {
      c.fail("world.obstacles", "expected [x, y, radius] or [x, y, radius, vx, vy]");
    }
    if (v.size() != 3 && v.size() != 5) c.fail("world.obstacles", "expected [x, y, radius] or [x, y, radius, vx, vy]");
    Obstacle ob{v[0], v[1], v[2], 0.0, 0.0};
    if (v.size() == 5) {
      ob.vx = v[3];
      ob.vy = v[4];
    }
    out.push_back(ob);
  }
}

void parse_world(const Context& c, const YAML::Node& world, Scenario& s) {
  check_keys(c, world, "world",
             {"start", "goal", "team_spacing", "goal_radius", "stop_at_goal", "stop_on_collision", "ground_z",
              "vehicle_radius", "arena_margin", "track_limit", "off_track", "max_published_obstacles", "forest",
              "moving", "obstacles"});
  read_vec3(c, world, "world", "start", s.start);
  read_vec3(c, world, "world", "goal", s.goal);
  read(c, world, "world", "team_spacing", s.team_spacing);
  read(c, world, "world", "goal_radius", s.goal_radius);
  read(c, world, "world", "stop_at_goal", s.stop_at_goal);
  read(c, world, "world", "stop_on_collision", s.stop_on_collision);
  read(c, world, "world", "ground_z", s.ground_z);
  read(c, world, "world", "vehicle_radius", s.vehicle_radius);
  read(c, world, "world", "arena_margin", s.arena_margin);
  read(c, world, "world", "track_limit", s.track_limit);
  read(c, world, "world", "off_track", s.off_track);
  read(c, world, "world", "max_published_obstacles", s.max_published_obstacles);
  if (s.max_published_obstacles < 0 || s.max_published_obstacles > 4096)
    c.fail("world.max_published_obstacles", "must be 0..4096");
  if (!world) return;
  if (world["forest"]) parse_forest(c, world["forest"], s.forest);
  if (world["moving"]) parse_moving(c, world["moving"], s.moving);
  if (world["obstacles"]) parse_fixed_obstacles(c, world["obstacles"], s.fixed_obstacles);
}

void parse_reference(const Context& c, const YAML::Node& ref, ReferenceSpec& r) {
  check_keys(c, ref, "reference", {"kind", "center", "radius", "speed", "yaw"});
  read(c, ref, "reference", "kind", r.kind);
  read_vec3(c, ref, "reference", "center", r.center);
  read(c, ref, "reference", "radius", r.radius);
  read(c, ref, "reference", "speed", r.speed);
  read(c, ref, "reference", "yaw", r.yaw);
  const auto& k = r.kind;
  if (k != "none" && k != "hold" && k != "waypoint" && k != "circle" && k != "figure_eight")
    c.fail("reference.kind", "one of none, hold, waypoint, circle, figure_eight");
}

void parse_disturbances(const Context& c, const YAML::Node& wind, const YAML::Node& noise, Scenario& s) {
  check_keys(c, wind, "wind", {"mean", "gust_std", "gust_tau"});
  read_vec3(c, wind, "wind", "mean", s.wind.mean);
  read(c, wind, "wind", "gust_std", s.wind.gust_std);
  read(c, wind, "wind", "gust_tau", s.wind.gust_tau);
  positive(c, s.wind.gust_tau, "wind.gust_tau");
  check_keys(c, noise, "noise", {"position", "velocity", "attitude", "rate", "other"});
  read(c, noise, "noise", "position", s.noise.position);
  read(c, noise, "noise", "velocity", s.noise.velocity);
  read(c, noise, "noise", "attitude", s.noise.attitude);
  read(c, noise, "noise", "rate", s.noise.rate);
  read(c, noise, "noise", "other", s.noise.other);
}

Scenario parse_scenario(const Context& c, const YAML::Node& root, std::uint64_t seed) {
  check_keys(c, root, "scenario",
             {"name", "description", "task", "plant", "timing", "world", "reference", "wind", "noise",
              "success", "mppid", "mission", "sensing", "mapper"});  // mppid, mission, mapper: the harness's
  Scenario s;
  s.seed = seed;
  read(c, root, "scenario", "name", s.name);
  read(c, root, "scenario", "task", s.task);
  if (s.task.empty()) c.fail("task", "required (names config/tasks/<task>.yaml)");
  parse_plant(c, root["plant"], s);
  parse_timing(c, root["timing"], s);
  parse_world(c, root["world"], s);
  parse_reference(c, root["reference"], s.reference);
  parse_disturbances(c, root["wind"], root["noise"], s);
  parse_sensing(c, root["sensing"], s.sensing);
  generate_obstacles(s);
  return s;
}
}  // namespace

namespace {

// A circle of radius r at (x, y) leaves each vehicle's start and goal forest.clear_radius free.
bool clear_of_ends(const Scenario& s, double x, double y, double r) {
  for (int v = 0; v < s.vehicles; ++v) {
    for (const Vec3& p : {s.start_of(v), s.goal_of(v)}) {
      if (std::hypot(x - p[0], y - p[1]) < s.forest.clear_radius + r) return false;
    }
  }
  return true;
}

// Jittered hexagonal lattice: neighbours are `spacing` apart before the jitter, so the mean
// spacing is the scenario's; a seed fixes the jitter, i.e. names the forest.
void plant_forest(Scenario& s) {
  Rng rng(s.seed, 1);
  const double sp = s.forest.spacing;
  const double row = sp * std::sqrt(3.0) / 2.0;
  const auto& f = s.forest;
  int j = 0;
  for (double y = f.y_min; y <= f.y_max + 1e-9; y += row, ++j) {
    const double x0 = f.x_min + ((j % 2) != 0 ? 0.5 * sp : 0.0);
    for (double x = x0; x <= f.x_max + 1e-9; x += sp) {
      const double px = x + rng.uniform(-0.5, 0.5) * f.jitter * sp;
      const double py = y + rng.uniform(-0.5, 0.5) * f.jitter * sp;
      const double r = f.radius + rng.uniform(-1.0, 1.0) * f.radius_jitter;
      if (r <= 0.05 || !clear_of_ends(s, px, py, r)) continue;
      bool overlaps = false;
      for (const auto& o : s.obstacles) overlaps = overlaps || std::hypot(px - o.x, py - o.y) < o.radius + r + 0.5;
      if (!overlaps) s.obstacles.push_back({px, py, r, 0.0, 0.0, f.height});
    }
  }
}

// moving.count obstacles anywhere in the forest's area, each heading its own way.
void add_moving_obstacles(Scenario& s) {
  Rng rng(s.seed, 2);
  const double x_lo = s.forest.x_min, x_hi = s.forest.x_max;
  const double y_lo = s.forest.y_min, y_hi = s.forest.y_max;
  for (int i = 0; i < s.moving.count; ++i) {
    for (int attempt = 0; attempt < 1000; ++attempt) {
      const double px = rng.uniform(x_lo, x_hi), py = rng.uniform(y_lo, y_hi);
      const double a = rng.uniform(0.0, 6.283185307179586);
      if (!clear_of_ends(s, px, py, s.moving.radius)) continue;
      s.obstacles.push_back({px, py, s.moving.radius, s.moving.speed * std::cos(a), s.moving.speed * std::sin(a)});
      break;
    }
  }
}

}  // namespace

void generate_obstacles(Scenario& s) {
  s.obstacles = s.fixed_obstacles;
  if (s.forest.enabled) plant_forest(s);
  if (s.moving.count > 0) add_moving_obstacles(s);
}

}  // namespace sim
