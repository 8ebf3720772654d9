#include "mppi/daemon/daemon_settings.hpp"

#include <cmath>
#include <cstdint>
#include <set>

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

double number(const YAML::Node& parent, const std::string& field, double def, double lo, double hi,
              const std::string& prefix = "") {
  const YAML::Node n = parent[field];
  if (!n) return def;
  const double v = scalar<double>(n, prefix + field);
  if (!std::isfinite(v) || v < lo || v > hi)
    fail(prefix + field, "must be in [" + num(lo) + ", " + num(hi) + "], got " + n.Scalar());
  return v;
}

std::string text(const YAML::Node& parent, const std::string& field, const std::string& def,
                 const std::string& prefix = "") {
  const YAML::Node n = parent[field];
  if (!n) return def;
  const auto v = scalar<std::string>(n, prefix + field);
  if (v.empty()) fail(prefix + field, "must not be empty");
  return v;
}

void check_known(const YAML::Node& map, const std::string& prefix, const std::set<std::string>& known) {
  for (const auto& kv : map) {
    if (!kv.first.IsScalar()) {  // a list or map as a key: name the section, not a yaml-cpp conversion
      const std::string where = prefix.empty() ? "daemon" : "daemon." + prefix.substr(0, prefix.size() - 1);
      throw ConfigError(where + ": keys must be plain names (line " + std::to_string(kv.first.Mark().line + 1) + ")");
    }
    const auto name = kv.first.Scalar();
    if (!known.count(name)) fail(prefix + name, "unknown field");
  }
}
}  // namespace

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
  d.expect_model = state_model_for(task);
  if (!section || section.IsNull()) return d;
  if (!section.IsMap()) throw ConfigError("daemon: expected a map");
  check_known(section, "",
              {"rate_hz", "state_timeout_ms", "failsafe_timeout_ms", "status_hz", "plan_hz", "lcm_url",
               "receive_timeout_ms", "lockstep", "lockstep_trigger", "channels", "realtime", "warmup_iterations",
               "watchdog_max_consecutive_misses", "watchdog_max_optimizer_errors", "failsafe_u", "deadline_guard",
               "latency", "disturbance", "anytime_margin_ms", "live", "trigger", "state_trigger", "identification"});
  LoopSettings& l = d.loop;
  l.rate_hz = number(section, "rate_hz", l.rate_hz, 0.1, 2000.0);
  const double state_ms = number(section, "state_timeout_ms", 100.0, 1.0, 60000.0);
  const double failsafe_ms = number(section, "failsafe_timeout_ms", std::max(500.0, 2.0 * state_ms), 1.0, 60000.0);
  if (failsafe_ms <= state_ms) fail("failsafe_timeout_ms", "must be greater than daemon.state_timeout_ms");
  l.state_timeout_ns = std::llround(state_ms * 1e6);
  l.failsafe_timeout_ns = std::llround(failsafe_ms * 1e6);
  l.status_hz = number(section, "status_hz", l.status_hz, 1.0, l.rate_hz);
  l.plan_hz = number(section, "plan_hz", l.plan_hz, 0.0, l.rate_hz);
  l.watchdog_max_consecutive_misses =
      static_cast<int>(number(section, "watchdog_max_consecutive_misses", l.watchdog_max_consecutive_misses, 1, 1e6));
  l.watchdog_max_optimizer_errors =
      static_cast<int>(number(section, "watchdog_max_optimizer_errors", l.watchdog_max_optimizer_errors, 1, 1e6));
  if (section["lockstep"]) l.lockstep = scalar<bool>(section["lockstep"], "lockstep");
  if (section["deadline_guard"]) l.deadline_guard = scalar<bool>(section["deadline_guard"], "deadline_guard");
  l.anytime_margin_ns =
      std::llround(number(section, "anytime_margin_ms", static_cast<double>(l.anytime_margin_ns) / 1e6, 0.0,
                          1000.0 / l.rate_hz) * 1e6);
  const std::string trigger = text(section, "trigger", "clock");
  if (trigger != "clock" && trigger != "state") fail("trigger", "must be clock or state");
  l.trigger = trigger == "state" ? Trigger::kState : Trigger::kClock;
  if (const YAML::Node st = section["state_trigger"]) {
    if (!st.IsMap()) fail("state_trigger", "expected a map");
    check_known(st, "state_trigger.", {"min_gap", "grace"});
    l.state_trigger_min_gap = number(st, "min_gap", l.state_trigger_min_gap, 0.05, 1.0, "state_trigger.");
    l.state_trigger_grace = number(st, "grace", l.state_trigger_grace, 0.0, 10.0, "state_trigger.");
  }
  d.lockstep_trigger = text(section, "lockstep_trigger", d.lockstep_trigger);
  if (d.lockstep_trigger != "clock" && d.lockstep_trigger != "state") fail("lockstep_trigger", "must be clock or state");
  d.lcm_url = text(section, "lcm_url", d.lcm_url);
  d.receive_timeout_ms = static_cast<int>(number(section, "receive_timeout_ms", d.receive_timeout_ms, 1, 50));
  d.warmup_iterations = static_cast<int>(number(section, "warmup_iterations", d.warmup_iterations, 0, 1000));
  if (const YAML::Node f = section["failsafe_u"]) {
    if (!f.IsSequence() || static_cast<int>(f.size()) != nu)
      fail("failsafe_u", "expected a list of " + std::to_string(nu) + " numbers");
    for (std::size_t i = 0; i < f.size(); ++i) {
      const auto v = scalar<float>(f[i], "failsafe_u[" + std::to_string(i) + "]");
      if (!std::isfinite(v)) fail("failsafe_u[" + std::to_string(i) + "]", "must be finite");
      l.failsafe_u.push_back(v);
    }
  }
  if (const YAML::Node c = section["channels"]) {
    if (!c.IsMap()) fail("channels", "expected a map");
    check_known(c, "channels.",
                {"state", "command", "status", "plan", "reference", "obstacles", "params", "param_result", "clock"});
    auto& ch = d.channels;
    ch.state = text(c, "state", ch.state, "channels.");
    ch.command = text(c, "command", ch.command, "channels.");
    ch.status = text(c, "status", ch.status, "channels.");
    ch.plan = text(c, "plan", ch.plan, "channels.");
    ch.reference = text(c, "reference", ch.reference, "channels.");
    ch.obstacles = text(c, "obstacles", ch.obstacles, "channels.");
    ch.params = text(c, "params", ch.params, "channels.");
    ch.param_result = text(c, "param_result", ch.param_result, "channels.");
    ch.clock = text(c, "clock", ch.clock, "channels.");
  }
  // The default ceiling of the expected latency is one period: a cycle that needs longer
  // misses its deadline anyway (and the deadline guard covers it).
  LatencySettings& lat = l.latency;
  lat.estimator.ceiling_ns = std::llround(1e9 / l.rate_hz);
  if (const YAML::Node n = section["latency"]) {
    if (!n.IsMap()) fail("latency", "expected a map");
    check_known(n, "latency.",
                {"compensate", "quantile", "window", "floor_ms", "ceiling_ms", "transport_ms", "actuation_delay_ms",
                 "state_time", "future_tolerance_ms", "delay_estimate"});
    const std::string p = "latency.";
    if (n["compensate"]) lat.compensate = scalar<bool>(n["compensate"], p + "compensate");
    lat.estimator.quantile = number(n, "quantile", lat.estimator.quantile, 0.01, 1.0, p);
    lat.estimator.window = static_cast<int>(number(n, "window", lat.estimator.window, 1, 10000, p));
    const double floor_ms = number(n, "floor_ms", 1.0, 0.0, 1000.0, p);
    const double ceiling_ms = number(n, "ceiling_ms", 1000.0 / l.rate_hz, 0.0, 1000.0, p);
    if (ceiling_ms < floor_ms) fail("latency.ceiling_ms", "must be >= daemon.latency.floor_ms");
    lat.estimator.floor_ns = std::llround(floor_ms * 1e6);
    lat.estimator.ceiling_ns = std::llround(ceiling_ms * 1e6);
    lat.transport_ns = std::llround(number(n, "transport_ms", 0.2, 0.0, 1000.0, p) * 1e6);
    lat.actuation_delay_ns = std::llround(number(n, "actuation_delay_ms", 0.0, 0.0, 1000.0, p) * 1e6);
    lat.future_tolerance_ns = std::llround(number(n, "future_tolerance_ms", 2.0, 0.0, 60000.0, p) * 1e6);
    const std::string st = text(n, "state_time", "sample", p);
    if (st != "sample" && st != "receive") fail("latency.state_time", "must be sample or receive");
    lat.use_sample_time = st == "sample";
    if (const YAML::Node e = n["delay_estimate"]) {
      if (!e.IsMap()) fail("latency.delay_estimate", "expected a map");
      const std::string q = "latency.delay_estimate.";
      check_known(e, q, {"estimate", "max_ms", "step_ms", "window", "min_gain"});
      DelayEstimateSettings& de = lat.delay_estimate;
      if (e["estimate"]) de.estimate = scalar<bool>(e["estimate"], q + "estimate");
      de.max_ms = number(e, "max_ms", de.max_ms, 1.0, 500.0, q);
      de.step_ms = number(e, "step_ms", de.step_ms, 0.1, de.max_ms, q);
      de.window = static_cast<int>(number(e, "window", de.window, 5, 1000, q));
      de.min_gain = number(e, "min_gain", de.min_gain, 0.0, 0.9, q);
    }
  }
  if (const YAML::Node n = section["disturbance"]) {
    if (!n.IsMap()) fail("disturbance", "expected a map");
    check_known(n, "disturbance.", {"estimate", "time_constant_s", "limit", "mass"});
    DisturbanceSettings& ds = l.disturbance;
    if (n["estimate"]) ds.estimate = scalar<bool>(n["estimate"], "disturbance.estimate");
    ds.time_constant_s = number(n, "time_constant_s", ds.time_constant_s, 0.02, 100.0, "disturbance.");
    ds.limit = static_cast<float>(number(n, "limit", ds.limit, 0.0, 50.0, "disturbance."));
    if (const YAML::Node m = n["mass"]) {
      if (!m.IsMap()) fail("disturbance.mass", "expected a map");
      check_known(m, "disturbance.mass.", {"estimate", "time_constant_s", "prior_std", "max_change", "accel_noise"});
      MassEstimateSettings& ms = ds.mass;
      const std::string p = "disturbance.mass.";
      if (m["estimate"]) ms.estimate = scalar<bool>(m["estimate"], p + "estimate");
      ms.time_constant_s = number(m, "time_constant_s", ms.time_constant_s, 0.02, 100.0, p);
      ms.prior_std = number(m, "prior_std", ms.prior_std, 1e-3, 1.0, p);
      ms.max_change = number(m, "max_change", ms.max_change, 0.01, 0.9, p);
      ms.accel_noise = number(m, "accel_noise", ms.accel_noise, 1e-3, 100.0, p);
    }
  }
  if (const YAML::Node n = section["identification"]) {
    if (!n.IsMap()) fail("identification", "expected a map");
    check_known(n, "identification.", {"rate_amplitude", "yaw_amplitude", "thrust_step", "pulse_s", "gap_s", "box_m",
                                       "max_tilt_deg", "repeats"});
    IdentificationSettings& is = l.identification;
    const std::string p = "identification.";
    is.rate_amplitude = number(n, "rate_amplitude", is.rate_amplitude, 0.0, 10.0, p);
    is.yaw_amplitude = number(n, "yaw_amplitude", is.yaw_amplitude, 0.0, 10.0, p);
    is.thrust_step = number(n, "thrust_step", is.thrust_step, 0.0, 0.5, p);
    is.pulse_s = number(n, "pulse_s", is.pulse_s, 0.02, 5.0, p);
    is.gap_s = number(n, "gap_s", is.gap_s, 0.0, 10.0, p);
    is.box_m = number(n, "box_m", is.box_m, 0.1, 100.0, p);
    is.max_tilt_deg = number(n, "max_tilt_deg", is.max_tilt_deg, 1.0, 80.0, p);
    is.repeats = static_cast<int>(number(n, "repeats", is.repeats, 1, 100, p));
  }
  if (const YAML::Node n = section["live"]) {
    if (!n.IsMap()) fail("live", "expected a map");
    check_known(n, "live.", {"enabled", "max_horizon", "max_rollouts", "max_threads"});
    LiveSettings& lv = d.live;
    if (n["enabled"]) lv.enabled = scalar<bool>(n["enabled"], "live.enabled");
    lv.max_horizon = static_cast<int>(number(n, "max_horizon", lv.max_horizon, 2, 100000, "live."));
    lv.max_rollouts = static_cast<int>(number(n, "max_rollouts", lv.max_rollouts, 1, 1 << 26, "live."));
    lv.max_threads = static_cast<int>(number(n, "max_threads", lv.max_threads, 0, 1024, "live."));
  }
  if (const YAML::Node r = section["realtime"]) {
    if (!r.IsMap()) fail("realtime", "expected a map");
    check_known(r, "realtime.", {"priority", "cpu", "lock_memory"});
    d.realtime.fifo_priority = static_cast<int>(number(r, "priority", d.realtime.fifo_priority, 0, 99, "realtime."));
    d.realtime.cpu = static_cast<int>(number(r, "cpu", d.realtime.cpu, -1, 1023, "realtime."));
    if (r["lock_memory"]) d.realtime.lock_memory = scalar<bool>(r["lock_memory"], "realtime.lock_memory");
  }
  return d;
}

}  // namespace mppi::daemon
