// OpenMP rollout backend. Samples run in SIMD batches (settings.simd: the best target this
// CPU runs, or one named, or "off" for one sample at a time) spread over threads; every
// reduction over samples has one fixed order whatever the thread count and the target
// (cpu_kernel.hpp), and threads split the time steps for it, so the plan is bit-identical
// for any thread count and any run with the same seed. Targets differ from each other and
// from the scalar code only through the transcendental functions (a few ulp; see
// simd/lanes.hpp and test/core/test_simd.cpp).
//
// Anytime: given a stop flag, the rollouts run in chunks of samples in sample order, the
// flag read before each; a stopped update uses the samples 0..K'-1 finished so far, which
// is exactly the update of a K'-sample backend. The chunks need no barrier: each thread runs
// its share of each chunk and reads the flag before its next one, and K' is the chunks every
// thread finished (a barrier per chunk cost the daemon 1.2 ms of a 5.9 ms cycle at K = 4096
// on the 2-core VM: a sleeping OpenMP worker is woken through the hypervisor).
//
// Active rollouts (set_active_rollouts): the same prefix, chosen between updates: the
// buffers stay sized for K and the update runs and weighs samples 0..n-1 only.
#pragma once

#include <cstdint>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "mppi/backend.hpp"
#include "mppi/cpu_kernel.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"
#include "mppi/simd.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace cpu {

// The SIMD kernels of a named task for one target, defined in that target's translation
// unit (core/src/simd/kernels.cpp.in); only for the targets this build compiles.
template <class T, simd::Target kTarget>
const KernelOps<T>* simd_kernel_ops();

// The kernels of task T for target t: null when the binary has no SIMD kernels for T there
// (a task not in tasks.hpp's list, or a target not built).
template <class T>
const KernelOps<T>* kernels_for(simd::Target t) {
  if constexpr (!kNamedTask<T>) {
    (void)t;
    return nullptr;
  } else {
    switch (t) {
#ifdef MPPID_SIMD_SSE4
      case simd::Target::kSse4: return simd_kernel_ops<T, simd::Target::kSse4>();
#endif
#ifdef MPPID_SIMD_AVX2
      case simd::Target::kAvx2: return simd_kernel_ops<T, simd::Target::kAvx2>();
#endif
#ifdef MPPID_SIMD_AVX3
      case simd::Target::kAvx3: return simd_kernel_ops<T, simd::Target::kAvx3>();
#endif
#ifdef MPPID_SIMD_NEON
      case simd::Target::kNeon: return simd_kernel_ops<T, simd::Target::kNeon>();
#endif
      default: return nullptr;
    }
  }
}

}  // namespace cpu

template <class TaskT>
class CpuBackend final : public RolloutBackend<TaskT> {
 public:
  using Base = RolloutBackend<TaskT>;
  using typename Base::Params;
  using Base::kNu;
  using Base::kNx;

  // Throws std::invalid_argument when settings.simd names a target this CPU does not run.
  explicit CpuBackend(const MppiSettings& s)
      : k_(s.rollouts),
        active_(s.rollouts),
        t_(s.horizon),
        stride_((s.rollouts + cpu::kPartials - 1) / cpu::kPartials * cpu::kPartials),
        dt_(s.dt),
        substeps_(s.substeps),
        inv_lambda_(1.0f / s.lambda),
        weighting_(s.weighting),
        seed_(s.seed),
        threads_(s.threads > 0 ? s.threads : omp_get_max_threads()),
        chunk_(resolved_chunk_rollouts(s)),
        min_rollouts_(resolved_min_rollouts(s)),
        c_(make_sampler_constants<kNu>(s)),
        cost_(static_cast<std::size_t>(t_) * stride_),
        du_(static_cast<std::size_t>(t_) * kNu * stride_),
        crashed_(static_cast<std::size_t>(stride_)),
        weights_(static_cast<std::size_t>(stride_)),
        chunks_done_(static_cast<std::size_t>(std::max(1, threads_))) {
    const simd::Target asked = simd::resolve(s.simd);
    const cpu::KernelOps<TaskT>* simd_ops = asked == simd::Target::kScalar ? nullptr : cpu::kernels_for<TaskT>(asked);
    if (simd_ops != nullptr) {
      ops_ = *simd_ops;
      target_ = asked;
      name_ = std::string("cpu-") + simd::name(asked);
    }
    // Chunks hold whole batches of the widest target, so a chunk is a prefix of samples.
    chunk_ = std::max(cpu::kPartials, (chunk_ + cpu::kPartials - 1) / cpu::kPartials * cpu::kPartials);
  }

  // Tests: these kernels (e.g. a target's with the C library's transcendentals) as `name`.
  CpuBackend(const MppiSettings& s, const cpu::KernelOps<TaskT>& ops, const char* name) : CpuBackend(s) {
    ops_ = ops;
    name_ = name;
  }

  // "cpu" (scalar) or "cpu-<target>", e.g. "cpu-avx3".
  const char* name() const override { return name_.c_str(); }
  simd::Target target() const { return target_; }

  void set_stop_flag(const std::atomic<bool>* stop) override { stop_ = stop; }
  int set_active_rollouts(int n) override { return active_ = std::clamp(n, 1, k_); }
  int active_rollouts() const override { return active_; }
  int rollout_quantum() const override { return cpu::kPartials; }
  void set_nominal(const float* u_nominal) override { std::copy_n(u_nominal, kNu, c_.u_nominal); }

  // Test hook: called between chunks (on one of the threads, the others waiting at a barrier)
  // with the number of rollouts finished, so a test stops at an exact chunk. Only when a stop
  // flag or a hook is set do rollouts run in chunks; without a hook they run barrier-free.
  void set_chunk_hook(void (*hook)(void* ctx, int finished), void* ctx) {
    hook_ = hook;
    hook_ctx_ = ctx;
  }

  void update(const float* x0, const Params& params, std::uint32_t cycle, float* plan,
              UpdateStats* stats) override {
    cpu::Batch<TaskT> b;
    b.params = &params;
    b.x0 = x0;
    b.plan = plan;
    b.sampler = &c_;
    b.key = NoiseKey{seed_, cycle};
    b.horizon = t_;
    b.stride = stride_;
    b.dt = dt_;
    b.substeps = substeps_;
    b.inv_lambda = inv_lambda_;
    b.trajectory = weighting_ == Weighting::kTrajectory;
    b.cost = cost_.data();
    b.du = du_.data();
    b.crashed = crashed_.data();
    b.weights = weights_.data();

    const int n = roll_out(b);
    // A full run of the active rollouts always updates, however few they are.
    if ((n < min_rollouts_ && n < active_) || n == 0) {
      // Too few rollouts for an update: the plan stays as it was.
      if (stats != nullptr) {
        *stats = UpdateStats{};
        stats->rollouts = n;
        stats->partial = true;
        stats->updated = false;
      }
      return;
    }

    float partial[cpu::kPartials];
    const float best = ops_.step0_weights(b, n, partial);
    const float sum0 = cpu::tree_sum(partial);
    const auto* ops = &ops_;
#pragma omp parallel for schedule(static) num_threads(threads_)
    for (int i = 0; i < t_; ++i) {
      float sums[(1 + kNu) * cpu::kPartials];
      ops->step_sums(b, i, n, sums);
      const float sw = cpu::tree_sum(sums);
      for (int j = 0; j < kNu; ++j) {
        const float acc = cpu::tree_sum(sums + (1 + j) * cpu::kPartials);
        plan[i * kNu + j] = fclamp(plan[i * kNu + j] + acc / sw, c_.u_min[j], c_.u_max[j]);
      }
    }
    summarise(stats, plan, n, best, sum0);
  }

  // S~(tau_0,k) of the active rollouts of the last update (after a partial one, the first
  // UpdateStats::rollouts are this cycle's).
  std::vector<float> rollout_costs() const override {
    return std::vector<float>(cost_.begin(), cost_.begin() + active_);
  }
  void step0_costs(float* out) const override { std::copy_n(cost_.begin(), active_, out); }

  std::size_t host_bytes() const override {
    return (cost_.size() + du_.size() + weights_.size()) * sizeof(float) + crashed_.size();
  }

 private:
  // Runs the rollouts: all of them, or with a stop flag (or hook) chunk by chunk until it is
  // set. Returns how many finished (a prefix of the samples).
  int roll_out(const cpu::Batch<TaskT>& b) {
    const int k = active_;
    const auto* ops = &ops_;
    const int lanes = ops_.lanes;
    if (stop_ == nullptr && hook_ == nullptr) {
      const int batches = (k + lanes - 1) / lanes;
#pragma omp parallel for schedule(static) num_threads(threads_)
      for (int c = 0; c < batches; ++c) ops->rollouts(b, c * lanes, std::min(k, (c + 1) * lanes));
      return k;
    }
    if (hook_ == nullptr) return roll_out_anytime(b);
    int done = 0;
    bool go = true;
#pragma omp parallel num_threads(threads_)
    {
      for (int c0 = 0;; c0 += chunk_) {
#pragma omp single
        {
          done = std::min(c0, k);
          if (c0 > 0 && hook_ != nullptr) hook_(hook_ctx_, done);
          go = c0 < k && !(stop_ != nullptr && stop_->load(std::memory_order_acquire));
        }
        if (!go) break;
        const int c1 = std::min(k, c0 + chunk_);
        const int batches = (c1 - c0 + lanes - 1) / lanes;
#pragma omp for schedule(static)
        for (int c = 0; c < batches; ++c) ops->rollouts(b, c0 + c * lanes, std::min(c1, c0 + (c + 1) * lanes));
      }
    }
    return done;
  }

  // The anytime rollouts with no barrier per chunk: thread t of n runs the batches of each
  // chunk that `omp for schedule(static)` would give it, reading the flag before each chunk.
  // The threads agree on nothing until the region ends; then the chunks all of them finished
  // are the prefix the update uses (samples a thread ran beyond it are left out).
  int roll_out_anytime(const cpu::Batch<TaskT>& b) {
    const int k = active_;
    const auto* ops = &ops_;
    const int lanes = ops_.lanes, chunks = (k + chunk_ - 1) / chunk_;
    int threads = 1;
    int* done = chunks_done_.data();
    const std::atomic<bool>* stop = stop_;
#pragma omp parallel num_threads(threads_)
    {
      const int t = omp_get_thread_num(), n = omp_get_num_threads();
      if (t == 0) threads = n;
      int c = 0;
      for (; c < chunks && !stop->load(std::memory_order_acquire); ++c) {
        const int c0 = c * chunk_, c1 = std::min(k, c0 + chunk_);
        const int batches = (c1 - c0 + lanes - 1) / lanes;
        const int first = batches * t / n, last = batches * (t + 1) / n;
        for (int i = first; i < last; ++i) ops->rollouts(b, c0 + i * lanes, std::min(c1, c0 + (i + 1) * lanes));
      }
      if (t < static_cast<int>(chunks_done_.size())) done[t] = c;
    }
    int all = chunks;
    for (int t = 0; t < std::min(threads, static_cast<int>(chunks_done_.size())); ++t) all = std::min(all, done[t]);
    return std::min(k, all * chunk_);
  }

  // Statistics of the step-0 weights of the first n rollouts, summed in the kernels' order.
  void summarise(UpdateStats* stats, const float* plan, int n, float best, float sum0) const {
    if (stats == nullptr) return;
    const float inv = 1.0f / sum0;
    float sq[cpu::kPartials] = {}, total[cpu::kPartials] = {};
    int finite = 0, crashed = 0;
    for (int k = 0; k < n; ++k) {
      const float s = cost_[static_cast<std::size_t>(k)];
      const float w = weights_[static_cast<std::size_t>(k)] * inv;
      sq[k % cpu::kPartials] += w * w;
      if (s < kCostCeiling) {
        total[k % cpu::kPartials] += s;
        ++finite;
      }
      crashed += crashed_[static_cast<std::size_t>(k)];
    }
    const float sum_sq = cpu::tree_sum(sq);
    *stats = UpdateStats{};
    stats->min_cost = best;
    stats->mean_cost = finite > 0 ? cpu::tree_sum(total) / static_cast<float>(finite) : kCostCeiling;
    stats->ess = sum_sq > 0.0f ? 1.0f / sum_sq : 0.0f;
    stats->crashed = crashed;
    stats->rollouts = n;
    stats->partial = n < active_;
    stats->updated = true;
    bool ok = ffinite(stats->ess);
    for (int i = 0; i < t_ * kNu; ++i) ok = ok && ffinite(plan[i]);
    stats->finite = ok;
  }

  int k_;       // allocated: the ceiling of the active count
  int active_;  // the rollouts an update runs (a prefix of the K)
  int t_, stride_;
  float dt_;
  int substeps_;
  float inv_lambda_;
  Weighting weighting_;
  std::uint64_t seed_;
  int threads_;
  int chunk_;
  int min_rollouts_;
  SamplerConstants<kNu> c_;
  std::vector<float> cost_;              // T x stride, S~(tau_i,k)
  std::vector<float> du_;                // T x NU x stride, the applied variations
  std::vector<unsigned char> crashed_;   // stride
  std::vector<float> weights_;           // stride, unnormalised step-0 weights
  std::vector<int> chunks_done_;         // per thread: anytime chunks finished this update
  cpu::KernelOps<TaskT> ops_ = cpu::kernel_ops<TaskT, cpu::ScalarLanes>();
  simd::Target target_ = simd::Target::kScalar;
  std::string name_ = "cpu";
  const std::atomic<bool>* stop_ = nullptr;
  void (*hook_)(void*, int) = nullptr;
  void* hook_ctx_ = nullptr;
};

}  // namespace mppi
