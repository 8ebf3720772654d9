// ControlLoop: the parameter table. Every key a parameter update may name is routed by one
// table of {key, validate, apply}, as Navigation2's ParametersHandler holds its parameters:
// the loop's own daemon.* keys (the live rows of the daemon's settings table,
// daemon_settings.hpp), the optimizer's mppi.* keys (a live optimizer's builder takes them
// through the optimizer's table, mppi/settings.hpp; without one they are fixed for a run)
// and the task's model.* and cost.* keys (the controller's field tables,
// core/include/mppi/params.hpp). A new key is one row.
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstring>

#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"

namespace mppi::daemon {

namespace {
constexpr std::int8_t kThrustRates = 2;  // command_t::KIND_THRUST_RATES
}  // namespace

// The first row that matches, in order: an exact key, or a prefix (ending in '.'); the last
// row ("") takes the rest (the controller names them unknown).
const ControlLoop::ParamRoute& ControlLoop::route_for(const char* key) {
  using L = ControlLoop;
  static const ParamRoute kRoutes[] = {
      {"daemon.state_timeout_ms", false, &L::check_state_timeout, &L::set_state_timeout},
      {"daemon.failsafe_timeout_ms", false, &L::check_failsafe_timeout, &L::set_failsafe_timeout},
      {"daemon.identify", false, &L::check_identify, &L::set_identify},
      {"daemon.restart_estimates", false, nullptr, &L::set_restart_estimates},
      {"daemon.", false, &L::refuse_daemon_key, nullptr},
      {"mppi.", true, &L::refuse_optimizer_key, nullptr},
      {"model.", false, nullptr, &L::set_task_param},
      {"cost.", false, nullptr, &L::set_task_param},
      {"", false, nullptr, &L::set_task_param},
  };
  for (const ParamRoute& r : kRoutes) {
    const std::size_t n = std::strlen(r.key);
    const bool prefix = n == 0 || r.key[n - 1] == '.';
    if (prefix ? std::strncmp(key, r.key, n) == 0 : std::strcmp(key, r.key) == 0) return r;
  }
  return kRoutes[sizeof(kRoutes) / sizeof(kRoutes[0]) - 1];
}

bool ControlLoop::forward_live_param(const transport::ParamUpdate& p) {
  if (live_ == nullptr || !route_for(p.key).live) return false;
  if (live_->request(p)) return true;
  counters_.params_rejected.fetch_add(1, std::memory_order_relaxed);
  spdlog::warn("parameter update seq {} rejected: the optimizer builder is busy", p.seq);
  answer_param(p, false, std::string(p.key) + ": the optimizer builder is busy (64 updates queued); send it again");
  return true;
}

std::string ControlLoop::apply_param(const transport::ParamUpdate& p) {
  const std::string key(p.key);
  const double v = p.value;
  if (!std::isfinite(v)) return key + ": must be finite";
  const ParamRoute& r = route_for(p.key);
  std::string err = r.validate != nullptr ? (this->*r.validate)(key, v) : std::string();
  if (err.empty() && r.apply != nullptr) err = (this->*r.apply)(key, v);
  return err;
}

std::string ControlLoop::check_state_timeout(const std::string& key, double v) const {
  if (v <= 0.0 || v * 1e6 >= static_cast<double>(s_.failsafe_timeout_ns))
    return key + ": must be > 0 and below daemon.failsafe_timeout_ms";
  return {};
}

std::string ControlLoop::set_state_timeout(const std::string&, double v) {
  s_.state_timeout_ns = std::llround(v * 1e6);
  return {};
}

std::string ControlLoop::check_failsafe_timeout(const std::string& key, double v) const {
  if (v * 1e6 <= static_cast<double>(s_.state_timeout_ns) || v > 60000.0)
    return key + ": must be above daemon.state_timeout_ms and <= 60000";
  return {};
}

// Between cycles, so no cycle is armed: the guard's copy is handed over here (its ordering:
// deadline_guard.hpp).
std::string ControlLoop::set_failsafe_timeout(const std::string&, double v) {
  s_.failsafe_timeout_ns = std::llround(v * 1e6);
  if (guard_ != nullptr) guard_->set_failsafe_timeout(s_.failsafe_timeout_ns);
  return {};
}

std::string ControlLoop::check_identify(const std::string& key, double) const {
  if (s_.command_kind != kThrustRates) return key + ": the identification manoeuvre is for the rate-controlled tasks";
  return {};
}

std::string ControlLoop::set_identify(const std::string&, double v) {
  manoeuvre_.request(v != 0.0);
  return {};
}

std::string ControlLoop::set_restart_estimates(const std::string&, double) {
  restart_estimates();
  return {};
}

// The daemon's settings table (daemon_settings.hpp) says which keys are live; each has a row above.
std::string ControlLoop::refuse_daemon_key(const std::string& key, double) const {
  static const std::string tunable = live_daemon_keys();
  return key + ": not tunable at run time (tunable: " + tunable + ")";
}

std::string ControlLoop::refuse_optimizer_key(const std::string& key, double) const {
  return key + ": optimizer settings are fixed for a run (restart with --set); tunable: model.*, cost.*";
}

std::string ControlLoop::set_task_param(const std::string& key, double v) {
  std::string err = c_->set_param(key, v);
  // A new model.mass is the mass estimate's new nominal (else the next estimate overwrites it).
  if (err.empty() && key == "model.mass") estimators_.set_nominal_mass(*c_, static_cast<float>(v));
  return err;
}

}  // namespace mppi::daemon
