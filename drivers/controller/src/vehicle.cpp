#include "mppi/app/vehicle.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "mppi/app/config.hpp"
#include "mppi/tasks.hpp"

namespace mppi::app {
namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

class VehicleReader {
 public:
  explicit VehicleReader(std::string path) : path_(std::move(path)) {}

  [[noreturn]] void fail(const std::string& field, const std::string& why) const {
    throw ConfigError(path_ + ": " + field + ": " + why);
  }

  void known(const YAML::Node& map, const std::string& section, const std::set<std::string>& names) const {
    if (!map.IsMap()) fail(section.empty() ? "(file)" : section, "expected a map");
    for (const auto& kv : map) {
      const std::string name = kv.first.IsScalar() ? kv.first.Scalar() : "?";
      if (!names.count(name)) fail(section.empty() ? name : section + "." + name, "unknown field");
    }
  }

  double number(const YAML::Node& n, const std::string& field, double lo, double hi) const {
    if (!n || !n.IsScalar()) fail(field, "expected a number");
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(field, "cannot read '" + n.Scalar() + "' as a number");
    }
    if (!std::isfinite(v) || v < lo || v > hi) fail(field, "must be in [" + num(lo) + ", " + num(hi) + "], got " + n.Scalar());
    return v;
  }

  // A number, or a list of three (per body axis x, y, z).
  std::vector<double> axes(const YAML::Node& n, const std::string& field, double lo, double hi) const {
    if (n && n.IsSequence()) {
      if (n.size() != 3) fail(field, "expected 3 numbers (x, y, z) or one");
      std::vector<double> out;
      for (std::size_t i = 0; i < 3; ++i) out.push_back(number(n[i], field + "[" + std::to_string(i) + "]", lo, hi));
      return out;
    }
    const double v = number(n, field, lo, hi);
    return {v, v, v};
  }

  std::string text(const YAML::Node& n, const std::string& field) const {
    if (!n || !n.IsScalar() || n.Scalar().empty()) fail(field, "expected a name");
    return n.Scalar();
  }

 private:
  std::string path_;
};

void read_rate_model(const VehicleReader& r, const YAML::Node& doc, VehicleFile& v) {
  if (const YAML::Node rr = doc["rate_response"]) {
    r.known(rr, "rate_response", {"tau", "gain", "delay"});
    static const char* const kAxis[3] = {"x", "y", "z"};
    if (rr["tau"]) {
      const auto tau = r.axes(rr["tau"], "rate_response.tau", 1e-3, 10.0);
      for (int i = 0; i < 3; ++i) v.settings.emplace_back(std::string("model.rate_tau_") + kAxis[i], tau[i]);
    }
    if (rr["gain"]) {
      const auto gain = r.axes(rr["gain"], "rate_response.gain", 0.05, 20.0);
      for (int i = 0; i < 3; ++i) v.settings.emplace_back(std::string("model.rate_gain_") + kAxis[i], gain[i]);
    }
    if (rr["delay"]) v.settings.emplace_back("daemon.latency.actuation_delay_ms", 1e3 * r.number(rr["delay"], "rate_response.delay", 0.0, 1.0));
  }
  const YAML::Node lim = doc["limits"];
  if (!lim) r.fail("limits", "missing (max_thrust, max_body_rate)");
  r.known(lim, "limits", {"max_thrust", "max_body_rate"});
  const double thrust = r.number(lim["max_thrust"], "limits.max_thrust", 1e-3, 1e6);
  const auto rate = r.axes(lim["max_body_rate"], "limits.max_body_rate", 1e-3, 100.0);
  v.u_lo = {0.0f, static_cast<float>(-rate[0]), static_cast<float>(-rate[1]), static_cast<float>(-rate[2])};
  v.u_hi = {static_cast<float>(thrust), static_cast<float>(rate[0]), static_cast<float>(rate[1]), static_cast<float>(rate[2])};
}

void read_motor_model(const VehicleReader& r, const YAML::Node& doc, VehicleFile& v) {
  if (doc["rate_response"]) r.fail("rate_response", "only for model quadrotor_rate");
  const YAML::Node lim = doc["limits"];
  if (!lim) r.fail("limits", "missing (max_motor_speed)");
  r.known(lim, "limits", {"max_motor_speed"});
  const auto top = static_cast<float>(r.number(lim["max_motor_speed"], "limits.max_motor_speed", 1.0, 1e6));
  v.u_lo.assign(4, 0.0f);
  v.u_hi.assign(4, top);
}

// The dotted path's parts ("daemon.latency.x" -> daemon, latency, x).
std::vector<std::string> parts_of(const std::string& key) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  for (std::size_t dot; (dot = key.find('.', start)) != std::string::npos; start = dot + 1)
    parts.push_back(key.substr(start, dot - start));
  parts.push_back(key.substr(start));
  return parts;
}

// The value at a dotted path of the tree, or an undefined node. (Nodes are kept in a list:
// assigning one yaml-cpp node to another copies the tree, it does not move the handle.)
YAML::Node at_path(const YAML::Node& root, const std::string& key) {
  std::vector<YAML::Node> path{root};
  for (const auto& part : parts_of(key)) {
    const YAML::Node& n = path.back();
    if (!n.IsMap() || !n[part]) return YAML::Node(YAML::NodeType::Undefined);
    path.push_back(n[part]);
  }
  return path.back();
}

void set_path(YAML::Node root, const std::string& key, double value) {
  const auto parts = parts_of(key);
  std::vector<YAML::Node> path{root};
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    YAML::Node next = path.back()[parts[i]];
    if (!next || !next.IsMap()) {
      path.back()[parts[i]] = YAML::Node(YAML::NodeType::Map);
      next = path.back()[parts[i]];
    }
    path.push_back(next);
  }
  path.back()[parts.back()] = value;
}

bool same(double a, double b) { return std::fabs(a - b) <= 1e-6 * std::max(1.0, std::max(std::fabs(a), std::fabs(b))); }

YAML::Node load_vehicle_yaml(const std::string& path) {
  try {
    return YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw ConfigError("vehicle file " + path + ": cannot open");
  } catch (const YAML::Exception& e) {
    throw ConfigError("vehicle file " + path + ": " + e.what());
  }
}

// Further model parameters by their names in the model's table (checked by the task).
void read_params(const VehicleReader& r, const YAML::Node& doc, VehicleFile& v) {
  const YAML::Node p = doc["params"];
  if (!p) return;
  if (!p.IsMap()) r.fail("params", "expected a map of name: number");
  for (const auto& kv : p) {
    const std::string name = r.text(kv.first, "params");
    if (name == "mass" || name == "gravity" || name == "drag" || name.rfind("rate_", 0) == 0)
      r.fail("params." + name, "has its own field in a vehicle file");
    v.settings.emplace_back("model." + name, r.number(kv.second, "params." + name, -1e12, 1e12));
  }
}

}  // namespace

VehicleFile load_vehicle(const std::string& path) {
  const YAML::Node doc = load_vehicle_yaml(path);
  const VehicleReader r(path);
  r.known(doc, "", {"description", "name", "model", "mass", "gravity", "hover_thrust", "drag", "limits",
                    "rate_response", "estimate_lag", "params"});
  VehicleFile v;
  v.path = path;
  v.name = r.text(doc["name"], "name");
  v.model = r.text(doc["model"], "model");
  v.settings.emplace_back("model.mass", r.number(doc["mass"], "mass", 1e-3, 100.0));
  if (doc["gravity"]) v.settings.emplace_back("model.gravity", r.number(doc["gravity"], "gravity", 0.0, 20.0));
  if (doc["drag"]) v.settings.emplace_back("model.drag", r.number(doc["drag"], "drag", 0.0, 100.0));
  // How far the autopilot's position and velocity estimate trails the vehicle (s): the act-time
  // prediction starts them that much earlier (docs/latency.md).
  if (doc["estimate_lag"])
    v.settings.emplace_back("daemon.latency.estimate_lag_ms", 1e3 * r.number(doc["estimate_lag"], "estimate_lag", 0.0, 0.5));
  // The bridge's: the autopilot's throttle (0..1) that holds the mass up, or null (read it).
  if (const YAML::Node h = doc["hover_thrust"]; h && !h.IsNull()) r.number(h, "hover_thrust", 0.01, 0.99);
  if (v.model == "quadrotor_rate") {
    read_rate_model(r, doc, v);
  } else if (v.model == "quadrotor") {
    read_motor_model(r, doc, v);
  } else {
    r.fail("model", "must be quadrotor_rate or quadrotor, got '" + v.model + "'");
  }
  read_params(r, doc, v);
  return v;
}

void merge_vehicle(const VehicleFile& v, YAML::Node root, const YAML::Node& file, const std::string& task,
                   const std::string& task_label) {
  std::string model;
  visit_task(task, [&](auto tag) { model = decltype(tag)::type::Vehicle::kName; });
  if (model != v.model)
    throw ConfigError("vehicle: " + task_label + " flies the " + (model.empty() ? task : model) +
                      " model but the vehicle file " + v.path + " describes a " + v.model);
  for (const auto& [key, value] : v.settings) {
    const YAML::Node have = at_path(root, key);
    if (have.IsDefined() && !have.IsNull()) {
      double mine = 0.0;
      bool numeric = have.IsScalar();
      if (numeric) {
        try {
          mine = have.as<double>();
        } catch (const YAML::Exception&) {
          numeric = false;
        }
      }
      const std::string where = at_path(file, key).IsDefined() ? task_label : "--set " + key;
      if (!numeric || !same(mine, value))
        throw ConfigError(key + ": " + where + " gives " + (have.IsScalar() ? have.Scalar() : "a non-number") +
                          " but the vehicle file " + v.path + " gives " + num(value) +
                          " (they must agree: keep it in the vehicle file only)");
    }
    set_path(root, key, value);
  }
}

void check_vehicle_fits(const VehicleFile& v, const std::vector<float>& hover, const std::vector<float>& u_min,
                        const std::vector<float>& u_max, const std::vector<float>& u_init,
                        const std::vector<float>& u_nominal, const std::string& task_label) {
  const std::size_t nu = v.u_lo.size();
  const auto channel = [](const char* list, std::size_t i) { return std::string("mppi.") + list + "[" + std::to_string(i) + "]"; };
  for (std::size_t i = 0; i < u_min.size() && i < u_max.size(); ++i) {
    const std::size_t j = i % nu;
    if (u_min[i] < v.u_lo[j] - 1e-6f || u_max[i] > v.u_hi[j] + 1e-6f)
      throw ConfigError(channel("u_min/u_max", i) + ": " + task_label + " flies [" + num(u_min[i]) + ", " +
                        num(u_max[i]) + "] but the vehicle file " + v.path + " limits it to [" + num(v.u_lo[j]) + ", " +
                        num(v.u_hi[j]) + "]");
  }
  const auto hover_check = [&](const char* list, const std::vector<float>& u) {
    for (std::size_t i = 0; i < u.size() && i < hover.size(); ++i) {
      if (hover[i] == 0.0f || std::fabs(u[i] - hover[i]) <= 0.01f * std::fabs(hover[i])) continue;
      throw ConfigError(channel(list, i) + ": " + task_label + " gives " + num(u[i]) + ", not the hover of the vehicle file " +
                        v.path + " (" + num(hover[i]) + "; write `hover` there to take the vehicle's)");
    }
  };
  hover_check("u_init", u_init);
  hover_check("u_nominal", u_nominal);
}

}  // namespace mppi::app
