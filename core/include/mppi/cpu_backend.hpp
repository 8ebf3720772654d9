// OpenMP rollout backend. Samples are spread over threads; every reduction over samples
// runs in sample order inside one thread (threads split the time steps instead), so the
// plan is bit-identical for any thread count and any run with the same seed.
#pragma once

#include <omp.h>

#include <algorithm>
#include <memory>
#include <vector>

#include "mppi/backend.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"

namespace mppi {

template <class TaskT>
class CpuBackend final : public RolloutBackend<TaskT> {
 public:
  using Base = RolloutBackend<TaskT>;
  using typename Base::Params;
  using Base::kNu;
  using Base::kNx;

  explicit CpuBackend(const MppiSettings& s)
      : k_(s.rollouts),
        t_(s.horizon),
        dt_(s.dt),
        substeps_(s.substeps),
        inv_lambda_(1.0f / s.lambda),
        weighting_(s.weighting),
        seed_(s.seed),
        threads_(s.threads > 0 ? s.threads : omp_get_max_threads()),
        c_(make_sampler_constants<kNu>(s)),
        cost_to_go_(static_cast<std::size_t>(k_) * t_),
        du_(static_cast<std::size_t>(k_) * t_ * kNu),
        crashed_(static_cast<std::size_t>(k_)),
        weights_(static_cast<std::size_t>(k_)),
        scratch_(static_cast<std::size_t>(k_) * threads_) {}

  const char* name() const override { return "cpu"; }

  void update(const float* x0, const Params& params, std::uint32_t cycle, float* plan,
              UpdateStats* stats) override {
    const NoiseKey key{seed_, cycle};
#pragma omp parallel for schedule(static) num_threads(threads_)
    for (int k = 0; k < k_; ++k) rollout(x0, params, key, k, plan);

    if (weighting_ == Weighting::kTrajectory) {
      normalised_weights(0);
#pragma omp parallel for schedule(static) num_threads(threads_)
      for (int i = 0; i < t_; ++i) weighted_update(i, weights_.data(), plan);
    } else {
#pragma omp parallel for schedule(static) num_threads(threads_)
      for (int i = 0; i < t_; ++i) {
        float* w = &scratch_[static_cast<std::size_t>(omp_get_thread_num()) * k_];
        step_weights(i, w);
        weighted_update(i, w, plan);
      }
      normalised_weights(0);  // step-0 weights for the statistics
    }
    summarise(stats, plan);
  }

  std::vector<float> rollout_costs() const override {
    std::vector<float> out(static_cast<std::size_t>(k_));
    for (int k = 0; k < k_; ++k) out[k] = cost_to_go_[static_cast<std::size_t>(k) * t_];
    return out;
  }

  std::size_t host_bytes() const override {
    return (cost_to_go_.size() + du_.size() + weights_.size() + scratch_.size()) * sizeof(float) + crashed_.size();
  }

 private:
  void rollout(const float* x0, const Params& p, const NoiseKey& key, int k, const float* plan) {
    float x[kNx];
    float u[kNu];
    for (int j = 0; j < kNx; ++j) x[j] = x0[j];
    std::uint32_t crashed = 0;
    float* q = &cost_to_go_[static_cast<std::size_t>(k) * t_];
    float* du = &du_[static_cast<std::size_t>(k) * t_ * kNu];
    for (int i = 0; i < t_; ++i) {
      const float* pu = plan + i * kNu;
      float* dui = du + i * kNu;
      perturb<kNu>(c_, key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, dui);
      TaskT::advance(p, x, u, dt_, substeps_, crashed);
      const float t = static_cast<float>(i + 1) * dt_;
      q[i] = sanitize_cost(TaskT::running(p, x, t, &crashed) + control_cost<kNu>(c_, pu, dui));
    }
    q[t_ - 1] = sanitize_cost(q[t_ - 1] + TaskT::terminal(p, x));
    // Cost-to-go S~(tau_i,k), summed from the end.
    for (int i = t_ - 2; i >= 0; --i) q[i] = sanitize_cost(q[i] + q[i + 1]);
    crashed_[k] = crashed != 0;
  }

  // Unnormalised weights of step i into w; returns their sum (>= 1: the best sample has 1).
  float step_weights(int i, float* w) const {
    float best = kCostCeiling;
    for (int k = 0; k < k_; ++k) best = std::min(best, cost_to_go_[static_cast<std::size_t>(k) * t_ + i]);
    float sum = 0.0f;
    for (int k = 0; k < k_; ++k) {
      w[k] = unnormalised_weight(cost_to_go_[static_cast<std::size_t>(k) * t_ + i] - best, inv_lambda_);
      sum += w[k];
    }
    return sum;
  }

  void normalised_weights(int i) {
    const float sum = step_weights(i, weights_.data());
    const float inv = 1.0f / sum;
    for (auto& w : weights_) w *= inv;
  }

  // u_i += sum_k w_k du_{i,k} / sum_k w_k, with w unnormalised.
  void weighted_update(int i, const float* w, float* plan) const {
    float acc[kNu] = {};
    float sum = 0.0f;
    for (int k = 0; k < k_; ++k) {
      const float* d = &du_[(static_cast<std::size_t>(k) * t_ + i) * kNu];
      for (int j = 0; j < kNu; ++j) acc[j] += w[k] * d[j];
      sum += w[k];
    }
    for (int j = 0; j < kNu; ++j) plan[i * kNu + j] = fclamp(plan[i * kNu + j] + acc[j] / sum, c_.u_min[j], c_.u_max[j]);
  }

  void summarise(UpdateStats* stats, const float* plan) const {
    if (stats == nullptr) return;
    float best = kCostCeiling, total = 0.0f, sq = 0.0f;
    int finite = 0, crashed = 0;
    for (int k = 0; k < k_; ++k) {
      const float s = cost_to_go_[static_cast<std::size_t>(k) * t_];
      best = std::min(best, s);
      if (s < kCostCeiling) {
        total += s;
        ++finite;
      }
      crashed += crashed_[k];
      sq += weights_[k] * weights_[k];
    }
    stats->min_cost = best;
    stats->mean_cost = finite > 0 ? total / static_cast<float>(finite) : kCostCeiling;
    stats->ess = sq > 0.0f ? 1.0f / sq : 0.0f;
    stats->crashed = crashed;
    bool ok = ffinite(stats->ess);
    for (int i = 0; i < t_ * kNu; ++i) ok = ok && ffinite(plan[i]);
    stats->finite = ok;
  }

  int k_, t_;
  float dt_;
  int substeps_;
  float inv_lambda_;
  Weighting weighting_;
  std::uint64_t seed_;
  int threads_;
  SamplerConstants<kNu> c_;
  std::vector<float> cost_to_go_;  // K x T, S~(tau_i,k)
  std::vector<float> du_;          // K x T x NU, the applied variations
  std::vector<unsigned char> crashed_;
  std::vector<float> weights_;     // K, normalised step-0 weights
  std::vector<float> scratch_;     // threads x K, per-step weights
};

}  // namespace mppi
