// The MPC-DDP baseline as a Controller: each cycle, a few iLQR iterations (ilqr.hpp) from
// the current state, warm started from the previous plan shifted by one step, then u_0 out.
// The model is the task's own (Task::advance in double: the same Euler steps MPPI rolls
// out), the cost is the task's own running and terminal cost with its crash term off (a
// step function has no derivative), plus smooth penalties where MPPI relies on crashes:
// the obstacles and the ground (DdpSettings). The control cost is MPPI's quadratic term
// unless ddp.r says otherwise.
//
// What the daemon, the offline runner and the tests hold is the same Controller interface as
// for MPPI, so the loop, the latency prediction and the transports are shared unchanged.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/ddp/ilqr.hpp"
#include "mppi/ddp/settings.hpp"

namespace mppi {

// The tasks the DDP baseline is built for (single vehicles; the paper compares on these).
template <class T>
constexpr bool kDdpTask = std::is_same_v<T, CartpoleSwingup> || std::is_same_v<T, QuadrotorForest>;

namespace ddp {

// The optimal-control problem of one cycle, for Ilqr<TaskProblem<T>>.
template <class T>
struct TaskProblem {
  static constexpr int kNx = T::kNx;
  static constexpr int kNu = T::kNu;
  static constexpr bool kForest = std::is_same_v<typename T::Cost, ForestCost<typename T::Vehicle>>;
  static_assert(T::kVehicles == 1, "the DDP baseline is for single vehicles");

  const typename T::Params* params = nullptr;  // prepared for the cycle, crash cost off
  const DdpSettings* ddp = nullptr;
  float dt = 0.02f;
  int substeps = 1;
  double r[kNu] = {}, u_ref[kNu] = {}, u_lo[kNu] = {}, u_hi[kNu] = {};
  // The cylinders near the plan's path this cycle (indices into params->cost.obstacles).
  const int* near = nullptr;
  int near_count = 0;

  void step(const double* x, const double* u, double* x_next) const {
    std::copy_n(x, kNx, x_next);
    T::advance(*params, x_next, u, dt, substeps, std::uint32_t{0});
  }

  double state_cost(const double* x, int i) const {
    const float t = static_cast<float>(i) * dt;
    std::uint32_t crashed = 0;
    double q = T::running(*params, x, t, &crashed);
    if constexpr (kForest) q += penalty(x, t);
    return q;
  }

  double terminal_cost(const double* x) const { return T::terminal(*params, x); }

  // The smooth obstacle, speed and ground penalties.
  double penalty(const double* x, float t) const {
    double pos[3];
    T::Vehicle::position(x, pos);
    const auto& c = params->cost;
    double q = 0.0;
    if (ddp->obstacle_weight > 0.0) {
      for (int n = 0; n < near_count; ++n) {
        const double clearance =
            ObstacleSet::surface_distance(c.obstacles.items[near[n]], pos[0], pos[1], t) - c.vehicle_radius;
        q += ddp->obstacle_weight *
             std::exp(std::min(ddp->exp_cap, -(clearance - ddp->obstacle_margin) / ddp->obstacle_softness));
      }
    }
    if (ddp->speed_weight > 0.0) {
      using Vehicle = typename T::Vehicle;
      const double speed = std::sqrt(x[Vehicle::VX] * x[Vehicle::VX] + x[Vehicle::VY] * x[Vehicle::VY] +
                                     x[Vehicle::VZ] * x[Vehicle::VZ]);
      const double over = std::max(0.0, speed - ddp->speed_limit);
      q += ddp->speed_weight * over * over;
    }
    if (ddp->ground_weight > 0.0) {
      const double above = pos[2] - static_cast<double>(c.ground_z) - ddp->ground_margin;
      q += ddp->ground_weight * std::exp(std::min(ddp->exp_cap, -above / ddp->ground_softness));
    }
    return q;
  }
};

}  // namespace ddp

template <class T>
class DdpController final : public Controller {
 public:
  static constexpr int NX = T::kNx;
  static constexpr int NU = T::kNu;
  using Problem = ddp::TaskProblem<T>;

  // Throws std::invalid_argument naming the bad field ("mppi.horizon: ...", "ddp.r: ...").
  DdpController(std::string name, const MppiSettings& s, const DdpSettings& d, typename T::Params params)
      : name_(std::move(name)),
        settings_(checked(s, d)),
        ddp_(d),
        params_(std::make_unique<typename T::Params>(params)),
        work_(std::make_unique<typename T::Params>(params)),
        solver_(d, s.horizon),
        plan_(static_cast<std::size_t>(s.horizon) * NU),
        plan_d_(plan_.size()),
        path_(static_cast<std::size_t>(s.horizon + 1) * 2),
        near_(ObstacleSet::kCapacity) {
    for (int j = 0; j < NU; ++j) {
      const float sig = s.sigma[static_cast<std::size_t>(j)];
      problem_.r[j] = d.r.empty() ? static_cast<double>(s.control_cost_scale * s.lambda / (sig * sig))
                                  : static_cast<double>(d.r[static_cast<std::size_t>(j)]);
      problem_.u_ref[j] = s.u_nominal.empty() ? 0.0 : static_cast<double>(s.u_nominal[static_cast<std::size_t>(j)]);
      problem_.u_lo[j] = s.u_min[static_cast<std::size_t>(j)];
      problem_.u_hi[j] = s.u_max[static_cast<std::size_t>(j)];
    }
    problem_.params = work_.get();
    problem_.ddp = &ddp_;
    problem_.dt = s.dt;
    problem_.substeps = s.substeps;
    problem_.near = near_.data();
    reset();
  }

  const std::string& task() const override { return name_; }
  const char* backend() const override { return "ddp"; }
  int nx() const override { return NX; }
  int nu() const override { return NU; }
  int vehicles() const override { return 1; }
  int horizon() const override { return settings_.horizon; }
  float dt() const override { return settings_.dt; }

  void set_inputs(const TaskInputs& in) override { apply_task_inputs<T>(*params_, in); }
  std::string set_param(const std::string& key, double value) override {
    return set_task_param<T>(*params_, key, value);
  }

  const UpdateStats& iterate(const float* x0, float* u_out) override {
    *work_ = *params_;
    work_->cost.w_crash = 0.0f;
    if constexpr (T::kUsesPath)
      T::prepare(*work_, x0, plan_.data(), settings_.horizon, settings_.dt, settings_.substeps, path_.data());
    if constexpr (Problem::kForest) select_near(x0);
    double x[NX];
    for (int n = 0; n < NX; ++n) x[n] = x0[n];
    last_ = solver_.solve(problem_, x, plan_d_.data());
    stats_ = UpdateStats{};
    // In float range (a cost beyond it is "infinitely bad", as kCostCeiling says for MPPI).
    const double cost = std::isnan(last_.cost) ? last_.cost : std::clamp(last_.cost, -1e30, 1e30);
    stats_.min_cost = static_cast<float>(cost);
    stats_.mean_cost = static_cast<float>(cost);
    stats_.ess = 1.0f;  // one trajectory
    stats_.rollouts = last_.iterations;
    stats_.finite = last_.finite;
    if (last_.finite) {
      to_float();
    } else {
      // Keep the previous plan (the loop publishes it through its gate).
      for (std::size_t n = 0; n < plan_.size(); ++n) plan_d_[n] = plan_[n];
      solver_.set_mu(ddp_.mu_init);
    }
    std::copy_n(plan_.data(), NU, u_out);
    shift(1);
    return stats_;
  }

  void fallback(float* u_out) override {
    std::copy_n(plan_.data(), NU, u_out);
    shift(1);
  }
  void reset() override {
    const std::vector<float>& first = ddp_.initial_plan.empty() ? settings_.u_init : ddp_.initial_plan;
    for (int i = 0; i < settings_.horizon; ++i)
      for (int j = 0; j < NU; ++j) plan_d_[i * NU + j] = clamp(j, first[static_cast<std::size_t>(j)]);
    to_float();
    solver_.set_mu(ddp_.mu_init);
  }
  void set_plan(const float* plan) override {
    for (std::size_t n = 0; n < plan_.size(); ++n) plan_d_[n] = clamp(static_cast<int>(n % NU), plan[n]);
    to_float();
  }
  void shift(int steps) override {
    const int t = settings_.horizon;
    steps = std::clamp(steps, 0, t);
    if (steps == 0) return;
    std::copy(plan_d_.begin() + static_cast<std::ptrdiff_t>(steps) * NU, plan_d_.end(), plan_d_.begin());
    for (int i = t - steps; i < t; ++i)
      for (int j = 0; j < NU; ++j) plan_d_[i * NU + j] = settings_.u_init[static_cast<std::size_t>(j)];
    to_float();
  }
  void propagate(float* x, const float* u, float seconds) const override { rk4_task<T>(*params_, x, u, seconds); }
  bool set_external_accel(const float accel[3]) override { return set_vehicle_accel(params_->vehicle, accel); }
  float mass() const override { return vehicle_mass(params_->vehicle); }
  bool set_mass(float kg) override { return set_vehicle_mass(params_->vehicle, kg); }
  int predict(const float* x0, const float* plan, float* xyz, int capacity) const override {
    return predict_positions<T>(*params_, settings_, x0, plan, xyz, capacity);
  }
  int positions(const float* x, float* xyz, int capacity) const override {
    return vehicle_positions<T>(x, xyz, capacity);
  }

  // Live updates: a DDP controller of the same task built with new settings takes over the
  // task's parameters as they stand (not the plan: the caller resamples it).
  bool adopt(const Controller& from) override {
    const auto* o = dynamic_cast<const DdpController<T>*>(&from);
    if (o == nullptr || o->name_ != name_) return false;
    *params_ = *o->params_;
    return true;
  }

  const std::vector<float>& plan() const override { return plan_; }
  const MppiSettings& settings() const override { return settings_; }
  std::vector<float> rollout_costs() const override { return {}; }
  std::size_t host_bytes() const override {
    return sizeof(*this) + 2 * sizeof(typename T::Params) + plan_.size() * (sizeof(float) + sizeof(double)) +
           static_cast<std::size_t>(settings_.horizon + 1) *
               (4 * sizeof(double) * (NX * NX + NX * NU + NX + NU));
  }
  std::size_t device_bytes() const override { return 0; }

  // For tests and reports.
  const ddp::IlqrResult& last_result() const { return last_; }
  const DdpSettings& ddp_settings() const { return ddp_; }
  typename T::Params& params() { return *params_; }
  int near_obstacles() const { return problem_.near_count; }

 private:
  // The settings it reports: the task's, with one "rollout" (the nominal trajectory).
  static MppiSettings checked(const MppiSettings& s, const DdpSettings& d) {
    if (std::string e = validate(s, NU); !e.empty()) throw std::invalid_argument("mppi." + e);
    if (std::string e = validate(d, NU); !e.empty()) throw std::invalid_argument(e);
    MppiSettings out = s;
    out.rollouts = 1;
    out.chunk_rollouts = 0;
    out.min_rollouts = 0;
    return out;
  }
  double clamp(int j, double v) const {
    return std::clamp(v, static_cast<double>(settings_.u_min[static_cast<std::size_t>(j)]),
                      static_cast<double>(settings_.u_max[static_cast<std::size_t>(j)]));
  }
  void to_float() {
    for (std::size_t n = 0; n < plan_.size(); ++n) plan_[n] = static_cast<float>(plan_d_[n]);
  }

  // The cylinders within ddp.obstacle_reach of the plan's path (path_, from prepare()).
  void select_near(const float* x0) {
    const auto& set = work_->cost.obstacles;
    const int points = settings_.horizon + 1;
    (void)x0;
    int n = 0;
    for (int c = 0; c < set.count; ++c) {
      bool close = false;
      for (int i = 0; i < points && !close; ++i) {
        const float t = static_cast<float>(i) * settings_.dt;
        close = ObstacleSet::surface_distance(set.items[c], path_[2 * i], path_[2 * i + 1], t) <
                static_cast<float>(ddp_.obstacle_reach);
      }
      if (close) near_[static_cast<std::size_t>(n++)] = c;
    }
    problem_.near_count = n;
  }

  std::string name_;
  MppiSettings settings_;
  DdpSettings ddp_;
  std::unique_ptr<typename T::Params> params_;  // as set by inputs and parameter updates
  std::unique_ptr<typename T::Params> work_;    // this cycle's: crash off, obstacle grid built
  Problem problem_;
  ddp::Ilqr<Problem> solver_;
  std::vector<float> plan_;
  std::vector<double> plan_d_;
  std::vector<float> path_;
  std::vector<int> near_;
  ddp::IlqrResult last_;
  UpdateStats stats_;
};

}  // namespace mppi
