// A display sample of one cycle's rollouts (the "fan" tools/view draws): the lowest-cost
// rollouts and a random subsample of the rest, each with its weight and its positions.
//
// No backend keeps the rollouts' states (the CPU keeps costs and variations, the GPU only
// costs), and keeping them for every cycle would cost memory traffic on every cycle for a
// picture asked for a few times a second. The noise is counter-based, so a rollout is
// rebuilt on the host from what the cycle started with: the plan before the update, the
// state, the prepared parameters and the noise key. Only the step-0 costs S~(tau_0,k) come
// from the backend (RolloutBackend::step0_costs: K floats, a device-to-host copy on CUDA),
// and only on the cycles asked for (Mppi::keep_rollouts), read after the command is out. A rebuilt rollout is the CPU
// scalar kernel's (cpu_kernel.hpp, rollouts<ScalarLanes>): the same perturb, advance and
// running cost; its recomputed cost is kept beside the backend's, and the tests hold them
// equal, so the picture cannot drift from what the optimizer weighed.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "mppi/backend.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"
#include "mppi/settings.hpp"

namespace mppi {

struct RolloutFan {
  // Filled by fill_rollout_fan; sized once by reserve(), never grown in a cycle.
  std::uint32_t cycle = 0;  // the noise counter of the update
  int total = 0;            // rollouts the update used
  int vehicles = 0;
  int steps = 0;            // positions per rollout and vehicle: horizon + 1
  float lambda = 0.0f;
  int count = 0;            // rollouts below; the first `top` are the lowest-cost, lowest first
  int top = 0;
  std::vector<int> index;             // sample index k
  std::vector<float> cost;            // S~(tau_0,k) as the backend computed it
  std::vector<float> rebuilt_cost;    // ... and as the rebuilt rollout gives it (tests)
  std::vector<float> weight;          // normalised step-0 weight
  std::vector<unsigned char> crashed;
  std::vector<float> xyz;             // count x vehicles x steps x 3
  std::vector<float> step_cost;       // scratch: one rollout's running costs

  void reserve(int rollouts, int vehicle_count, int horizon) {
    const auto n = static_cast<std::size_t>(std::max(0, rollouts));
    index.assign(n, 0);
    cost.assign(n, 0.0f);
    rebuilt_cost.assign(n, 0.0f);
    weight.assign(n, 0.0f);
    crashed.assign(n, 0);
    xyz.assign(n * static_cast<std::size_t>(vehicle_count) * static_cast<std::size_t>(horizon + 1) * 3, 0.0f);
    step_cost.assign(static_cast<std::size_t>(std::max(1, horizon)), 0.0f);
  }
  int capacity() const { return static_cast<int>(index.size()); }
};

// What an update leaves for a fan (Mppi::keep_rollouts): its inputs and the backend's costs.
struct KeptRollouts {
  std::vector<float> plan;   // horizon x NU, before the update
  std::vector<float> x0;     // NX
  std::vector<float> costs;  // K: S~(tau_0,k), read at Mppi::fan()
  std::uint32_t cycle = 0;
  int rollouts = 0;          // the update's (UpdateStats::rollouts)
};

namespace fan_detail {

// splitmix64: the random subsample's draw, keyed by (seed, cycle, stratum).
inline std::uint64_t mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// The `want` lowest of costs[0..n) into idx, lowest first (ties: the lower index).
inline int lowest(const float* costs, int n, int want, int* idx) {
  if (want <= 0) return 0;
  int have = 0;
  for (int k = 0; k < n; ++k) {
    if (have == want && !(costs[k] < costs[idx[have - 1]])) continue;
    int at = have < want ? have++ : want - 1;
    while (at > 0 && costs[k] < costs[idx[at - 1]]) {
      idx[at] = idx[at - 1];
      --at;
    }
    idx[at] = k;
  }
  return have;
}

// The draw's index in [lo, hi), moved on (cyclically within the stratum) past the indices
// already taken as top ones, so no rollout appears twice; a stratum of top ones only keeps it.
inline int not_in(const int* taken, int n_taken, std::int64_t lo, std::int64_t hi, std::uint64_t draw) {
  const std::int64_t width = hi - lo;
  const std::int64_t first = static_cast<std::int64_t>(draw % static_cast<std::uint64_t>(width));
  for (std::int64_t step = 0; step < width; ++step) {
    const int k = static_cast<int>(lo + (first + step) % width);
    if (std::find(taken, taken + n_taken, k) == taken + n_taken) return k;
  }
  return static_cast<int>(lo + first);
}

}  // namespace fan_detail

// Rebuilds sample k of the kept update as the scalar CPU kernel runs it: positions into xyz
// (vehicles x (horizon + 1) x 3), the crash flag, and S~(tau_0,k) returned.
template <class T>
float rebuild_rollout(const typename T::Params& p, const MppiSettings& s, const SamplerConstants<T::kNu>& c,
                      const KeptRollouts& kept, std::uint32_t k, float* q, float* xyz, unsigned char* crashed) {
  constexpr int NX = T::kNx, NU = T::kNu, M = T::kVehicles;
  const int steps = s.horizon + 1;
  const NoiseKey key{s.seed, kept.cycle};
  float x[NX];
  std::copy_n(kept.x0.data(), NX, x);
  std::uint32_t crash = 0;
  auto put = [&](int i) {
    for (int j = 0; j < M; ++j) T::Vehicle::position(x + j * T::kVehicleNx, xyz + 3 * (j * steps + i));
  };
  put(0);
  for (int i = 0; i < s.horizon; ++i) {
    const float* pu = kept.plan.data() + i * NU;
    float u[NU], du[NU];
    perturb<NU>(c, key, k, static_cast<std::uint32_t>(i), pu, u, du);
    T::advance(p, x, u, s.dt, s.substeps, crash);
    const float t = static_cast<float>(i + 1) * s.dt;
    q[i] = sanitize_cost(T::running(p, x, t, &crash) + control_cost<NU>(c, pu, du));
    if (i == s.horizon - 1) q[i] = sanitize_cost(q[i] + T::terminal(p, x));
    put(i + 1);
  }
  float acc = q[s.horizon - 1];
  for (int i = s.horizon - 2; i >= 0; --i) acc = sanitize_cost(q[i] + acc);
  *crashed = crash != 0u;
  return acc;
}

// The `top` lowest-cost rollouts of the kept update and `random` others (one drawn from
// each of `random` equal strata of the sample index), into fan, as many as its buffers hold
// (fewer for a longer horizon than it was reserved for; none, and false, when not even one
// fits). Allocates nothing.
template <class T>
bool fill_rollout_fan(const typename T::Params& p, const MppiSettings& s, const KeptRollouts& kept, int top,
                      int random, RolloutFan* fan) {
  const int n = kept.rollouts;
  const float* costs = kept.costs.data();
  const std::size_t per = static_cast<std::size_t>(T::kVehicles) * static_cast<std::size_t>(s.horizon + 1) * 3;
  const int cap = std::min(fan->capacity(), static_cast<int>(fan->xyz.size() / per));
  if (cap < 1 || fan->step_cost.size() < static_cast<std::size_t>(s.horizon)) return false;
  top = std::clamp(top, 0, std::min(cap, n));
  random = std::clamp(random, 0, std::min(cap - top, n));
  fan->count = fan_detail::lowest(costs, n, top, fan->index.data());
  fan->top = fan->count;
  for (int m = 0; m < random; ++m) {
    const std::int64_t lo = std::int64_t{m} * n / random, hi = std::int64_t{m + 1} * n / random;
    const std::uint64_t draw = fan_detail::mix(s.seed ^ fan_detail::mix((std::uint64_t{kept.cycle} << 20) + m));
    fan->index[fan->count++] = fan_detail::not_in(fan->index.data(), fan->top, lo, hi, draw);
  }
  // Normalised step-0 weights, with the backends' flush of tiny weights.
  float min_cost = kCostCeiling;
  for (int k = 0; k < n; ++k) min_cost = std::min(min_cost, costs[k]);
  const float inv_lambda = 1.0f / s.lambda;
  double sum = 0.0;
  for (int k = 0; k < n; ++k) sum += unnormalised_weight(costs[k] - min_cost, inv_lambda);
  const SamplerConstants<T::kNu> c = make_sampler_constants<T::kNu>(s);
  for (int r = 0; r < fan->count; ++r) {
    const int k = fan->index[r];
    fan->cost[r] = costs[k];
    const float w = unnormalised_weight(costs[k] - min_cost, inv_lambda);
    fan->weight[r] = sum > 0.0 ? static_cast<float>(w / sum) : 0.0f;
    fan->rebuilt_cost[r] = rebuild_rollout<T>(p, s, c, kept, static_cast<std::uint32_t>(k), fan->step_cost.data(),
                                              fan->xyz.data() + per * r, &fan->crashed[r]);
  }
  fan->cycle = kept.cycle;
  fan->total = n;
  fan->vehicles = T::kVehicles;
  fan->steps = s.horizon + 1;
  fan->lambda = s.lambda;
  return true;
}

}  // namespace mppi
