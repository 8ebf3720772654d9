// The daemon's own section of the settings file (`daemon:`), validated with errors that
// name the field ("daemon.rate_hz: must be in (0, 2000]").
#pragma once

#include <cstdint>
#include <yaml-cpp/yaml.h>

#include <string>

#include "mppi/daemon/control_loop.hpp"
#include "mppi/rt/realtime.hpp"
#include "mppi/transport/lcm_transport.hpp"

namespace mppi::daemon {

struct DaemonSettings {
  LoopSettings loop;
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  transport::LcmChannels channels;
  int receive_timeout_ms = 20;
  // daemon.spin: the loop thread and the LCM receive thread poll instead of sleeping (a busy
  // core each; for a host with cores to spare, e.g. next to a GPU): no wake-up latency.
  bool spin = false;
  std::string lockstep_trigger = "clock";  // clock | state
  rt::RealtimeRequest realtime;
  int warmup_iterations = 3;
  std::int8_t expect_model = 0;  // vehicle_state_t::MODEL_*, from the task
  LiveSettings live;             // live optimizer updates (mppi.* at run time)
  // daemon.map.enabled: the inbox takes local_map_t on channels.local_map (default: forest
  // tasks); the timeout is loop.map_timeout_ns (daemon.map.timeout_ms).
  bool local_map = false;
};

// The daemon's settings table (`daemon.*`), as visit_fields is for the models and costs: one
// row per key, with its range and whether a parameter update may change it while mppid
// runs. The settings-file reader (its known keys, ranges and messages), the loop's
// parameter routes (loop_params.cpp) and their messages all read it.

// What bounds a number from above.
enum class DaemonHi {
  kConstant,   // DaemonKey::hi
  kRateHz,     // daemon.rate_hz
  kPeriodMs,   // one period, 1000 / daemon.rate_hz
  kDelayMaxMs  // daemon.latency.delay_estimate.max_ms
};

struct DaemonKey {
  const char* path;      // under `daemon.`; a dot names a sub-section ("latency.window")
  double lo, hi;         // a number's range
  DaemonHi hi_is;
  double scale;          // kept as value * scale (ms -> ns: 1e6, rounded); 1: as given
  const char* choices;   // text with a fixed set of values ("clock|state"); null: any non-empty text
  bool live;             // a parameter update may change it while mppid runs
};

// A key of parameter updates alone (no settings-file field): a command to the loop.
struct DaemonCommand {};

namespace table {
constexpr double kMs = 1e6;  // ms in ns
constexpr DaemonKey number(const char* path, double lo, double hi, DaemonHi h = DaemonHi::kConstant) {
  return {path, lo, hi, h, 1.0, nullptr, false};
}
constexpr DaemonKey millis(const char* path, double lo, double hi, DaemonHi h = DaemonHi::kConstant) {
  return {path, lo, hi, h, kMs, nullptr, false};
}
// A flag, a text, a list (the field's type says which) or a command.
constexpr DaemonKey key(const char* path, const char* choices = nullptr) {
  return {path, 0.0, 0.0, DaemonHi::kConstant, 1.0, choices, false};
}
constexpr DaemonKey live(DaemonKey k) { return {k.path, k.lo, k.hi, k.hi_is, k.scale, k.choices, true}; }

template <class C, class V>
void visit_channels(C& c, V&& v) {
  v(key("channels.state"), c.state);
  v(key("channels.command"), c.command);
  v(key("channels.status"), c.status);
  v(key("channels.plan"), c.plan);
  v(key("channels.reference"), c.reference);
  v(key("channels.obstacles"), c.obstacles);
  v(key("channels.params"), c.params);
  v(key("channels.param_result"), c.param_result);
  v(key("channels.clock"), c.clock);
  v(key("channels.rollouts"), c.rollouts);
  v(key("channels.local_map"), c.local_map);
}

template <class L, class V>
void visit_latency(L& lat, V&& v) {
  using H = DaemonHi;
  v(key("latency.compensate"), lat.compensate);
  v(number("latency.quantile", 0.01, 1.0), lat.estimator.quantile);
  v(number("latency.window", 1, 10000), lat.estimator.window);
  v(millis("latency.floor_ms", 0.0, 1000.0), lat.estimator.floor_ns);
  v(millis("latency.ceiling_ms", 0.0, 1000.0), lat.estimator.ceiling_ns);
  v(millis("latency.transport_ms", 0.0, 1000.0), lat.transport_ns);
  v(millis("latency.actuation_delay_ms", 0.0, 1000.0), lat.actuation_delay_ns);
  v(millis("latency.future_tolerance_ms", 0.0, 60000.0), lat.future_tolerance_ns);
  v(millis("latency.estimate_lag_ms", 0.0, 500.0), lat.estimate_lag_ns);
  v(key("latency.state_time", "sample|receive"), lat.use_sample_time);  // true: sample
  auto& de = lat.delay_estimate;
  v(key("latency.delay_estimate.estimate"), de.estimate);
  v(number("latency.delay_estimate.max_ms", 1.0, 500.0), de.max_ms);
  v(number("latency.delay_estimate.step_ms", 0.1, 0.0, H::kDelayMaxMs), de.step_ms);
  v(number("latency.delay_estimate.window", 5, 1000), de.window);
  v(number("latency.delay_estimate.min_gain", 0.0, 0.9), de.min_gain);
}

// The disturbance observer, its mass estimate and the identification manoeuvre.
template <class L, class V>
void visit_estimators(L& l, V&& v) {
  auto& ds = l.disturbance;
  v(key("disturbance.estimate"), ds.estimate);
  v(number("disturbance.time_constant_s", 0.02, 100.0), ds.time_constant_s);
  v(number("disturbance.limit", 0.0, 50.0), ds.limit);
  v(key("disturbance.mass.estimate"), ds.mass.estimate);
  v(number("disturbance.mass.time_constant_s", 0.02, 100.0), ds.mass.time_constant_s);
  v(number("disturbance.mass.prior_std", 1e-3, 1.0), ds.mass.prior_std);
  v(number("disturbance.mass.max_change", 0.01, 0.9), ds.mass.max_change);
  v(number("disturbance.mass.accel_noise", 1e-3, 100.0), ds.mass.accel_noise);
  auto& is = l.identification;
  v(number("identification.rate_amplitude", 0.0, 10.0), is.rate_amplitude);
  v(number("identification.yaw_amplitude", 0.0, 10.0), is.yaw_amplitude);
  v(number("identification.thrust_step", 0.0, 0.5), is.thrust_step);
  v(number("identification.pulse_s", 0.02, 5.0), is.pulse_s);
  v(number("identification.gap_s", 0.0, 10.0), is.gap_s);
  v(number("identification.box_m", 0.1, 100.0), is.box_m);
  v(number("identification.max_tilt_deg", 1.0, 80.0), is.max_tilt_deg);
  v(number("identification.repeats", 1, 100), is.repeats);
}
}  // namespace table

// A visitor is called as v(const DaemonKey&, field&): a double, float, int, std::int64_t
// (scaled), bool, std::string, Trigger or std::vector<float> of `d` (DaemonSettings or
// const), or a DaemonCommand. Rows come in reading order: a bound names a row before it.
template <class D, class V>
void visit_daemon_settings(D& d, V&& v) {
  using namespace table;
  using H = DaemonHi;
  auto& l = d.loop;
  static DaemonCommand command;  // no state: the loop's parameter routes act on it
  v(number("rate_hz", 0.1, 2000.0), l.rate_hz);
  v(live(millis("state_timeout_ms", 1.0, 60000.0)), l.state_timeout_ns);
  v(live(millis("failsafe_timeout_ms", 1.0, 60000.0)), l.failsafe_timeout_ns);
  v(live(key("identify")), command);
  v(live(key("restart_estimates")), command);
  v(number("status_hz", 1.0, 0.0, H::kRateHz), l.status_hz);
  v(number("plan_hz", 0.0, 0.0, H::kRateHz), l.plan_hz);
  v(number("watchdog_max_consecutive_misses", 1, 1e6), l.watchdog_max_consecutive_misses);
  v(number("watchdog_max_optimizer_errors", 1, 1e6), l.watchdog_max_optimizer_errors);
  v(key("lockstep"), l.lockstep);
  v(key("deadline_guard"), l.deadline_guard);
  v(millis("anytime_margin_ms", 0.0, 0.0, H::kPeriodMs), l.anytime_margin_ns);
  v(key("trigger", "clock|state"), l.trigger);
  v(number("state_trigger.min_gap", 0.05, 1.0), l.state_trigger_min_gap);
  v(number("state_trigger.grace", 0.0, 10.0), l.state_trigger_grace);
  v(key("lockstep_trigger", "clock|state"), d.lockstep_trigger);
  v(key("spin"), d.spin);
  v(key("lcm_url"), d.lcm_url);
  v(number("receive_timeout_ms", 1, 50), d.receive_timeout_ms);
  v(number("warmup_iterations", 0, 1000), d.warmup_iterations);
  v(key("failsafe_u"), l.failsafe_u);
  visit_channels(d.channels, v);
  visit_latency(l.latency, v);
  visit_estimators(l, v);
  v(key("live.enabled"), d.live.enabled);
  v(number("live.max_horizon", 2, 100000), d.live.max_horizon);
  v(number("live.max_rollouts", 1, 1 << 26), d.live.max_rollouts);
  v(number("live.max_threads", 0, 1024), d.live.max_threads);
  v(number("rollouts.hz", 0.0, 0.0, H::kRateHz), l.rollouts.hz);
  v(number("rollouts.top", 0, FanSettings::kMaxRollouts), l.rollouts.top);
  v(number("rollouts.random", 0, FanSettings::kMaxRollouts), l.rollouts.random);
  v(number("realtime.priority", 0, 99), d.realtime.fifo_priority);
  v(number("realtime.cpu", -1, 1023), d.realtime.cpu);
  v(key("realtime.lock_memory"), d.realtime.lock_memory);
  v(key("map.enabled"), d.local_map);
  v(millis("map.timeout_ms", 1.0, 60000.0), l.map_timeout_ns);
  v(key("work.enabled"), l.work.enabled);
  v(number("work.target", 0.01, 1.0), l.work.target);
  v(number("work.grow_below", 0.001, 1.0), l.work.grow_below);
  v(number("work.floor", 1, 1 << 26), l.work.floor);
  v(number("work.window", 1, 100000), l.work.window);
  v(number("work.shrink", 0.1, 0.95), l.work.shrink);
  v(number("work.grow", 1.05, 4.0), l.work.grow);
}

// The keys a parameter update may change while mppid runs, from the table:
// "daemon.state_timeout_ms, daemon.failsafe_timeout_ms, ...".
std::string live_daemon_keys();

// Reads `section` (may be null: all defaults) for a controller with nu controls of task
// `task`. Throws mppi::app::ConfigError naming the field.
DaemonSettings parse_daemon_settings(const YAML::Node& section, const std::string& task, int nu);

// What the inbox accepts and when it posts a tick or a wake-up, for `controller` flown with
// these settings (mppid, mppid-replay).
transport::Inbox::Expect inbox_expects(const DaemonSettings& ds, const Controller& controller);

// command_t::KIND_* and vehicle_state_t::MODEL_* for a task name.
std::int8_t command_kind_for(const std::string& task);
std::int8_t state_model_for(const std::string& task);

}  // namespace mppi::daemon
