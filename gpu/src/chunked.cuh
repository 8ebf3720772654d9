// rollout_chunked: the single-vehicle update with the serial chain cut down to the dynamics,
// the dynamics of one chunk of steps overlapped with the costs of the previous one, and the
// weighting done in the same kernel (finalize_blocks combines the blocks).
//
// A block holds R = 32 rollouts and NW warps (4 by default, at most 8; ~100 registers a
// thread, so four blocks of 4 warps share a multiprocessor). The horizon is walked in chunks
// of C steps. In iteration c, between two block barriers:
//   producer  one warp (a different one each iteration, so the dynamics spread over the
//             schedulers) advances the 32 rollouts through chunk c + 1 with T::advance and
//             stores every state in shared memory (double-buffered by chunk): only this is
//             serial in the step;
//   consumers the other warps, one (rollout, step) item per thread: the running cost of
//             chunk c (T::running_with; the forest's obstacle search through core's
//             ObstacleGrid over the cylinders in global memory, L1-cached) plus the control
//             cost, into a T x R table in shared memory; and the noise of chunk c + 2 (perturb,
//             control_cost; triple-buffered), the controls also kept in global memory for the
//             update. Then, behind a barrier of the consumers alone, the crash fix-up below.
// With one warp the same work runs in turn.
//
// Crashes. Task::advance freezes a crashed vehicle, and a crash is only known from the cost.
// The producer never waits for it: it advances as if nothing crashed. The consumers find, per
// rollout, the first step s* whose cost set a crash bit; the rollout's state is frozen at x(s*)
// from there on (kept in shared memory), the items after s* in this chunk are costed again
// with it (crashed on entry, as CpuBackend's running() sees them), and every later chunk costs
// the frozen state instead of the producer's. That is exactly CpuBackend's sequence:
// x(s*+1) = x(s*) = ... and running(x(s*), t_i) with the crash bit set, after s*.
//
// Weights. After the last chunk one thread per rollout adds the terminal cost and turns its
// column of the table into the cost-to-go (summed from the end, as CpuBackend does; row 0,
// S~(tau_0,k), also goes to global memory for rollout_costs()). Then one thread per step i
// weighs the block's rollouts against the block's own minimum m_b, w = exp(-(S - m_b)/lambda),
// and sums w, w du (du from the kept controls, or drawn again) and the step-0 statistics, in
// rollout order. finalize_blocks rescales each block's sums by exp(-(m_b - m)/lambda), m the
// minimum over all blocks, and adds them in block order: the CPU's weights exp(-(S - m)/lambda)
// up to rounding (plans agree to ~1e-7 relative), and a block whose minimum is past the flush
// point (a > 60) contributes nothing, as its rollouts do on the CPU. Every sum has a fixed
// order: the update is bit-for-bit repeatable.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "forest.cuh"
#include "kernels.cuh"

namespace mppi::cuda_detail {

// Launch bounds of rollout_chunked: at most 256 threads; two blocks of 256 (four of 128) a
// multiprocessor, so at most 128 registers a thread (a cap of 64 made the kept-controls
// variant spill).
constexpr int kChunkMaxThreads = 256;
constexpr int kChunkMinBlocks = 2;

// The bytes of T::Params staged into shared memory: for the forest tasks everything up to the
// obstacle count (the cylinders and the obstacle grid are read from global memory, through
// core's ObstacleGrid::nearest_surface); for the others the whole struct.
template <class T>
__host__ __device__ constexpr std::size_t chunk_param_bytes() {
  using P = typename T::Params;
  if constexpr (kForestTask<T>) {
    using C = typename T::Cost::Params;
    static_assert(offsetof(ObstacleSet, count) == 0, "the obstacle count comes first");
    return (offsetof(P, cost) + offsetof(C, obstacles) + sizeof(int) + 3) / 4 * 4;
  } else {
    return (sizeof(P) + 3) / 4 * 4;
  }
}

// Floats per rollout of a vector in shared memory, laid out [rollout][n] so that a thread
// moves it 16 (or 8) bytes at a time: n rounded up to 4, plus 4 more when that is an even
// number of 16-byte units (an odd number keeps a quarter-warp's 16-byte accesses on distinct
// banks); 1 and 2 stay as they are.
__host__ __device__ constexpr int lane_stride(int n) {
  return n <= 2 ? n : ((n + 3) / 4 % 2 == 0 ? (n + 3) / 4 * 4 + 4 : (n + 3) / 4 * 4);
}

// N floats from / to shared memory at p, laid out by lane_stride (p aligned to match).
template <int N>
__device__ __forceinline__ void lds_vec(const float* p, float* v) {
  if constexpr (N <= 2) {
#pragma unroll
    for (int n = 0; n < N; ++n) v[n] = p[n];
  } else {
    constexpr int N4 = (N + 3) / 4 * 4;
    float t[N4];
#pragma unroll
    for (int n = 0; n < N4; n += 4) {
      const float4 q = *reinterpret_cast<const float4*>(p + n);
      t[n] = q.x;
      t[n + 1] = q.y;
      t[n + 2] = q.z;
      t[n + 3] = q.w;
    }
#pragma unroll
    for (int n = 0; n < N; ++n) v[n] = t[n];
  }
}
template <int N>
__device__ __forceinline__ void sts_vec(float* p, const float* v) {
  if constexpr (N <= 2) {
#pragma unroll
    for (int n = 0; n < N; ++n) p[n] = v[n];
  } else {
    constexpr int N4 = (N + 3) / 4 * 4;
#pragma unroll
    for (int n = 0; n < N4; n += 4)
      *reinterpret_cast<float4*>(p + n) = make_float4(v[n], n + 1 < N ? v[n + 1] : 0.0f, n + 2 < N ? v[n + 2] : 0.0f,
                                                      n + 3 < N ? v[n + 3] : 0.0f);
  }
}

template <class T>
struct ChunkLayout {
  static constexpr int R = 32;       // rollouts per block
  static constexpr int QS = R + 1;   // row stride of the cost table (no bank conflicts by step)
  static constexpr int NX = T::kNx, NU = T::kNu;
  static constexpr int XS = lane_stride(NX), US = lane_stride(NU);  // floats per rollout
  std::size_t params, xs, us, cc, hit, xf, flags, qb, bytes;
  __host__ __device__ ChunkLayout(int chunk, int horizon) {
    std::size_t at = 0;
    auto take = [&](std::size_t n) {
      const std::size_t here = at;
      at += align16(n);
      return here;
    };
    params = take(chunk_param_bytes<T>());
    xs = take(sizeof(float) * 2 * chunk * R * XS);  // [chunk & 1][s][lane][n]: states after step s
    us = take(sizeof(float) * 3 * chunk * R * US);  // [chunk % 3][s][lane][n]: perturbed controls
    cc = take(sizeof(float) * 3 * chunk * R);       // [chunk % 3][s][lane]: control costs
    hit = take(sizeof(std::uint32_t) * chunk * R);  // [s][lane]: crash bits of step s
    xf = take(sizeof(float) * R * XS);              // [lane][n]: the frozen (crashed) state
    flags = take(sizeof(int) * (2 * R + 8));        // frozen[lane], refix_from[lane], slot[warp]
    qb = take(sizeof(float) * static_cast<std::size_t>(horizon) * QS);  // [i][lane]: q, then S~
    bytes = at;
  }
};

// Task::running for a single vehicle; forest tasks search the obstacles through the grid in
// global memory (gp: the cycle's parameters on the device), exactly as ForestCost::vehicle;
// kField false: without the distance field's code (the parameters carry none).
template <class T, bool kField>
__device__ __forceinline__ float running_chunked(const typename T::Params& p, const typename T::Params& gp,
                                                 const float* x, float t, std::uint32_t* crashed) {
  if constexpr (kForestTask<T>) {
    using Vehicle = typename T::Vehicle;
    return T::running_with(p, x, crashed, [&](int j, const float* xj, bool* hit) {
      float pos[3];
      Vehicle::position(xj, pos);
      const float d = gp.cost.obstacle_grid.nearest_surface(gp.cost.obstacles, pos[0], pos[1], t);
      return ForestCost<Vehicle>::template vehicle_at_distance<float, kField>(p.cost, j, xj, d, hit);
    });
  } else {
    (void)gp;
    return T::running(p, x, t, crashed);
  }
}

// The hardware warp slot of the calling warp on its multiprocessor (PTX %warpid). A warp
// issues from scheduler slot mod 4 (the four sub-partitions of an SM), which is all this is
// used for: a hint, never for correctness.
__device__ __forceinline__ int warp_slot() {
  unsigned w;
  asm volatile("mov.u32 %0, %%warpid;" : "=r"(w));
  return static_cast<int>(w);
}

// A barrier of the n consumer threads (named barrier 1; n a multiple of 32).
__device__ __forceinline__ void consumer_sync(int n) { asm volatile("bar.sync 1, %0;" ::"r"(n) : "memory"); }

// ---- Pieces both chunked kernels (this one and rollout_chunked_team) are made of -----------

// The parameters the kernel reads at every step (chunk_param_bytes) into shared memory; the
// caller's next block barrier publishes them.
template <class T>
__device__ __forceinline__ void stage_chunk_params(const typename T::Params& from, unsigned char* to) {
  constexpr int kWords = static_cast<int>(chunk_param_bytes<T>() / 4);
  const auto* src = reinterpret_cast<const std::uint32_t*>(&from);
  auto* dst = reinterpret_cast<std::uint32_t*>(to);
  for (int w = static_cast<int>(threadIdx.x); w < kWords; w += static_cast<int>(blockDim.x)) dst[w] = src[w];
}

// The warp that advances chunk ci (slot[w]: warp w's hardware slot). The producer's dependent
// chain is the one serial part, so each producer should have a scheduler of its own: the
// blocks that share a multiprocessor (their warps hold consecutive slots, `warps` a block)
// start on different sub-partitions (slot mod 4) and each moves on by one every chunk.
// Without a warp on the wanted sub-partition (fewer than 4 warps), the warps take turns.
__device__ __forceinline__ int producer_warp(int ci, const int* slot, int warps) {
  const int turn = ci + slot[0] / warps;
  if (warps >= 4) {
    for (int w = 0; w < warps; ++w)
      if ((slot[w] & 3) == (turn & 3) && (warps < 8 || ((w >> 2) & 1) == ((turn >> 2) & 1))) return w;
    for (int w = 0; w < warps; ++w)
      if ((slot[w] & 3) == (turn & 3)) return w;
  }
  return turn % warps;
}

// The threads that consume while warp `producer` produces (-1: none, every warp consumes; one
// warp alone does both in turn): this thread's index among them (ct) and their number (nct).
struct Consumers {
  int ct, nct;
};
__device__ __forceinline__ Consumers consumers_of(int producer) {
  const int tid = static_cast<int>(threadIdx.x), threads = static_cast<int>(blockDim.x);
  const int warps = threads >> 5, warp = tid >> 5;
  const bool all = warps == 1 || producer < 0;
  return {all || warp < producer ? tid : tid - 32, all ? threads : threads - 32};
}

// The block's running costs q and then its cost-to-go: row i, rollout l at q[i * stride + l].
struct CostTable {
  float* q;
  int stride;
  int horizon;
};

// One rollout's column of the table turned into its cost-to-go in place, with the terminal
// cost added to the last step, summed from the end as CpuBackend does; returns S~(tau_0).
__device__ __forceinline__ float cost_to_go(const CostTable& t, int l, float terminal) {
  float* col = t.q + l;
  const int qs = t.stride;
  float acc = sanitize_cost(col[(t.horizon - 1) * qs] + terminal);
  col[(t.horizon - 1) * qs] = acc;
  int i = t.horizon - 2;
  constexpr int kBatch = 8;  // loads ahead of the dependent sums
  for (; i >= kBatch - 1; i -= kBatch) {
    float v[kBatch];
#pragma unroll
    for (int b = 0; b < kBatch; ++b) v[b] = col[(i - b) * qs];
#pragma unroll
    for (int b = 0; b < kBatch; ++b) {
      acc = sanitize_cost(v[b] + acc);
      col[(i - b) * qs] = acc;
    }
  }
  for (; i >= 0; --i) {
    acc = sanitize_cost(col[i * qs] + acc);
    col[i * qs] = acc;
  }
  return acc;
}

// Rollouts k0 .. k0 + valid - 1 of K in this block.
struct BlockRollouts {
  int k0, valid, K;
};

// Where a block's weighted sums go: pmin[i * blocks + b] its minimum at step i,
// part[(i * blocks + b) * (NU + 1) + n] (n = 0: sum w, 1..NU: sum w du), stats_part[b] its
// step-0 statistics.
struct BlockSums {
  float* pmin;
  float* part;
  StatsPart* stats_part;
};

// One thread per step i: the block's minimum of the weighting row (row i, or row 0 under
// trajectory weighting), w = exp(-(S - m_b)/lambda), and the sums of w and w du (du from the
// kept controls u_keep, or drawn again) and, at step 0, the statistics, in rollout order.
// crashed(l): whether rollout l crashed.
template <int NU, bool kKeep, class Crashed>
__device__ __forceinline__ void weigh_block(const CostTable& t, const BlockRollouts& r, const float* plan,
                                            const float* u_keep, const NoiseKey& key, const SamplerConstants<NU>& c,
                                            float inv_lambda, int trajectory, Crashed&& crashed, const BlockSums& out) {
  const int blocks = static_cast<int>(gridDim.x), b = static_cast<int>(blockIdx.x);
  for (int i = static_cast<int>(threadIdx.x); i < t.horizon; i += static_cast<int>(blockDim.x)) {
    const float* row = t.q + (trajectory ? 0 : i) * t.stride;
    float m = kCostCeiling;
    for (int l = 0; l < r.valid; ++l) m = fmin_(m, row[l]);
    const float* pu = plan + i * NU;
    float acc[NU + 1] = {};
    float w2 = 0.0f, sum_cost = 0.0f;
    int finite = 0, crashed_count = 0;
#pragma unroll 4
    for (int l = 0; l < r.valid; ++l) {
      const float s = row[l];
      const float w = unnormalised_weight(s - m, inv_lambda);
      float u[NU], du[NU];
      if constexpr (kKeep) {
        load_floats<NU>(u_keep + (static_cast<std::size_t>(i) * r.K + r.k0 + l) * NU, u);
#pragma unroll
        for (int n = 0; n < NU; ++n) du[n] = u[n] - pu[n];
      } else {
        perturb<NU>(c, key, static_cast<std::uint32_t>(r.k0 + l), static_cast<std::uint32_t>(i), pu, u, du);
      }
      acc[0] += w;
#pragma unroll
      for (int n = 0; n < NU; ++n) acc[1 + n] += w * du[n];
      if (i == 0) {
        // Step-0 statistics: sum w^2 (of these block-relative weights), S~ over the finite
        // rollouts, how many, how many crashed.
        w2 += w * w;
        if (s < kCostCeiling) {
          sum_cost += s;
          ++finite;
        }
        crashed_count += crashed(l) ? 1 : 0;
      }
    }
    out.pmin[static_cast<std::size_t>(i) * blocks + b] = m;
    float* o = out.part + (static_cast<std::size_t>(i) * blocks + b) * (NU + 1);
#pragma unroll
    for (int n = 0; n <= NU; ++n) o[n] = acc[n];
    if (i == 0) out.stats_part[b] = StatsPart{w2, sum_cost, finite, crashed_count};
  }
}

// ---- rollout_chunked's block: its shared memory and its phases ------------------------------

template <class T, bool kKeep, bool kField>
struct ChunkedBlock {
  static constexpr int R = ChunkLayout<T>::R, QS = ChunkLayout<T>::QS, NX = T::kNx, NU = T::kNu;
  static constexpr int XS = ChunkLayout<T>::XS, US = ChunkLayout<T>::US;
  using Params = typename T::Params;

  const Input<T>* in;
  const float* plan;
  float* u_keep;
  int K, horizon, chunk, substeps;
  float dt;
  int tid, threads, warps, warp, lane, k0, valid, nchunks;
  float *xs, *us, *ccs, *xf, *qb;
  std::uint32_t* hits;
  int *frozen, *refix, *slot;
  const Params* p;  // staged in shared memory
  NoiseKey key;

  // Lays out shared memory, stages the parameters and clears the crash flags (no barrier).
  __device__ ChunkedBlock(const Input<T>* in_, const float* plan_, float* u_keep_, int K_, int horizon_, int chunk_,
                          float dt_, int substeps_, unsigned char* smem)
      : in(in_), plan(plan_), u_keep(u_keep_), K(K_), horizon(horizon_), chunk(chunk_), substeps(substeps_), dt(dt_) {
    const ChunkLayout<T> L(chunk, horizon);
    tid = static_cast<int>(threadIdx.x);
    threads = static_cast<int>(blockDim.x);
    warps = threads >> 5;
    warp = tid >> 5;
    lane = tid & 31;
    k0 = static_cast<int>(blockIdx.x) * R;
    valid = K - k0 < R ? K - k0 : R;
    nchunks = (horizon + chunk - 1) / chunk;
    stage_chunk_params<T>(in->params, smem + L.params);
    xs = reinterpret_cast<float*>(smem + L.xs);
    us = reinterpret_cast<float*>(smem + L.us);
    ccs = reinterpret_cast<float*>(smem + L.cc);
    hits = reinterpret_cast<std::uint32_t*>(smem + L.hit);
    xf = reinterpret_cast<float*>(smem + L.xf);
    frozen = reinterpret_cast<int*>(smem + L.flags);
    refix = frozen + R;
    slot = refix + R;
    qb = reinterpret_cast<float*>(smem + L.qb);
    if (tid < R) frozen[tid] = 0;
    if (lane == 0) slot[warp] = warp_slot();
    key = in->key;
    p = reinterpret_cast<const Params*>(smem + L.params);
  }

  __device__ int steps_of(int ci) const { return horizon - ci * chunk < chunk ? horizon - ci * chunk : chunk; }
  // Rollout l's state after step s of chunk ci, its control at that step, the control costs.
  __device__ float* xs_at(int ci, int s, int l) const {
    return xs + (static_cast<std::size_t>((ci & 1) * chunk + s) * R + l) * XS;
  }
  __device__ float* us_at(int ci, int s, int l) const {
    return us + (static_cast<std::size_t>((ci % 3) * chunk + s) * R + l) * US;
  }
  __device__ float* cc_at(int ci, int s) const { return ccs + static_cast<std::size_t>((ci % 3) * chunk + s) * R; }
  __device__ CostTable table() const { return {qb, QS, horizon}; }

  // The noise of item (step s of chunk ci, rollout l).
  __device__ void draw(int ci, int s, int l, const SamplerConstants<NU>& c) const {
    const int i = ci * chunk + s;
    const float* pu = plan + i * NU;
    float u[NU], du[NU];
    perturb<NU>(c, key, static_cast<std::uint32_t>(k0 + l), static_cast<std::uint32_t>(i), pu, u, du);
    sts_vec<NU>(us_at(ci, s, l), u);
    cc_at(ci, s)[l] = control_cost<NU>(c, pu, du);
    if (kKeep && l < valid) store_floats<NU>(u_keep + (static_cast<std::size_t>(i) * K + k0 + l) * NU, u);
  }
  // q of item (s, l) of chunk ci at state x; bits: the crash bits, in and out.
  __device__ void cost(int ci, int s, int l, const float* x, std::uint32_t* bits) const {
    const int i = ci * chunk + s;
    const float t = static_cast<float>(i + 1) * dt;
    qb[i * QS + l] = sanitize_cost(running_chunked<T, kField>(*p, in->params, x, t, bits) + cc_at(ci, s)[l]);
  }
  // The dynamics of chunk ci, lane = rollout, from the last state of chunk ci - 1.
  __device__ void produce(int ci) const {
    float x[NX];
    if (ci == 0) {
#pragma unroll
      for (int n = 0; n < NX; ++n) x[n] = in->x0[n];
    } else {
      lds_vec<NX>(xs_at(ci - 1, steps_of(ci - 1) - 1, lane), x);
    }
    const int steps = steps_of(ci);
    float un[NU];  // the next step's control, loaded a step ahead
    lds_vec<NU>(us_at(ci, 0, lane), un);
    for (int s = 0; s < steps; ++s) {
      float u[NU];
#pragma unroll
      for (int n = 0; n < NU; ++n) u[n] = un[n];
      if (s + 1 < steps) lds_vec<NU>(us_at(ci, s + 1, lane), un);
      T::advance(*p, x, u, dt, substeps, 0u);
      sts_vec<NX>(xs_at(ci, s, lane), x);
    }
  }

  // Prologue: the noise of chunk 0; then the dynamics of chunk 0 beside the noise of chunk 1.
  __device__ void prologue(const SamplerConstants<NU>& c) const {
    for (int e = tid; e < steps_of(0) * R; e += threads) draw(0, e / R, e % R, c);
    __syncthreads();
    const int producer = producer_warp(0, slot, warps);
    if (warp == producer) produce(0);
    if (nchunks > 1 && (warps == 1 || warp != producer)) {
      const Consumers con = consumers_of(producer);
      for (int e = con.ct; e < steps_of(1) * R; e += con.nct) draw(1, e / R, e % R, c);
    }
    __syncthreads();
  }

  // The consumers' part of iteration ci: the costs of chunk ci beside the noise of chunk
  // ci + 2, then the crash fix-up.
  __device__ void consume(int ci, int producer, const SamplerConstants<NU>& c) const {
    const Consumers con = consumers_of(producer);
    cost_and_draw(ci, con, c);
    consumer_sync(con.nct);
    freeze_at_first_crash(ci, con);
    consumer_sync(con.nct);
    cost_after_crash(ci, con);
  }
  __device__ void cost_and_draw(int ci, const Consumers& con, const SamplerConstants<NU>& c) const {
    const int n_cost = steps_of(ci) * R;
    const int n_items = n_cost + (ci + 2 < nchunks ? steps_of(ci + 2) * R : 0);
    for (int e = con.ct; e < n_items; e += con.nct) {
      if (e < n_cost) {
        const int s = e / R, l = e % R;
        std::uint32_t bits = 0;
        if (l < valid) {
          const bool fz = frozen[l] != 0;
          float x[NX];
          lds_vec<NX>(fz ? xf + l * XS : xs_at(ci, s, l), x);
          bits = fz ? 1u : 0u;  // crashed before: CpuBackend's running() sees the bit
          cost(ci, s, l, x, &bits);
        }
        hits[s * R + l] = bits;
      } else {
        const int f = e - n_cost;
        draw(ci + 2, f / R, f % R, c);
      }
    }
  }
  // Per rollout: its first crash in chunk ci freezes its state there; refix[l]: the first
  // step of the chunk to cost again on the frozen state.
  __device__ void freeze_at_first_crash(int ci, const Consumers& con) const {
    if (con.ct >= R) return;
    const int l = con.ct, steps = steps_of(ci);
    int from = steps;
    if (!frozen[l]) {
      for (int s = 0; s < steps; ++s) {
        if (hits[s * R + l] != 0u) {
          const float* src = xs_at(ci, s, l);
          for (int n = 0; n < XS; ++n) xf[l * XS + n] = src[n];
          frozen[l] = 1;
          from = s + 1;
          break;
        }
      }
    }
    refix[l] = from;
  }
  // The steps after a crash in chunk ci, costed on the frozen state.
  __device__ void cost_after_crash(int ci, const Consumers& con) const {
    for (int e = con.ct; e < steps_of(ci) * R; e += con.nct) {
      const int s = e / R, l = e % R;
      if (l >= valid || s < refix[l]) continue;
      float x[NX];
      lds_vec<NX>(xf + l * XS, x);
      std::uint32_t bits = 1u;
      cost(ci, s, l, x, &bits);
    }
  }

  // One thread per rollout: the terminal cost at its last (or frozen) state and its
  // cost-to-go; S~(tau_0) and the crash flag to global memory.
  __device__ void cost_to_go_per_rollout(float* S0, unsigned char* crashed_out) const {
    if (tid >= valid) return;
    const int l = tid, last = nchunks - 1;
    float x[NX];
    lds_vec<NX>(frozen[l] ? xf + l * XS : xs_at(last, steps_of(last) - 1, l), x);
    S0[k0 + l] = cost_to_go(table(), l, T::terminal(*p, x));
    crashed_out[k0 + l] = frozen[l] != 0;
  }
};

// S0: S~(tau_0,k), the first row of the cost-to-go (for rollout_costs()); sums: BlockSums.
// kKeep: the controls are kept in u_keep for the update (else drawn again there). kField: the
// forest cost reads the distance field (the variant without runs while the parameters carry
// none: the field's code costs the field-less kernel registers and ~5 % at K = 16,384).
template <class T, bool kKeep, bool kField = false>
__global__ void __launch_bounds__(kChunkMaxThreads, kChunkMinBlocks)
    rollout_chunked(const Input<T>* in, const float* plan, float* S0, unsigned char* crashed_out, float* pmin,
                    float* part, StatsPart* stats_part, float* u_keep, int K, int horizon, int chunk, float dt,
                    int substeps, float inv_lambda, int trajectory, SamplerConstants<T::kNu> c) {
  static_assert(T::kVehicles == 1, "rollout_chunked is for single vehicles");
  extern __shared__ __align__(16) unsigned char smem[];
  const ChunkedBlock<T, kKeep, kField> b(in, plan, u_keep, K, horizon, chunk, dt, substeps, smem);
  b.prologue(c);
  griddep_wait();  // launched behind the device's obstacle grid: it is packed now
  for (int ci = 0; ci < b.nchunks; ++ci) {
    // The producer of chunk ci + 1 (none after the last chunk: every warp consumes).
    const int producer = ci + 1 < b.nchunks ? producer_warp(ci + 1, b.slot, b.warps) : -1;
    if (b.warp == producer) b.produce(ci + 1);
    if (b.warps == 1 || b.warp != producer) b.consume(ci, producer, c);
    // The next iteration's producer reads the noise drawn here and overwrites the states of
    // chunk ci - 1 (read by the producer here); its consumers read these states and flags.
    __syncthreads();
  }
  griddep_launch_dependents();  // finalize_blocks may be scheduled behind the last blocks
  b.cost_to_go_per_rollout(S0, crashed_out);
  __syncthreads();
  weigh_block<T::kNu, kKeep>(b.table(), BlockRollouts{b.k0, b.valid, K}, plan, u_keep, b.key, c, inv_lambda,
                             trajectory, [&](int l) { return b.frozen[l] != 0; }, BlockSums{pmin, part, stats_part});
}

// Block i: m = min over the blocks' minima of the weighting step; every block's sums scaled
// by exp(-(m_b - m)/lambda) (0 past the flush point) and added in block order; then
// u_i = clamp(u_i + sum w du / sum w). Block 0 also writes the statistics (min S~_0, sum w,
// sum w^2, sum of finite S~_0, counts).
template <int NU>
__global__ void finalize_blocks(const float* plan, const float* part, const StatsPart* stats_part, const float* pmin,
                                int blocks, float inv_lambda, int trajectory, float* plan_out, DeviceStats* stats,
                                SamplerConstants<NU> c) {
  griddep_wait();  // launched as a programmatic dependent: the blocks' sums are complete
  const int i = static_cast<int>(blockIdx.x), wi = trajectory ? 0 : i;
  const float* mrow = pmin + static_cast<std::size_t>(wi) * blocks;
  float m = kCostCeiling;
  for (int n = static_cast<int>(threadIdx.x); n < blocks; n += static_cast<int>(blockDim.x)) m = fmin_(m, mrow[n]);
  m = block_min(m);
  float acc[NU + 1] = {};
  float st[2] = {};
  int cnt[2] = {};
  for (int n = static_cast<int>(threadIdx.x); n < blocks; n += static_cast<int>(blockDim.x)) {
    const float f = unnormalised_weight(mrow[n] - m, inv_lambda);
    const float* p = part + (static_cast<std::size_t>(i) * blocks + n) * (NU + 1);
    for (int j = 0; j <= NU; ++j) acc[j] += f * p[j];
    if (i == 0) {
      st[0] += f * f * stats_part[n].sum_w2;
      st[1] += stats_part[n].sum_cost;
      cnt[0] += stats_part[n].finite;
      cnt[1] += stats_part[n].crashed;
    }
  }
  block_sum(acc);
  if (threadIdx.x == 0)
    for (int j = 0; j < NU; ++j)
      plan_out[i * NU + j] = fclamp(plan[i * NU + j] + acc[1 + j] / acc[0], c.u_min[j], c.u_max[j]);
  if (i != 0) return;
  // min S~(tau_0,k): the step-0 row of minima (also under trajectory weighting, where it is
  // the weighting row).
  block_sum(st);
  block_sum(cnt);
  if (threadIdx.x == 0) *stats = DeviceStats{m, acc[0], st[0], st[1], cnt[0], cnt[1]};
}

}  // namespace mppi::cuda_detail
