// The rollout-backend interface: one MPPI update (sample, roll out, weight, update the
// plan) for a task. The CPU (OpenMP) and CUDA backends implement it; the optimizer above
// owns the plan, the warm start and the smoothing.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mppi/hd.hpp"
#include "mppi/sampling.hpp"
#include "mppi/settings.hpp"

namespace mppi {

struct UpdateStats {
  float min_cost = 0.0f;        // lowest S~(tau_0,k)
  float mean_cost = 0.0f;       // mean S~(tau_0,k) over finite rollouts
  float ess = 0.0f;             // effective sample size 1 / sum w^2 of the step-0 weights
  int crashed = 0;              // rollouts that crashed somewhere in the horizon
  bool finite = true;           // every number of the update was finite
  // Anytime cycle (RolloutBackend::set_stop_flag): the rollouts the update used (the first
  // `rollouts` samples), whether the stop flag cut the cycle short, and whether the plan was
  // updated at all (false when fewer than min_rollouts finished: the plan is left as it was).
  int rollouts = 0;
  bool partial = false;
  bool updated = true;
};

// Costs at or above this are treated as "infinitely bad" but stay finite, so the min
// subtraction never computes inf - inf.
constexpr float kCostCeiling = 1e30f;

template <class V>
MPPI_HD V sanitize_cost(const V& q) {
  return select(q == q, fmin_(fmax_(q, V(-kCostCeiling)), V(kCostCeiling)), V(kCostCeiling));
}

// Unnormalised weight of a rollout whose cost exceeds the minimum by `excess` (>= 0).
// Below e^-60 a weight is flushed to zero: it changes no sum at float precision, and
// denormal products would make the weighted update many times slower on a CPU.
template <class V>
MPPI_HD V unnormalised_weight(const V& excess, float inv_lambda) {
  const V a = excess * inv_lambda;
  return select(a > 60.0f, V(0.0f), fexp(-a));
}

template <int NU>
SamplerConstants<NU> make_sampler_constants(const MppiSettings& s) {
  SamplerConstants<NU> c{};
  const float root_nu = std::sqrt(s.nu);
  for (int j = 0; j < NU; ++j) {
    c.noise_std[j] = root_nu * s.sigma[j];
    c.r[j] = s.control_cost_scale * s.lambda / (s.sigma[j] * s.sigma[j]);
    c.u_min[j] = s.u_min[j];
    c.u_max[j] = s.u_max[j];
    c.u_nominal[j] = s.u_nominal.empty() ? 0.0f : s.u_nominal[j];
  }
  c.inv_nu_term = 0.5f * (1.0f - 1.0f / s.nu);
  c.groups = s.noise_groups > 1 ? s.noise_groups : 1;
  c.group_channels = NU / c.groups;
  return c;
}

template <class TaskT>
class RolloutBackend {
 public:
  using Task = TaskT;
  using Params = typename Task::Params;
  static constexpr int kNx = Task::kNx;
  static constexpr int kNu = Task::kNu;

  virtual ~RolloutBackend() = default;
  virtual const char* name() const = 0;

  // Sample K sequences (the active count, set_active_rollouts) around `plan` (T x NU,
  // row-major, inside the limits), roll each out from x0 with `params`, weight them, and
  // overwrite `plan` with the weighted update.
  // `cycle` keys the noise with the settings' seed. Allocates nothing.
  virtual void update(const float* x0, const Params& params, std::uint32_t cycle, float* plan,
                      UpdateStats* stats) = 0;

  // S~(tau_0,k) of every rollout of the last update, the active ones (tests and tools; may
  // allocate).
  virtual std::vector<float> rollout_costs() const = 0;
  // The same floats (the active count, at most K) into out without allocating (the display
  // sample of a cycle's rollouts, rollout_fan.hpp, on the cycles that publish one). The
  // default allocates.
  virtual void step0_costs(float* out) const {
    const std::vector<float> c = rollout_costs();
    std::copy(c.begin(), c.end(), out);
  }

  // The anytime cycle: the backend reads *stop between chunks of rollouts; once it is set,
  // update() uses the rollouts finished so far (UpdateStats::rollouts, partial). The caller
  // clears it before update() and sets it from another thread when the deadline nears
  // (core keeps no clock). Null (the default) runs every rollout. A backend that cannot stop
  // early (CUDA) ignores it.
  virtual void set_stop_flag(const std::atomic<bool>* stop) { (void)stop; }

  // The active rollout count: update() runs samples 0..n-1 of the K allocated (K =
  // MppiSettings::rollouts, the ceiling) and weighs those, exactly the update of a backend
  // built with K = n (the noise is keyed by the sample index, so sample k draws the same
  // numbers whatever n is). n is clamped into [1, K]; returns the count in use. Between
  // updates only; allocates nothing (the CUDA backend captures its graph again).
  virtual int set_active_rollouts(int n) = 0;
  virtual int active_rollouts() const = 0;
  // The multiple a count should be of to run without a partly filled batch (the CPU's
  // SIMD lanes and partial sums, the CUDA chunked kernel's block).
  virtual int rollout_quantum() const { return 1; }

  // Whether update() prepares the parameters for the cycle itself (Task::prepare: the forest
  // cost's obstacle grid over the plan's path, which the CUDA backend builds on the device
  // from x0 and the plan it is given). The optimizer then skips Task::prepare and passes the
  // parameters as they are; any grid in them is ignored.
  virtual bool prepares_params() const { return false; }

  // The control the control cost is measured from (MppiSettings::u_nominal, NU floats): the
  // hover of the vehicle as the daemon estimates it (Controller::set_mass). Between updates
  // only; rare (the CUDA backend captures its graph again).
  virtual void set_nominal(const float* u_nominal) = 0;

  // Bytes allocated at start-up (host, device).
  virtual std::size_t host_bytes() const = 0;
  virtual std::size_t device_bytes() const { return 0; }
};

}  // namespace mppi
