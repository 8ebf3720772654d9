#include "mppi/daemon/daemon_settings.hpp"

#include <algorithm>
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

// A sub-section: absent (a null node), or a map of known fields.
YAML::Node subsection(const YAML::Node& parent, const std::string& name, const std::set<std::string>& known,
                      const std::string& prefix = "") {
  const YAML::Node n = parent[name];
  if (!n) return n;
  if (!n.IsMap()) fail(prefix + name, "expected a map");
  check_known(n, prefix + name + ".", known);
  return n;
}

bool flag(const YAML::Node& parent, const std::string& field, bool def, const std::string& prefix = "") {
  return parent[field] ? scalar<bool>(parent[field], prefix + field) : def;
}

// Rate, timeouts, status and plan rates, the watchdog's limits, the deadline guard.
void parse_timing(const YAML::Node& section, LoopSettings* l) {
  l->rate_hz = number(section, "rate_hz", l->rate_hz, 0.1, 2000.0);
  const double state_ms = number(section, "state_timeout_ms", 100.0, 1.0, 60000.0);
  const double failsafe_ms = number(section, "failsafe_timeout_ms", std::max(500.0, 2.0 * state_ms), 1.0, 60000.0);
  if (failsafe_ms <= state_ms) fail("failsafe_timeout_ms", "must be greater than daemon.state_timeout_ms");
  l->state_timeout_ns = std::llround(state_ms * 1e6);
  l->failsafe_timeout_ns = std::llround(failsafe_ms * 1e6);
  l->status_hz = number(section, "status_hz", l->status_hz, 1.0, l->rate_hz);
  l->plan_hz = number(section, "plan_hz", l->plan_hz, 0.0, l->rate_hz);
  l->watchdog_max_consecutive_misses =
      static_cast<int>(number(section, "watchdog_max_consecutive_misses", l->watchdog_max_consecutive_misses, 1, 1e6));
  l->watchdog_max_optimizer_errors =
      static_cast<int>(number(section, "watchdog_max_optimizer_errors", l->watchdog_max_optimizer_errors, 1, 1e6));
  l->lockstep = flag(section, "lockstep", l->lockstep);
  l->deadline_guard = flag(section, "deadline_guard", l->deadline_guard);
  // Default 3 ms, at most a quarter of the period (faster loops: tools/gpu/rate_dial.py).
  const double default_margin_ms = std::min(static_cast<double>(l->anytime_margin_ns) / 1e6, 250.0 / l->rate_hz);
  l->anytime_margin_ns =
      std::llround(number(section, "anytime_margin_ms", default_margin_ms, 0.0, 1000.0 / l->rate_hz) * 1e6);
}

// What starts a cycle, in real time and in lock-step.
void parse_triggers(const YAML::Node& section, DaemonSettings* d) {
  LoopSettings& l = d->loop;
  const std::string trigger = text(section, "trigger", "clock");
  if (trigger != "clock" && trigger != "state") fail("trigger", "must be clock or state");
  l.trigger = trigger == "state" ? Trigger::kState : Trigger::kClock;
  if (const YAML::Node st = subsection(section, "state_trigger", {"min_gap", "grace"})) {
    l.state_trigger_min_gap = number(st, "min_gap", l.state_trigger_min_gap, 0.05, 1.0, "state_trigger.");
    l.state_trigger_grace = number(st, "grace", l.state_trigger_grace, 0.0, 10.0, "state_trigger.");
  }
  d->lockstep_trigger = text(section, "lockstep_trigger", d->lockstep_trigger);
  if (d->lockstep_trigger != "clock" && d->lockstep_trigger != "state") fail("lockstep_trigger", "must be clock or state");
}

void parse_failsafe_u(const YAML::Node& f, int nu, std::vector<float>* out) {
  if (!f.IsSequence() || static_cast<int>(f.size()) != nu)
    fail("failsafe_u", "expected a list of " + std::to_string(nu) + " numbers");
  for (std::size_t i = 0; i < f.size(); ++i) {
    const auto v = scalar<float>(f[i], "failsafe_u[" + std::to_string(i) + "]");
    if (!std::isfinite(v)) fail("failsafe_u[" + std::to_string(i) + "]", "must be finite");
    out->push_back(v);
  }
}

void parse_channels(const YAML::Node& c, transport::LcmChannels* ch) {
  const std::string p = "channels.";
  ch->state = text(c, "state", ch->state, p);
  ch->command = text(c, "command", ch->command, p);
  ch->status = text(c, "status", ch->status, p);
  ch->plan = text(c, "plan", ch->plan, p);
  ch->reference = text(c, "reference", ch->reference, p);
  ch->obstacles = text(c, "obstacles", ch->obstacles, p);
  ch->params = text(c, "params", ch->params, p);
  ch->param_result = text(c, "param_result", ch->param_result, p);
  ch->clock = text(c, "clock", ch->clock, p);
  ch->rollouts = text(c, "rollouts", ch->rollouts, p);
  ch->local_map = text(c, "local_map", ch->local_map, p);
}

// The local map (local_map_t): taken or not, and when the one in use is stale.
void parse_map(const YAML::Node& m, DaemonSettings* d) {
  d->local_map = flag(m, "enabled", d->local_map, "map.");
  d->loop.map_timeout_ns = std::llround(number(m, "timeout_ms", 500.0, 1.0, 60000.0, "map.") * 1e6);
}

// The rollout fan on the wire (RolloutPublisher): off unless hz > 0.
void parse_rollouts(const YAML::Node& n, double rate_hz, FanSettings* f) {
  f->hz = number(n, "hz", f->hz, 0.0, rate_hz, "rollouts.");
  f->top = static_cast<int>(number(n, "top", f->top, 0, FanSettings::kMaxRollouts, "rollouts."));
  f->random = static_cast<int>(number(n, "random", f->random, 0, FanSettings::kMaxRollouts, "rollouts."));
  if (f->top + f->random > FanSettings::kMaxRollouts)
    fail("rollouts.random", "top + random must be at most " + std::to_string(FanSettings::kMaxRollouts));
}

// The actuation delay estimated in flight (DelayEstimator).
void parse_delay_estimate(const YAML::Node& e, DelayEstimateSettings* de) {
  const std::string q = "latency.delay_estimate.";
  de->estimate = flag(e, "estimate", de->estimate, q);
  de->max_ms = number(e, "max_ms", de->max_ms, 1.0, 500.0, q);
  de->step_ms = number(e, "step_ms", de->step_ms, 0.1, de->max_ms, q);
  de->window = static_cast<int>(number(e, "window", de->window, 5, 1000, q));
  de->min_gain = number(e, "min_gain", de->min_gain, 0.0, 0.9, q);
}

void parse_latency(const YAML::Node& n, double rate_hz, LatencySettings* lat) {
  const std::string p = "latency.";
  lat->compensate = flag(n, "compensate", lat->compensate, p);
  lat->estimator.quantile = number(n, "quantile", lat->estimator.quantile, 0.01, 1.0, p);
  lat->estimator.window = static_cast<int>(number(n, "window", lat->estimator.window, 1, 10000, p));
  const double floor_ms = number(n, "floor_ms", 1.0, 0.0, 1000.0, p);
  const double ceiling_ms = number(n, "ceiling_ms", 1000.0 / rate_hz, 0.0, 1000.0, p);
  if (ceiling_ms < floor_ms) fail("latency.ceiling_ms", "must be >= daemon.latency.floor_ms");
  lat->estimator.floor_ns = std::llround(floor_ms * 1e6);
  lat->estimator.ceiling_ns = std::llround(ceiling_ms * 1e6);
  lat->transport_ns = std::llround(number(n, "transport_ms", 0.2, 0.0, 1000.0, p) * 1e6);
  lat->actuation_delay_ns = std::llround(number(n, "actuation_delay_ms", 0.0, 0.0, 1000.0, p) * 1e6);
  lat->future_tolerance_ns = std::llround(number(n, "future_tolerance_ms", 2.0, 0.0, 60000.0, p) * 1e6);
  lat->estimate_lag_ns = std::llround(number(n, "estimate_lag_ms", 0.0, 0.0, 500.0, p) * 1e6);
  const std::string st = text(n, "state_time", "sample", p);
  if (st != "sample" && st != "receive") fail("latency.state_time", "must be sample or receive");
  lat->use_sample_time = st == "sample";
  if (const YAML::Node e = subsection(n, "delay_estimate", {"estimate", "max_ms", "step_ms", "window", "min_gain"},
                                      "latency."))
    parse_delay_estimate(e, &lat->delay_estimate);
}

// The mass (hover thrust) estimate beside the disturbance observer.
void parse_mass_estimate(const YAML::Node& m, MassEstimateSettings* ms) {
  const std::string p = "disturbance.mass.";
  ms->estimate = flag(m, "estimate", ms->estimate, p);
  ms->time_constant_s = number(m, "time_constant_s", ms->time_constant_s, 0.02, 100.0, p);
  ms->prior_std = number(m, "prior_std", ms->prior_std, 1e-3, 1.0, p);
  ms->max_change = number(m, "max_change", ms->max_change, 0.01, 0.9, p);
  ms->accel_noise = number(m, "accel_noise", ms->accel_noise, 1e-3, 100.0, p);
}

void parse_disturbance(const YAML::Node& n, DisturbanceSettings* ds) {
  ds->estimate = flag(n, "estimate", ds->estimate, "disturbance.");
  ds->time_constant_s = number(n, "time_constant_s", ds->time_constant_s, 0.02, 100.0, "disturbance.");
  ds->limit = static_cast<float>(number(n, "limit", ds->limit, 0.0, 50.0, "disturbance."));
  if (const YAML::Node m = subsection(n, "mass", {"estimate", "time_constant_s", "prior_std", "max_change",
                                                  "accel_noise"}, "disturbance."))
    parse_mass_estimate(m, &ds->mass);
}

// The identification manoeuvre (daemon.identify: rate doublets and thrust steps in a box).
void parse_identification(const YAML::Node& n, IdentificationSettings* is) {
  const std::string p = "identification.";
  is->rate_amplitude = number(n, "rate_amplitude", is->rate_amplitude, 0.0, 10.0, p);
  is->yaw_amplitude = number(n, "yaw_amplitude", is->yaw_amplitude, 0.0, 10.0, p);
  is->thrust_step = number(n, "thrust_step", is->thrust_step, 0.0, 0.5, p);
  is->pulse_s = number(n, "pulse_s", is->pulse_s, 0.02, 5.0, p);
  is->gap_s = number(n, "gap_s", is->gap_s, 0.0, 10.0, p);
  is->box_m = number(n, "box_m", is->box_m, 0.1, 100.0, p);
  is->max_tilt_deg = number(n, "max_tilt_deg", is->max_tilt_deg, 1.0, 80.0, p);
  is->repeats = static_cast<int>(number(n, "repeats", is->repeats, 1, 100, p));
}

void parse_live(const YAML::Node& n, LiveSettings* lv) {
  lv->enabled = flag(n, "enabled", lv->enabled, "live.");
  lv->max_horizon = static_cast<int>(number(n, "max_horizon", lv->max_horizon, 2, 100000, "live."));
  lv->max_rollouts = static_cast<int>(number(n, "max_rollouts", lv->max_rollouts, 1, 1 << 26, "live."));
  lv->max_threads = static_cast<int>(number(n, "max_threads", lv->max_threads, 0, 1024, "live."));
}

void parse_realtime(const YAML::Node& r, rt::RealtimeRequest* rq) {
  rq->fifo_priority = static_cast<int>(number(r, "priority", rq->fifo_priority, 0, 99, "realtime."));
  rq->cpu = static_cast<int>(number(r, "cpu", rq->cpu, -1, 1023, "realtime."));
  rq->lock_memory = flag(r, "lock_memory", rq->lock_memory, "realtime.");
}
}  // namespace

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
  if (!section || section.IsNull()) return d;
  if (!section.IsMap()) throw ConfigError("daemon: expected a map");
  check_known(section, "",
              {"rate_hz", "state_timeout_ms", "failsafe_timeout_ms", "status_hz", "plan_hz", "lcm_url",
               "receive_timeout_ms", "lockstep", "lockstep_trigger", "channels", "realtime", "warmup_iterations",
               "watchdog_max_consecutive_misses", "watchdog_max_optimizer_errors", "failsafe_u", "deadline_guard",
               "latency", "disturbance", "anytime_margin_ms", "live", "trigger", "state_trigger", "rollouts",
               "spin", "identification", "map", "work"});
  parse_timing(section, &d.loop);
  parse_triggers(section, &d);
  d.spin = flag(section, "spin", d.spin);
  d.lcm_url = text(section, "lcm_url", d.lcm_url);
  d.receive_timeout_ms = static_cast<int>(number(section, "receive_timeout_ms", d.receive_timeout_ms, 1, 50));
  d.warmup_iterations = static_cast<int>(number(section, "warmup_iterations", d.warmup_iterations, 0, 1000));
  if (const YAML::Node f = section["failsafe_u"]) parse_failsafe_u(f, nu, &d.loop.failsafe_u);
  if (const YAML::Node c = subsection(section, "channels", {"state", "command", "status", "plan", "reference",
                                                            "obstacles", "params", "param_result", "clock", "rollouts",
                                                            "local_map"}))
    parse_channels(c, &d.channels);
  // The default ceiling of the expected latency is one period: a cycle that needs longer
  // misses its deadline anyway (and the deadline guard covers it).
  d.loop.latency.estimator.ceiling_ns = std::llround(1e9 / d.loop.rate_hz);
  if (const YAML::Node n = subsection(section, "latency", {"compensate", "quantile", "window", "floor_ms", "ceiling_ms",
                                                           "transport_ms", "actuation_delay_ms", "state_time",
                                                           "future_tolerance_ms", "delay_estimate", "estimate_lag_ms"}))
    parse_latency(n, d.loop.rate_hz, &d.loop.latency);
  // Position and velocity first: the quadrotor models' states (daemon.latency.estimate_lag_ms).
  if (d.loop.latency.estimate_lag_ns > 0 && d.expect_model != 1 && d.expect_model != 2)
    fail("latency.estimate_lag_ms", "only for the quadrotor models (position and velocity first), not " + task);
  if (const YAML::Node n = subsection(section, "disturbance", {"estimate", "time_constant_s", "limit", "mass"}))
    parse_disturbance(n, &d.loop.disturbance);
  if (const YAML::Node n = subsection(section, "identification", {"rate_amplitude", "yaw_amplitude", "thrust_step",
                                                                  "pulse_s", "gap_s", "box_m", "max_tilt_deg",
                                                                  "repeats"}))
    parse_identification(n, &d.loop.identification);
  if (const YAML::Node n = subsection(section, "live", {"enabled", "max_horizon", "max_rollouts", "max_threads"}))
    parse_live(n, &d.live);
  if (const YAML::Node n = subsection(section, "rollouts", {"hz", "top", "random"}))
    parse_rollouts(n, d.loop.rate_hz, &d.loop.rollouts);
  if (const YAML::Node r = subsection(section, "realtime", {"priority", "cpu", "lock_memory"}))
    parse_realtime(r, &d.realtime);
  if (const YAML::Node m = subsection(section, "map", {"enabled", "timeout_ms"})) parse_map(m, &d);
  if (const YAML::Node w = section["work"]) parse_work_settings(w, &d.loop.work);
  return d;
}

}  // namespace mppi::daemon
