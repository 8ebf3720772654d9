// rollout_chunked: the single-vehicle rollout with the serial chain cut down to the dynamics.
//
// A block holds R = 32 rollouts and NW warps. The horizon is walked in chunks of C steps;
// each chunk has two phases, separated by block barriers:
//   A  one warp (a different one each chunk, so the dynamics spread over the schedulers)
//      advances the 32 rollouts C steps with T::advance and stores every state in shared
//      memory; only this is serial in the step.
//   B  every warp, one (rollout, step) item per thread: the running cost T::running of the
//      stored state (Task::running_with, the forest's obstacle search over a copy of the
//      cylinders laid out for 16-byte loads), plus the control cost; and the noise of the
//      next chunk (perturb, control_cost), drawn ahead into a second buffer.
// Several blocks per multiprocessor overlap one block's phase A with the others' phase B.
//
// Crashes. Task::advance freezes a crashed vehicle, and a crash is only known from the cost.
// Phase A never waits for it: it advances as if nothing crashed. Phase B then finds, per
// rollout, the first step s* whose cost set a crash bit; the rollout's state is frozen at
// x(s*) from there on (kept in shared memory), the items after s* in this chunk are costed
// again with it, and every later chunk costs the frozen state instead of phase A's. That is
// exactly CpuBackend's sequence: x(s*+1) = x(s*) = ... and running(x(s*), t_i) after s*.
//
// The per-step costs stay in shared memory (T x 32 floats) until the end, where one warp
// turns them into the cost-to-go (summed from the end, as CpuBackend does), writes S~ once,
// and the block writes its minimum of every step (pmin[i][block]) for the weights. The
// weights and the plan update are weigh/finalize (kernels.cuh), unchanged; u_out (when not
// null) keeps every perturbed control (K x T x NU, [i][k][n]) for weigh, which otherwise
// draws the noise again.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "forest.cuh"
#include "kernels.cuh"

namespace mppi::cuda_detail {

// The cylinders as five arrays (structure of arrays) in shared memory, so the search reads
// four cylinders with one 16-byte load per field; unused slots are never picked.
struct ObstacleSoA {
  float x[ObstacleSet::kCapacity];
  float y[ObstacleSet::kCapacity];
  float r[ObstacleSet::kCapacity];
  float vx[ObstacleSet::kCapacity];
  float vy[ObstacleSet::kCapacity];
  int count;
};

// ObstacleSet::nearest_surface over the SoA copy: the same cylinders, in the same order, each
// through ObstacleSet::surface_distance and the same comparison, so bit-identical to it.
__device__ __forceinline__ float nearest_surface_soa(const ObstacleSoA& o, float px, float py, float t) {
  constexpr float kInf = __builtin_huge_valf();
  const int count = o.count;
  float best = ObstacleSet::kFar;
  for (int base = 0; base < count; base += 8) {
    float d[8];
#pragma unroll
    for (int h = 0; h < 2; ++h) {
      const int b = base + 4 * h;
      const float4 cx = *reinterpret_cast<const float4*>(o.x + b);
      const float4 cy = *reinterpret_cast<const float4*>(o.y + b);
      const float4 cr = *reinterpret_cast<const float4*>(o.r + b);
      const float4 cvx = *reinterpret_cast<const float4*>(o.vx + b);
      const float4 cvy = *reinterpret_cast<const float4*>(o.vy + b);
      const Cylinder c0{cx.x, cy.x, cr.x, cvx.x, cvy.x}, c1{cx.y, cy.y, cr.y, cvx.y, cvy.y};
      const Cylinder c2{cx.z, cy.z, cr.z, cvx.z, cvy.z}, c3{cx.w, cy.w, cr.w, cvx.w, cvy.w};
      d[4 * h + 0] = ObstacleSet::surface_distance(c0, px, py, t);
      d[4 * h + 1] = ObstacleSet::surface_distance(c1, px, py, t);
      d[4 * h + 2] = ObstacleSet::surface_distance(c2, px, py, t);
      d[4 * h + 3] = ObstacleSet::surface_distance(c3, px, py, t);
    }
#pragma unroll
    for (int u = 0; u < 8; ++u) {
      const float v = base + u < count ? d[u] : kInf;  // past the count: never picked
      best = v < best ? v : best;
    }
  }
  return best;
}

// Task::running for a single vehicle; forest tasks search the SoA cylinders.
template <class T>
__device__ __forceinline__ float running_chunked(const typename T::Params& p, const ObstacleSoA* soa, const float* x,
                                                 float t, std::uint32_t* crashed) {
  if constexpr (kForestTask<T>) {
    using Vehicle = typename T::Vehicle;
    return T::running_with(p, x, crashed, [&](int j, const float* xj, bool* hit) {
      float pos[3];
      Vehicle::position(xj, pos);
      const float d = nearest_surface_soa(*soa, pos[0], pos[1], t);
      return ForestCost<Vehicle>::vehicle_at_distance(p.cost, j, xj, d, hit);
    });
  } else {
    (void)soa;
    return T::running(p, x, t, crashed);
  }
}

// Where everything lives in the dynamic shared memory of rollout_chunked (bytes from the
// start, each 16-aligned). Sized on the host for (chunk, horizon).
template <class T>
struct ChunkLayout {
  static constexpr int R = 32;  // rollouts per block
  static constexpr int NX = T::kNx, NU = T::kNu;
  std::size_t params, soa, xs, us, cc, hit, qs, xf, flags, bytes;
  __host__ __device__ ChunkLayout(int chunk, int horizon) {
    std::size_t at = 0;
    auto take = [&](std::size_t n) {
      const std::size_t here = at;
      at += align16(n);
      return here;
    };
    params = take(sizeof(typename T::Params));
    soa = take(kForestTask<T> ? sizeof(ObstacleSoA) : 0);
    xs = take(sizeof(float) * chunk * NX * R);        // [s][n][lane]: states after step s
    us = take(sizeof(float) * 2 * chunk * NU * R);    // [buf][s][n][lane]: perturbed controls
    cc = take(sizeof(float) * 2 * chunk * R);         // [buf][s][lane]: control costs
    hit = take(sizeof(std::uint32_t) * chunk * R);    // [s][lane]: crash bits of step s
    qs = take(sizeof(float) * horizon * R);           // [i][lane]: q, then S~
    xf = take(sizeof(float) * NX * R);                // [n][lane]: the frozen (crashed) state
    flags = take(sizeof(int) * 2 * R);                // frozen[lane], refix_from[lane]
    bytes = at;
  }
};

template <class T>
__global__ void rollout_chunked(const Input<T>* in, const float* plan, float* S, unsigned char* crashed_out,
                                float* pmin, float* u_out, int K, int horizon, int chunk, float dt, int substeps,
                                SamplerConstants<T::kNu> c) {
  constexpr int R = ChunkLayout<T>::R, NX = T::kNx, NU = T::kNu;
  static_assert(T::kVehicles == 1, "rollout_chunked is for single vehicles");
  extern __shared__ __align__(16) unsigned char smem[];
  const ChunkLayout<T> L(chunk, horizon);
  using Params = typename T::Params;

  const int tid = static_cast<int>(threadIdx.x), threads = static_cast<int>(blockDim.x);
  const int warps = threads >> 5, warp = tid >> 5, lane = tid & 31;
  const int k0 = static_cast<int>(blockIdx.x) * R;

  // Stage the parameters (and the cylinders as arrays), clear the flags.
  {
    static_assert(sizeof(Params) % 4 == 0, "parameters are copied as 32-bit words");
    const auto* from = reinterpret_cast<const std::uint32_t*>(&in->params);
    auto* to = reinterpret_cast<std::uint32_t*>(smem + L.params);
    for (int w = tid; w < static_cast<int>(sizeof(Params) / 4); w += threads) to[w] = from[w];
  }
  ObstacleSoA* soa = nullptr;
  if constexpr (kForestTask<T>) {
    soa = reinterpret_cast<ObstacleSoA*>(smem + L.soa);
    const ObstacleSet& set = in->params.cost.obstacles;
    for (int n = tid; n < ObstacleSet::kCapacity; n += threads) {
      const Cylinder& cy = set.items[n];
      soa->x[n] = cy.x;
      soa->y[n] = cy.y;
      soa->r[n] = cy.radius;
      soa->vx[n] = cy.vx;
      soa->vy[n] = cy.vy;
    }
    if (tid == 0) soa->count = set.count < ObstacleSet::kCapacity ? set.count : ObstacleSet::kCapacity;
  }
  float* xs = reinterpret_cast<float*>(smem + L.xs);
  float* us = reinterpret_cast<float*>(smem + L.us);
  float* ccs = reinterpret_cast<float*>(smem + L.cc);
  auto* hits = reinterpret_cast<std::uint32_t*>(smem + L.hit);
  float* qs = reinterpret_cast<float*>(smem + L.qs);
  float* xf = reinterpret_cast<float*>(smem + L.xf);
  int* frozen = reinterpret_cast<int*>(smem + L.flags);
  int* refix = frozen + R;
  if (tid < R) frozen[tid] = 0;
  const NoiseKey key = in->key;
  const Params& p = *reinterpret_cast<const Params*>(smem + L.params);

  // The noise of the chunk starting at step i0 into buffer b: item (s, lane).
  auto draw = [&](int i0, int b) {
    const int steps = horizon - i0 < chunk ? horizon - i0 : chunk;
    for (int item = tid; item < steps * R; item += threads) {
      const int s = item / R, l = item % R, i = i0 + s;
      const float* pu = plan + i * NU;
      float u[NU], du[NU];
      perturb<NU>(c, key, static_cast<std::uint32_t>(k0 + l), static_cast<std::uint32_t>(i), pu, u, du);
      float* uo = us + (static_cast<std::size_t>(b * chunk + s) * NU) * R + l;
#pragma unroll
      for (int n = 0; n < NU; ++n) uo[n * R] = u[n];
      ccs[(b * chunk + s) * R + l] = control_cost<NU>(c, pu, du);
      if (u_out != nullptr && k0 + l < K) store_floats<NU>(u_out + (static_cast<std::size_t>(i) * K + k0 + l) * NU, u);
    }
  };
  draw(0, 0);
  __syncthreads();

  int b = 0;
  for (int i0 = 0, ci = 0; i0 < horizon; i0 += chunk, ++ci, b ^= 1) {
    const int steps = horizon - i0 < chunk ? horizon - i0 : chunk;
    // ---- phase A: the dynamics, one warp ----
    if (warp == (ci + static_cast<int>(blockIdx.x)) % warps) {
      float x[NX];
      if (i0 == 0) {
#pragma unroll
        for (int n = 0; n < NX; ++n) x[n] = in->x0[n];
      } else {
        // The last state of the previous chunk (its phase A wrote slot chunk - 1).
#pragma unroll
        for (int n = 0; n < NX; ++n) x[n] = xs[((chunk - 1) * NX + n) * R + lane];
      }
      for (int s = 0; s < steps; ++s) {
        float u[NU];
        const float* ui = us + (static_cast<std::size_t>(b * chunk + s) * NU) * R + lane;
#pragma unroll
        for (int n = 0; n < NU; ++n) u[n] = ui[n * R];
        T::advance(p, x, u, dt, substeps, 0u);
#pragma unroll
        for (int n = 0; n < NX; ++n) xs[(s * NX + n) * R + lane] = x[n];
      }
    }
    __syncthreads();
    // ---- phase B1: costs of this chunk; noise of the next ----
    for (int item = tid; item < steps * R; item += threads) {
      const int s = item / R, l = item % R, i = i0 + s;
      float x[NX];
      const float* src = frozen[l] ? xf + l : xs + s * NX * R + l;
#pragma unroll
      for (int n = 0; n < NX; ++n) x[n] = src[n * R];
      std::uint32_t bits = 0;
      const float t = static_cast<float>(i + 1) * dt;
      qs[i * R + l] = sanitize_cost(running_chunked<T>(p, soa, x, t, &bits) + ccs[(b * chunk + s) * R + l]);
      hits[s * R + l] = bits;
    }
    if (i0 + chunk < horizon) draw(i0 + chunk, b ^ 1);
    __syncthreads();
    // ---- phase B2: first crash of each rollout in this chunk ----
    if (tid < R) {
      int from = steps;
      if (!frozen[tid]) {
        for (int s = 0; s < steps; ++s) {
          if (hits[s * R + tid] != 0u) {
            for (int n = 0; n < NX; ++n) xf[n * R + tid] = xs[(s * NX + n) * R + tid];
            frozen[tid] = 1;
            from = s + 1;
            break;
          }
        }
      }
      refix[tid] = from;
    }
    __syncthreads();
    // ---- phase B3: the steps after a crash in this chunk, costed on the frozen state ----
    for (int item = tid; item < steps * R; item += threads) {
      const int s = item / R, l = item % R, i = i0 + s;
      if (s < refix[l]) continue;
      float x[NX];
#pragma unroll
      for (int n = 0; n < NX; ++n) x[n] = xf[n * R + l];
      std::uint32_t bits = 0;
      const float t = static_cast<float>(i + 1) * dt;
      qs[i * R + l] = sanitize_cost(running_chunked<T>(p, soa, x, t, &bits) + ccs[(b * chunk + s) * R + l]);
    }
    // The next phase A writes only xs and reads the other noise buffer; the barrier after it
    // orders this phase's reads of ccs before the next draw into this buffer.
  }
  __syncthreads();

  // ---- terminal cost and the cost-to-go, one warp ----
  const int last_steps = horizon - (horizon - 1) / chunk * chunk;  // steps of the last chunk
  if (warp == 0) {
    const int k = k0 + lane;
    float x[NX];
    const float* src = frozen[lane] ? xf + lane : xs + (last_steps - 1) * NX * R + lane;
#pragma unroll
    for (int n = 0; n < NX; ++n) x[n] = src[n * R];
    float acc = sanitize_cost(qs[(horizon - 1) * R + lane] + T::terminal(p, x));
    qs[(horizon - 1) * R + lane] = acc;
    const bool write = k < K;
    if (write) S[static_cast<std::size_t>(horizon - 1) * K + k] = acc;
    for (int i = horizon - 2; i >= 0; --i) {
      acc = sanitize_cost(qs[i * R + lane] + acc);
      qs[i * R + lane] = acc;
      if (write) S[static_cast<std::size_t>(i) * K + k] = acc;
    }
    if (write) crashed_out[k] = frozen[lane] != 0;
  }
  __syncthreads();
  // ---- this block's minimum of S~(tau_i, k) per step ----
  const int valid = K - k0 < R ? K - k0 : R;
  for (int i = tid; i < horizon; i += threads) {
    float m = kCostCeiling;
    for (int l = 0; l < valid; ++l) m = fmin_(m, qs[i * R + l]);
    pmin[static_cast<std::size_t>(i) * gridDim.x + blockIdx.x] = m;
  }
}

// Block i: m_i = min over the n per-block minima of step i (rollout_chunked's pmin[i][b]).
template <class T>
__global__ void reduce_min(const float* pmin, int n, float* out) {
  const int i = static_cast<int>(blockIdx.x);
  float m = kCostCeiling;
  for (int b = static_cast<int>(threadIdx.x); b < n; b += static_cast<int>(blockDim.x))
    m = fmin_(m, pmin[static_cast<std::size_t>(i) * n + b]);
  m = block_min(m);
  if (threadIdx.x == 0) out[i] = m;
}

}  // namespace mppi::cuda_detail
