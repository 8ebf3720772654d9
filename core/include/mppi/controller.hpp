// A controller for one named task, with its type erased: what the daemon, the offline
// runner and the benchmark hold. It owns the optimizer and the task's parameters; what the
// world says each cycle (goals, reference, obstacles) arrives as TaskInputs between cycles.
#pragma once

#include <algorithm>
#include <cmath>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "mppi/costs/obstacles.hpp"
#include "mppi/costs/reference.hpp"
#include "mppi/optimizer.hpp"
#include "mppi/params.hpp"
#include "mppi/rk4.hpp"
#include "mppi/tasks.hpp"

namespace mppi {

struct TaskInputs {
  static constexpr int kMaxVehicles = 32;
  int vehicle_count = 1;
  float goals[kMaxVehicles][3] = {};
  Reference reference;
  float reference_time = 0.0f;  // reference time at the state's sample time, s
  ObstacleSet obstacles;
  DistanceField field;  // the local map (a view; none by default): the forest costs' field
};

class Controller {
 public:
  virtual ~Controller() = default;
  virtual const std::string& task() const = 0;
  // The backend and, on the CPU, its SIMD target: "cpu-avx3", "cpu-avx2", "cpu-sse4",
  // "cpu-neon", "cpu" (one sample at a time) or "cuda".
  virtual const char* backend() const = 0;
  virtual int nx() const = 0;
  virtual int nu() const = 0;
  virtual int vehicles() const = 0;
  virtual int horizon() const = 0;
  virtual float dt() const = 0;

  // Between cycles only.
  virtual void set_inputs(const TaskInputs& in) = 0;
  virtual std::string set_param(const std::string& key, double value) = 0;  // "" on success

  // One cycle from state x0 (nx floats): writes nu floats of command to u_out.
  virtual const UpdateStats& iterate(const float* x0, float* u_out) = 0;
  // Shifted previous plan, for a missed deadline or a rejected update.
  virtual void fallback(float* u_out) = 0;
  // The anytime cycle: iterate() reads *stop between chunks of rollouts and, once it is set,
  // updates from the rollouts finished (UpdateStats::rollouts, partial), or not at all below
  // mppi.min_rollouts (UpdateStats::updated false: the held plan's u_0 goes out, shifted).
  // The caller owns the flag: clear it before iterate(), set it from another thread. Null:
  // off. CPU backend only (CUDA ignores it, as does this default).
  virtual void set_stop_flag(const std::atomic<bool>* stop) { (void)stop; }
  // The work of a cycle: iterate() runs the first n of the mppi.rollouts samples (the
  // ceiling), as a controller built with mppi.rollouts = n would; the plan and the noise
  // stream go on. Clamped into [1, mppi.rollouts]; returns the count in use. Between cycles
  // only; allocates nothing. rollout_quantum(): the multiple a count is best rounded to; 0
  // for a controller without rollouts (DDP), whose work these leave alone (mppi.rollouts).
  virtual int set_active_rollouts(int n) {
    (void)n;
    return settings().rollouts;
  }
  virtual int active_rollouts() const { return settings().rollouts; }
  virtual int rollout_quantum() const { return 0; }
  virtual void reset() = 0;
  // Replace the plan (horizon x nu, clamped into the limits): e.g. restore the last good one.
  virtual void set_plan(const float* plan) = 0;
  // Drop the plan's first `steps` controls (time moved on by that many control steps).
  virtual void shift(int steps) = 0;
  // Advance state x (nx floats) in place by `seconds` under the control u (nu floats) held
  // constant, with RK4 on the task's model and parameters: latency prediction.
  virtual void propagate(float* x, const float* u, float seconds) const = 0;
  // The external acceleration (world frame, m/s^2) the model adds to every vehicle: the
  // disturbance observer's estimate. False (and nothing set) for a model without one.
  virtual bool set_external_accel(const float accel[3]) { (void)accel; return false; }
  // The mass the model flies with (kg; every vehicle of a team) and setting it: the daemon's
  // mass estimate (a payload, weaker motors: the thrust each command buys). 0 and false for a
  // model without one (the quadrotors have one).
  virtual float mass() const { return 0.0f; }
  virtual bool set_mass(float kg) { (void)kg; return false; }

  // Positions along `plan` (horizon x nu) from x0, rolled out without noise: horizon + 1
  // per vehicle, vehicle-major, xyz, at most `capacity` of them. Returns how many.
  virtual int predict(const float* x0, const float* plan, float* xyz, int capacity) const = 0;
  // Each vehicle's position in state x (nx floats), xyz, vehicle by vehicle: vehicles() of
  // them, or 0 when capacity is smaller (or the controller has no positions).
  virtual int positions(const float* x, float* xyz, int capacity) const {
    (void)x, (void)xyz, (void)capacity;
    return 0;
  }

  // Live optimizer updates: a controller built with new optimizer settings takes over from
  // `from` (the one running): the task's parameters as they stand (goals, obstacles,
  // reference, model and cost values set at run time, the external acceleration) and the
  // noise counter. Not the plan (its length may differ: the caller resamples it). False,
  // and nothing taken, when `from` runs another task.
  virtual bool adopt(const Controller& from) { (void)from; return false; }
  // The counter that keys the next update's noise with the seed (Philox: seed, cycle).
  virtual std::uint32_t noise_cycle() const { return 0; }

  // Display sample of the rollouts (rollout_fan.hpp): keep_rollouts() before an iterate()
  // makes it keep what a sample needs (copies into buffers sized at start-up); fan() right
  // after (the backend's K step-0 costs are read then: on CUDA one device-to-host copy)
  // fills `out` (reserved by the caller) with the `top` lowest-cost and `random` other
  // rollouts of that iterate, rebuilt from the shared noise. False when the last iterate
  // kept nothing or did not update the plan.
  virtual void keep_rollouts() {}
  virtual bool fan(int top, int random, RolloutFan* out) {
    (void)top, (void)random, (void)out;
    return false;
  }

  virtual const std::vector<float>& plan() const = 0;
  virtual const MppiSettings& settings() const = 0;
  virtual std::vector<float> rollout_costs() const = 0;
  virtual std::size_t host_bytes() const = 0;
  virtual std::size_t device_bytes() const = 0;
};

template <class P, class = void>
constexpr bool has_external_accel = false;
template <class P>
constexpr bool has_external_accel<P, std::void_t<decltype(P::accel_z)>> = true;

// The daemon's estimates into a vehicle's parameters (every controller of a task uses these):
// the external acceleration and the mass, for the models that have them (the quadrotors).
template <class P>
bool set_vehicle_accel(P& p, const float accel[3]) {
  if constexpr (has_external_accel<P>) {
    p.accel_x = accel[0];
    p.accel_y = accel[1];
    p.accel_z = accel[2];
    return true;
  } else {
    (void)p, (void)accel;
    return false;
  }
}
template <class P>
float vehicle_mass(const P& p) {
  if constexpr (has_external_accel<P>) return p.mass;
  (void)p;
  return 0.0f;
}
template <class P>
bool set_vehicle_mass(P& p, float kg) {
  if constexpr (has_external_accel<P>) {
    p.mass = kg;
    return true;
  } else {
    (void)p, (void)kg;
    return false;
  }
}

// What the world says between cycles, into a task's parameters: goals and obstacles for the
// forest costs, the reference for the tracking costs (every controller of a task uses this).
template <class T>
void apply_task_inputs(typename T::Params& params, const TaskInputs& in) {
  using Cost = typename T::Cost;
  if constexpr (std::is_same_v<Cost, ForestCost<typename T::Vehicle>>) {
    for (int j = 0; j < T::kVehicles; ++j)
      for (int d = 0; d < 3; ++d) params.cost.goal[j][d] = in.goals[j][d];
    params.cost.obstacles = in.obstacles;
    params.cost.field = in.field;
  } else if constexpr (std::is_same_v<Cost, TrackingCost<typename T::Vehicle>>) {
    params.cost.reference = in.reference;
    params.cost.time0 = in.reference_time;
  }
}

// Positions along `plan` (horizon x nu) from x0, rolled out without noise with the task's
// Euler steps: horizon + 1 per vehicle, vehicle-major, xyz; 0 if `capacity` is too small.
template <class T>
int predict_positions(const typename T::Params& params, const MppiSettings& s, const float* x0, const float* plan,
                      float* xyz, int capacity) {
  using V = typename T::Vehicle;
  const int per = s.horizon + 1;
  if (capacity < per * T::kVehicles) return 0;
  float x[T::kNx];
  std::copy_n(x0, T::kNx, x);
  auto put = [&](int i) {
    for (int j = 0; j < T::kVehicles; ++j) V::position(x + j * T::kVehicleNx, xyz + 3 * (j * per + i));
  };
  put(0);
  for (int i = 0; i < s.horizon; ++i) {
    T::advance(params, x, plan + i * T::kNu, s.dt, s.substeps, 0u);
    put(i + 1);
  }
  return per * T::kVehicles;
}

// Each vehicle's position in state x, xyz (Controller::positions).
template <class T>
int vehicle_positions(const float* x, float* xyz, int capacity) {
  if (capacity < T::kVehicles) return 0;
  for (int j = 0; j < T::kVehicles; ++j) T::Vehicle::position(x + j * T::kVehicleNx, xyz + 3 * j);
  return T::kVehicles;
}

template <class T>
class TaskController final : public Controller {
 public:
  TaskController(std::string name, const MppiSettings& s, typename T::Params params,
                 std::unique_ptr<RolloutBackend<T>> backend)
      : name_(std::move(name)), params_(params), mppi_(s, std::move(backend)), mass0_(vehicle_mass(params.vehicle)) {}

  const std::string& task() const override { return name_; }
  const char* backend() const override { return mppi_.backend().name(); }
  int nx() const override { return T::kNx; }
  int nu() const override { return T::kNu; }
  int vehicles() const override { return T::kVehicles; }
  int horizon() const override { return mppi_.settings().horizon; }
  float dt() const override { return mppi_.settings().dt; }

  void set_inputs(const TaskInputs& in) override { apply_task_inputs<T>(params_, in); }

  std::string set_param(const std::string& key, double value) override {
    return set_task_param<T>(params_, key, value);
  }

  const UpdateStats& iterate(const float* x0, float* u_out) override { return mppi_.iterate(x0, params_, u_out); }
  void fallback(float* u_out) override { mppi_.fallback(u_out); }
  void set_stop_flag(const std::atomic<bool>* stop) override { mppi_.set_stop_flag(stop); }
  int set_active_rollouts(int n) override { return mppi_.set_active_rollouts(n); }
  int active_rollouts() const override { return mppi_.active_rollouts(); }
  int rollout_quantum() const override { return mppi_.backend().rollout_quantum(); }
  void reset() override { mppi_.reset(); }
  void set_plan(const float* plan) override { mppi_.set_plan(plan); }
  void shift(int steps) override { mppi_.shift(steps); }
  void propagate(float* x, const float* u, float seconds) const override { rk4_task<T>(params_, x, u, seconds); }
  bool set_external_accel(const float accel[3]) override { return set_vehicle_accel(params_.vehicle, accel); }
  float mass() const override { return vehicle_mass(params_.vehicle); }
  // The control cost's nominal and the warm start follow the hover of the new mass.
  bool set_mass(float kg) override {
    if (!set_vehicle_mass(params_.vehicle, kg)) return false;
    follow_hover();
    return true;
  }

  int predict(const float* x0, const float* plan, float* xyz, int capacity) const override {
    return predict_positions<T>(params_, mppi_.settings(), x0, plan, xyz, capacity);
  }
  int positions(const float* x, float* xyz, int capacity) const override {
    return vehicle_positions<T>(x, xyz, capacity);
  }

  bool adopt(const Controller& from) override {
    const auto* o = dynamic_cast<const TaskController<T>*>(&from);
    if (o == nullptr || o->name_ != name_) return false;
    params_ = o->params_;
    mppi_.set_cycle(o->mppi_.cycle());
    mass0_ = o->mass0_;
    follow_hover();
    return true;
  }
  std::uint32_t noise_cycle() const override { return mppi_.cycle(); }
  void keep_rollouts() override { mppi_.keep_rollouts(); }
  bool fan(int top, int random, RolloutFan* out) override { return mppi_.fan(top, random, out); }

  const std::vector<float>& plan() const override { return mppi_.plan(); }
  const MppiSettings& settings() const override { return mppi_.settings(); }
  std::vector<float> rollout_costs() const override { return mppi_.backend().rollout_costs(); }
  std::size_t host_bytes() const override { return mppi_.backend().host_bytes(); }
  std::size_t device_bytes() const override { return mppi_.backend().device_bytes(); }

  typename T::Params& params() { return params_; }
  Mppi<T>& optimizer() { return mppi_; }

 private:
  // Each vehicle's share of u_nominal and u_init scaled to hold the mass the model flies with
  // (m / m0 of the mass it started with): the control cost then pulls towards the hover of
  // the vehicle as estimated, not of the nominal one (a payload's extra thrust would pay for
  // itself every cycle). In steps of kHoverStep, so that the CUDA backend captures its graph
  // again rarely.
  void follow_hover() {
    if constexpr (has_external_accel<typename T::Vehicle::Params>) {
      constexpr float kHoverStep = 0.005f;
      const float ratio = vehicle_mass(params_.vehicle) / mass0_;
      if (!(mass0_ > 0.0f) || std::fabs(ratio - hover_ratio_) < kHoverStep * hover_ratio_) return;
      hover_ratio_ = ratio;
      const MppiSettings& s = mppi_.settings();
      float nominal[T::kNu], init[T::kNu];
      for (int i = 0; i < T::kNu; ++i) {
        nominal[i] = s.u_nominal.empty() ? 0.0f : s.u_nominal[static_cast<std::size_t>(i)];
        init[i] = s.u_init[static_cast<std::size_t>(i)];
      }
      for (int j = 0; j < T::kVehicles; ++j) {
        T::Vehicle::scale_hover(ratio, nominal + j * T::kVehicleNu);
        T::Vehicle::scale_hover(ratio, init + j * T::kVehicleNu);
      }
      mppi_.set_nominal(nominal, init);
    }
  }

  std::string name_;
  typename T::Params params_;
  Mppi<T> mppi_;
  float mass0_;              // the model's mass when built (0: none)
  float hover_ratio_ = 1.0f; // the mass ratio u_nominal and u_init were last scaled for
};

}  // namespace mppi
