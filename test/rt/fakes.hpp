// Test doubles for the loop: a clock that moves only when told (or when the loop sleeps),
// a transport that records what was published, and a controller whose outputs, stalls
// and failures are scripted.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/transport/transport.hpp"

namespace mppi::test {

class FakeClock final : public rt::Clock {
 public:
  std::int64_t now_ns() override { return t_.load(); }
  void sleep_until(std::int64_t t) override {
    sleeps.push_back(t);
    if (t > t_.load()) t_.store(t + oversleep_ns);
    oversleep_ns = 0;
  }
  // A pending post ends the wait at once (the states the test offered before the step); else
  // the clock jumps to t, as a wait that no state ended.
  bool sleep_until_or(rt::Wakeup& wake, std::int64_t t) override {
    if (wake.try_wait()) return true;
    sleep_until(t);
    return false;
  }
  void advance(std::int64_t ns) { t_ += ns; }
  void set(std::int64_t t) { t_ = t; }
  std::vector<std::int64_t> sleeps;  // loop thread only
  std::int64_t oversleep_ns = 0;     // the next sleep wakes this late (a stalled machine), once

 private:
  std::atomic<std::int64_t> t_{1'000'000'000};  // read by receive threads too
};

// A fake clock two threads share: the loop's and the deadline guard's. The thread that made
// it (the test's, which runs the loop) moves time: its sleeps jump to their end, as
// FakeClock's do, and set()/advance() move it. Any other thread's sleep returns when the time
// reaches its end, or after a millisecond of real time (as a signal would end it: callers
// re-check, and see their quit flag). Nothing here depends on how fast the machine is.
class SharedFakeClock final : public rt::Clock {
 public:
  std::int64_t now_ns() override { return t_.load(); }
  void sleep_until(std::int64_t t) override {
    if (std::this_thread::get_id() == driver_) {
      if (t > t_.load()) set(t);
      return;
    }
    std::unique_lock<std::mutex> lock(mu_);
    moved_.wait_for(lock, std::chrono::milliseconds(1), [&] { return t_.load() >= t; });
  }
  bool sleep_until_or(rt::Wakeup& wake, std::int64_t t) override {
    if (wake.try_wait()) return true;
    sleep_until(t);
    return false;
  }
  void set(std::int64_t t) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      t_.store(t);
    }
    moved_.notify_all();
  }
  void advance(std::int64_t ns) { set(t_.load() + ns); }

 private:
  std::atomic<std::int64_t> t_{1'000'000'000};
  std::thread::id driver_ = std::this_thread::get_id();
  std::mutex mu_;
  std::condition_variable moved_;
};

// Waits (yielding) until `cond` holds; false if it did not within `seconds` of real time. A
// guard against a hang, never a timing assertion: the tests' claims hold however long it takes.
inline bool eventually(const std::function<bool()>& cond, double seconds = 60.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!cond()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::yield();
  }
  return true;
}

// A transport with nothing to open or close: the fakes publish into memory.
class InMemoryTransport : public transport::Transport {
 public:
  std::string self_test() override { return {}; }
  void start(transport::Inbox*) override {}
  void stop() override {}
};

// Keeps everything published, in order.
class RecordingTransport final : public InMemoryTransport {
 public:
  bool publish_command(const transport::Command& c) override { return record(&commands, c); }
  bool publish_status(const transport::StatusReport& s) override { return record(&statuses, s); }
  bool publish_plan(const transport::PlanView& p) override { return record(&plans, p); }
  bool publish_param_result(const transport::ParamResult& r) override { return record(&param_results, r); }
  bool any_nonfinite() const {
    for (const auto& c : commands)
      for (int i = 0; i < c.n; ++i)
        if (!std::isfinite(c.u[i])) return true;
    return false;
  }
  std::vector<transport::Command> commands;
  std::vector<transport::StatusReport> statuses;
  std::vector<transport::PlanView> plans;
  std::vector<transport::ParamResult> param_results;

 private:
  template <class T>
  static bool record(std::vector<T>* kept, const T& message) {
    kept->push_back(message);
    return true;
  }
};

// nx = 16, nu = 4, plan of T steps. iterate() writes u = plan[0] where the plan's step i
// is filled with (base + cycle + i) on every channel, then shifts; hooks script faults.
class FakeController final : public Controller {
 public:
  // `base`: commands are base + 10 * iteration + step (so tests can tell controllers apart).
  explicit FakeController(FakeClock* clock, int horizon = 10, float base = 1000.0f) : clock_(clock), base_(base) {
    s_.rollouts = 8;
    s_.horizon = horizon;
    s_.dt = 0.02f;
    s_.sigma = {1, 1, 1, 1};
    s_.u_min = {0, 0, 0, 0};
    s_.u_max = {6000, 6000, 6000, 6000};
    s_.u_init = {3000, 3000, 3000, 3000};
    plan_.assign(static_cast<std::size_t>(horizon) * 4, 3000.0f);
  }
  // A fake built by a live-update factory: these settings (horizon included).
  void use_settings(const MppiSettings& s) {
    s_ = s;
    active_ = -1;
    plan_.assign(static_cast<std::size_t>(s.horizon) * 4, 3000.0f);
  }
  // The rollouts it is built with (mppi.rollouts, the work sizer's ceiling); all active.
  void set_rollouts(int k) {
    s_.rollouts = k;
    active_ = -1;
  }
  const std::string& task() const override { return name_; }
  const char* backend() const override { return "fake"; }
  int nx() const override { return 16; }
  int nu() const override { return 4; }
  int vehicles() const override { return 1; }
  int horizon() const override { return s_.horizon; }
  float dt() const override { return s_.dt; }
  void set_inputs(const TaskInputs& in) override {
    if (in_iterate_) mid_cycle_changes++;
    inputs = in;
    ++inputs_set;
  }
  std::string set_param(const std::string& key, double value) override {
    if (in_iterate_) mid_cycle_changes++;
    if (key == "cost.w_xy" && value >= 0.0 && value <= 1e6) {
      params_set.emplace_back(key, value);
      return {};
    }
    return key == "cost.w_xy" ? key + ": out of range [0, 1e6]" : key + ": unknown parameter";
  }
  const UpdateStats& iterate(const float* x0, float* u_out) override {
    in_iterate_ = true;
    ++iterations;
    last_x0.assign(x0, x0 + 16);
    plan_at_iterate.assign(plan_.begin(), plan_.end());
    if (compute_ns) clock_->advance(compute_ns(iterations));
    stats_ = UpdateStats{};
    stats_.ess = 5.0f;
    const int T = s_.horizon;
    for (int i = 0; i < T; ++i)
      for (int j = 0; j < 4; ++j) plan_[static_cast<std::size_t>(i * 4 + j)] = base_ + static_cast<float>(iterations * 10 + i);
    if (fault && fault(iterations, &plan_, &stats_)) {
      in_iterate_ = false;
      throw std::runtime_error("injected optimizer error");
    }
    std::copy_n(plan_.data(), 4, u_out);
    shift();
    in_iterate_ = false;
    return stats_;
  }
  void fallback(float* u_out) override {
    std::copy_n(plan_.data(), 4, u_out);
    shift();
  }
  void set_stop_flag(const std::atomic<bool>* stop) override { stop_flag = stop; }
  int set_active_rollouts(int n) override {
    if (in_iterate_) mid_cycle_changes++;
    ++active_changes;
    return active_ = std::clamp(n, 1, s_.rollouts);
  }
  int active_rollouts() const override { return active_ < 0 ? s_.rollouts : active_; }
  int rollout_quantum() const override { return quantum; }
  void reset() override {
    ++resets;
    std::fill(plan_.begin(), plan_.end(), 3000.0f);
  }
  void set_plan(const float* plan) override {
    std::copy(plan, plan + plan_.size(), plan_.begin());
    ++restores;
  }
  void shift(int steps) override {
    for (int i = 0; i < steps; ++i) shift();
    shifts += steps;
  }
  // A model the tests can follow by hand: x[0] moves at the speed u[0] (u in units/s).
  void propagate(float* x, const float* u, float seconds) const override {
    x[0] += u[0] * seconds;   // a position
    x[10] += u[0] * seconds;  // a body rate (past position and velocity)
    ++propagations;
  }
  // Live updates: takes over another fake's inputs and iteration count.
  bool adopt(const Controller& from) override {
    const auto* o = dynamic_cast<const FakeController*>(&from);
    if (o == nullptr) return false;
    inputs = o->inputs;
    adopted_from = o;
    return true;
  }
  int predict(const float*, const float*, float*, int) const override { return 0; }
  int positions(const float* x, float* xyz, int capacity) const override {
    if (capacity < 1) return 0;
    for (int d = 0; d < 3; ++d) xyz[d] = x[d];
    return 1;
  }
  const std::vector<float>& plan() const override { return plan_; }
  const MppiSettings& settings() const override { return s_; }
  std::vector<float> rollout_costs() const override { return {}; }
  std::size_t host_bytes() const override { return 0; }
  std::size_t device_bytes() const override { return 0; }

  // Returns compute time (ns) of iteration n (1-based); the fake clock advances by it.
  std::function<std::int64_t(int)> compute_ns;
  // Iteration n may corrupt the plan/stats; return true to throw instead.
  std::function<bool(int, std::vector<float>*, UpdateStats*)> fault;
  int iterations = 0, resets = 0, inputs_set = 0, mid_cycle_changes = 0;
  int active_changes = 0;  // set_active_rollouts calls
  int quantum = 1;         // rollout_quantum()
  int restores = 0;  // set_plan calls (the loop restoring its last good plan)
  int shifts = 0;    // extra steps the loop shifted the plan by (time moved on)
  mutable int propagations = 0;
  const std::atomic<bool>* stop_flag = nullptr;  // the anytime stop flag last given
  std::vector<float> last_x0;
  std::vector<float> plan_at_iterate;  // the plan as iterate() found it (warm start)
  const Controller* adopted_from = nullptr;
  std::vector<std::pair<std::string, double>> params_set;
  TaskInputs inputs;

 private:
  void shift() {
    std::copy(plan_.begin() + 4, plan_.end(), plan_.begin());
    std::fill(plan_.end() - 4, plan_.end(), 3000.0f);
  }
  FakeClock* clock_;
  float base_;
  std::string name_ = "quadrotor_forest";
  MppiSettings s_;
  std::vector<float> plan_;
  UpdateStats stats_;
  bool in_iterate_ = false;
  int active_ = -1;  // set_active_rollouts; -1: all of s_.rollouts
};

// The header of a one-vehicle state: by default a 16-state quadrotor (model 1, the shape the
// rigs' inboxes expect).
inline void shape_state(transport::StateSample& s, std::int64_t seq, std::int16_t nx = 16, std::int8_t model = 1) {
  s.seq = seq;
  s.nx = nx;
  s.vehicle_count = 1;
  s.n = nx;
  s.model = model;
}

}  // namespace mppi::test
