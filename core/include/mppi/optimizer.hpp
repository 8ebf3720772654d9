// The MPPI optimizer of Algorithm 1 above a rollout backend: it owns the plan, runs one
// update per control cycle, smooths the plan inside the limits, hands out u_0 and warm
// starts the next cycle by shifting (u_{N-1} <- u_init). Before each update it lets the
// task's cost prepare for the cycle from the plan's noise-free path (Task::prepare: the
// forest cost's obstacle culling), on its own copy of the parameters, unless the backend
// does that itself (RolloutBackend::prepares_params).
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <vector>

#include "mppi/backend.hpp"
#include "mppi/held_plan.hpp"
#include "mppi/rollout_fan.hpp"
#include "mppi/settings.hpp"

namespace mppi {

template <class TaskT>
class Mppi {
 public:
  using Task = TaskT;
  using Params = typename Task::Params;
  static constexpr int kNx = Task::kNx;
  static constexpr int kNu = Task::kNu;

  Mppi(const MppiSettings& s, std::unique_ptr<RolloutBackend<Task>> backend)
      : settings_(s),
        backend_(std::move(backend)),
        plan_(s.horizon, s.u_init),
        scratch_(plan_.size()),
        path_(static_cast<std::size_t>(s.horizon + 1) * Task::kVehicles * 2),
        work_(std::make_unique<Params>()) {
    kept_.plan.assign(plan_.size(), 0.0f);
    kept_.x0.assign(kNx, 0.0f);
    kept_.costs.assign(static_cast<std::size_t>(s.rollouts), 0.0f);
    const std::string err = validate(s, kNu);
    if (!err.empty()) throw std::invalid_argument(err);
    if (!backend_) throw std::invalid_argument("backend: none given");
  }

  // One control cycle from state x0: update the plan, smooth it, write u_0 to u_out and
  // shift the plan for the next cycle. Returns the update's statistics. An anytime update
  // stopped before min_rollouts (stats.updated false) leaves the plan as it was: u_0 of the
  // held plan goes out and the plan shifts, as fallback() does.
  const UpdateStats& iterate(const float* x0, const Params& params, float* u_out) {
    const Params* p = &params;
    if (Task::kUsesPath && !backend_->prepares_params()) {
      *work_ = params;
      Task::prepare(*work_, x0, plan_.data(), settings_.horizon, settings_.dt, settings_.substeps, path_.data());
      p = work_.get();
    }
    const bool keep = keep_next_;
    keep_next_ = false;
    kept_ok_ = false;
    if (keep) keep_inputs(x0, *p);
    backend_->update(x0, *p, cycle_++, plan_.data(), &stats_);
    kept_.rollouts = stats_.rollouts;
    kept_ok_ = keep;
    if (stats_.updated && settings_.smoothing_window > 1) smooth();
    std::copy_n(plan_.data(), kNu, u_out);
    plan_.shift();
    return stats_;
  }

  // The next iterate() keeps what a display sample of its rollouts needs (the plan it
  // starts from, the state, the parameters: copies into buffers sized at construction);
  // fan() then rebuilds the sample. Off again after that iterate().
  void keep_rollouts() { keep_next_ = true; }
  // The `top` lowest-cost and `random` other rollouts of the last iterate() into fan, if it
  // kept them and updated the plan; false (fan untouched) otherwise. Reads the backend's
  // step-0 costs of that update here, after the command is out (on CUDA a device-to-host
  // copy), so the kept cycle itself pays only the copies above. Allocates nothing.
  bool fan(int top, int random, RolloutFan* out) {
    if (!kept_ok_ || !stats_.updated) return false;
    backend_->step0_costs(kept_.costs.data());
    return fill_rollout_fan<Task>(*kept_params_, settings_, kept_, top, random, out);
  }

  // The anytime cycle (RolloutBackend::set_stop_flag).
  void set_stop_flag(const std::atomic<bool>* stop) { backend_->set_stop_flag(stop); }

  // The rollouts the next updates run, samples 0..n-1 of settings().rollouts (the ceiling;
  // RolloutBackend::set_active_rollouts): the plan, the warm start and the noise counter go
  // on as they are. Returns the count in use (n clamped into [1, K]). Between updates only.
  int set_active_rollouts(int n) { return backend_->set_active_rollouts(n); }
  int active_rollouts() const { return backend_->active_rollouts(); }

  // The parameters the last update ran with, after Task::prepare (tasks whose cost uses the
  // plan's path, e.g. the forest's obstacle grid; for the others, unused defaults).
  const Params& prepared_params() const { return *work_; }

  // The fallback after a missed deadline or a bad update: the previous plan, shifted.
  void fallback(float* u_out) {
    std::copy_n(plan_.data(), kNu, u_out);
    plan_.shift();
  }

  // Drop the first `steps` controls and append u_init as often (warm start; one step per
  // cycle, more when time moved on further: skipped cycles, an older state).
  void shift(int steps = 1) { plan_.shift(steps); }

  void reset() { plan_.reset(); }

  // The hover of the vehicle as the daemon estimates it, in place of the settings' u_nominal
  // (what the control cost is measured from) and u_init (what the warm start appends); the
  // settings themselves stay as they were loaded. The plan moves with u_init (inside the
  // limits): it was planned around the old hover, and a plan that kept a lighter vehicle's
  // thrust would take the optimizer many cycles to raise while the vehicle sinks. NU floats
  // each; between updates only.
  void set_nominal(const float* u_nominal, const float* u_init) {
    backend_->set_nominal(u_nominal);
    float* plan = plan_.data();
    const std::vector<float>& was = plan_.u_init();
    for (std::size_t n = 0; n < plan_.size(); ++n) {
      const std::size_t j = n % kNu;
      plan[n] = std::clamp(plan[n] + u_init[j] - was[j], settings_.u_min[j], settings_.u_max[j]);
    }
    plan_.set_u_init(u_init);
  }
  const std::vector<float>& u_init() const { return plan_.u_init(); }

  // Replace the plan (tests; a restored plan). Values are clamped into the limits.
  void set_plan(const std::vector<float>& plan) { set_plan(plan.data()); }
  void set_plan(const float* plan) {
    float* out = plan_.data();
    for (std::size_t n = 0; n < plan_.size(); ++n) {
      const int j = static_cast<int>(n % kNu);
      out[n] = std::clamp(plan[n], settings_.u_min[j], settings_.u_max[j]);
    }
  }

  const std::vector<float>& plan() const { return plan_.values(); }
  const UpdateStats& stats() const { return stats_; }
  const MppiSettings& settings() const { return settings_; }
  RolloutBackend<Task>& backend() { return *backend_; }
  const RolloutBackend<Task>& backend() const { return *backend_; }
  std::uint32_t cycle() const { return cycle_; }
  // The noise counter of the next update (an optimizer that takes over from another keeps
  // its count, so the noise stream goes on and a replay can rebuild it).
  void set_cycle(std::uint32_t c) { cycle_ = c; }

 private:
  void keep_inputs(const float* x0, const Params& p) {
    std::copy(plan_.values().begin(), plan_.values().end(), kept_.plan.begin());
    std::copy_n(x0, kNx, kept_.x0.begin());
    *kept_params_ = p;
    kept_.cycle = cycle_;
  }

  // Centred moving average over time, the window shrinking at the ends. Each output is a
  // convex combination of in-limit controls, so the limits hold mathematically; in float the
  // average of equal values can round one ulp outside ((2.2f * 3) * (1.0f / 3) > 2.2f), so
  // it is clamped back.
  void smooth() {
    const int half = settings_.smoothing_window / 2;
    const int t = settings_.horizon;
    for (int i = 0; i < t; ++i) {
      const int lo = std::max(0, i - half), hi = std::min(t - 1, i + half);
      const float inv = 1.0f / static_cast<float>(hi - lo + 1);
      for (int j = 0; j < kNu; ++j) {
        float acc = 0.0f;
        for (int m = lo; m <= hi; ++m) acc += plan_.data()[m * kNu + j];
        scratch_[i * kNu + j] = std::clamp(acc * inv, settings_.u_min[j], settings_.u_max[j]);
      }
    }
    plan_.swap(scratch_);
  }

  MppiSettings settings_;
  std::unique_ptr<RolloutBackend<Task>> backend_;
  HeldPlan plan_;  // the warm start
  std::vector<float> scratch_;
  std::vector<float> path_;       // the plan's noise-free path, xy per step and vehicle
  std::unique_ptr<Params> work_;  // the parameters as prepared for this cycle
  UpdateStats stats_;
  std::uint32_t cycle_ = 0;
  bool keep_next_ = false;
  KeptRollouts kept_;                     // the last iterate's inputs (costs: at fan()) ...
  std::unique_ptr<Params> kept_params_ = std::make_unique<Params>();  // ... and parameters
  bool kept_ok_ = false;                  // ... when it kept them
};

}  // namespace mppi
