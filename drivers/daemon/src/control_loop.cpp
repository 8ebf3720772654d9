// ControlLoop: the cycle, its paths and the sends, and the glue between the collaborators
// that own the state (control_loop.hpp lists them). The parameter table is in
// loop_params.cpp, live optimizer updates in control_loop_live.cpp.
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

OutputSettings output_settings(const LoopSettings& s, const Controller& c) {
  OutputSettings o;
  o.rate_hz = s.rate_hz;
  o.status_hz = s.status_hz;
  o.plan_hz = s.plan_hz;
  o.command_kind = s.command_kind >= 0 ? s.command_kind : command_kind_for(c.task());
  o.failsafe_u = s.failsafe_u;
  o.rollouts = s.rollouts;
  return o;
}

std::unique_ptr<Pacing> make_pacing(const LoopSettings& s, const PacingContext& ctx, std::int64_t period_ns) {
  if (s.lockstep) return std::make_unique<LockStepPacing>(ctx, s.lockstep_poll_ns);
  return std::make_unique<RealTimePacing>(ctx, period_ns, s.trigger == Trigger::kState, s.state_trigger_min_gap,
                                          s.state_trigger_grace);
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
      period_ns_(std::llround(1e9 / s_.rate_hz)),
      monitor_(period_ns_),
      pacing_(make_pacing(s_, {clock, inbox, &monitor_, &counters_, {s_.latency.use_sample_time, s_.latency.future_tolerance_ns}},
                          period_ns_)),
      outputs_(transport, &counters_, *controller, output_settings(s_, *controller)),
      feed_(controller->vehicles(), s_.map_timeout_ns),
      plan_(controller),
      u_(static_cast<std::size_t>(controller->nu())),
      act_(s_.latency, *controller),
      estimators_(s_.disturbance, s_.latency.delay_estimate, *controller, actuator_states(s_, *controller)),
      manoeuvre_(s_.identification, controller->settings().u_min, controller->settings().u_max),
      work_(s_.work, period_ns_) {
  s_.command_kind = outputs_.kind();
  counters_.actuation_delay_ns.store(s_.latency.actuation_delay_ns, std::memory_order_relaxed);
  if (s_.deadline_guard && !s_.lockstep)
    guard_ = std::make_unique<DeadlineGuard>(guard_settings(s_, period_ns_),
                                             guard_clock != nullptr ? guard_clock : &own_guard_clock_,
                                             outputs_.command_out(), &counters_, plan_.held(), outputs_.failsafe());
}

ControlLoop::~ControlLoop() = default;

void ControlLoop::prepare() {
  if (guard_) guard_->start();
}

void ControlLoop::start() {
  prepare();
  pacing_->start(clock_->now_ns());
  outputs_.set_heartbeat(clock_->now_ns());
}

void ControlLoop::run(const std::atomic<bool>& stop, std::int64_t max_cycles) {
  if (!pacing_->started()) start();
  for (std::int64_t n = 0; (max_cycles < 0 || n < max_cycles) && !stop.load(std::memory_order_relaxed);)
    if (step(stop)) ++n;
}

bool ControlLoop::step(const std::atomic<bool>& stop) {
  if (!pacing_->started()) start();
  CycleTimes t;
  switch (pacing_->wait(stop, &t)) {
    case Pacing::Wait::kCycle: cycle(t); return true;
    case Pacing::Wait::kResend:  // a lock-step tick answered already: its answer again
      outputs_.resend_last();
      return false;
    case Pacing::Wait::kStopped:
    case Pacing::Wait::kDrop: return false;
  }
  return false;
}


// One control cycle, as it runs: take what arrived and the newest state; decide (failsafe,
// hold the plan, or optimise from a fresh state); publish what came of it; settle the plan
// on it; then the bookkeeping (timing, health, status, displays).
void ControlLoop::cycle(const CycleTimes& t) {
  const std::int64_t t0 = pacing_->compute_start(t.start_ns);
  apply_between_cycles();
  const CycleState s = act_.read(*in_, *pacing_, t.now_state_ns, last_state_seq_used_);
  const Outcome outcome = decide(s, t.deadline_ns);
  const Mode published = send(outcome, s, t0);
  plan_.settle(outcome);
  account(s, t.start_ns, t0, published);
}

Outcome ControlLoop::decide(const CycleState& s, std::int64_t deadline_ns) {
  switch (check_state(s.have, s.age_ns, s.future, s_.state_timeout_ns, s_.failsafe_timeout_ns)) {
    case StateCheck::kFailsafe: return enter_failsafe();
    case StateCheck::kHold: return hold_stale(s);
    case StateCheck::kFresh: return optimize(s, deadline_ns);
  }
  return enter_failsafe();
}

// What goes out: the failsafe; the held plan's step due now (a stale state, a bad, missing
// or late update: the optimizer's output is never published then); nothing, when the guard
// published the held plan through a stall; or the update's command.
Mode ControlLoop::send(Outcome outcome, const CycleState& s, std::int64_t t0) {
  switch (outcome) {
    case Outcome::kFailsafe: return send_failsafe(s, t0);
    case Outcome::kGuardCovered: return Mode::kHoldPlan;
    case Outcome::kStale:
    case Outcome::kBadUpdate:
    case Outcome::kAnytimeHold:
    case Outcome::kLate: return send_held(s, t0);
    case Outcome::kFresh: return send_fresh(s, t0);
  }
  return send_failsafe(s, t0);
}

// No state, or one past the failsafe timeout. On entry the plan is too old to mean anything
// when the state comes back: start over.
Outcome ControlLoop::enter_failsafe() {
  if (outputs_.mode() == Mode::kFailsafe) return Outcome::kFailsafe;
  plan_.restart();
  forget_estimates();
  return Outcome::kFailsafe;
}

Outcome ControlLoop::hold_stale(const CycleState& s) {
  counters_.stale_cycles.fetch_add(1, std::memory_order_relaxed);
  if (s.future) counters_.future_states.fetch_add(1, std::memory_order_relaxed);
  if (act_.compensate()) counters_.plan_skips.fetch_add(plan_.align(s.t_act_ns), std::memory_order_relaxed);
  plan_.advance();  // keep the warm start aligned with time
  return Outcome::kStale;
}

// A fresh state: predict it to when the command acts, run one update (under the deadline
// guard in real time) and say what came of it.
// (Lock-step has no guard, and its deadline is never missed.)
Outcome ControlLoop::optimize(const CycleState& s, std::int64_t deadline_ns) {
  const float* x0 = predict_to_act(s);
  monitor_.record_age(s.age_ns);
  work_.before_update(*c_);  // the rollout count this update runs
  const bool guarded = guard_ != nullptr && guard_->running();
  if (guarded && guard_->anytime()) c_->set_stop_flag(guard_->next_stop_flag());
  if (guarded) guard_->arm(deadline_ns, s.seq, plan_.held());
  const std::int64_t optimize_start = clock_->now_ns();
  const bool good = run_optimizer(x0);
  const std::int64_t done = clock_->now_ns();
  monitor_.record_optimize(done - optimize_start);
  work_.after_update(done - optimize_start);
  const int guard_steps = guarded ? guard_->disarm() : 0;
  const Outcome o = choose_outcome(guard_steps > 0, good, plan_.last_stats().updated, done > deadline_ns);
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
    const UpdateStats& stats = plan_.iterate(x0, u_.data());
    if (stats.partial) counters_.partial_updates.fetch_add(1, std::memory_order_relaxed);
    if (!stats.finite) {
      counters_.optimizer_nonfinite.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    if (!outputs_.passes(u_.data())) {
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
  for (int i = 0; i < steps; ++i) act_.remember_sent(deadline_ns + i * period_ns_, guard_->step(i));
  consecutive_bad_updates_ = good ? 0 : consecutive_bad_updates_ + 1;
  plan_.take_back(steps, good);
}

// The state to optimise from. A new sample first teaches the loop what the last prediction
// missed (adapt_to). Latency compensation: the state as it will be when this command acts,
// predicted through the commands already sent.
const float* ControlLoop::predict_to_act(const CycleState& s) {
  if (s.new_sample) adapt_to(s);
  if (!act_.compensate()) {
    plan_.detach();
    return s.x->x;
  }
  counters_.plan_skips.fetch_add(plan_.align(s.t_act_ns), std::memory_order_relaxed);
  const float* x = act_.predict(*c_, s);
  monitor_.record_lead(s.lead_ns);
  // A moving reference is compared with the predicted state at the predicted state's time:
  // the reference at t_act, not at the sample time (else a lag of `lead` at its speed).
  feed_.reference_at_lead(*c_, *s.x, s.lead_ns);
  return x;
}

// What the new state teaches: the disturbance and mass estimates, the actuation delay.
void ControlLoop::adapt_to(const CycleState& s) {
  if (estimators_.learn(*c_, act_.history(), s.x->x, s.t_state_ns, act_.actuation_delay_ns())) {
    act_.set_actuation_delay_ns(estimators_.delay_ns());
    counters_.actuation_delay_ns.store(estimators_.delay_ns(), std::memory_order_relaxed);
  }
}

// What the commands sent so far taught: the command history they are predicted through, the
// disturbance and mass estimates, the delay estimate's window (its delay stays).
void ControlLoop::forget_estimates() {
  act_.forget_commands();
  estimators_.forget(*c_);
}

// The commands sent so far were not flown (an autopilot flew its own take-off until the bridge
// engaged: it asks for this then). What the estimates learnt from them goes: the disturbance,
// the mass, the delay (back to the settings'), and the command history they predict through.
void ControlLoop::restart_estimates() {
  forget_estimates();
  act_.set_actuation_delay_ns(act_.configured_actuation_delay_ns());
  counters_.actuation_delay_ns.store(act_.configured_actuation_delay_ns(), std::memory_order_relaxed);
}

// ---- the sends: stamp the timing, publish, remember what went out (the command history) --

Mode ControlLoop::send_failsafe(const CycleState& s, std::int64_t t0) {
  outputs_.stamp_timing(s.have ? s.age_ns : 0, clock_->now_ns() - t0, 0, c_->active_rollouts());
  if (outputs_.publish_failsafe(s.seq)) act_.remember_sent(sent_ns(s.now_ns, t0), outputs_.failsafe().data());
  return Mode::kFailsafe;
}

// The held plan's step due now (the plan has moved on past it). Returns the mode actually
// published: the failsafe if the held step fails the gate. The command history records what
// went out: the failsafe then, not the refused step (nothing, if the failsafe was blocked too).
Mode ControlLoop::send_held(const CycleState& s, std::int64_t t0) {
  outputs_.stamp_timing(s.age_ns, clock_->now_ns() - t0, 0, c_->active_rollouts());
  std::copy_n(plan_.due(), u_.size(), u_.data());
  if (outputs_.publish(Mode::kHoldPlan, u_.data(), s.seq)) {
    act_.remember_sent(sent_ns(s.now_ns, t0), u_.data());
    return Mode::kHoldPlan;
  }
  if (outputs_.publish_failsafe(s.seq)) act_.remember_sent(sent_ns(s.now_ns, t0), outputs_.failsafe().data());
  return Mode::kFailsafe;
}

Mode ControlLoop::send_fresh(const CycleState& s, std::int64_t t0) {
  manoeuvre_.excite(s.x->x, s.now_ns, u_.data());  // the identification manoeuvre, when asked for
  outputs_.stamp_timing(s.age_ns, clock_->now_ns() - t0, s.lead_ns, c_->active_rollouts());
  const Mode m = outputs_.publish(Mode::kNormal, u_.data(), s.seq) ? Mode::kNormal : Mode::kFailsafe;
  const std::int64_t sent = sent_ns(s.now_ns, t0);
  // In lock-step the plant's clock stands still while the controller computes, and the
  // simulator charges its latency: the command acts when the controller expected it
  // to (exactly, when the latency charged is fixed and the estimator pinned to it, so
  // the run repeats bit for bit). In real time it acts after the measured latency.
  act_.record(pacing_->command_acts_ns(s.t_act_ns, act_.acts_after_sent(sent)), u_.data());
  // What the estimator learns: this cycle's start to its command out.
  if (!act_.learn(sent - s.now_ns)) counters_.latency_rejected.fetch_add(1, std::memory_order_relaxed);
  if (s.new_sample) monitor_.record_latency(sent - s.t_state_ns);
  return m;
}

// ---- after the command: timing, health, status, plan --------------------------------

void ControlLoop::account(const CycleState& s, std::int64_t start_ns, std::int64_t t0, Mode published) {
  outputs_.set_mode(published);
  const std::int64_t heartbeat = pacing_->finish(start_ns, t0, clock_->now_ns());
  ++cycle_index_;
  const bool loop_ok = monitor_.consecutive_misses() < s_.watchdog_max_consecutive_misses &&
                       consecutive_bad_updates_ < s_.watchdog_max_optimizer_errors;
  outputs_.note_cycle(monitor_, loop_ok, heartbeat);
  maybe_status(false);
  outputs_.maybe_plan(*c_, cycle_index_, published, plan_.held(), s.seq, s.x->x);
  outputs_.after_cycle_rollouts(*c_, cycle_index_ - 1, s.seq, published == Mode::kNormal);
}

void ControlLoop::maybe_status(bool force) {
  if (!outputs_.status_due(cycle_index_, force)) return;
  outputs_.publish_status({monitor_.window(), act_.estimate_ns(), estimators_.disturbance(), c_->mass(),
                           act_.actuation_delay_ns(), plan_.last_stats(), in_->counters, c_->active_rollouts(),
                           work_.changes()});
  monitor_.reset_window();
}

void ControlLoop::publish_final_status() {
  // The forced status reports the mode; the final one is unhealthy.
  outputs_.set_unhealthy();
  maybe_status(true);
}

void ControlLoop::apply_between_cycles() {
  const bool new_state = in_->state.update();
  apply_due_params();
  if (live_ != nullptr) service_live();
  const bool new_ref = in_->reference.update();
  const bool new_obs = in_->obstacles.update();
  const bool new_map = in_->map != nullptr && in_->map->update();
  if (new_state || new_ref || new_obs || new_map) feed_.update(*in_, *c_, counters_, {new_ref, new_obs, new_map});
  feed_.note_map_age(*in_, counters_);
}

// The updates that arrived are held until the state time they name (0: none); those due at the
// newest state are applied, in the order they came.
void ControlLoop::apply_due_params() {
  transport::ParamUpdate p;
  while (in_->params.pop(&p)) {
    if (params_.hold(p)) continue;
    counters_.params_rejected.fetch_add(1, std::memory_order_relaxed);
    answer_param(p, false, std::string(p.key) + ": too many updates waiting for their time");
  }
  while (params_.pop_due(in_->state.front().sample_utime, &p)) {
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
}

}  // namespace mppi::daemon
