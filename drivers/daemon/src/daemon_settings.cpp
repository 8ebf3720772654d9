#include "mppi/daemon/daemon_settings.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <set>
#include <type_traits>
#include <vector>

#include "mppi/app/config.hpp"

namespace mppi::daemon {

using app::ConfigError;

namespace {
[[noreturn]] void fail(const std::string& field, const std::string& why) {
  throw ConfigError("daemon." + field + ": " + why);
}

template <class T>
T scalar(const YAML::Node& n, const std::string& field) {
  if (!n.IsScalar()) fail(field, "expected a scalar");
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    fail(field, "cannot read '" + n.Scalar() + "'");
  }
}

std::string num(double v) {
  std::string s = std::to_string(v);
  s.erase(s.find_last_not_of('0') + 1);
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s;
}

// The rows of the table, by path, and the sections their paths name ("latency", "latency.delay_estimate").
struct Paths {
  std::set<std::string> keys, sections;
  Paths() {
    const DaemonSettings d;
    visit_daemon_settings(d, [this](const DaemonKey& k, const auto& field) {
      if constexpr (std::is_same_v<std::decay_t<decltype(field)>, DaemonCommand>) return;  // updates only
      const std::string path = k.path;
      keys.insert(path);
      for (auto dot = path.find('.'); dot != std::string::npos; dot = path.find('.', dot + 1))
        sections.insert(path.substr(0, dot));
    });
  }
};

const Paths& paths() {
  static const Paths p;
  return p;
}

// Every key of `map` (the section at `prefix`, "" or "latency.") a row or a section of the
// table; a section a map.
void check_known(const YAML::Node& map, const std::string& prefix) {
  for (const auto& kv : map) {
    if (!kv.first.IsScalar()) {  // a list or map as a key: name the section, not a yaml-cpp conversion
      const std::string where = prefix.empty() ? "daemon" : "daemon." + prefix.substr(0, prefix.size() - 1);
      throw ConfigError(where + ": keys must be plain names (line " + std::to_string(kv.first.Mark().line + 1) + ")");
    }
    const std::string path = prefix + kv.first.Scalar();
    if (paths().sections.count(path)) {
      if (!kv.second.IsMap()) fail(path, "expected a map");
      check_known(kv.second, path + ".");
    } else if (!paths().keys.count(path)) {
      fail(path, "unknown field");
    }
  }
}

// The node at a row's path ("latency.window"), or an undefined one.
YAML::Node at(const YAML::Node& n, const std::string& path) {
  const auto dot = path.find('.');
  if (dot == std::string::npos) return n[path];
  const YAML::Node sub = n[path.substr(0, dot)];
  if (!sub) return sub;
  return at(sub, path.substr(dot + 1));
}

// "clock or state", "a, b or c" from "a|b|c".
std::string or_list(const std::string& choices) {
  std::string out = choices;
  const auto last = out.rfind('|');
  if (last != std::string::npos) out.replace(last, 1, " or ");
  for (auto bar = out.find('|'); bar != std::string::npos; bar = out.find('|')) out.replace(bar, 1, ", ");
  return out;
}

// A row's value read from the file, as its field's type, in its range; errors name the row.
struct ReadRow {
  const DaemonSettings& d;  // the rows read so far (a bound names one)
  int nu;

  double hi(const DaemonKey& k) const {
    switch (k.hi_is) {
      case DaemonHi::kRateHz: return d.loop.rate_hz;
      case DaemonHi::kPeriodMs: return 1000.0 / d.loop.rate_hz;
      case DaemonHi::kDelayMaxMs: return d.loop.latency.delay_estimate.max_ms;
      default: return k.hi;
    }
  }
  double number(const DaemonKey& k, const YAML::Node& n) const {
    const double v = scalar<double>(n, k.path);
    if (!std::isfinite(v) || v < k.lo || v > hi(k))
      fail(k.path, "must be in [" + num(k.lo) + ", " + num(hi(k)) + "], got " + n.Scalar());
    return v;
  }
  double whole(const DaemonKey& k, const YAML::Node& n) const {
    const double v = number(k, n);
    if (v != std::floor(v)) fail(k.path, "must be a whole number, got " + n.Scalar());
    return v;
  }
  std::string text(const DaemonKey& k, const YAML::Node& n) const {
    const auto v = scalar<std::string>(n, k.path);
    if (v.empty()) fail(k.path, "must not be empty");
    return v;
  }
  // The index of the row's choice the file gives.
  int choice(const DaemonKey& k, const YAML::Node& n) const {
    const std::string v = text(k, n);
    const std::string all = k.choices;
    int i = 0;
    for (std::size_t start = 0;; ++i) {
      const auto bar = all.find('|', start);
      if (all.compare(start, bar == std::string::npos ? std::string::npos : bar - start, v) == 0) return i;
      if (bar == std::string::npos) break;
      start = bar + 1;
    }
    fail(k.path, "must be " + or_list(all));
  }

  void operator()(const DaemonKey& k, const YAML::Node& n, double& f) const { f = number(k, n); }
  void operator()(const DaemonKey& k, const YAML::Node& n, float& f) const { f = static_cast<float>(number(k, n)); }
  void operator()(const DaemonKey& k, const YAML::Node& n, int& f) const { f = static_cast<int>(whole(k, n)); }
  void operator()(const DaemonKey& k, const YAML::Node& n, std::int64_t& f) const {
    f = std::llround(number(k, n) * k.scale);
  }
  void operator()(const DaemonKey& k, const YAML::Node& n, bool& f) const {
    f = k.choices != nullptr ? choice(k, n) == 0 : scalar<bool>(n, k.path);
  }
  void operator()(const DaemonKey& k, const YAML::Node& n, std::string& f) const {
    if (k.choices != nullptr) choice(k, n);
    f = text(k, n);
  }
  void operator()(const DaemonKey& k, const YAML::Node& n, Trigger& f) const {
    f = choice(k, n) == 1 ? Trigger::kState : Trigger::kClock;
  }
  void operator()(const DaemonKey& k, const YAML::Node& n, std::vector<float>& f) const {
    const std::string path = k.path;
    if (!n.IsSequence() || static_cast<int>(n.size()) != nu)
      fail(path, "expected a list of " + std::to_string(nu) + " numbers");
    for (std::size_t i = 0; i < n.size(); ++i) {
      const auto v = scalar<float>(n[i], path + "[" + std::to_string(i) + "]");
      if (!std::isfinite(v)) fail(path + "[" + std::to_string(i) + "]", "must be finite");
      f.push_back(v);
    }
  }
  void operator()(const DaemonKey&, const YAML::Node&, DaemonCommand&) const {}
};

// The defaults that follow other rows, for the rows the file leaves out.
void derived_defaults(const std::set<std::string>& given, DaemonSettings* d) {
  LoopSettings& l = d->loop;
  if (!given.count("failsafe_timeout_ms"))
    l.failsafe_timeout_ns = std::llround(std::max(500.0, 2.0 * static_cast<double>(l.state_timeout_ns) / 1e6) * 1e6);
  // Default 3 ms, at most a quarter of the period (faster loops: tools/gpu/rate_dial.py).
  if (!given.count("anytime_margin_ms"))
    l.anytime_margin_ns = std::llround(std::min(static_cast<double>(l.anytime_margin_ns) / 1e6, 250.0 / l.rate_hz) * 1e6);
  // The default ceiling of the expected latency is one period: a cycle that needs longer
  // misses its deadline anyway (and the deadline guard covers it).
  if (!given.count("latency.ceiling_ms")) l.latency.estimator.ceiling_ns = std::llround(1e9 / l.rate_hz);
}

// The rules between rows.
void check_rows(const YAML::Node& section, const std::string& task, const DaemonSettings& d) {
  const LoopSettings& l = d.loop;
  if (l.failsafe_timeout_ns <= l.state_timeout_ns)
    fail("failsafe_timeout_ms", "must be greater than daemon.state_timeout_ms");
  if (section["latency"] && l.latency.estimator.ceiling_ns < l.latency.estimator.floor_ns)
    fail("latency.ceiling_ms", "must be >= daemon.latency.floor_ms");
  // Position and velocity first: the quadrotor models' states (daemon.latency.estimate_lag_ms).
  if (l.latency.estimate_lag_ns > 0 && d.expect_model != 1 && d.expect_model != 2)
    fail("latency.estimate_lag_ms", "only for the quadrotor models (position and velocity first), not " + task);
  if (l.rollouts.top + l.rollouts.random > FanSettings::kMaxRollouts)
    fail("rollouts.random", "top + random must be at most " + std::to_string(FanSettings::kMaxRollouts));
  // The grown count's compute must stay under the target, or a steady load would swing.
  if (l.work.grow_below * l.work.grow >= l.work.target)
    fail("work.grow_below", "must be below work.target / work.grow (" + num(l.work.target / l.work.grow) +
                                "), got " + num(l.work.grow_below));
}
}  // namespace

std::string live_daemon_keys() {
  std::string out;
  const DaemonSettings d;
  visit_daemon_settings(d, [&out](const DaemonKey& k, const auto&) {
    if (k.live) out += (out.empty() ? "daemon." : ", daemon.") + std::string(k.path);
  });
  return out;
}

transport::Inbox::Expect inbox_expects(const DaemonSettings& ds, const Controller& controller) {
  transport::Inbox::Expect e;
  e.vehicles = controller.vehicles();
  e.nx = controller.nx() / controller.vehicles();
  e.model = ds.expect_model;
  e.restart_after_ns = ds.loop.state_timeout_ns;
  e.tick_on_state = ds.loop.lockstep && ds.lockstep_trigger == "state";
  e.wake_on_state = !ds.loop.lockstep && ds.loop.trigger == Trigger::kState;
  e.local_map = ds.local_map;
  e.map_timeout_ns = ds.loop.map_timeout_ns;
  return e;
}

std::int8_t command_kind_for(const std::string& task) {
  if (task.rfind("quadrotor_rate", 0) == 0) return 2;                               // KIND_THRUST_RATES
  if (task.rfind("quadrotor", 0) == 0 || task.rfind("team", 0) == 0) return 1;     // KIND_MOTOR_SPEEDS
  return 3;                                                                         // KIND_GENERIC
}

std::int8_t state_model_for(const std::string& task) {
  if (task.rfind("quadrotor_rate", 0) == 0) return 2;
  if (task.rfind("quadrotor", 0) == 0 || task.rfind("team", 0) == 0) return 1;
  if (task.rfind("cartpole", 0) == 0) return 3;
  if (task.rfind("racecar", 0) == 0) return 4;
  return 0;
}

DaemonSettings parse_daemon_settings(const YAML::Node& section, const std::string& task, int nu) {
  DaemonSettings d;
  d.loop.command_kind = command_kind_for(task);
  d.loop.deadline_guard = true;
  d.loop.anytime_margin_ns = 3 * rt::kNsPerMs;
  d.loop.work.enabled = true;  // the rollout count sized to the computer (daemon.work)
  d.expect_model = state_model_for(task);
  d.local_map = task.find("forest") != std::string::npos;
  if (!section || section.IsNull()) {
    derived_defaults({}, &d);
    return d;
  }
  if (!section.IsMap()) throw ConfigError("daemon: expected a map");
  check_known(section, "");
  std::set<std::string> given;
  const ReadRow read{d, nu};
  visit_daemon_settings(d, [&](const DaemonKey& k, auto& field) {
    const YAML::Node n = at(section, k.path);
    if (!n) return;
    given.insert(k.path);
    read(k, n, field);
  });
  derived_defaults(given, &d);
  check_rows(section, task, d);
  return d;
}

}  // namespace mppi::daemon
