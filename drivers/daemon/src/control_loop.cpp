// ControlLoop: the cycle, its paths and the sends. The rooms around it: what starts a cycle
// (loop_trigger.cpp), when its command acts (act_time.cpp), the task inputs
// (task_inputs.cpp), what a state teaches (adaptation.cpp), the status (loop_status.cpp),
// the parameter table (loop_params.cpp), live optimizer updates (control_loop_live.cpp); the
// plan's time (PlanTimeline) and the deadline guard (DeadlineGuard) are classes of their own.
#include "mppi/daemon/control_loop.hpp"

#include "mppi/daemon/daemon_settings.hpp"

#include <cstdint>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <exception>

namespace mppi::daemon {

using transport::Mode;

namespace {
constexpr std::int8_t kMotorSpeeds = 1, kThrustRates = 2;  // command_t::KIND_*

// The states that answer a command first, for the actuation delay estimate: the motors'
// speeds (16-state quadrotor, at 12..15 of each vehicle) or the body rates the autopilot's
// rate loop tracks (rate model, 10..12); none for the other models.
std::vector<int> actuator_states(const LoopSettings& s, const Controller& c) {
  const std::int8_t kind = s.command_kind >= 0 ? s.command_kind : command_kind_for(c.task());
  const int first = kind == kMotorSpeeds ? 12 : kind == kThrustRates ? 10 : -1;
  const int count = kind == kMotorSpeeds ? 4 : 3;
  const int vnx = c.nx() / c.vehicles();
  std::vector<int> out;
  if (first < 0 || first + count > vnx) return out;
  for (int j = 0; j < c.vehicles(); ++j)
    for (int i = 0; i < count; ++i) out.push_back(j * vnx + first + i);
  return out;
}

std::int64_t every(double rate_hz, double sub_hz) {
  if (sub_hz <= 0.0) return 0;
  return std::max<std::int64_t>(1, std::llround(rate_hz / sub_hz));
}

GuardSettings guard_settings(const LoopSettings& s, std::int64_t period_ns) {
  GuardSettings g;
  g.period_ns = period_ns;
  g.failsafe_timeout_ns = s.failsafe_timeout_ns;
  g.anytime_margin_ns = s.anytime_margin_ns;
  g.fifo_priority = s.guard_fifo_priority;
  return g;
}
}  // namespace

ControlLoop::ControlLoop(Controller* controller, rt::Clock* clock, transport::Transport* transport,
                         transport::Inbox* inbox, LoopSettings settings, rt::Clock* guard_clock)
    : c_(controller),
      clock_(clock),
      tx_(transport),
      in_(inbox),
      s_(std::move(settings)),
      nu_(controller->nu()),
      period_ns_(std::llround(1e9 / s_.rate_hz)),
      status_every_(every(s_.rate_hz, s_.status_hz)),
      plan_every_(every(s_.rate_hz, s_.plan_hz)),
      rollouts_(s_.rollouts, s_.rate_hz, c_->vehicles(), c_->horizon()),
      schedule_(period_ns_),
      monitor_(period_ns_),
      out_(transport, &counters_, controller->settings().u_min, controller->settings().u_max, nu_,
           s_.command_kind >= 0 ? s_.command_kind : command_kind_for(controller->task())),
      obstacle_order_(transport::kMaxObstaclesIn),
      distances_(transport::kMaxObstaclesIn),
      plan_(controller),
      u_(static_cast<std::size_t>(nu_)),
      failsafe_(s_.failsafe_u.empty() ? controller->settings().u_init : s_.failsafe_u),
      latency_(s_.latency.estimator),
      history_(nu_, controller->settings().u_init),
      x_pred_(static_cast<std::size_t>(controller->nx())),
      x_lag_(static_cast<std::size_t>(controller->nx())),
      observer_(s_.disturbance, controller->vehicles(), controller->nx() / controller->vehicles(), controller->mass()),
      delays_(s_.latency.delay_estimate, controller->nx(), actuator_states(s_, *controller)),
      manoeuvre_(s_.identification, controller->settings().u_min, controller->settings().u_max),
      work_(s_.work, period_ns_) {
  s_.command_kind = out_.kind();
  configured_delay_ns_ = s_.latency.actuation_delay_ns;
  counters_.actuation_delay_ns.store(s_.latency.actuation_delay_ns, std::memory_order_relaxed);
  inputs_.vehicle_count = controller->vehicles();
  status_.backend = c_->backend();
  status_.task = c_->task().c_str();
  status_.rollouts = c_->settings().rollouts;
  status_.horizon = c_->horizon();
  latency_estimate_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
  // Only models with an external acceleration (the quadrotors) take the observer's estimate.
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  observe_ = s_.disturbance.estimate && c_->set_external_accel(zero);
  if (s_.deadline_guard && !s_.lockstep)
    guard_ = std::make_unique<DeadlineGuard>(guard_settings(s_, period_ns_),
                                             guard_clock != nullptr ? guard_clock : &own_guard_clock_, &out_,
                                             &counters_, plan_.held(), failsafe_);
}

ControlLoop::~ControlLoop() = default;

void ControlLoop::prepare() {
  if (guard_) guard_->start();
}

void ControlLoop::remember(std::int64_t sent_ns, const float* u) {
  history_.add(sent_ns + s_.latency.transport_ns + s_.latency.actuation_delay_ns, u);
}

// One control cycle, as it runs: check the state; optimise from a fresh one; publish what
// came of it; then the bookkeeping (timing, health, status, plan).
void ControlLoop::cycle(std::int64_t start_ns, std::int64_t deadline_ns, std::int64_t now_state_ns, bool lockstep) {
  const std::int64_t t0 = lockstep ? clock_->now_ns() : start_ns;
  apply_between_cycles();
  const CycleState s = read_state(now_state_ns, lockstep);

  Outcome outcome = Outcome::kFailsafe;
  switch (check_state(s.have, s.age_ns, s.future, s_.state_timeout_ns, s_.failsafe_timeout_ns)) {
    case StateCheck::kFailsafe: outcome = enter_failsafe(); break;
    case StateCheck::kHold: outcome = hold_stale(s); break;
    case StateCheck::kFresh: outcome = optimize(s, deadline_ns, lockstep); break;
  }

  Mode published = Mode::kHoldPlan;
  switch (outcome) {
    case Outcome::kFailsafe:
      published = send_failsafe(s, t0);
      break;
    case Outcome::kStale:  // the plan moved a step on (hold_stale)
      published = send_held(s, t0);
      break;
    case Outcome::kGuardCovered:
      break;  // the guard published the held plan, one step per period
    case Outcome::kBadUpdate:
    case Outcome::kAnytimeHold:
      // The optimizer's plan may hold NaN (or is not updated): it restarts from the held
      // plan, the last good one shifted in step with what went out.
      published = send_held(s, t0);
      plan_.revert();
      break;
    case Outcome::kLate:
      published = send_held(s, t0);
      plan_.adopt();  // the late update is the plan to fall back on
      break;
    case Outcome::kFresh:
      published = send_fresh(s, t0, lockstep);
      break;
  }
  account(s, start_ns, t0, published, lockstep);
}

// No state, or one past the failsafe timeout. On entry the plan is too old to mean anything
// when the state comes back: start over.
Outcome ControlLoop::enter_failsafe() {
  if (mode_.load(std::memory_order_relaxed) == Mode::kFailsafe) return Outcome::kFailsafe;
  plan_.restart();
  forget_estimates();
  return Outcome::kFailsafe;
}

Outcome ControlLoop::hold_stale(const CycleState& s) {
  counters_.stale_cycles.fetch_add(1, std::memory_order_relaxed);
  if (s.future) counters_.future_states.fetch_add(1, std::memory_order_relaxed);
  if (s_.latency.compensate) counters_.plan_skips.fetch_add(plan_.align(s.t_act_ns), std::memory_order_relaxed);
  plan_.advance();  // keep the warm start aligned with time
  return Outcome::kStale;
}

// A fresh state: predict it to when the command acts, run one update (under the deadline
// guard in real time) and say what came of it.
Outcome ControlLoop::optimize(const CycleState& s, std::int64_t deadline_ns, bool lockstep) {
  const float* x0 = predict_to_act(s);
  monitor_.record_age(s.age_ns);
  work_.before_update(*c_);  // the rollout count this update runs
  const bool guarded = guard_ != nullptr && guard_->running() && !lockstep;
  if (guarded && guard_->anytime()) c_->set_stop_flag(guard_->next_stop_flag());
  if (guarded) guard_->arm(deadline_ns, s.seq, plan_.held());
  const std::int64_t optimize_start = clock_->now_ns();
  const bool good = run_optimizer(x0);
  const std::int64_t done = clock_->now_ns();
  monitor_.record_optimize(done - optimize_start);
  work_.after_update(done - optimize_start);
  const int guard_steps = guarded ? guard_->disarm() : 0;
  const Outcome o = choose_outcome(guard_steps > 0, good, last_stats_.updated, !lockstep && done > deadline_ns);
  if (o == Outcome::kGuardCovered) take_back_from_guard(guard_steps, good, deadline_ns);
  else consecutive_bad_updates_ = o == Outcome::kBadUpdate ? consecutive_bad_updates_ + 1 : 0;
  if (o == Outcome::kGuardCovered || o == Outcome::kLate) counters_.late_holds.fetch_add(1, std::memory_order_relaxed);
  if (o == Outcome::kAnytimeHold) counters_.anytime_holds.fetch_add(1, std::memory_order_relaxed);
  last_state_seq_used_ = s.seq;
  return o;
}

// One update into u_ (the plan's time moves a step on with it); true when it is finite and
// inside the limits (the command gate).
bool ControlLoop::run_optimizer(const float* x0) {
  try {
    last_stats_ = plan_.iterate(x0, u_.data());
    if (last_stats_.partial) counters_.partial_updates.fetch_add(1, std::memory_order_relaxed);
    if (!last_stats_.finite) {
      counters_.optimizer_nonfinite.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    if (!out_.passes(u_.data())) {
      counters_.gate_rejects.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    return true;
  } catch (const std::exception& e) {
    counters_.optimizer_errors.fetch_add(1, std::memory_order_relaxed);
    spdlog::error("optimizer error: {}", e.what());
    return false;
  }
}

// The guard covered the stall with the held plan, one step per period from the deadline;
// this late result is not published. The command history and the held plan follow what
// went out; a good update still becomes the plan to fall back on.
void ControlLoop::take_back_from_guard(int steps, bool good, std::int64_t deadline_ns) {
  for (int i = 0; i < steps; ++i) remember(deadline_ns + i * period_ns_, guard_->step(i));
  consecutive_bad_updates_ = good ? 0 : consecutive_bad_updates_ + 1;
  plan_.take_back(steps, good);
}

// ---- the sends: stamp the timing, publish, remember what went out (the command history) --

Mode ControlLoop::send_failsafe(const CycleState& s, std::int64_t t0) {
  stamp_timing(s.have ? s.age_ns : 0, clock_->now_ns() - t0, 0);
  if (publish_failsafe(s.seq)) remember(sent_ns(s.now_ns, t0), failsafe_.data());
  return Mode::kFailsafe;
}

// The held plan's step due now (the plan has moved on past it). Returns the mode actually
// published: the failsafe if the held step fails the gate. The command history records what
// went out: the failsafe then, not the refused step (nothing, if the failsafe was blocked too).
Mode ControlLoop::send_held(const CycleState& s, std::int64_t t0) {
  stamp_timing(s.age_ns, clock_->now_ns() - t0, 0);
  std::copy_n(plan_.due(), nu_, u_.data());
  if (publish(Mode::kHoldPlan, u_.data(), s.seq)) {
    remember(sent_ns(s.now_ns, t0), u_.data());
    return Mode::kHoldPlan;
  }
  if (publish_failsafe(s.seq)) remember(sent_ns(s.now_ns, t0), failsafe_.data());
  return Mode::kFailsafe;
}

Mode ControlLoop::send_fresh(const CycleState& s, std::int64_t t0, bool lockstep) {
  manoeuvre_.excite(s.x->x, s.now_ns, u_.data());  // the identification manoeuvre, when asked for
  stamp_timing(s.age_ns, clock_->now_ns() - t0, s.lead_ns);
  const Mode m = publish(Mode::kNormal, u_.data(), s.seq) ? Mode::kNormal : Mode::kFailsafe;
  const std::int64_t sent = sent_ns(s.now_ns, t0);
  // In lock-step the plant's clock stands still while the controller computes, and the
  // simulator charges its latency: the command acts when the controller expected it
  // to (exactly, when the latency charged is fixed and the estimator pinned to it, so
  // the run repeats bit for bit). In real time it acts after the measured latency.
  const LatencySettings& ls = s_.latency;
  remember(lockstep ? s.t_act_ns - ls.transport_ns - ls.actuation_delay_ns : sent, u_.data());
  plan_.adopt();
  // What the estimator learns: this cycle's start to its command out.
  if (!latency_.add(sent - s.now_ns)) counters_.latency_rejected.fetch_add(1, std::memory_order_relaxed);
  latency_estimate_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
  if (s.new_sample) monitor_.record_latency(sent - s.t_state_ns);
  return m;
}

bool ControlLoop::publish(Mode mode, const float* u, std::int64_t state_seq) {
  if (!out_.passes(u)) return false;
  out_.send(&cmd_, mode, u, state_seq);
  return true;
}

bool ControlLoop::publish_failsafe(std::int64_t state_seq) {
  if (publish(Mode::kFailsafe, failsafe_.data(), state_seq)) return true;
  counters_.commands_blocked.fetch_add(1, std::memory_order_relaxed);
  return false;
}

void ControlLoop::stamp_timing(std::int64_t age_ns, std::int64_t compute_ns, std::int64_t lead_ns) {
  auto us = [](std::int64_t ns) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(ns / rt::kNsPerUs, 0, INT32_MAX));
  };
  cmd_.age_us = us(age_ns);
  cmd_.compute_us = us(compute_ns);
  cmd_.lead_us = us(lead_ns);
  cmd_.rollouts = c_->active_rollouts();
}

// ---- after the command: timing, health, status, plan --------------------------------

void ControlLoop::account(const CycleState& s, std::int64_t start_ns, std::int64_t t0, Mode published, bool lockstep) {
  set_mode(published);
  const std::int64_t end = clock_->now_ns();
  if (lockstep) {
    monitor_.record(start_ns, start_ns + (end - t0), false);
  } else {
    const bool missed = schedule_.finish(end);
    monitor_.record(start_ns, end, missed);
  }
  ++cycle_index_;

  const bool loop_ok = monitor_.consecutive_misses() < s_.watchdog_max_consecutive_misses &&
                       consecutive_bad_updates_ < s_.watchdog_max_optimizer_errors;
  loop_healthy_.store(loop_ok, std::memory_order_relaxed);
  snap_cycles_.store(monitor_.cycles(), std::memory_order_relaxed);
  snap_misses_.store(monitor_.misses(), std::memory_order_relaxed);
  snap_consecutive_.store(monitor_.consecutive_misses(), std::memory_order_relaxed);
  heartbeat_ns_.store(lockstep ? clock_->now_ns() : end, std::memory_order_relaxed);

  maybe_status(published != last_status_mode_);
  if (plan_every_ > 0 && cycle_index_ % plan_every_ == 0 && published == Mode::kNormal) maybe_plan(s.seq, s.x->x);
  rollouts_.after_cycle(*c_, *tx_, cycle_index_ - 1, s.seq, published == Mode::kNormal);
}

void ControlLoop::apply_between_cycles() {
  transport::ParamUpdate p;
  while (in_->params.pop(&p)) {
    if (forward_live_param(p)) continue;  // the builder answers
    const std::string err = apply_param(p);
    if (err.empty()) {
      counters_.params_applied.fetch_add(1, std::memory_order_relaxed);
      spdlog::info("parameter {} = {} applied (update seq {})", p.key, p.value, p.seq);
    } else {
      counters_.params_rejected.fetch_add(1, std::memory_order_relaxed);
      spdlog::warn("parameter update seq {} rejected: {}", p.seq, err);
    }
    answer_param(p, err.empty(), err);
  }
  if (live_ != nullptr) service_live();
  const bool new_state = in_->state.update();
  const bool new_ref = in_->reference.update();
  const bool new_obs = in_->obstacles.update();
  const bool new_map = in_->map != nullptr && in_->map->update();
  if (new_state || new_ref || new_obs || new_map) update_inputs(in_->state.front(), new_ref, new_obs, new_map);
  note_map_age();
}

}  // namespace mppi::daemon
