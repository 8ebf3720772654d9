// The CPU backend's kernels, written once for any number type: ScalarLanes (below) runs one
// sample at a time, SimdLanes (simd/lanes.hpp) a SIMD batch of them, through the same
// models, costs, sampler and noise. The backend (cpu_backend.hpp) spreads the calls over
// threads and finishes the reductions.
//
// Layout: sample k's values sit at [row * stride + k], rows over steps (and channels), so a
// batch of consecutive samples loads and stores one vector. stride is K rounded up to
// kPartials, so a batch never runs past a row.
//
// Reductions over samples have one fixed shape, whatever the number type and thread count:
// sample k adds into partial sum k mod kPartials, in sample order, and the backend adds the
// kPartials partials in a fixed tree. A SIMD batch of L lanes holds kPartials / L vectors of
// partials (lane l of vector p is partial p * L + l), so every target and the scalar code
// add the same numbers in the same order.
#pragma once

#include <cstddef>
#include <cstdint>

#include "mppi/backend.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"

namespace mppi::cpu {

constexpr int kPartials = 16;

// One sample at a time.
struct ScalarLanes {
  using F = float;
  using Index = std::uint32_t;
  template <int M>
  using Crash = std::uint32_t;
  static constexpr int kLanes = 1;

  static F load(const float* p) { return *p; }
  static void store(F v, float* p) { *p = v; }
  static Index samples(int k0) { return static_cast<std::uint32_t>(k0); }
  static F keep_first(F v, int n) { return n > 0 ? v : 0.0f; }
  static float min_of(F v) { return v; }
  template <int M>
  static void store_crashed(std::uint32_t c, unsigned char* out) {
    *out = c != 0u;
  }
};

// What the kernels of one update read and write.
template <class T>
struct Batch {
  const typename T::Params* params = nullptr;
  const float* x0 = nullptr;
  const float* plan = nullptr;  // horizon x NU, shared by every sample
  const SamplerConstants<T::kNu>* sampler = nullptr;
  NoiseKey key{};
  int horizon = 0;
  int stride = 0;  // K rounded up to kPartials
  float dt = 0.0f;
  int substeps = 1;
  float inv_lambda = 0.0f;
  bool trajectory = false;          // trajectory weighting: every step uses the step-0 weights
  float* cost = nullptr;            // horizon x stride: S~(tau_i,k), the cost-to-go
  float* du = nullptr;              // horizon x NU x stride: the applied variations
  unsigned char* crashed = nullptr;  // stride: the rollout crashed somewhere
  float* weights = nullptr;         // stride: unnormalised step-0 weights
};

// Rolls out samples [k_begin, k_end): k_begin is a multiple of N::kLanes; the last batch may
// run past k_end (its extra lanes are real samples, kept out of every reduction).
template <class N, class T>
void rollouts(const Batch<T>& b, int k_begin, int k_end) {
  using F = typename N::F;
  constexpr int NX = T::kNx, NU = T::kNu;
  const typename T::Params& p = *b.params;
  const std::size_t stride = static_cast<std::size_t>(b.stride);
  for (int k0 = k_begin; k0 < k_end; k0 += N::kLanes) {
    F x[NX];
    for (int n = 0; n < NX; ++n) x[n] = F(b.x0[n]);
    typename N::template Crash<T::kVehicles> crashed{};
    const auto sample = N::samples(k0);
    float* q = b.cost + k0;
    float* dus = b.du + k0;
    for (int i = 0; i < b.horizon; ++i) {
      const float* pu = b.plan + i * NU;
      F u[NU], du[NU];
      perturb<NU>(*b.sampler, b.key, sample, static_cast<std::uint32_t>(i), pu, u, du);
      for (int j = 0; j < NU; ++j) N::store(du[j], dus + (static_cast<std::size_t>(i) * NU + j) * stride);
      T::advance(p, x, u, b.dt, b.substeps, crashed);
      const float t = static_cast<float>(i + 1) * b.dt;
      F qi = sanitize_cost(T::running(p, x, t, &crashed) + control_cost<NU>(*b.sampler, pu, du));
      if (i == b.horizon - 1) qi = sanitize_cost(qi + T::terminal(p, x));
      N::store(qi, q + static_cast<std::size_t>(i) * stride);
    }
    // Cost-to-go S~(tau_i,k), summed from the end.
    F acc = N::load(q + static_cast<std::size_t>(b.horizon - 1) * stride);
    for (int i = b.horizon - 2; i >= 0; --i) {
      acc = sanitize_cost(N::load(q + static_cast<std::size_t>(i) * stride) + acc);
      N::store(acc, q + static_cast<std::size_t>(i) * stride);
    }
    N::template store_crashed<T::kVehicles>(crashed, b.crashed + k0);
  }
}

// Least S~(tau_i,k) over the first n samples (exact in any order).
template <class N>
float row_min(const float* row, int n) {
  using F = typename N::F;
  F m = kCostCeiling;
  for (int k0 = 0; k0 < n; k0 += N::kLanes) {
    F v = N::load(row + k0);
    if (k0 + N::kLanes > n) v = select(N::keep_first(F(1.0f), n - k0) > 0.0f, v, F(kCostCeiling));
    m = fmin_(m, v);
  }
  return N::min_of(m);
}

// The unnormalised step-0 weights of the first n samples into b.weights (0 for the lanes of
// the last batch past n), and their kPartials partial sums into partial. Returns the least
// S~(tau_0,k).
template <class N, class T>
float step0_weights(const Batch<T>& b, int n, float* partial) {
  using F = typename N::F;
  constexpr int L = N::kLanes, P = kPartials / L;
  const float best = row_min<N>(b.cost, n);
  F sum[P];
  for (int p = 0; p < P; ++p) sum[p] = 0.0f;
  for (int k0 = 0; k0 < n; k0 += L) {
    F w = unnormalised_weight(N::load(b.cost + k0) - best, b.inv_lambda);
    if (k0 + L > n) w = N::keep_first(w, n - k0);
    N::store(w, b.weights + k0);
    sum[(k0 % kPartials) / L] += w;
  }
  for (int p = 0; p < P; ++p) N::store(sum[p], partial + p * L);
  return best;
}

// Step i of the update over the first n samples: the kPartials partial sums of w and of
// w du_j (j < NU) into out[0..kPartials) and out[(1 + j) kPartials ..), with w the
// unnormalised weights of step i (cost-to-go) or of step 0 (b.trajectory; step0_weights
// first).
template <class N, class T>
void step_sums(const Batch<T>& b, int i, int n, float* out) {
  using F = typename N::F;
  constexpr int NU = T::kNu, L = N::kLanes, P = kPartials / L;
  const std::size_t stride = static_cast<std::size_t>(b.stride);
  const float* du = b.du + static_cast<std::size_t>(i) * NU * stride;
  const float* row = b.cost + static_cast<std::size_t>(i) * stride;
  const float best = b.trajectory ? 0.0f : row_min<N>(row, n);
  F sw[P], sdu[NU][P];
  for (int p = 0; p < P; ++p) {
    sw[p] = 0.0f;
    for (int j = 0; j < NU; ++j) sdu[j][p] = 0.0f;
  }
  for (int k0 = 0; k0 < n; k0 += L) {
    F w;
    if (b.trajectory) {
      w = N::load(b.weights + k0);
    } else {
      w = unnormalised_weight(N::load(row + k0) - best, b.inv_lambda);
      if (k0 + L > n) w = N::keep_first(w, n - k0);
    }
    const int p = (k0 % kPartials) / L;
    sw[p] += w;
    for (int j = 0; j < NU; ++j) sdu[j][p] += w * N::load(du + j * stride + k0);
  }
  for (int p = 0; p < P; ++p) {
    N::store(sw[p], out + p * L);
    for (int j = 0; j < NU; ++j) N::store(sdu[j][p], out + (1 + j) * kPartials + p * L);
  }
}

// The kernels of one task for one number type, as the backend calls them.
template <class T>
struct KernelOps {
  int lanes;
  void (*rollouts)(const Batch<T>&, int k_begin, int k_end);
  float (*step0_weights)(const Batch<T>&, int n, float* partial);
  void (*step_sums)(const Batch<T>&, int i, int n, float* out);
};

template <class T, class N>
constexpr KernelOps<T> kernel_ops() {
  return KernelOps<T>{N::kLanes, &rollouts<N, T>, &step0_weights<N, T>, &step_sums<N, T>};
}

// The kPartials partial sums added in the fixed tree ((p0 + p1) + (p2 + p3)) + ... .
inline float tree_sum(const float* p) {
  float level[kPartials];
  for (int i = 0; i < kPartials; ++i) level[i] = p[i];
  for (int width = kPartials; width > 1; width /= 2)
    for (int i = 0; i < width / 2; ++i) level[i] = level[2 * i] + level[2 * i + 1];
  return level[0];
}

}  // namespace mppi::cpu
