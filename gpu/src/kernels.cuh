// The kernels of one MPPI update (Sec. V.A of the notes), templated on the task. They call
// the same HD model, cost and sampler functions as CpuBackend; only the parallel layout
// differs. Every reduction has a fixed shape (no float atomics), so a run is bit-for-bit
// repeatable.
//
//   sample          teams: one thread per (rollout k, step i), the perturbed control u
//                   (K x T x NU, kept for the update) and its control cost (K x T)
//   rollout_single  G lanes per rollout, state in registers (single vehicles; forest.cuh)
//   rollout_team    M consecutive lanes of a warp per rollout, vehicle j on lane j
//   weigh_local     per (step i, chunk of rollouts): the chunk's own minimum m_c of S~, then
//                   w = exp(-(S - m_c)/lambda), sum w and w du, with du = u - plan from the
//                   kept controls (the pre-pass's, or the rollout's), or regenerated from the
//                   same counter-based noise
//   finalize_blocks (chunked.cuh) per step i: the chunks' sums rescaled to the global minimum
//                   and added in chunk order, u_i = clamp(u_i + sum w du / sum w); stats
//
// Where the noise is drawn (NoiseMode). Teams: in the pre-pass when its K x T x NU buffer
// fits, which takes a chunk of noise draws off every team rollout's serial chain (-10 % at
// team3 K=1200 on an H100). Single vehicles (lane kernel): inside the rollout, which keeps
// the controls for the update when they fit (cuda_backend_impl.cuh), else draws them again.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "mppi/backend.hpp"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"
#include "forest.cuh"

namespace mppi::cuda_detail {

// What the host sends each cycle (one copy): noise key, state, task parameters. The plan
// (T x NU floats) follows at plan_offset<T>().
template <class T>
struct Input {
  NoiseKey key;
  float x0[T::kNx];
  typename T::Params params;
};

// Statistics of the step-0 weights, per chunk of rollouts and in total.
struct StatsPart {
  float sum_w2;
  float sum_cost;  // S~(tau_0,k) over finite rollouts
  int finite;
  int crashed;
};
struct DeviceStats {
  float min_cost;
  float sum_w;
  float sum_w2;
  float sum_cost;
  int finite;
  int crashed;
};

constexpr unsigned kFullMask = 0xffffffffu;

__host__ __device__ constexpr std::size_t align16(std::size_t n) { return (n + 15) / 16 * 16; }

enum class NoiseMode { kPrepass, kInline };

// N consecutive floats, 16 bytes at a time when N is a multiple of 4 (the caller's pointer
// is then 16-byte aligned: it points at a multiple of N floats into a 16-aligned buffer).
template <int N>
__device__ __forceinline__ void load_floats(const float* __restrict__ src, float* dst) {
  if constexpr (N % 4 == 0) {
#pragma unroll
    for (int n = 0; n < N; n += 4) {
      const float4 v = __ldg(reinterpret_cast<const float4*>(src + n));
      dst[n] = v.x;
      dst[n + 1] = v.y;
      dst[n + 2] = v.z;
      dst[n + 3] = v.w;
    }
  } else {
#pragma unroll
    for (int n = 0; n < N; ++n) dst[n] = __ldg(src + n);
  }
}
template <int N>
__device__ __forceinline__ void store_floats(float* dst, const float* src) {
  if constexpr (N % 4 == 0) {
#pragma unroll
    for (int n = 0; n < N; n += 4)
      *reinterpret_cast<float4*>(dst + n) = make_float4(src[n], src[n + 1], src[n + 2], src[n + 3]);
  } else {
#pragma unroll
    for (int n = 0; n < N; ++n) dst[n] = src[n];
  }
}

// Copies the task parameters the kernels read (staged_param_bytes) into shared memory (read
// by every thread at every step).
template <class T>
__device__ const typename T::Params* stage_params(const typename T::Params& src, unsigned char* smem) {
  constexpr std::size_t kBytes = staged_param_bytes<T>();
  static_assert(kBytes % 4 == 0, "parameters are copied as 32-bit words");
  const auto* from = reinterpret_cast<const std::uint32_t*>(&src);
  auto* to = reinterpret_cast<std::uint32_t*>(smem);
  for (unsigned w = threadIdx.x; w < kBytes / 4; w += blockDim.x) to[w] = from[w];
  __syncthreads();
  return reinterpret_cast<const typename T::Params*>(smem);
}

// The configuration of a launch on stream st that is a programmatic dependent of the kernel
// before it when pdl is set (sm_90 on; see below); *attr holds the attribute (it must outlive the
// cudaLaunchKernelEx call).
inline cudaLaunchConfig_t launch_config(dim3 grid, dim3 block, std::size_t smem, cudaStream_t st, bool pdl,
                                        cudaLaunchAttribute* attr) {
  cudaLaunchConfig_t cfg{};
  cfg.gridDim = grid;
  cfg.blockDim = block;
  cfg.dynamicSmemBytes = smem;
  cfg.stream = st;
  attr->id = cudaLaunchAttributeProgrammaticStreamSerialization;
  attr->val.programmaticStreamSerializationAllowed = 1;
  cfg.attrs = attr;
  cfg.numAttrs = pdl ? 1 : 0;
  return cfg;
}

// Programmatic dependent launch (sm_90 on): the kernel after this one in the stream may be
// launched now (it waits in griddep_wait() until this grid has finished and its writes are
// visible); elsewhere, and when not launched that way, both are no-ops.
__device__ __forceinline__ void griddep_launch_dependents() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.launch_dependents;" ::: "memory");
#endif
}
__device__ __forceinline__ void griddep_wait() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  asm volatile("griddepcontrol.wait;" ::: "memory");
#endif
}

// Sum of N values over the block (blockDim.x a multiple of 32); the result is in thread 0.
// Butterfly shuffles in a warp, then warp 0 over the warps' sums: a fixed order.
template <int N, class V>
__device__ void block_sum(V (&v)[N]) {
  __shared__ V sh[32][N];
  for (int n = 0; n < N; ++n)
    for (int off = 16; off > 0; off >>= 1) v[n] += __shfl_xor_sync(kFullMask, v[n], off);
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, warps = blockDim.x >> 5;
  __syncthreads();
  if (lane == 0)
    for (int n = 0; n < N; ++n) sh[warp][n] = v[n];
  __syncthreads();
  if (warp == 0) {
    for (int n = 0; n < N; ++n) {
      v[n] = lane < warps ? sh[lane][n] : V(0);
      for (int off = 16; off > 0; off >>= 1) v[n] += __shfl_xor_sync(kFullMask, v[n], off);
    }
  }
}

// Minimum over the block; the result is in every thread (min is exact in any order).
__device__ inline float block_min(float v) {
  __shared__ float sh[32];
  for (int off = 16; off > 0; off >>= 1) v = fmin_(v, __shfl_xor_sync(kFullMask, v, off));
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, warps = blockDim.x >> 5;
  __syncthreads();
  if (lane == 0) sh[warp] = v;
  __syncthreads();
  v = kCostCeiling;
  for (int w = 0; w < warps; ++w) v = fmin_(v, sh[w]);
  return v;
}

// S~ of one rollout: q was written per step (row-major over steps, S[i * K + k]); turn it
// into the cost-to-go in place, summed from the end as CpuBackend does. The loads of a batch
// of steps are issued together (one memory round trip per batch, not per step).
__device__ inline void suffix_sums(float* S, int K, int horizon, int k, float last) {
  constexpr int kBatch = 16;
  float acc = last;
  int i = horizon - 2;
  for (; i >= kBatch - 1; i -= kBatch) {
    float v[kBatch];
#pragma unroll
    for (int b = 0; b < kBatch; ++b) v[b] = S[static_cast<std::size_t>(i - b) * K + k];
#pragma unroll
    for (int b = 0; b < kBatch; ++b) {
      acc = sanitize_cost(v[b] + acc);
      S[static_cast<std::size_t>(i - b) * K + k] = acc;
    }
  }
  for (; i >= 0; --i) {
    float* s = S + static_cast<std::size_t>(i) * K + k;
    acc = sanitize_cost(*s + acc);
    *s = acc;
  }
}

// ---- the noise pre-pass --------------------------------------------------------------------
// Thread (k, i): u = clamp(plan_i + noise) into u_out[(i K + k) NU ...] and its control cost
// into cc_out[i K + k], both exactly as the rollout would compute them.
template <class T>
__global__ void sample(const Input<T>* in, const float* plan, int K, float* u_out, float* cc_out,
                       SamplerConstants<T::kNu> c) {
  constexpr int NU = T::kNu;
  const int k = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  const int i = static_cast<int>(blockIdx.y);
  if (k >= K) return;
  const float* pu = plan + i * NU;
  float u[NU], du[NU];
  perturb<NU>(c, in->key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, du);
  const std::size_t at = static_cast<std::size_t>(i) * K + k;
  store_floats<NU>(u_out + at * NU, u);
  cc_out[at] = control_cost<NU>(c, pu, du);
}

// Where the rollout kernels find the noise of the pre-pass (null without one).
template <int NU>
struct RolloutIo {
  const float* u_in;   // K x T x NU controls
  const float* cc_in;  // K x T control costs
};

// ---- single vehicle: G lanes per rollout, the state in registers --------------------
// The G lanes of a rollout run the same dynamics on the same numbers (so they agree bit for
// bit) and split the obstacle loop (forest.cuh). With few rollouts the GPU is mostly idle and
// a rollout's serial chain of steps sets the time; G > 1 shortens each step's link of it.
// At most 64 registers (eight blocks of 128 a multiprocessor, no spills): 32 warps an SM at
// K = 1 M, -2.7 % on an H100 against 75 registers and 24 warps. u_keep (or null): the
// perturbed controls kept for the update, [(i K + k) NU + n].
template <class T, int G>
__global__ void __launch_bounds__(128, 8) rollout_single(const Input<T>* in, const float* plan, RolloutIo<T::kNu> io, float* S,
                               unsigned char* crashed_out, float* u_keep, int K, int horizon, float dt, int substeps,
                               SamplerConstants<T::kNu> c) {
  constexpr int NX = T::kNx, NU = T::kNu;
  static_assert(G == 1 || G == 2 || G == 4 || G == 8, "lanes per rollout: 1, 2, 4 or 8");
  (void)io;
  extern __shared__ __align__(16) unsigned char smem[];
  const typename T::Params& p = *stage_params<T>(in->params, smem);
  const int thread = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  const int lane = thread % G;
  int k = thread / G;
  const bool active = k < K;
  if constexpr (G == 1) {
    if (!active) return;
  } else {
    // Every lane of the warp takes part in the shuffles: the spare ones repeat rollout K-1.
    if (!active) k = K - 1;
  }
  const bool writer = active && lane == 0;
  const ObstacleGrid* grid = device_grid<T>(in->params);
  const NoiseKey key = in->key;
  float x[NX], u[NU], du[NU];
  for (int n = 0; n < NX; ++n) x[n] = in->x0[n];
  std::uint32_t crashed = 0;
  float q = 0.0f;
  for (int i = 0; i < horizon; ++i) {
    const float* pu = plan + i * NU;
    perturb<NU>(c, key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, du);
    if (u_keep != nullptr && writer) store_floats<NU>(u_keep + (static_cast<std::size_t>(i) * K + k) * NU, u);
    T::advance(p, x, u, dt, substeps, crashed);
    const float t = static_cast<float>(i + 1) * dt;
    q = sanitize_cost(running_cost<T, G>(p, grid, x, t, lane, &crashed) + control_cost<NU>(c, pu, du));
    if (writer && i < horizon - 1) S[static_cast<std::size_t>(i) * K + k] = q;
  }
  if (!writer) return;
  q = sanitize_cost(q + T::terminal(p, x));
  S[static_cast<std::size_t>(horizon - 1) * K + k] = q;
  suffix_sums(S, K, horizon, k, q);
  crashed_out[k] = crashed != 0u;
}

// ---- teams: M lanes per rollout, vehicle j on lane j ----------------------------------
// Shared state of one rollout: the perturbed controls of M steps (lane j draws step i0 + j
// with perturb<NU>, so the noise is exactly CpuBackend's and drawn once), every vehicle's
// state for the pair terms (double-buffered by step), per-lane cost and the crash mask.
template <class T>
struct TeamRollout {
  static constexpr int kPairs = T::kVehicles * (T::kVehicles - 1) / 2;
  float u[T::kVehicles][T::kNu];
  float control_cost[T::kVehicles];
  float x[2][T::kVehicles][T::kVehicleNx];
  float q[2][T::kVehicles + kPairs];  // vehicle terms, then pair terms in CpuBackend's order
  unsigned mask;
};

template <class T>
__host__ __device__ constexpr int team_rollouts_per_warp() { return 32 / T::kVehicles; }

template <class T, NoiseMode kMode>
__global__ void rollout_team(const Input<T>* in, const float* plan, RolloutIo<T::kNu> io, float* S,
                             unsigned char* crashed_out, float* u_keep, int K, int horizon, float dt, int substeps,
                             SamplerConstants<T::kNu> c) {
  constexpr int M = T::kVehicles, VNX = T::kVehicleNx, VNU = T::kVehicleNu, NU = T::kNu;
  constexpr int G = team_rollouts_per_warp<T>();
  (void)u_keep;  // the pre-pass keeps them
  using Vehicle = typename T::Vehicle;
  using Cost = typename T::Cost;
  extern __shared__ __align__(16) unsigned char smem[];
  const typename T::Params& p = *stage_params<T>(in->params, smem);
  auto* teams = reinterpret_cast<TeamRollout<T>*>(smem + align16(staged_param_bytes<T>()));

  const int lane = static_cast<int>(threadIdx.x & 31), warp = static_cast<int>(threadIdx.x >> 5);
  const int warps = static_cast<int>(blockDim.x >> 5);
  const int k0 = (static_cast<int>(blockIdx.x) * warps + warp) * G;
  if (k0 >= K) return;  // the whole warp
  const int g = lane / M, j = lane % M;
  const int k = k0 + g;
  const bool active = g < G && k < K;  // the other lanes only keep the warp's barriers
  TeamRollout<T>& r = teams[warp * G + (g < G ? g : 0)];
  const NoiseKey key = in->key;
  const ObstacleGrid* grid = device_grid<T>(in->params);
  const float h = dt / static_cast<float>(substeps);

  float x[VNX];
  for (int n = 0; n < VNX; ++n) x[n] = in->x0[j * VNX + n];
  if (active && j == 0) r.mask = 0u;
  std::uint32_t mask = 0u;
  float q_last = 0.0f;
  int buf = 0;
  for (int i0 = 0; i0 < horizon; i0 += M) {
    const int steps = horizon - i0 < M ? horizon - i0 : M;
    if (kMode != NoiseMode::kPrepass && active && j < steps) {
      const int i = i0 + j;
      const float* pu = plan + i * NU;
      float u[NU], du[NU];
      perturb<NU>(c, key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, du);
      for (int n = 0; n < NU; ++n) r.u[j][n] = u[n];
      r.control_cost[j] = control_cost<NU>(c, pu, du);
    }
    __syncwarp();
    for (int s = 0; s < steps; ++s) {
      const int i = i0 + s;
      std::uint32_t bits = 0u;
      const std::size_t at = static_cast<std::size_t>(i) * K + k;
      float qc = 0.0f;
      if (active) {
        float uj[VNU];
        if constexpr (kMode == NoiseMode::kPrepass) {
          load_floats<VNU>(io.u_in + at * NU + j * VNU, uj);
          if (j == 0) qc = __ldg(io.cc_in + at);
        } else {
          for (int n = 0; n < VNU; ++n) uj[n] = r.u[s][j * VNU + n];
          qc = r.control_cost[s];
        }
        if (((mask >> j) & 1u) == 0u)
          for (int sub = 0; sub < substeps; ++sub) Vehicle::step(p.vehicle, x, uj, h);
        for (int n = 0; n < VNX; ++n) r.x[buf][j][n] = x[n];
        bool hit = ((mask >> j) & 1u) != 0u;  // crashed before (Task::running_with)
        r.q[buf][j] = vehicle_cost<T>(p, grid, j, x, static_cast<float>(i + 1) * dt, 0, &hit);
        if (hit) bits |= 1u << j;
      }
      __syncwarp();
      if (active) {
        // Pair number n (CpuBackend's order) goes to lane n mod M.
        int n = 0;
        for (int a = 0; a < M; ++a) {
          for (int b = a + 1; b < M; ++b, ++n) {
            if (n % M == j) {
              bool hit = false;
              r.q[buf][M + n] = Cost::pair(p.cost, r.x[buf][a], r.x[buf][b], &hit);
              if (hit) bits |= (1u << a) | (1u << b);
            }
          }
        }
        if (bits != 0u) atomicOr(&r.mask, bits);
      }
      __syncwarp();
      if (active) {
        mask = r.mask;
        if (j == 0) {
          // Summed in Task::running's order (vehicles, then pairs), so the sum rounds alike.
          float run = 0.0f;
          for (int v = 0; v < M + TeamRollout<T>::kPairs; ++v) run += r.q[buf][v];
          q_last = sanitize_cost(run + qc);
          if (i < horizon - 1) S[at] = q_last;
        }
      }
      buf ^= 1;
    }
    __syncwarp();  // every lane is done with this chunk's controls
  }
  if (active) r.q[buf][j] = Cost::terminal(p.cost, j, x);
  __syncwarp();
  if (active && j == 0) {
    float phi = 0.0f;
    for (int v = 0; v < M; ++v) phi += r.q[buf][v];
    q_last = sanitize_cost(q_last + phi);
    S[static_cast<std::size_t>(horizon - 1) * K + k] = q_last;
    suffix_sums(S, K, horizon, k, q_last);
    crashed_out[k] = mask != 0u;
  }
}

// ---- weights and the update ------------------------------------------------------------
// Block (i, c): over chunk c of the rollouts at step i, the chunk's own minimum m_c of the
// weighting row (S~(tau_i,k), cost-to-go, or S~(tau_0,k), trajectory), then with
// w = exp(-(S - m_c)/lambda) the sums w and w du, in a fixed order; m_c into pmin[i * chunks + c]
// and the sums into part, for finalize_blocks (chunked.cuh), which rescales each chunk to the
// global minimum. Block (0, c) also sums the step-0 statistics. u_stored: the controls of
// every (k, i), or null to draw them again.
template <class T>
__global__ void weigh_local(const Input<T>* in, const float* plan, const float* u_stored, const float* S,
                            const unsigned char* crashed, int K, int chunk, float inv_lambda, int trajectory,
                            float* pmin, float* part, StatsPart* stats_part, SamplerConstants<T::kNu> c) {
  constexpr int NU = T::kNu;
  const int i = static_cast<int>(blockIdx.x), ci = static_cast<int>(blockIdx.y), chunks = static_cast<int>(gridDim.y);
  const int wi = trajectory ? 0 : i;
  const float* row = S + static_cast<std::size_t>(wi) * K;
  const int begin = ci * chunk, end = begin + chunk < K ? begin + chunk : K;
  float m = kCostCeiling;
  for (int k = begin + static_cast<int>(threadIdx.x); k < end; k += static_cast<int>(blockDim.x)) m = fmin_(m, row[k]);
  m = block_min(m);

  const NoiseKey key = in->key;
  const float* pu = plan + i * NU;
  float acc[NU + 1] = {};
  float st[2] = {};
  int cnt[2] = {};
  float u[NU], du[NU];
  for (int k = begin + static_cast<int>(threadIdx.x); k < end; k += static_cast<int>(blockDim.x)) {
    const float s = row[k];
    const float w = unnormalised_weight(s - m, inv_lambda);
    if (u_stored != nullptr) {
      // du = u - plan, as perturb computes it
      load_floats<NU>(u_stored + (static_cast<std::size_t>(i) * K + k) * NU, u);
      for (int n = 0; n < NU; ++n) du[n] = u[n] - pu[n];
    } else {
      perturb<NU>(c, key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, du);
    }
    acc[0] += w;
    for (int n = 0; n < NU; ++n) acc[1 + n] += w * du[n];
    if (i == 0) {
      st[0] += w * w;
      if (s < kCostCeiling) {
        st[1] += s;
        ++cnt[0];
      }
      cnt[1] += crashed[k];
    }
  }
  block_sum(acc);
  griddep_launch_dependents();
  if (threadIdx.x == 0) {
    pmin[static_cast<std::size_t>(i) * chunks + ci] = m;
    for (int n = 0; n <= NU; ++n) part[(static_cast<std::size_t>(i) * chunks + ci) * (NU + 1) + n] = acc[n];
  }
  if (i == 0) {
    block_sum(st);
    block_sum(cnt);
    if (threadIdx.x == 0) stats_part[ci] = StatsPart{st[0], st[1], cnt[0], cnt[1]};
  }
}

}  // namespace mppi::cuda_detail
