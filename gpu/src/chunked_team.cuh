// rollout_chunked_team: the team update (M vehicles per rollout, coupled only through the
// cost) split as rollout_chunked splits a single vehicle's (chunked.cuh): only the dynamics
// stay serial, one lane per (rollout, vehicle) of a producer warp, and everything else runs
// over parallel items on the other warps:
//   noise   per (rollout, step, block of 4 channels): core's gaussian4; then per (rollout,
//           step) core's perturb and control_cost on those normals (CachedSample below: the
//           sample type through which perturb draws them, as a SIMD batch draws its own);
//   costs   per (rollout, step, term), the terms of Task::running_with: each vehicle's
//           ForestCost term (its obstacle search through the grid in global memory), then
//           each pair's; then per (rollout, step) their sum in running_with's order plus the
//           control cost.
// R = 32 / M rollouts a block (team3: 10, team9: 3). In iteration c the producer advances
// chunk c + 1 while the consumers cost chunk c and draw the noise of chunk c + 2.
//
// Crashes. Task::advance freezes each crashed vehicle of a rollout; a crash is only known
// from the cost, and with several vehicles one crash changes the later terms of the others
// (pairs with the frozen vehicle, the crash bit a ForestCost term sees on entry). Per chunk
// and rollout: the terms are first computed with the vehicles frozen before the chunk; the
// first step s1 whose terms set a new crash bit is exact (nothing before it changed), so the
// new vehicles freeze at x(s1) and the terms after s1 are computed again; then the next new
// crash after s1, and so on until none (at most M rounds, usually none). That is CpuBackend's
// sequence: advance with the crash mask of the step before, running() with it on entry.
//
// Weights: as in rollout_chunked (block minimum, finalize_blocks combines the blocks).
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "chunked.cuh"
#include "kernels.cuh"
#include "mppi/rng.hpp"
#include "mppi/sampling.hpp"
#include "mppi/task.hpp"

namespace mppi::cuda_detail {

// A sample whose standard normals were drawn ahead (by core's gaussian4, into shared memory):
// perturb<NU>() called with it finds them through the two functions below (argument-dependent
// lookup, as for a SIMD batch of samples), so the perturbation and its control cost are core's.
struct CachedSample {
  std::uint32_t k;       // the sample index
  const float* normals;  // its NU normals at this step, block b at normals[4 b]
};
__device__ __forceinline__ void gaussian4(const NoiseKey&, CachedSample s, std::uint32_t, std::uint32_t block,
                                          float out[4]) {
  const float4 v = *reinterpret_cast<const float4*>(s.normals + 4 * block);
  out[0] = v.x;
  out[1] = v.y;
  out[2] = v.z;
  out[3] = v.w;
}
__device__ __forceinline__ float sample_group(CachedSample s, std::uint32_t groups) { return mppi::sample_group(s.k, groups); }

template <class T>
struct TeamChunkLayout {
  static constexpr int M = T::kVehicles, VNX = T::kVehicleNx, NU = T::kNu;
  static constexpr int R = 32 / M;                  // rollouts per block
  static constexpr int P = M * (M - 1) / 2;         // vehicle pairs
  static constexpr int TERMS = M + P;
  static constexpr int NB = (NU + 3) / 4;           // noise blocks of 4 channels
  static constexpr int XS = lane_stride(VNX);       // floats per vehicle state
  static constexpr int US = (NU + 3) / 4 * 4;       // floats per control vector (16-byte rows)
  static constexpr int QS = R + 1;
  std::size_t params, xs, us, cc, gz, tq, hit, xf, flags, qb, bytes;
  __host__ __device__ TeamChunkLayout(int chunk, int horizon) {
    std::size_t at = 0;
    auto take = [&](std::size_t n) {
      const std::size_t here = at;
      at += align16(n);
      return here;
    };
    params = take(chunk_param_bytes<T>());
    xs = take(sizeof(float) * 2 * chunk * R * M * XS);  // [chunk & 1][s][r][j][n]
    us = take(sizeof(float) * 3 * chunk * R * US);      // [chunk % 3][s][r][n]: perturbed controls
    cc = take(sizeof(float) * 3 * chunk * R);           // [chunk % 3][s][r]: control costs
    gz = take(sizeof(float) * chunk * R * NB * 4);      // [s][r][n]: normals of the chunk being drawn
    tq = take(sizeof(float) * chunk * R * TERMS);       // [s][r][term]: vehicle terms, then pair terms
    hit = take(sizeof(std::uint32_t) * chunk * R);      // [s][r]: crash bits set at step s
    xf = take(sizeof(float) * R * M * XS);              // [r][j][n]: frozen states
    flags = take(sizeof(int) * (3 * R + 32 + 2));       // mask[r], from[r], scan[r], slot[warp], pending[2]
    qb = take(sizeof(float) * static_cast<std::size_t>(horizon) * QS);  // [i][r]: q, then S~
    bytes = at;
  }
};

// Term `term` of Task::running_with for one rollout: vehicle terms first (ForestCost through
// the grid in global memory, gp), then the pairs in running_with's order. state(j): where
// vehicle j's state is; crashed: the rollout's crash mask on entry; *bits: the bits it sets.
template <class T, class State>
__device__ __forceinline__ float team_term(const typename T::Params& p, const typename T::Params& gp, int term,
                                           State&& state, float t, std::uint32_t crashed, std::uint32_t* bits) {
  constexpr int M = T::kVehicles;
  using Vehicle = typename T::Vehicle;
  if (term < M) {
    const int j = term;
    const float* x = state(j);
    bool hit = mppi::vehicle_crashed(crashed, j);
    float q;
    if constexpr (kForestTask<T>) {
      float pos[3];
      Vehicle::position(x, pos);
      const float d = gp.cost.obstacle_grid.nearest_surface(gp.cost.obstacles, pos[0], pos[1], t);
      q = ForestCost<Vehicle>::vehicle_at_distance(p.cost, j, x, d, &hit);
    } else {
      (void)gp;
      q = T::Cost::vehicle(p.cost, j, x, t, &hit);
    }
    *bits = hit ? 1u << j : 0u;
    return q;
  }
  int n = term - M, a = 0;
  while (n >= M - 1 - a) {
    n -= M - 1 - a;
    ++a;
  }
  const int b = a + 1 + n;
  bool hit = false;
  const float q = T::Cost::pair(p.cost, state(a), state(b), &hit);
  *bits = hit ? (1u << a) | (1u << b) : 0u;
  return q;
}

// Launch bounds: up to 16 warps (one block a multiprocessor when the blocks are few), at most
// 128 registers a thread.
constexpr int kTeamMaxThreads = 512;

// ---- rollout_chunked_team's block: its shared memory and its phases ------------------------

template <class T, bool kKeep>
struct TeamChunkedBlock {
  using Lay = TeamChunkLayout<T>;
  static constexpr int M = Lay::M, VNX = Lay::VNX, VNU = T::kVehicleNu, NU = Lay::NU, R = Lay::R, TERMS = Lay::TERMS;
  static constexpr int NB = Lay::NB, XS = Lay::XS, US = Lay::US, QS = Lay::QS;
  static_assert(M > 1 && M <= 32, "rollout_chunked_team is for teams");
  using Params = typename T::Params;
  using Vehicle = typename T::Vehicle;

  const Input<T>* in;
  const float* plan;
  float* u_keep;
  int K, horizon, chunk, substeps;
  float dt;
  int tid, threads, warps, warp, lane, k0, valid, nchunks;
  float *xs, *us, *ccs, *gz, *tq, *xf, *qb;
  std::uint32_t* hits;
  std::uint32_t* mask;  // crashed vehicles, per rollout
  int* from;            // first step to cost again, per rollout
  int* scan;            // first step to look for crashes at, per rollout
  int *slot, *pending;
  const Params* p;   // staged in shared memory
  const Params* gp;  // the cycle's parameters in global memory (the obstacles and their grid)
  NoiseKey key;

  // Lays out shared memory, stages the parameters and clears the crash state (no barrier).
  __device__ TeamChunkedBlock(const Input<T>* in_, const float* plan_, float* u_keep_, int K_, int horizon_,
                              int chunk_, float dt_, int substeps_, unsigned char* smem)
      : in(in_), plan(plan_), u_keep(u_keep_), K(K_), horizon(horizon_), chunk(chunk_), substeps(substeps_), dt(dt_) {
    const Lay L(chunk, horizon);
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
    gz = reinterpret_cast<float*>(smem + L.gz);
    tq = reinterpret_cast<float*>(smem + L.tq);
    hits = reinterpret_cast<std::uint32_t*>(smem + L.hit);
    xf = reinterpret_cast<float*>(smem + L.xf);
    mask = reinterpret_cast<std::uint32_t*>(smem + L.flags);
    from = reinterpret_cast<int*>(mask + R);
    scan = from + R;
    slot = scan + R;
    pending = slot + 32;
    qb = reinterpret_cast<float*>(smem + L.qb);
    for (int e = tid; e < R; e += threads) mask[e] = 0u;
    for (int e = tid; e < chunk * R; e += threads) hits[e] = 0u;
    if (lane == 0) slot[warp] = warp_slot();
    if (tid < 2) pending[tid] = 0;
    key = in->key;
    p = reinterpret_cast<const Params*>(smem + L.params);
    gp = &in->params;
  }

  __device__ int steps_of(int ci) const { return horizon - ci * chunk < chunk ? horizon - ci * chunk : chunk; }
  // Vehicle j of rollout r after step s of chunk ci; the rollout's control at that step; the control costs.
  __device__ float* xs_at(int ci, int s, int r, int j) const {
    return xs + ((static_cast<std::size_t>((ci & 1) * chunk + s) * R + r) * M + j) * XS;
  }
  __device__ float* us_at(int ci, int s, int r) const {
    return us + (static_cast<std::size_t>((ci % 3) * chunk + s) * R + r) * US;
  }
  __device__ float* cc_at(int ci, int s) const { return ccs + static_cast<std::size_t>((ci % 3) * chunk + s) * R; }
  __device__ CostTable table() const { return {qb, QS, horizon}; }

  // Noise, first half: the normals of (step s of chunk ci, rollout r, block b).
  __device__ void normals(int ci, int s, int r, int b) const {
    float v[4];
    mppi::gaussian4(key, static_cast<std::uint32_t>(k0 + r), static_cast<std::uint32_t>(ci * chunk + s),
                    static_cast<std::uint32_t>(b), v);
    *reinterpret_cast<float4*>(gz + ((s * R + r) * NB + b) * 4) = make_float4(v[0], v[1], v[2], v[3]);
  }
  // Second half: core's perturb and control cost on them.
  __device__ void perturbed(int ci, int s, int r, const SamplerConstants<NU>& c) const {
    const int i = ci * chunk + s;
    const float* pu = plan + i * NU;
    float u[NU], du[NU];
    perturb<NU>(c, key, CachedSample{static_cast<std::uint32_t>(k0 + r), gz + (s * R + r) * NB * 4},
                static_cast<std::uint32_t>(i), pu, u, du);
    float* uo = us_at(ci, s, r);
#pragma unroll
    for (int n = 0; n < NU; ++n) uo[n] = u[n];
    cc_at(ci, s)[r] = control_cost<NU>(c, pu, du);
    if (kKeep && r < valid) store_floats<NU>(u_keep + (static_cast<std::size_t>(i) * K + k0 + r) * NU, u);
  }
  // The noise of chunk ci by threads ct of nct: normals, a barrier (bar), perturb.
  template <class Barrier>
  __device__ void draw_chunk(int ci, int ct, int nct, Barrier&& bar, const SamplerConstants<NU>& c) const {
    const int steps = steps_of(ci);
    for (int e = ct; e < steps * R * NB; e += nct) normals(ci, e / (R * NB), e / NB % R, e % NB);
    bar();
    for (int e = ct; e < steps * R; e += nct) perturbed(ci, e / R, e % R, c);
  }

  // Term `term` of (step s of chunk ci, rollout r), with the rollout's current crash mask.
  __device__ void term_item(int ci, int s, int r, int term) const {
    const std::uint32_t m = mask[r];
    auto state = [&](int j) -> const float* {
      return ((m >> j) & 1u) != 0u ? xf + (r * M + j) * XS : xs_at(ci, s, r, j);
    };
    std::uint32_t bits = 0u;
    const float t = static_cast<float>(ci * chunk + s + 1) * dt;
    tq[(s * R + r) * TERMS + term] = team_term<T>(*p, *gp, term, state, t, m, &bits);
    if (bits != 0u) atomicOr(&hits[s * R + r], bits);
  }
  // The dynamics of chunk ci: lane r * M + j advances vehicle j of rollout r.
  __device__ void produce(int ci) const {
    const int r = lane / M, j = lane % M;
    if (r >= R) return;
    float x[VNX];
    if (ci == 0) {
#pragma unroll
      for (int n = 0; n < VNX; ++n) x[n] = in->x0[j * VNX + n];
    } else {
      lds_vec<VNX>(xs_at(ci - 1, steps_of(ci - 1) - 1, r, j), x);
    }
    const float h = dt / static_cast<float>(substeps);
    const int steps = steps_of(ci);
    for (int s = 0; s < steps; ++s) {
      float u[VNU];
      lds_vec<VNU>(us_at(ci, s, r) + j * VNU, u);
      for (int sub = 0; sub < substeps; ++sub) Vehicle::step(p->vehicle, x, u, h);  // Task::advance's step
      sts_vec<VNX>(xs_at(ci, s, r, j), x);
    }
  }

  // Prologue: the noise of chunk 0; then the dynamics of chunk 0 beside the noise of chunk 1.
  __device__ void prologue(const SamplerConstants<NU>& c) const {
    __syncthreads();
    draw_chunk(0, tid, threads, [] { __syncthreads(); }, c);
    __syncthreads();
    const int producer = producer_warp(0, slot, warps);
    if (warp == producer) produce(0);
    if (nchunks > 1 && (warps == 1 || warp != producer)) {
      const Consumers con = consumers_of(producer);
      draw_chunk(1, con.ct, con.nct, [con] { consumer_sync(con.nct); }, c);
    }
    __syncthreads();
  }

  // The consumers' part of iteration ci: the terms of chunk ci beside the normals of chunk
  // ci + 2; the crash rounds beside its perturbed controls; the running costs.
  __device__ void consume(int ci, int producer, const SamplerConstants<NU>& c) const {
    const Consumers con = consumers_of(producer);
    terms_and_normals(ci, con);
    consumer_sync(con.nct);
    crash_rounds(ci, con, c);
    running_costs(ci, con);
  }
  // The terms of chunk ci (vehicles frozen before it); the normals of chunk ci + 2.
  __device__ void terms_and_normals(int ci, const Consumers& con) const {
    const int n_terms = steps_of(ci) * R * TERMS;
    const int steps2 = ci + 2 < nchunks ? steps_of(ci + 2) : 0;
    for (int e = con.ct; e < n_terms + steps2 * R * NB; e += con.nct) {
      if (e < n_terms) {
        const int s = e / (R * TERMS), r = e / TERMS % R, term = e % TERMS;
        if (r < valid) term_item(ci, s, r, term);
      } else {
        const int f = e - n_terms;
        normals(ci + 2, f / (R * NB), f / NB % R, f % NB);
      }
    }
    if (con.ct < R) scan[con.ct] = 0;
  }
  // Rounds: the first new crash of each rollout freezes its vehicles and the steps after it
  // are costed again, until no rollout has one; the perturbed controls of chunk ci + 2 beside
  // round 0.
  __device__ void crash_rounds(int ci, const Consumers& con, const SamplerConstants<NU>& c) const {
    const int steps = steps_of(ci), n_terms = steps * R * TERMS;
    const int steps2 = ci + 2 < nchunks ? steps_of(ci + 2) : 0;
    for (int round = 0;; ++round) {
      if (con.ct < R) freeze_at_next_crash(ci, con.ct, round);
      if (con.ct == R) pending[(round + 1) & 1] = 0;
      if (round == 0)
        for (int e = con.ct; e < steps2 * R; e += con.nct) perturbed(ci + 2, e / R, e % R, c);
      consumer_sync(con.nct);
      if (pending[round & 1] == 0) break;
      for (int e = con.ct; e < n_terms; e += con.nct) {
        const int s = e / (R * TERMS), r = e / TERMS % R, term = e % TERMS;
        if (r < valid && s >= from[r]) term_item(ci, s, r, term);
      }
      consumer_sync(con.nct);
    }
  }
  // Rollout r: its first crash in chunk ci from scan[r] on with a vehicle not yet frozen
  // freezes those vehicles there; from[r]: the first step to cost again (none: the chunk's end).
  __device__ void freeze_at_next_crash(int ci, int r, int round) const {
    const int steps = steps_of(ci);
    if (r >= valid) {
      from[r] = steps;
      return;
    }
    const std::uint32_t m = mask[r];
    int s = scan[r];
    std::uint32_t fresh = 0u;
    for (; s < steps; ++s) {
      fresh = hits[s * R + r] & ~m;
      if (fresh != 0u) break;
    }
    if (fresh == 0u) {
      from[r] = steps;
      scan[r] = steps;
      return;
    }
    for (int j = 0; j < M; ++j) {
      if (((fresh >> j) & 1u) == 0u) continue;
      const float* src = xs_at(ci, s, r, j);
      for (int n = 0; n < XS; ++n) xf[(r * M + j) * XS + n] = src[n];
    }
    mask[r] = m | fresh;
    from[r] = s + 1;
    scan[r] = s + 1;
    for (int s2 = s + 1; s2 < steps; ++s2) hits[s2 * R + r] = 0u;
    if (s + 1 < steps) pending[round & 1] = 1;
  }
  // q per (step, rollout): the terms in running_with's order, plus the control cost.
  __device__ void running_costs(int ci, const Consumers& con) const {
    for (int e = con.ct; e < steps_of(ci) * R; e += con.nct) {
      const int s = e / R, r = e % R;
      if (r < valid) {
        const float* tv = tq + (s * R + r) * TERMS;
        float q = 0.0f;
        for (int n = 0; n < TERMS; ++n) q += tv[n];
        qb[(ci * chunk + s) * QS + r] = sanitize_cost(q + cc_at(ci, s)[r]);
      }
      hits[s * R + r] = 0u;
    }
  }

  // One thread per rollout: the terminal cost at its vehicles' last (or frozen) states and its
  // cost-to-go; S~(tau_0) and the crash flag to global memory.
  __device__ void cost_to_go_per_rollout(float* S0, unsigned char* crashed_out) const {
    if (tid >= valid) return;
    const int r = tid, last = nchunks - 1;
    const std::uint32_t m = mask[r];
    float x[M * VNX];
    for (int j = 0; j < M; ++j)
      lds_vec<VNX>(((m >> j) & 1u) != 0u ? xf + (r * M + j) * XS : xs_at(last, steps_of(last) - 1, r, j), x + j * VNX);
    S0[k0 + r] = cost_to_go(table(), r, T::terminal(*p, x));
    crashed_out[k0 + r] = m != 0u;
  }
};

// S0: S~(tau_0,k), the first row of the cost-to-go (for rollout_costs()); sums: BlockSums.
// kKeep: the controls are kept in u_keep for the update (else drawn again there).
template <class T, bool kKeep>
__global__ void __launch_bounds__(kTeamMaxThreads, 1)
    rollout_chunked_team(const Input<T>* in, const float* plan, float* S0, unsigned char* crashed_out, float* pmin,
                         float* part, StatsPart* stats_part, float* u_keep, int K, int horizon, int chunk, float dt,
                         int substeps, float inv_lambda, int trajectory, SamplerConstants<T::kNu> c) {
  extern __shared__ __align__(16) unsigned char smem[];
  const TeamChunkedBlock<T, kKeep> b(in, plan, u_keep, K, horizon, chunk, dt, substeps, smem);
  b.prologue(c);
  griddep_wait();  // launched behind the device's obstacle grid: it is packed now
  for (int ci = 0; ci < b.nchunks; ++ci) {
    // The producer of chunk ci + 1 (none after the last chunk: every warp consumes).
    const int producer = ci + 1 < b.nchunks ? producer_warp(ci + 1, b.slot, b.warps) : -1;
    if (b.warp == producer) b.produce(ci + 1);
    if (b.warps == 1 || b.warp != producer) b.consume(ci, producer, c);
    __syncthreads();
  }
  griddep_launch_dependents();
  b.cost_to_go_per_rollout(S0, crashed_out);
  __syncthreads();
  weigh_block<T::kNu, kKeep>(b.table(), BlockRollouts{b.k0, b.valid, K}, plan, u_keep, b.key, c, inv_lambda,
                             trajectory, [&](int r) { return b.mask[r] != 0u; }, BlockSums{pmin, part, stats_part});
}

}  // namespace mppi::cuda_detail
