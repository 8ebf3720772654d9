#include "mppi/daemon/control_loop.hpp"

#include "mppi/daemon/daemon_settings.hpp"

#include <cstdint>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <pthread.h>
#include <sched.h>

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
}  // namespace

ControlLoop::ControlLoop(Controller* controller, rt::Clock* clock, transport::Transport* transport,
                         transport::Inbox* inbox, LoopSettings settings)
    : c_(controller),
      clock_(clock),
      tx_(transport),
      in_(inbox),
      s_(std::move(settings)),
      nu_(controller->nu()),
      horizon_(controller->horizon()),
      period_ns_(std::llround(1e9 / s_.rate_hz)),
      status_every_(every(s_.rate_hz, s_.status_hz)),
      plan_every_(every(s_.rate_hz, s_.plan_hz)),
      rollouts_(s_.rollouts, s_.rate_hz, c_->vehicles(), c_->horizon()),
      schedule_(period_ns_),
      monitor_(period_ns_),
      gate_(controller->settings().u_min, controller->settings().u_max),
      obstacle_order_(transport::kMaxObstaclesIn),
      distances_(transport::kMaxObstaclesIn),
      held_(controller->horizon(), controller->settings().u_init),
      u_(static_cast<std::size_t>(nu_)),
      u_init_(controller->settings().u_init),
      latency_(s_.latency.estimator),
      history_(nu_, controller->settings().u_init),
      dt_ns_(std::llround(static_cast<double>(controller->dt()) * 1e9)),
      x_pred_(static_cast<std::size_t>(controller->nx())),
      observer_(s_.disturbance, controller->vehicles(), controller->nx() / controller->vehicles(), controller->mass()),
      delays_(s_.latency.delay_estimate, controller->nx(), actuator_states(s_, *controller)),
      manoeuvre_(s_.identification, controller->settings().u_min, controller->settings().u_max) {
  held_.assign(c_->plan());
  failsafe_ = s_.failsafe_u.empty() ? u_init_ : s_.failsafe_u;
  if (s_.command_kind < 0) s_.command_kind = command_kind_for(controller->task());
  configured_delay_ns_ = s_.latency.actuation_delay_ns;
  counters_.actuation_delay_ns.store(s_.latency.actuation_delay_ns, std::memory_order_relaxed);
  inputs_.vehicle_count = controller->vehicles();
  status_.backend = c_->backend();
  status_.task = c_->task().c_str();
  status_.rollouts = c_->settings().rollouts;
  status_.horizon = horizon_;
  latency_estimate_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
  // Only models with an external acceleration (the quadrotors) take the observer's estimate.
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  observe_ = s_.disturbance.estimate && c_->set_external_accel(zero);
}

bool ControlLoop::is_loop_param(const std::string& key) { return key.rfind("daemon.", 0) == 0; }

ControlLoop::~ControlLoop() {
  guard_quit_.store(true);
  guard_wake_.post();
  if (guard_thread_.joinable()) guard_thread_.join();
}

void ControlLoop::prepare() {
  if (s_.deadline_guard && !s_.lockstep && !guard_thread_.joinable()) {
    guard_plan_.assign(held_.size(), 0.0f);
    anytime_ = s_.anytime_margin_ns > 0;
    guard_thread_ = std::thread([this] { guard_main(); });
  }
}

void ControlLoop::start() {
  prepare();
  schedule_.start(clock_->now_ns());
  heartbeat_ns_.store(clock_->now_ns(), std::memory_order_relaxed);
  started_ = true;
}

void ControlLoop::run(const std::atomic<bool>& stop, std::int64_t max_cycles) {
  if (!started_) start();
  for (std::int64_t n = 0; (max_cycles < 0 || n < max_cycles) && !stop.load(std::memory_order_relaxed);) {
    const bool ran = s_.lockstep ? step_lockstep(stop) : step_realtime(stop);
    if (ran) ++n;
  }
}

bool ControlLoop::step_realtime(const std::atomic<bool>& stop) {
  if (!started_) start();
  if (s_.trigger == Trigger::kState) return step_state_triggered(stop);
  // Absolute-time sleep; an early return (a signal) re-checks stop and sleeps again.
  std::int64_t now = clock_->now_ns();
  while (now < schedule_.next_release_ns()) {
    if (stop.load(std::memory_order_relaxed)) return false;
    clock_->sleep_until(schedule_.next_release_ns());
    now = clock_->now_ns();
  }
  if (stop.load(std::memory_order_relaxed)) return false;
  schedule_.begin(now);
  cycle(now, schedule_.deadline_ns(), now, false);
  return true;
}

bool ControlLoop::step_state_triggered(const std::atomic<bool>& stop) {
  const std::int64_t period = schedule_.period_ns(), next = schedule_.next_release_ns();
  const auto part = [&](double f) { return static_cast<std::int64_t>(f * static_cast<double>(period)); };
  // next is a period after the last cycle's start (or the end of a late cycle, or the start).
  // A new state starts a cycle if it came min_gap periods after the last start, or at once
  // after a cycle the grace started (states slower than the rate: each one is awaited). With
  // none, the grace runs out: after a state's cycle `grace` past the grid time, after the
  // grace's own cycle on the grid (no state: the stale path at rate_hz).
  const std::int64_t earliest = grace_started_ ? INT64_MIN : next - period + part(s_.state_trigger_min_gap);
  const std::int64_t latest = grace_started_ ? next : next + part(s_.state_trigger_grace);
  std::int64_t now = clock_->now_ns();
  for (;;) {
    if (stop.load(std::memory_order_relaxed)) return false;
    const std::int64_t got = in_->last_state_recv_ns();
    if (got >= earliest && got > trigger_recv_ns_) {
      counters_.state_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;
      grace_started_ = false;
      break;
    }
    if (now >= latest) {
      counters_.clock_triggered.fetch_add(1, std::memory_order_relaxed);
      trigger_recv_ns_ = got;  // an older state never starts a cycle later
      grace_started_ = true;
      break;
    }
    clock_->sleep_until_or(in_->state_wake, latest);  // each state (and a signal) re-checks
    now = clock_->now_ns();
  }
  if (!grace_started_) monitor_.record_wake(std::max<std::int64_t>(0, now - trigger_recv_ns_));
  schedule_.begin_at(now);
  cycle(now, schedule_.deadline_ns(), now, false);
  return true;
}

bool ControlLoop::step_lockstep(const std::atomic<bool>& stop) {
  transport::ClockTick tick;
  while (!in_->ticks.pop(&tick)) {
    if (stop.load(std::memory_order_relaxed)) return false;
    in_->wake.wait_for(s_.lockstep_poll_ns);
  }
  // A tick the simulator repeated (it republishes a state and its tick when no answer
  // came in time) was answered already: a second cycle on it would run the optimizer one
  // cycle ahead of the simulator and the run would no longer repeat. The answer is sent
  // again instead, in case it was the one lost. (A sequence far behind the last one is a
  // new simulator run, and is followed.)
  if (last_tick_seq_ >= 0 && tick.seq <= last_tick_seq_ && tick.seq > last_tick_seq_ - 100) {
    counters_.repeated_ticks.fetch_add(1, std::memory_order_relaxed);
    if (tick.seq == last_tick_seq_ && cmd_.seq > 0 && !tx_->publish_command(cmd_))
      counters_.publish_failures.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  last_tick_seq_ = tick.seq;
  const std::int64_t sim_ns = tick.sim_utime * rt::kNsPerUs;
  cycle(sim_ns, INT64_MAX, sim_ns, true);
  return true;
}

std::int64_t ControlLoop::state_time_ns(const transport::StateSample& x, bool lockstep, bool* future) const {
  // Lock-step: sample_utime is on the simulator's clock, as is now_state_ns.
  std::int64_t t = x.sample_utime * rt::kNsPerUs;
  std::int64_t ahead = 0;
  if (!lockstep) {
    // Real time: the loop's timeline is CLOCK_MONOTONIC. The state arrived at recv_ns; it
    // was (recv_utime - sample_utime) old then, both on this host's wall clock.
    std::int64_t in_flight = 0;
    if (s_.latency.use_sample_time && x.recv_utime != 0) in_flight = (x.recv_utime - x.sample_utime) * rt::kNsPerUs;
    ahead = -in_flight;
    t = x.recv_ns - std::max<std::int64_t>(0, in_flight);
  }
  *future = ahead > s_.latency.future_tolerance_ns;
  return t;
}

void ControlLoop::align_plan(std::int64_t t_act_ns) {
  if (plan_timed_ && dt_ns_ > 0) {
    const double steps = static_cast<double>(t_act_ns - plan_t0_ns_) / static_cast<double>(dt_ns_);
    const auto n = static_cast<int>(std::min<double>(std::floor(steps + 0.5), horizon_));
    if (n > 0) {
      c_->shift(n);
      held_.shift(n);
      counters_.plan_skips.fetch_add(n, std::memory_order_relaxed);
    }
  }
  plan_t0_ns_ = t_act_ns;
  plan_timed_ = true;
}

void ControlLoop::remember(std::int64_t sent_ns, const float* u) {
  history_.add(sent_ns + s_.latency.transport_ns + s_.latency.actuation_delay_ns, u);
}

// What the commands sent so far taught: the command history they are predicted through, the
// disturbance and mass estimates, the delay estimate's window (its delay stays).
void ControlLoop::forget_estimates() {
  history_.reset();
  if (observe_) {
    observer_.reset();
    observer_.apply(*c_);
  }
  delays_.reset();
}

// The commands sent so far were not flown (an autopilot flew its own take-off until the bridge
// engaged: it asks for this then). What the estimates learnt from them goes: the disturbance,
// the mass, the delay (back to the settings'), and the command history they predict through.
void ControlLoop::restart_estimates() {
  forget_estimates();
  s_.latency.actuation_delay_ns = configured_delay_ns_;
  counters_.actuation_delay_ns.store(configured_delay_ns_, std::memory_order_relaxed);
}

void ControlLoop::adapt_to(const float* x, std::int64_t t_state_ns) {
  // The disturbance observer compares the state with the last one predicted.
  if (observe_ && observer_.update(*c_, history_, x, t_state_ns)) observer_.apply(*c_);
  if (delays_.active() && delays_.update(*c_, history_, x, t_state_ns, s_.latency.actuation_delay_ns)) {
    s_.latency.actuation_delay_ns = delays_.delay_ns();
    counters_.actuation_delay_ns.store(s_.latency.actuation_delay_ns, std::memory_order_relaxed);
  }
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
    case Outcome::kStale:
      published = send_held(s, t0);
      c_->fallback(u_.data());  // keep the warm start aligned with time
      plan_t0_ns_ += dt_ns_;
      break;
    case Outcome::kGuardCovered:
      break;  // the guard published the held plan, one step per period
    case Outcome::kBadUpdate:
    case Outcome::kAnytimeHold:
      // The optimizer's plan may hold NaN (or is not updated): it restarts from the held
      // plan, the last good one shifted in step with what went out.
      published = send_held(s, t0);
      c_->set_plan(held_.data());
      break;
    case Outcome::kLate:
      published = send_held(s, t0);
      held_.assign(c_->plan());  // the late update is the plan to fall back on
      break;
    case Outcome::kFresh:
      published = send_fresh(s, t0, lockstep);
      break;
  }
  account(s, start_ns, t0, published, lockstep);
}

ControlLoop::CycleState ControlLoop::read_state(std::int64_t now_state_ns, bool lockstep) const {
  CycleState s;
  s.x = &in_->state.front();
  s.have = in_->state.writes() > 0;
  s.now_ns = now_state_ns;
  // Staleness from the state's sample time (see state_time_ns): a state older than the
  // timeouts, or stamped in the future, is not predicted from.
  s.t_state_ns = s.have ? state_time_ns(*s.x, lockstep, &s.future) : 0;
  s.age_ns = s.have ? std::max<std::int64_t>(0, now_state_ns - s.t_state_ns) : INT64_MAX;
  s.seq = s.have ? s.x->seq : -1;
  s.new_sample = s.seq != last_state_seq_used_;
  // Expected latency of this cycle (start -> command out), then when its command acts. In
  // whole microseconds: command_t's lead_us then gives t_act exactly (replay).
  const LatencySettings& ls = s_.latency;
  const std::int64_t expected =
      (expected_override_ns_ >= 0 ? expected_override_ns_ : latency_.estimate_ns()) / rt::kNsPerUs * rt::kNsPerUs;
  s.t_act_ns = now_state_ns + expected + ls.transport_ns + ls.actuation_delay_ns;
  s.lead_ns = ls.compensate ? s.t_act_ns - s.t_state_ns : 0;
  return s;
}

// No state, or one past the failsafe timeout. On entry the plan is too old to mean anything
// when the state comes back: start over.
Outcome ControlLoop::enter_failsafe() {
  if (mode_.load(std::memory_order_relaxed) == Mode::kFailsafe) return Outcome::kFailsafe;
  c_->reset();
  held_.assign(c_->plan());
  plan_timed_ = false;
  forget_estimates();
  return Outcome::kFailsafe;
}

Outcome ControlLoop::hold_stale(const CycleState& s) {
  counters_.stale_cycles.fetch_add(1, std::memory_order_relaxed);
  if (s.future) counters_.future_states.fetch_add(1, std::memory_order_relaxed);
  if (s_.latency.compensate) align_plan(s.t_act_ns);
  return Outcome::kStale;
}

// A fresh state: predict it to when the command acts, run one update (under the deadline
// guard in real time) and say what came of it.
Outcome ControlLoop::optimize(const CycleState& s, std::int64_t deadline_ns, bool lockstep) {
  const float* x0 = predict_to_act(s);
  monitor_.record_age(s.age_ns);
  const bool guarded = guard_thread_.joinable() && !lockstep;
  if (anytime_) clear_anytime_stop(guarded);
  if (guarded) guard_arm(deadline_ns, s.seq);
  const std::int64_t optimize_start = clock_->now_ns();
  const bool good = run_optimizer(x0);
  const std::int64_t done = clock_->now_ns();
  monitor_.record_optimize(done - optimize_start);
  const int guard_steps = guarded ? guard_disarm() : 0;
  const Outcome o = choose_outcome(guard_steps > 0, good, last_stats_.updated, !lockstep && done > deadline_ns);
  if (o == Outcome::kGuardCovered) take_back_from_guard(guard_steps, good, deadline_ns);
  else consecutive_bad_updates_ = o == Outcome::kBadUpdate ? consecutive_bad_updates_ + 1 : 0;
  if (o == Outcome::kGuardCovered || o == Outcome::kLate) counters_.late_holds.fetch_add(1, std::memory_order_relaxed);
  if (o == Outcome::kAnytimeHold) counters_.anytime_holds.fetch_add(1, std::memory_order_relaxed);
  if (plan_timed_) plan_t0_ns_ += dt_ns_;
  last_state_seq_used_ = s.seq;
  return o;
}

// The state to optimise from. A new sample first teaches the loop what the last prediction
// missed (adapt_to). Latency compensation: the state as it will be when this command acts,
// predicted through the commands already sent.
const float* ControlLoop::predict_to_act(const CycleState& s) {
  if (s.new_sample) adapt_to(s.x->x, s.t_state_ns);
  if (!s_.latency.compensate) {
    plan_timed_ = false;
    return s.x->x;
  }
  align_plan(s.t_act_ns);
  std::copy_n(s.x->x, x_pred_.size(), x_pred_.data());
  history_.predict(*c_, x_pred_.data(), s.t_state_ns, s.t_act_ns);
  monitor_.record_lead(s.lead_ns);
  // A moving reference is compared with the predicted state at the predicted state's time:
  // the reference at t_act, not at the sample time (else a lag of `lead` at its speed).
  if (have_reference_ && inputs_.reference.kind != Reference::kHold) {
    inputs_.reference_time = static_cast<float>(static_cast<double>(s.x->sample_utime - reference_t0_utime_) * 1e-6 +
                                                static_cast<double>(s.lead_ns) * 1e-9);
    c_->set_inputs(inputs_);
  }
  return x_pred_.data();
}

// Anytime: this cycle's stop flag (guard_arm makes it cycle guard_id_ + 1), clear; none
// unguarded.
void ControlLoop::clear_anytime_stop(bool guarded) {
  std::atomic<bool>* stop = guarded ? &anytime_stop_[(guard_id_ + 1) & 1u] : nullptr;
  if (stop != nullptr) stop->store(false, std::memory_order_relaxed);
  c_->set_stop_flag(stop);
}

// One update into u_; true when it is finite and inside the limits (the command gate).
bool ControlLoop::run_optimizer(const float* x0) {
  try {
    last_stats_ = c_->iterate(x0, u_.data());
    if (last_stats_.partial) counters_.partial_updates.fetch_add(1, std::memory_order_relaxed);
    if (!last_stats_.finite) {
      counters_.optimizer_nonfinite.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    if (!gate_.pass(u_.data(), nu_)) {
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
  for (int i = 0; i < steps; ++i) remember(deadline_ns + i * period_ns_, held_.step(i));
  if (good) {
    consecutive_bad_updates_ = 0;
    held_.assign(c_->plan());
  } else {
    held_.shift(steps);
    c_->reset();
    ++consecutive_bad_updates_;
  }
  plan_timed_ = false;  // the next fresh cycle starts the plan's timeline again
}

Mode ControlLoop::send_failsafe(const CycleState& s, std::int64_t t0) {
  stamp_timing(s.have ? s.age_ns : 0, clock_->now_ns() - t0, 0);
  if (publish_failsafe(s.seq)) remember(sent_ns(s.now_ns, t0), failsafe_.data());
  return Mode::kFailsafe;
}

// The held plan's next step, then the held plan shifted (u_init appended). Returns the mode
// actually published: the failsafe if the held step fails the gate.
Mode ControlLoop::send_held(const CycleState& s, std::int64_t t0) {
  stamp_timing(s.age_ns, clock_->now_ns() - t0, 0);
  std::copy_n(held_.step(0), nu_, u_.data());
  held_.shift();
  Mode m = Mode::kHoldPlan;
  if (!publish(Mode::kHoldPlan, u_.data(), s.seq)) {
    publish_failsafe(s.seq);
    m = Mode::kFailsafe;
  }
  remember(sent_ns(s.now_ns, t0), u_.data());
  return m;
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
  held_.assign(c_->plan());
  // What the estimator learns: this cycle's start to its command out.
  if (!latency_.add(sent - s.now_ns)) counters_.latency_rejected.fetch_add(1, std::memory_order_relaxed);
  latency_estimate_ns_.store(latency_.estimate_ns(), std::memory_order_relaxed);
  if (s.new_sample) monitor_.record_latency(sent - s.t_state_ns);
  return m;
}

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
  if (new_state || new_ref || new_obs) update_inputs(in_->state.front(), new_ref, new_obs);
}

std::string ControlLoop::apply_param(const transport::ParamUpdate& p) {
  const std::string key(p.key);
  const double v = p.value;
  if (!std::isfinite(v)) return key + ": must be finite";
  if (is_loop_param(key)) {
    if (key == "daemon.restart_estimates") {
      restart_estimates();
      return {};
    }
    if (key == "daemon.identify") {
      if (s_.command_kind != kThrustRates) return key + ": the identification manoeuvre is for the rate-controlled tasks";
      manoeuvre_.request(v != 0.0);
      return {};
    }
    if (key == "daemon.state_timeout_ms") {
      if (v <= 0.0 || v * 1e6 >= static_cast<double>(s_.failsafe_timeout_ns))
        return key + ": must be > 0 and below daemon.failsafe_timeout_ms";
      s_.state_timeout_ns = std::llround(v * 1e6);
      return {};
    }
    if (key == "daemon.failsafe_timeout_ms") {
      if (v * 1e6 <= static_cast<double>(s_.state_timeout_ns) || v > 60000.0)
        return key + ": must be above daemon.state_timeout_ms and <= 60000";
      s_.failsafe_timeout_ns = std::llround(v * 1e6);
      return {};
    }
    return key + ": not tunable at run time (tunable: daemon.state_timeout_ms, daemon.failsafe_timeout_ms, "
                 "daemon.identify, daemon.restart_estimates)";
  }
  if (key.rfind("mppi.", 0) == 0)
    return key + ": optimizer settings are fixed for a run (restart with --set); tunable: model.*, cost.*";
  std::string err = c_->set_param(key, v);
  // A new model.mass is the mass estimate's new nominal (else the next estimate overwrites it).
  if (err.empty() && key == "model.mass" && observer_.estimates_mass()) {
    observer_.set_nominal_mass(static_cast<float>(v));
    observer_.apply(*c_);
  }
  return err;
}

void ControlLoop::update_inputs(const transport::StateSample& x, bool reference_changed, bool obstacles_changed) {
  if (reference_changed) {
    const transport::ReferenceInput& r = in_->reference.front();
    Reference& ref = inputs_.reference;
    ref.kind = (r.kind == 1)   ? Reference::kCircle
               : (r.kind == 2) ? Reference::kFigureEight
               : (r.kind == 4 && r.vehicle_count > 0) ? Reference::kLine  // to goals[0]
                                                      : Reference::kHold;
    std::copy_n(r.center, 3, ref.center);
    std::copy_n(r.vehicle_count > 0 ? r.goals[0] : r.center, 3, ref.end);
    ref.radius = r.radius;
    ref.speed = r.speed;
    ref.yaw = r.yaw;
    ref.ramp = r.ramp_s;
    ref.phase = r.phase;
    ref.end_s = r.end_s;
    reference_t0_utime_ = r.t0_utime;
    have_reference_ = true;
    const int n = std::min<int>(r.vehicle_count, inputs_.vehicle_count);
    for (int v = 0; v < n; ++v) std::copy_n(r.goals[v], 3, inputs_.goals[v]);
    // KIND_HOLD/KIND_WAYPOINT with no goals: hover at the centre.
    if (n == 0)
      for (int v = 0; v < inputs_.vehicle_count; ++v) std::copy_n(r.center, 3, inputs_.goals[v]);
  }
  if (obstacles_changed) {
    const transport::ObstacleInput& o = in_->obstacles.front();
    obstacles_all_.count = o.count;
    obstacles_all_.seq = o.seq;
    std::copy_n(o.items, o.count, obstacles_all_.items);
    have_obstacles_ = true;
  }
  if (!have_reference_ && !holding_ && in_->state.writes() > 0) hold_where_the_state_is(x);
  if (have_obstacles_) select_obstacles(x);
  if (have_reference_ && in_->state.writes() > 0)
    inputs_.reference_time = static_cast<float>(static_cast<double>(x.sample_utime - reference_t0_utime_) * 1e-6);
  if (have_reference_ || have_obstacles_ || holding_) c_->set_inputs(inputs_);
}

// Before the first goal or reference: every vehicle's goal (and a tracking task's held
// point) is where the first state put it, so the loop hovers in place until one arrives.
// The task's own default is the origin, which a vehicle 2 m up would dive to: a real-time
// team flight on a loaded host whose first goal message came ~1 s late did exactly that.
void ControlLoop::hold_where_the_state_is(const transport::StateSample& x) {
  float xyz[3 * TaskInputs::kMaxVehicles];
  if (c_->positions(x.x, xyz, TaskInputs::kMaxVehicles) != inputs_.vehicle_count) return;
  for (int v = 0; v < inputs_.vehicle_count; ++v) std::copy_n(xyz + 3 * v, 3, inputs_.goals[v]);
  inputs_.reference.kind = Reference::kHold;
  std::copy_n(xyz, 3, inputs_.reference.center);
  holding_ = true;
  counters_.holds_without_goal.fetch_add(1, std::memory_order_relaxed);
}

// Keep the kCapacity cylinders nearest to any vehicle (surface distance), in place.
void ControlLoop::select_obstacles(const transport::StateSample& x) {
  const int n = obstacles_all_.count;
  ObstacleSet& out = inputs_.obstacles;
  if (n <= ObstacleSet::kCapacity) {
    out.count = n;
    std::copy_n(obstacles_all_.items, n, out.items);
    return;
  }
  const int vehicles = in_->state.writes() > 0 ? std::max<int>(1, x.vehicle_count) : 0;
  for (int i = 0; i < n; ++i) {
    const Cylinder& c = obstacles_all_.items[i];
    float best = 0.0f;
    for (int v = 0; v < vehicles; ++v) {
      const float dx = c.x - x.x[v * x.nx + 0], dy = c.y - x.x[v * x.nx + 1];
      const float d = std::sqrt(dx * dx + dy * dy) - c.radius;
      best = v == 0 ? d : std::min(best, d);
    }
    distances_[static_cast<std::size_t>(i)] = best;
    obstacle_order_[static_cast<std::size_t>(i)] = i;
  }
  auto first = obstacle_order_.begin();
  std::nth_element(first, first + ObstacleSet::kCapacity - 1, first + n, [this](int a, int b) {
    return distances_[static_cast<std::size_t>(a)] < distances_[static_cast<std::size_t>(b)];
  });
  out.count = ObstacleSet::kCapacity;
  for (int i = 0; i < ObstacleSet::kCapacity; ++i) out.items[i] = obstacles_all_.items[obstacle_order_[static_cast<std::size_t>(i)]];
}

bool ControlLoop::publish(Mode mode, const float* u, std::int64_t state_seq) {
  if (!gate_.pass(u, nu_)) return false;
  send_command(&cmd_, mode, u, state_seq);
  return true;
}

void ControlLoop::stamp_timing(std::int64_t age_ns, std::int64_t compute_ns, std::int64_t lead_ns) {
  auto us = [](std::int64_t ns) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(ns / rt::kNsPerUs, 0, INT32_MAX));
  };
  cmd_.age_us = us(age_ns);
  cmd_.compute_us = us(compute_ns);
  cmd_.lead_us = us(lead_ns);
}

// Fills `msg` (the loop's or the guard's own buffer: they run on different threads), sends
// it and counts it by mode. The caller has passed u through the gate.
void ControlLoop::send_command(transport::Command* msg, Mode mode, const float* u, std::int64_t state_seq) {
  msg->utime = rt::wall_utime();
  msg->seq = cmd_seq_.fetch_add(1, std::memory_order_relaxed) + 1;
  msg->state_seq = state_seq;
  msg->mode = mode;
  msg->kind = s_.command_kind;
  msg->n = nu_;
  std::copy_n(u, nu_, msg->u);
  if (!tx_->publish_command(*msg)) counters_.publish_failures.fetch_add(1, std::memory_order_relaxed);
  switch (mode) {
    case Mode::kNormal: counters_.commands_normal.fetch_add(1, std::memory_order_relaxed); break;
    case Mode::kHoldPlan: counters_.commands_hold.fetch_add(1, std::memory_order_relaxed); break;
    case Mode::kFailsafe: counters_.commands_failsafe.fetch_add(1, std::memory_order_relaxed); break;
  }
}

bool ControlLoop::publish_failsafe(std::int64_t state_seq) {
  if (publish(Mode::kFailsafe, failsafe_.data(), state_seq)) return true;
  counters_.commands_blocked.fetch_add(1, std::memory_order_relaxed);
  return false;
}

void ControlLoop::set_mode(Mode m) {
  const Mode before = mode_.exchange(m, std::memory_order_relaxed);
  if (before == m) return;
  if (m == Mode::kFailsafe) {
    counters_.failsafe_entries.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("mode {} -> failsafe", transport::to_string(before));
  } else if (m == Mode::kHoldPlan) {
    spdlog::warn("mode {} -> hold_plan", transport::to_string(before));
  } else {
    spdlog::info("mode {} -> normal", transport::to_string(before));
  }
}

void ControlLoop::maybe_status(bool force) {
  if (!force && (status_every_ == 0 || cycle_index_ % status_every_ != 0)) return;
  const rt::TimingSummary w = monitor_.window();
  auto f = [](double v) { return static_cast<float>(v); };
  status_.utime = rt::wall_utime();
  ++status_.seq;
  status_.mode = mode_.load(std::memory_order_relaxed);
  status_.compute_ms_last = f(w.last_compute_ms);
  status_.compute_ms_min = f(w.compute.min_ms);
  status_.compute_ms_mean = f(w.compute.mean_ms);
  status_.compute_ms_max = f(w.compute.max_ms);
  status_.compute_ms_p99 = f(w.compute.p99_ms);
  status_.period_ms_min = f(w.period.min_ms);
  status_.period_ms_mean = f(w.period.mean_ms);
  status_.period_ms_max = f(w.period.max_ms);
  status_.period_ms_p99 = f(w.period.p99_ms);
  status_.jitter_ms_p99 = f(w.jitter.p99_ms);
  if (w.period.count > 0 && w.period.mean_ms > 0.0) snap_rate_.store(1000.0 / w.period.mean_ms, std::memory_order_relaxed);
  status_.cycles = w.cycles;
  status_.misses = w.misses;
  status_.late_start_misses = w.late_start_misses;
  status_.consecutive_misses = w.consecutive_misses;
  status_.state_to_command_ms_p99 = f(w.latency.p99_ms);
  status_.state_age_ms_p99 = f(w.age.p99_ms);
  status_.latency_expected_ms = f(static_cast<double>(latency_.estimate_ns()) * 1e-6);
  status_.lead_ms_mean = f(w.lead.mean_ms);
  status_.lead_ms_p99 = f(w.lead.p99_ms);
  std::copy_n(observer_.estimate(), 3, status_.disturbance_accel);
  status_.model_mass = c_->mass();
  status_.actuation_delay_ms = static_cast<float>(static_cast<double>(s_.latency.actuation_delay_ns) * 1e-6);
  status_.ess = last_stats_.ess;
  status_.min_cost = last_stats_.min_cost;
  const auto& ic = in_->counters;
  auto ld = [](const std::atomic<std::int64_t>& a) { return a.load(std::memory_order_relaxed); };
  status_.rejected_nan = ld(ic.rejected_nan);
  status_.rejected_stale = ld(counters_.stale_cycles);
  status_.rejected_out_of_order = ld(ic.rejected_out_of_order) + ld(ic.rejected_duplicate);
  status_.rejected_undecodable = ld(ic.rejected_undecodable) + ld(ic.rejected_shape) + ld(ic.rejected_inputs);
  status_.rejected_params = ld(counters_.params_rejected) + ld(ic.params_dropped);
  status_.rejected_future = ld(counters_.future_states);
  status_.partial_updates = ld(counters_.partial_updates);
  status_.anytime_holds = ld(counters_.anytime_holds);
  status_.healthy = status_.mode == Mode::kNormal && loop_healthy_.load(std::memory_order_relaxed);
  tx_->publish_status(status_);
  counters_.status_published.fetch_add(1, std::memory_order_relaxed);
  last_status_mode_ = status_.mode;
  monitor_.reset_window();
}

void ControlLoop::publish_final_status() {
  loop_healthy_.store(false, std::memory_order_relaxed);
  maybe_status(true);
  // The forced status above reports the mode; mark the final one unhealthy explicitly.
}

void ControlLoop::maybe_plan(std::int64_t state_seq, const float* x0) {
  transport::PlanView p;
  p.utime = rt::wall_utime();
  p.seq = counters_.plans_published.load(std::memory_order_relaxed) + 1;
  p.state_seq = state_seq;
  p.horizon = horizon_;
  p.nu = nu_;
  p.dt = c_->dt();
  p.u = held_.data();
  // The path the held plan flies from this cycle's state (a nominal rollout, T model steps).
  p.npos = c_->predict(x0, held_.data(), plan_pos_.data(), transport::kMaxPlanPositions);
  p.pos = plan_pos_.data();
  if (tx_->publish_plan(p)) counters_.plans_published.fetch_add(1, std::memory_order_relaxed);
}

// ---- deadline guard ------------------------------------------------------------------

void ControlLoop::guard_arm(std::int64_t deadline_ns, std::int64_t state_seq) {
  std::copy_n(held_.data(), held_.size(), guard_plan_.begin());
  guard_state_seq_ = state_seq;
  guard_steps_.store(0, std::memory_order_relaxed);
  guard_deadline_.store(deadline_ns, std::memory_order_relaxed);
  guard_word_.store((++guard_id_ << 2) | kArmed, std::memory_order_release);
  guard_wake_.post();
}

int ControlLoop::guard_disarm() {
  std::uint64_t armed = (guard_id_ << 2) | kArmed;
  if (guard_word_.compare_exchange_strong(armed, guard_id_ << 2, std::memory_order_acq_rel)) return 0;
  // The guard took over: take the cycle back between two of its publishes.
  while (true) {
    std::uint64_t waiting = (guard_id_ << 2) | kGuardWaiting;
    if (guard_word_.compare_exchange_weak(waiting, guard_id_ << 2, std::memory_order_acq_rel)) break;
    std::this_thread::yield();
  }
  return std::max(1, guard_steps_.load(std::memory_order_acquire));
}

void ControlLoop::guard_publish(int step) {
  const int steps = static_cast<int>(guard_plan_.size()) / nu_;
  const float* u = step < steps ? guard_plan_.data() + static_cast<std::ptrdiff_t>(step) * nu_ : u_init_.data();
  Mode mode = Mode::kHoldPlan;
  // A stall longer than the failsafe timeout is no better than no state: failsafe.
  const bool too_long = static_cast<std::int64_t>(step) * period_ns_ > s_.failsafe_timeout_ns;
  if (too_long || !gate_.pass(u, nu_)) {
    u = failsafe_.data();
    mode = Mode::kFailsafe;
    if (!gate_.pass(u, nu_)) {
      counters_.commands_blocked.fetch_add(1, std::memory_order_relaxed);
      return;
    }
  }
  send_command(&guard_cmd_, mode, u, guard_state_seq_);
  counters_.guard_commands.fetch_add(1, std::memory_order_relaxed);
}

void ControlLoop::guard_main() {
  if (s_.guard_fifo_priority > 0) {
    sched_param sp{};
    sp.sched_priority = s_.guard_fifo_priority;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);  // refused: runs on at its policy
  }
  rt::MonotonicClock clock;
  while (!guard_quit_.load(std::memory_order_relaxed)) {
    std::uint64_t w = guard_word_.load(std::memory_order_acquire);
    if ((w & 3u) != kArmed) {
      guard_wake_.wait_for(period_ns_);
      continue;
    }
    const std::uint64_t id = w >> 2;
    std::int64_t t = guard_deadline_.load(std::memory_order_relaxed);
    if (anytime_) {
      // Anytime: ask the optimizer, still at work on this cycle, to wrap up before t.
      const std::int64_t early = t - s_.anytime_margin_ns;
      while (clock.now_ns() < early && !guard_quit_.load(std::memory_order_relaxed)) clock.sleep_until(early);
      if (guard_word_.load(std::memory_order_acquire) == ((id << 2) | kArmed))
        anytime_stop_[id & 1u].store(true, std::memory_order_release);
    }
    while (clock.now_ns() < t && !guard_quit_.load(std::memory_order_relaxed)) clock.sleep_until(t);
    std::uint64_t armed = (id << 2) | kArmed;
    if (!guard_word_.compare_exchange_strong(armed, (id << 2) | kGuardPublishing, std::memory_order_acq_rel))
      continue;  // the loop finished in time (or already re-armed): nothing to do
    counters_.guard_takeovers.fetch_add(1, std::memory_order_relaxed);
    for (int step = 0;; ++step) {
      guard_publish(step);
      guard_steps_.store(step + 1, std::memory_order_release);
      guard_word_.store((id << 2) | kGuardWaiting, std::memory_order_release);
      t += period_ns_;
      while (clock.now_ns() < t && !guard_quit_.load(std::memory_order_relaxed)) clock.sleep_until(t);
      std::uint64_t waiting = (id << 2) | kGuardWaiting;
      if (guard_quit_.load(std::memory_order_relaxed) ||
          !guard_word_.compare_exchange_strong(waiting, (id << 2) | kGuardPublishing, std::memory_order_acq_rel))
        break;  // the loop took the cycle back
    }
  }
}

}  // namespace mppi::daemon
