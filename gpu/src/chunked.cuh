// rollout_chunked: the single-vehicle update with the serial chain cut down to the dynamics,
// and the weighting done in the same kernel (finalize_blocks combines the blocks).
//
// A block holds R = 32 rollouts and NW warps. The horizon is walked in chunks of C steps;
// each chunk has two phases, separated by block barriers:
//   A  one warp (a different one each chunk, so the dynamics spread over the schedulers)
//      advances the 32 rollouts C steps with T::advance and stores every state in shared
//      memory; only this is serial in the step. Meanwhile the other warps move the cylinders
//      to each step's time (forest tasks).
//   B  every warp, one (rollout, step) item per thread: the running cost T::running of the
//      stored state (Task::running_with; the forest's obstacle search over the moved
//      cylinders, laid out for 16-byte loads), plus the control cost; and the noise of the
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
// Weights. Each q goes to S~ in global memory; after the last chunk one warp turns the
// block's rows into the cost-to-go (summed from the end, as CpuBackend does). Then, per step
// i, the block weighs its own rollouts against its own minimum m_b: w = exp(-(S - m_b)/lambda)
// and sums w, w du (du from the controls kept in global memory, or drawn again) and the
// step-0 statistics. finalize_blocks rescales each block's sums by exp(-(m_b - m)/lambda),
// m the minimum over all blocks, and adds them in block order: the CPU's weights
// exp(-(S - m)/lambda) up to rounding (plans agree to ~1e-7 relative), and a block whose
// minimum is past the flush point (a > 60) contributes nothing, as its rollouts do on the
// CPU. Every sum has a fixed order: the update is bit-for-bit repeatable.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "forest.cuh"
#include "kernels.cuh"

namespace mppi::cuda_detail {

// The cylinders' radii in shared memory, and per step of the chunk their centres moved to
// the step's time (c.x + c.vx t, c.y + c.vy t: ObstacleSet::surface_distance's own operations),
// padded to a multiple of 8 with cylinders so far away they are never the nearest.
struct ObstacleTable {
  static constexpr int kCap = ObstacleSet::kCapacity;
  // Padding: a NaN centre gives a NaN distance, which fminf never picks (whatever the position).
  static constexpr float kAway = __builtin_nanf("");
  alignas(16) float r[kCap];  // first: read 16 bytes at a time
  int count;                  // real cylinders
  int padded;                 // count rounded up to 8
};

template <class T>
struct ChunkLayout {
  static constexpr int R = 32;  // rollouts per block
  static constexpr int NX = T::kNx, NU = T::kNu;
  std::size_t params, obst, moved, xs, us, cc, hit, xf, flags, bytes;
  __host__ __device__ ChunkLayout(int chunk) {
    std::size_t at = 0;
    auto take = [&](std::size_t n) {
      const std::size_t here = at;
      at += align16(n);
      return here;
    };
    params = take(sizeof(typename T::Params));
    obst = take(kForestTask<T> ? sizeof(ObstacleTable) : 0);
    moved = take(kForestTask<T> ? sizeof(float) * chunk * 2 * ObstacleTable::kCap : 0);  // [s][x|y][n]
    xs = take(sizeof(float) * chunk * NX * R);        // [s][n][lane]: states after step s
    us = take(sizeof(float) * 2 * chunk * NU * R);    // [buf][s][n][lane]: perturbed controls
    cc = take(sizeof(float) * 2 * chunk * R);         // [buf][s][lane]: control costs
    hit = take(sizeof(std::uint32_t) * chunk * R);    // [s][lane]: crash bits of step s
    xf = take(sizeof(float) * NX * R);                // [n][lane]: the frozen (crashed) state
    flags = take(sizeof(int) * 2 * R);                // frozen[lane], refix_from[lane]
    bytes = at;
  }
};

// ObstacleSet::nearest_surface at one step, over the moved cylinders of that step (mx, my):
// each through ObstacleSet::surface_distance (with the motion already applied: zero velocity,
// t = 0, which the compiler folds away), the minimum taken with fminf (equal to the CPU's
// comparison except possibly in the sign of a zero distance, which no term of the cost sees).
__device__ __forceinline__ float nearest_surface_moved(const ObstacleTable& o, const float* mx, const float* my, float px,
                                                       float py) {
  float best = ObstacleSet::kFar;
  for (int b = 0; b < o.padded; b += 8) {
    float d[8];
#pragma unroll
    for (int h = 0; h < 2; ++h) {
      const float4 cx = *reinterpret_cast<const float4*>(mx + b + 4 * h);
      const float4 cy = *reinterpret_cast<const float4*>(my + b + 4 * h);
      const float4 cr = *reinterpret_cast<const float4*>(o.r + b + 4 * h);
      d[4 * h + 0] = ObstacleSet::surface_distance(Cylinder{cx.x, cy.x, cr.x, -0.0f, -0.0f}, px, py, 0.0f);
      d[4 * h + 1] = ObstacleSet::surface_distance(Cylinder{cx.y, cy.y, cr.y, -0.0f, -0.0f}, px, py, 0.0f);
      d[4 * h + 2] = ObstacleSet::surface_distance(Cylinder{cx.z, cy.z, cr.z, -0.0f, -0.0f}, px, py, 0.0f);
      d[4 * h + 3] = ObstacleSet::surface_distance(Cylinder{cx.w, cy.w, cr.w, -0.0f, -0.0f}, px, py, 0.0f);
    }
#pragma unroll
    for (int u = 0; u < 8; ++u) best = fminf(d[u], best);
  }
  return best;
}

// The same through the obstacle grid (ObstacleGrid::nearest_surface's lookup, the cell's
// list searched over the moved cylinders); outside the grid, or with none, every cylinder.
// The list of a cell holds the nearest cylinder of every point in it, so the distance is
// the full search's (and CpuBackend's, which searches the same grid).
__device__ __forceinline__ float nearest_surface_listed(const ObstacleGrid& g, const ObstacleTable& o, const float* mx,
                                                        const float* my, float px, float py) {
  if (g.nx > 0) {
    const float fx = (px - g.x0) * g.inv_cell;
    const float fy = (py - g.y0) * g.inv_cell;
    if (fx >= 0.0f && fx < static_cast<float>(g.nx) && fy >= 0.0f && fy < static_cast<float>(g.ny)) {
      int cell;
      store_cell_indices(fx, fy, g.nx, &cell);
      float best = ObstacleSet::kFar;
      const int end = g.first[cell + 1];
      for (int r = g.first[cell]; r < end; ++r) {
        const int n = g.refs[r];
        best = fminf(ObstacleSet::surface_distance(Cylinder{mx[n], my[n], o.r[n], -0.0f, -0.0f}, px, py, 0.0f), best);
      }
      return best;
    }
  }
  return nearest_surface_moved(o, mx, my, px, py);
}

// Task::running for a single vehicle at step s of the chunk; forest tasks search the moved
// cylinders of that step (through the grid).
template <class T>
__device__ __forceinline__ float running_chunked(const typename T::Params& p, const ObstacleTable* o,
                                                 const float* moved, int chunk, int s, const float* x, float t,
                                                 std::uint32_t* crashed) {
  if constexpr (kForestTask<T>) {
    using Vehicle = typename T::Vehicle;
    const float* mx = moved + static_cast<std::size_t>(s) * 2 * ObstacleTable::kCap;
    (void)chunk;
    (void)t;
    return T::running_with(p, x, crashed, [&](int j, const float* xj, bool* hit) {
      float pos[3];
      Vehicle::position(xj, pos);
      const float d = nearest_surface_listed(p.cost.obstacle_grid, *o, mx, mx + ObstacleTable::kCap, pos[0], pos[1]);
      return ForestCost<Vehicle>::vehicle_at_distance(p.cost, j, xj, d, hit);
    });
  } else {
    (void)o;
    (void)moved;
    (void)chunk;
    (void)s;
    return T::running(p, x, t, crashed);
  }
}

template <int N>
__device__ __forceinline__ void warp_sum(float (&v)[N]) {
#pragma unroll
  for (int n = 0; n < N; ++n)
#pragma unroll
    for (int off = 16; off > 0; off >>= 1) v[n] += __shfl_xor_sync(kFullMask, v[n], off);
}

// part layout: [(i * blocks + b) * (NU + 1) + n], n = 0: sum w, 1..NU: sum w du.
// stats_part[b]: step-0 statistics of block b. pmin[i * blocks + b]: block minima.
template <class T>
__global__ void rollout_chunked(const Input<T>* in, const float* plan, float* S, unsigned char* crashed_out,
                                float* pmin, float* part, StatsPart* stats_part, float* u_keep, int K, int horizon,
                                int chunk, float dt, int substeps, float inv_lambda, int trajectory,
                                SamplerConstants<T::kNu> c) {
  constexpr int R = ChunkLayout<T>::R, NX = T::kNx, NU = T::kNu;
  static_assert(T::kVehicles == 1, "rollout_chunked is for single vehicles");
  extern __shared__ __align__(16) unsigned char smem[];
  const ChunkLayout<T> L(chunk);
  using Params = typename T::Params;

  const int tid = static_cast<int>(threadIdx.x), threads = static_cast<int>(blockDim.x);
  const int warps = threads >> 5, warp = tid >> 5, lane = tid & 31;
  const int k0 = static_cast<int>(blockIdx.x) * R;
  const int blocks = static_cast<int>(gridDim.x);
  const int valid = K - k0 < R ? K - k0 : R;  // rollouts of this block

  // Stage the parameters (and the cylinders' radii), clear the flags.
  {
    static_assert(sizeof(Params) % 4 == 0, "parameters are copied as 32-bit words");
    const auto* from = reinterpret_cast<const std::uint32_t*>(&in->params);
    auto* to = reinterpret_cast<std::uint32_t*>(smem + L.params);
    for (int w = tid; w < static_cast<int>(sizeof(Params) / 4); w += threads) to[w] = from[w];
  }
  ObstacleTable* obst = nullptr;
  float* moved = nullptr;
  const Cylinder* cyl = nullptr;
  int n_obst = 0;
  if constexpr (kForestTask<T>) {
    obst = reinterpret_cast<ObstacleTable*>(smem + L.obst);
    moved = reinterpret_cast<float*>(smem + L.moved);
    const ObstacleSet& set = in->params.cost.obstacles;
    cyl = set.items;
    n_obst = set.count < ObstacleSet::kCapacity ? (set.count > 0 ? set.count : 0) : ObstacleSet::kCapacity;
    for (int n = tid; n < ObstacleTable::kCap; n += threads) obst->r[n] = n < n_obst ? set.items[n].radius : 0.0f;
    if (tid == 0) {
      obst->count = n_obst;
      obst->padded = (n_obst + 7) / 8 * 8;
    }
  }
  float* xs = reinterpret_cast<float*>(smem + L.xs);
  float* us = reinterpret_cast<float*>(smem + L.us);
  float* ccs = reinterpret_cast<float*>(smem + L.cc);
  auto* hits = reinterpret_cast<std::uint32_t*>(smem + L.hit);
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
      if (u_keep != nullptr && l < valid) store_floats<NU>(u_keep + (static_cast<std::size_t>(i) * K + k0 + l) * NU, u);
    }
  };
  draw(0, 0);
  __syncthreads();

  int b = 0;
  const int producer_base = static_cast<int>(blockIdx.x);
  for (int i0 = 0, ci = 0; i0 < horizon; i0 += chunk, ++ci, b ^= 1) {
    const int steps = horizon - i0 < chunk ? horizon - i0 : chunk;
    const int producer = (ci + producer_base) % warps;
    // The cylinders at each step's time (forest tasks), by the warps that are not advancing
    // the rollouts (by the one warp before it does, in a block of one warp).
    auto move_cylinders = [&](int first, int stride) {
      if constexpr (kForestTask<T>) {
        const int padded = (n_obst + 7) / 8 * 8;
        for (int e = first; e < steps * padded; e += stride) {
          const int s = e / padded, n = e % padded;
          const float t = static_cast<float>(i0 + s + 1) * dt;
          float* row = moved + static_cast<std::size_t>(s) * 2 * ObstacleTable::kCap;
          if (n < n_obst) {
            const Cylinder& cy = cyl[n];
            row[n] = cy.x + cy.vx * t;
            row[ObstacleTable::kCap + n] = cy.y + cy.vy * t;
          } else {
            row[n] = ObstacleTable::kAway;
            row[ObstacleTable::kCap + n] = ObstacleTable::kAway;
          }
        }
      } else {
        (void)first;
        (void)stride;
      }
    };
    if (warps == 1) move_cylinders(tid, threads);
    if (warp == producer) {
      // ---- phase A: the dynamics, one warp ----
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
    } else {
      move_cylinders(tid - (tid >= producer * 32 ? 32 : 0), threads - 32);
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
      const float q = sanitize_cost(running_chunked<T>(p, obst, moved, chunk, s, x, t, &bits) +
                                    ccs[(b * chunk + s) * R + l]);
      if (l < valid) S[static_cast<std::size_t>(i) * K + k0 + l] = q;
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
      if (s < refix[l] || l >= valid) continue;
      float x[NX];
#pragma unroll
      for (int n = 0; n < NX; ++n) x[n] = xf[n * R + l];
      std::uint32_t bits = 0;
      const float t = static_cast<float>(i + 1) * dt;
      S[static_cast<std::size_t>(i) * K + k0 + l] =
          sanitize_cost(running_chunked<T>(p, obst, moved, chunk, s, x, t, &bits) + ccs[(b * chunk + s) * R + l]);
    }
    // The next phase A writes xs and the moved cylinders and reads the other noise buffer; the
    // barrier after it orders this phase's reads before the next draw into this buffer.
  }
  __syncthreads();

  // ---- terminal cost and the cost-to-go, one warp ----
  const int last_steps = horizon - (horizon - 1) / chunk * chunk;  // steps of the last chunk
  if (warp == 0 && lane < valid) {
    const int k = k0 + lane;
    float x[NX];
    const float* src = frozen[lane] ? xf + lane : xs + (last_steps - 1) * NX * R + lane;
#pragma unroll
    for (int n = 0; n < NX; ++n) x[n] = src[n * R];
    float* sk = S + (static_cast<std::size_t>(horizon - 1) * K + k);
    const float last = sanitize_cost(*sk + T::terminal(p, x));
    *sk = last;
    suffix_sums(S, K, horizon, k, last);
    crashed_out[k] = frozen[lane] != 0;
  }
  __syncthreads();

  // ---- per step: the block's minimum and weighted sums, one warp a step ----
  for (int i = warp; i < horizon; i += warps) {
    const int wi = trajectory ? 0 : i;
    const bool on = lane < valid;
    const int k = k0 + lane;
    const float s_w = on ? S[static_cast<std::size_t>(wi) * K + k] : kCostCeiling;
    float m = s_w;
#pragma unroll
    for (int off = 16; off > 0; off >>= 1) m = fmin_(m, __shfl_xor_sync(kFullMask, m, off));
    const float w = on ? unnormalised_weight(s_w - m, inv_lambda) : 0.0f;
    const float* pu = plan + i * NU;
    float u[NU], du[NU];
    if (u_keep != nullptr) {
      if (on) load_floats<NU>(u_keep + (static_cast<std::size_t>(i) * K + k) * NU, u);
      else
        for (int n = 0; n < NU; ++n) u[n] = pu[n];
      for (int n = 0; n < NU; ++n) du[n] = u[n] - pu[n];
    } else {
      perturb<NU>(c, key, static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(i), pu, u, du);
    }
    float acc[NU + 1];
    acc[0] = w;
#pragma unroll
    for (int n = 0; n < NU; ++n) acc[1 + n] = w * du[n];
    warp_sum(acc);
    if (lane == 0) {
      pmin[static_cast<std::size_t>(i) * blocks + blockIdx.x] = m;
      float* out = part + (static_cast<std::size_t>(i) * blocks + blockIdx.x) * (NU + 1);
#pragma unroll
      for (int n = 0; n <= NU; ++n) out[n] = acc[n];
    }
    if (i == 0) {
      // Step-0 statistics: sum w^2 (of these block-relative weights), S~ over the finite
      // rollouts, how many, how many crashed.
      const float s0 = on ? S[k] : kCostCeiling;
      float st[2] = {w * w, on && s0 < kCostCeiling ? s0 : 0.0f};
      warp_sum(st);
      const unsigned fin = __ballot_sync(kFullMask, on && s0 < kCostCeiling);
      const unsigned cr = __ballot_sync(kFullMask, on && frozen[lane] != 0);
      if (lane == 0) stats_part[blockIdx.x] = StatsPart{st[0], st[1], __popc(fin), __popc(cr)};
    }
  }
}

// Block i: m = min over the blocks' minima of the weighting step; every block's sums scaled
// by exp(-(m_b - m)/lambda) (0 past the flush point) and added in block order; then
// u_i = clamp(u_i + sum w du / sum w). Block 0 also writes the statistics (min S~_0, sum w,
// sum w^2, sum of finite S~_0, counts).
template <int NU>
__global__ void finalize_blocks(const float* plan, const float* part, const StatsPart* stats_part, const float* pmin,
                                int blocks, float inv_lambda, int trajectory, float* plan_out, DeviceStats* stats,
                                SamplerConstants<NU> c) {
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
