// CudaBackend<T>: device buffers and pinned staging allocated once, one stream, the whole
// cycle (copy in, [obstacle grid], [noise pre-pass], roll out, weigh, update, copy out)
// captured in one CUDA graph, and one synchronisation per update. Included by the per-task
// instantiation units.
//
// The construction, in three parts: the launch plan (plan_launch, launch_plan.hpp: pure, from
// the device's limits, the task's kernel shapes and the `mppi.cuda` settings), the buffers it
// needs, and one log line of what was chosen (launch_log.hpp). The plan picks for single
// vehicles the rollout kernel, rollout_chunked (chunked.cuh: only the dynamics serial, costs
// and noise parallel over (rollout, step), the weighting in the same kernel) up to K = 128 x
// multiprocessors when its shared memory fits, else rollout_single with G lanes per rollout;
// for teams rollout_chunked_team (chunked_team.cuh) while its blocks are few, else
// rollout_team with the noise drawn by a pre-pass while its buffer fits (kernels.cuh).
// The weighting (weigh_local, or the chunked kernel itself) weighs each chunk of rollouts
// against its own minimum and finalize_blocks combines the chunks.
// Forest tasks build the cycle's obstacle grid on the device (obstacle_grid.cuh) from the plan's
// path, which update() computes on the host with the layout (prepares_params(): the optimizer
// skips its host build); mppi.cuda.grid: host searches the grid of the parameters given instead.
// Every `mppi.cuda` setting leaves the plan the same (rollout costs bit for bit).
// Forest tasks' distance field (costs/distance_field.hpp): the cells live in a device buffer of
// DistanceField::kMaxCells, taken from the host only when the field's cells or stamp change (a
// new map: one copy on the update's stream ahead of the graph), and the staged parameters point
// at it; a cycle otherwise copies only the field's ~48 bytes with the parameters. The single
// vehicle's chunked kernel comes in two variants, with the field's code and without (its
// registers cost the field-less kernel ~5 % at K = 16,384); the graph holds the one the
// parameters need and is captured again when that changes.
#pragma once

#include <cstdint>
#include <cuda_runtime.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "chunked.cuh"
#include "chunked_team.cuh"
#include "cuda_check.cuh"
#include "kernels.cuh"
#include "launch_log.hpp"
#include "mppi/gpu/cuda_backend.hpp"
#include "mppi/gpu/launch_plan.hpp"
#include "obstacle_grid.cuh"

namespace mppi::cuda_detail {

struct StreamDeleter {
  void operator()(cudaStream_t s) const { cudaStreamDestroy(s); }
};
struct GraphDeleter {
  void operator()(cudaGraph_t g) const { cudaGraphDestroy(g); }
};
struct GraphExecDeleter {
  void operator()(cudaGraphExec_t g) const { cudaGraphExecDestroy(g); }
};

inline int current_device_checked(std::string* name) {
  std::string why;
  if (!cuda_device_available(&why)) throw std::runtime_error("cuda backend: no usable CUDA device (" + why + ")");
  int dev = 0;
  check(cudaGetDevice(&dev), "cudaGetDevice");
  cudaDeviceProp prop{};
  check(cudaGetDeviceProperties(&prop, dev), "cudaGetDeviceProperties");
  *name = prop.name;
  return dev;
}

template <class T>
class CudaBackend final : public RolloutBackend<T> {
 public:
  using Base = RolloutBackend<T>;
  using typename Base::Params;
  static constexpr int kNu = T::kNu;
  static constexpr int kNx = T::kNx;
  static constexpr bool kTeam = T::kVehicles > 1;

  CudaBackend(const MppiSettings& s, const CudaSettings& cuda)
      : k_(s.rollouts), t_(s.horizon), active_(s.rollouts), dt_(s.dt), substeps_(s.substeps), seed_(s.seed) {
    // Settings first: the sampler constants index every per-channel vector.
    std::string err = validate(s, kNu);
    if (const std::string e = validate(cuda, T::kVehicles); err.empty() && !e.empty()) err = "mppi.cuda." + e;
    if (!err.empty()) throw std::runtime_error("cuda backend: invalid settings: " + err);
    device_ = current_device_checked(&device_name_);
    c_ = make_sampler_constants<kNu>(s);
    inv_lambda_ = 1.0f / s.lambda;
    trajectory_ = s.weighting == Weighting::kTrajectory;
    plan_floats_ = static_cast<std::size_t>(t_) * kNu;
    plan_ = plan_launch(s, task_shape(), device_limits(device_), cuda);
    if (!plan_.error.empty())
      throw std::runtime_error("cuda backend: invalid launch size: " + plan_.error + " [K=" + std::to_string(k_) +
                               ", T=" + std::to_string(t_) + "]");
    allocate_buffers();
    prepare_stream();
    log_cuda_launch(std::string(T::Vehicle::kName) + " x" + std::to_string(T::kVehicles) + " K=" + std::to_string(k_) +
                    " T=" + std::to_string(t_) + " on " + device_name_ + ": " + mppi::describe(plan_, task_shape()) +
                    "; mppi.cuda: " + mppi::describe(cuda));
    run_ = plan_;
    if (plan_.graph) capture_graph();
  }

  const char* name() const override { return "cuda"; }

  // The rollouts an update runs: the launch at K with its counts for n (resize_launch: the
  // same kernels, blocks and weighting chunks, fewer of them; the buffers are K's), the graph
  // captured again. Rare (the daemon's work sizer), never per cycle.
  int set_active_rollouts(int n) override {
    n = std::clamp(n, 1, k_);
    if (n == active_) return n;
    active_ = n;
    run_ = resize_launch(plan_, task_shape(), n);
    if (plan_.graph) capture_graph();
    return n;
  }
  int active_rollouts() const override { return active_; }
  // A block of the chunked kernel (32 rollouts; a team's: 32 / vehicles of them, fewer).
  int rollout_quantum() const override { return 32; }
  bool prepares_params() const override { return plan_.device_grid; }

  // The kernels take the sampler constants by value: the graph holds them, so it is captured
  // again (rare: the daemon moves the nominal only when its hover estimate moved).
  void set_nominal(const float* u_nominal) override {
    std::copy_n(u_nominal, kNu, c_.u_nominal);
    if (plan_.graph) capture_graph();
  }

  void update(const float* x0, const Params& params, std::uint32_t cycle, float* plan, UpdateStats* stats) override {
    auto* in = h_in_.as<Input<T>>();
    in->key = NoiseKey{seed_, cycle};
    std::memcpy(in->x0, x0, sizeof(in->x0));
    // With the grid built on the device, its ~10 KB stay behind (staged_param_bytes: all before it).
    std::memcpy(static_cast<void*>(&in->params), &params, plan_.device_grid ? staged_param_bytes<T>() : sizeof(Params));
    std::memcpy(h_in_.as<unsigned char>() + align16(sizeof(Input<T>)), plan, plan_floats_ * sizeof(float));
    if (plan_.device_grid) plan_obstacle_grid(x0, params, plan);
    stage_field(params, in);
    if (plan_.chunked && !kTeam && uses_field(params) != field_kernel_) {
      // The chunked kernel with or without the field's code: captured again when that changes
      // (the first map; rare after).
      field_kernel_ = !field_kernel_;
      if (plan_.graph) capture_graph();
    }
    // Messages are built only on failure: update() allocates nothing.
    if (plan_.graph) {
      const cudaError_t e = cudaGraphLaunch(exec_.get(), stream_.get());
      if (e != cudaSuccess) fail(e, what("cudaGraphLaunch of the update graph"));
    } else {
      enqueue();
    }
    const cudaError_t e = cudaStreamSynchronize(stream_.get());
    if (e != cudaSuccess) fail(e, what("the update (copy in, rollouts, weights, plan update, copy out)"));
    std::memcpy(plan, h_out_.as<float>(), plan_floats_ * sizeof(float));
    if (stats != nullptr) summarise(stats, plan);
  }

  // The host's share of the obstacle grid: the plan's path and the grid's layout
  // (Task::prepare's, whose lists the device fills).
  void plan_obstacle_grid(const float* x0, const Params& params, const float* plan) {
    if constexpr (kForestTask<T>) {
      T::plan_path(params, x0, plan, t_, dt_, substeps_, path_.data());
      *reinterpret_cast<ObstacleGridLayout*>(h_in_.as<unsigned char>() + layout_offset_) =
          ObstacleGridLayout::plan(params.cost.obstacles, path_.data(), (t_ + 1) * T::kVehicles,
                                   static_cast<float>(t_) * dt_, params.cost.obstacle_reach, params.cost.obstacle_cell);
    } else {
      (void)x0, (void)params, (void)plan;
    }
  }

  // Whether this update needs the chunked kernel that reads the distance field.
  static bool uses_field(const Params& params) {
    if constexpr (kForestTask<T>) return params.cost.field.present();
    (void)params;
    return false;
  }

  // The distance field's cells on the device (forest tasks): copied when the field the
  // parameters point at is another, or stamped anew, before the update's graph on its stream;
  // the staged parameters then point at the device's copy.
  void stage_field(const Params& params, Input<T>* in) {
    if constexpr (kForestTask<T>) {
      const DistanceField& f = params.cost.field;
      if (!f.present()) return;
      if (f.cells != field_source_ || f.stamp != field_stamp_) {
        const std::size_t cells = static_cast<std::size_t>(f.nx) * static_cast<std::size_t>(f.ny) * static_cast<std::size_t>(f.nz);
        if (cells > static_cast<std::size_t>(DistanceField::kMaxCells))
          throw std::runtime_error("cuda backend: a distance field of more than DistanceField::kMaxCells cells");
        const cudaError_t e = cudaMemcpyAsync(d_field_.as<void>(), f.cells, cells * sizeof(std::int16_t),
                                              cudaMemcpyHostToDevice, stream_.get());
        if (e != cudaSuccess) fail(e, what("cudaMemcpyAsync of the distance field"));
        field_source_ = f.cells;
        field_stamp_ = f.stamp;
      }
      in->params.cost.field.cells = d_field_.as<const std::int16_t>();
    } else {
      (void)params, (void)in;
    }
  }

  // S~(tau_0,k) of the active rollouts of the last update.
  std::vector<float> rollout_costs() const override {
    std::vector<float> out(static_cast<std::size_t>(active_));
    check(cudaMemcpy(out.data(), d_cost_.as<float>(), out.size() * sizeof(float), cudaMemcpyDeviceToHost),
          what("cudaMemcpy of the rollout costs"));
    return out;
  }

  // Row 0 of the cost-to-go through a pinned staging buffer, only when asked (the display
  // sample of the cycle's rollouts): K floats, one copy on the update's stream.
  void step0_costs(float* out) const override {
    const std::size_t bytes = static_cast<std::size_t>(active_) * sizeof(float);
    cudaError_t e = cudaMemcpyAsync(h_costs_.as<void>(), d_cost_.as<void>(), bytes, cudaMemcpyDeviceToHost, stream_.get());
    if (e == cudaSuccess) e = cudaStreamSynchronize(stream_.get());
    if (e != cudaSuccess) fail(e, what("the copy of the step-0 costs"));
    std::memcpy(out, h_costs_.as<void>(), bytes);
  }

  std::size_t host_bytes() const override { return h_in_.bytes() + h_out_.bytes() + h_costs_.bytes(); }
  std::size_t device_bytes() const override {
    return d_cost_.bytes() + d_crashed_.bytes() + d_u_.bytes() + d_cc_.bytes() + d_pmin_.bytes() + d_part_.bytes() +
           d_stats_part_.bytes() + d_in_.bytes() + d_out_.bytes() + d_grid_lists_.bytes() + d_grid_counts_.bytes() +
           d_field_.bytes();
  }

 private:
  // The update (enqueue()) as a graph, launched each update as one.
  void capture_graph() {
    check(cudaStreamBeginCapture(stream_.get(), cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture");
    try {
      enqueue();
    } catch (...) {
      cudaGraph_t g = nullptr;
      cudaStreamEndCapture(stream_.get(), &g);
      if (g != nullptr) cudaGraphDestroy(g);
      throw;
    }
    cudaGraph_t graph = nullptr;
    check(cudaStreamEndCapture(stream_.get(), &graph), "cudaStreamEndCapture (capturing the update graph)");
    graph_.reset(graph);
    cudaGraphExec_t exec = nullptr;
    check(cudaGraphInstantiate(&exec, graph_.get(), 0), "cudaGraphInstantiate (the update graph)");
    exec_.reset(exec);
    check(cudaGraphUpload(exec_.get(), stream_.get()), "cudaGraphUpload");
    check(cudaStreamSynchronize(stream_.get()), "cudaStreamSynchronize after the graph upload");
  }

  static constexpr int kReduceBlock = kCudaReduceBlock;
  static constexpr int kSampleBlock = 256;
  static_assert(kChunkMaxThreads / 32 == kCudaChunkMaxWarps, "mppi.cuda.warps' bound is rollout_chunked's");
  static_assert(kTeamMaxThreads / 32 == kCudaTeamChunkMaxWarps, "mppi.cuda.warps' bound is rollout_chunked_team's");

  // What plan_launch needs of this task's kernels.
  static CudaTaskShape task_shape() {
    CudaTaskShape shape;
    shape.name = T::Vehicle::kName;
    shape.vehicles = T::kVehicles;
    shape.nu = kNu;
    shape.forest = kForestTask<T>;
    shape.staged_param_bytes = staged_param_bytes<T>();
    if constexpr (kTeam) {
      shape.chunk_rollouts = TeamChunkLayout<T>::R;
      shape.team_rollouts_per_warp = team_rollouts_per_warp<T>();
      shape.team_rollout_bytes = sizeof(TeamRollout<T>);
      shape.chunk_smem_bytes = [](int steps, int horizon) { return TeamChunkLayout<T>(steps, horizon).bytes; };
    } else {
      shape.chunk_rollouts = ChunkLayout<T>::R;
      shape.chunk_smem_bytes = [](int steps, int horizon) { return ChunkLayout<T>(steps, horizon).bytes; };
    }
    return shape;
  }

  // The device's limits and its free memory (before this backend's buffers).
  static CudaDeviceLimits device_limits(int device) {
    cudaDeviceProp prop{};
    check(cudaGetDeviceProperties(&prop, device), "cudaGetDeviceProperties");
    std::size_t free_bytes = 0, total_bytes = 0;
    check(cudaMemGetInfo(&free_bytes, &total_bytes), "cudaMemGetInfo");
    CudaDeviceLimits d;
    d.multiprocessors = prop.multiProcessorCount;
    d.shared_per_block_optin = prop.sharedMemPerBlockOptin;
    d.max_grid_x = prop.maxGridSize[0];
    d.max_grid_y = prop.maxGridSize[1];
    d.compute_major = prop.major;
    d.free_bytes = free_bytes;
    return d;
  }

  // The plan's buffers, the big one first so an absurd K fails on it with a clear message.
  void allocate_buffers() {
    const std::size_t kt = static_cast<std::size_t>(k_) * static_cast<std::size_t>(t_);
    const std::size_t u_bytes = kt * kNu * sizeof(float), cc_bytes = kt * sizeof(float);
    d_cost_ = DeviceBuffer(kt * sizeof(float), "the cost-to-go S~ (K x T = " + std::to_string(k_) + " x " +
                                                   std::to_string(t_) + " floats)");
    d_crashed_ = DeviceBuffer(static_cast<std::size_t>(k_), "the crash flags (K bytes)");
    if (plan_.keep_controls || plan_.prepass) d_u_ = DeviceBuffer(u_bytes, "the sampled controls (K x T x NU floats)");
    if (plan_.prepass) d_cc_ = DeviceBuffer(cc_bytes, "the control costs (K x T floats)");
    // Per-chunk (weigh_local) or per-block (chunked kernel) minima, sums and statistics.
    const auto parts = static_cast<std::size_t>(plan_.parts());
    d_pmin_ = DeviceBuffer(static_cast<std::size_t>(t_) * parts * sizeof(float), "the per-chunk minima");
    d_part_ = DeviceBuffer(static_cast<std::size_t>(t_) * parts * (kNu + 1) * sizeof(float), "the per-chunk sums");
    d_stats_part_ = DeviceBuffer(parts * sizeof(StatsPart), "the per-chunk statistics");
    in_bytes_ = align16(sizeof(Input<T>)) + plan_floats_ * sizeof(float);
    if (plan_.device_grid) {
      layout_offset_ = align16(in_bytes_);
      in_bytes_ = layout_offset_ + sizeof(ObstacleGridLayout);
      path_.resize(static_cast<std::size_t>(t_ + 1) * T::kVehicles * 2);
      d_grid_lists_ = DeviceBuffer(kGridListBytes, "the obstacle grid's lists (every cell of every cell side tried)");
      d_grid_counts_ = DeviceBuffer(kGridCountBytes, "the obstacle grid's list lengths");
    }
    if constexpr (kForestTask<T>)
      d_field_ = DeviceBuffer(static_cast<std::size_t>(DistanceField::kMaxCells) * sizeof(std::int16_t),
                              "the distance field's cells (DistanceField::kMaxCells int16)");
    out_bytes_ = align16(plan_floats_ * sizeof(float)) + sizeof(DeviceStats);
    d_in_ = DeviceBuffer(in_bytes_, "the per-cycle input");
    d_out_ = DeviceBuffer(out_bytes_, "the per-cycle output");
    h_in_ = PinnedBuffer(in_bytes_, "the per-cycle input staging");
    h_out_ = PinnedBuffer(out_bytes_, "the per-cycle output staging");
    h_costs_ = PinnedBuffer(static_cast<std::size_t>(k_) * sizeof(float), "the step-0 costs staging (K floats)");
    std::memset(h_in_.as<void>(), 0, in_bytes_);
  }

  // The stream, and the rollout kernel's dynamic shared memory past the default 48 KiB.
  void prepare_stream() {
    cudaStream_t stream = nullptr;
    check(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), "cudaStreamCreateWithFlags");
    stream_.reset(stream);
    if (plan_.chunked && plan_.chunk_smem > 48 * 1024) {
      for (bool field : {false, true})
        check(cudaFuncSetAttribute(chunked_kernel(field), cudaFuncAttributeMaxDynamicSharedMemorySize,
                                   static_cast<int>(plan_.chunk_smem)),
              "cudaFuncSetAttribute (chunked rollout, dynamic shared memory " + std::to_string(plan_.chunk_smem) +
                  " bytes)");
    }
    if (!plan_.chunked && plan_.rollout_smem > 48 * 1024) {
      const std::string what =
          "cudaFuncSetAttribute (dynamic shared memory " + std::to_string(plan_.rollout_smem) + " bytes)";
      with_rollout_kernel([&](auto kernel) {
        check(cudaFuncSetAttribute(kernel, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                   static_cast<int>(plan_.rollout_smem)),
              what);
      });
    }
  }

  // The chunked rollout kernel of this task (single vehicle or team), controls kept or not.
  using ChunkedKernel = void (*)(const Input<T>*, const float*, float*, unsigned char*, float*, float*, StatsPart*,
                                 float*, int, int, int, float, int, float, int, SamplerConstants<kNu>);
  ChunkedKernel chunked_kernel() const { return chunked_kernel(field_kernel_); }
  ChunkedKernel chunked_kernel(bool field) const {
    if constexpr (kTeam) {
      (void)field;
      return plan_.keep_controls ? rollout_chunked_team<T, true> : rollout_chunked_team<T, false>;
    } else if constexpr (kForestTask<T>) {
      if (field) return plan_.keep_controls ? rollout_chunked<T, true, true> : rollout_chunked<T, false, true>;
      return plan_.keep_controls ? rollout_chunked<T, true> : rollout_chunked<T, false>;
    } else {
      (void)field;
      return plan_.keep_controls ? rollout_chunked<T, true> : rollout_chunked<T, false>;
    }
  }

  // Calls f with the rollout kernel of this task, noise mode and lanes per rollout.
  template <class F>
  void with_rollout_kernel(F&& f) const {
    if constexpr (kTeam) {
      if (plan_.prepass) f(rollout_team<T, NoiseMode::kPrepass>);
      else f(rollout_team<T, NoiseMode::kInline>);
    } else if constexpr (kForestTask<T>) {
      switch (plan_.lanes) {
        case 8: f(rollout_single<T, 8>); break;
        case 4: f(rollout_single<T, 4>); break;
        case 2: f(rollout_single<T, 2>); break;
        default: f(rollout_single<T, 1>); break;
      }
    } else {
      f(rollout_single<T, 1>);
    }
  }

  template <class F>
  static void lazy_check(cudaError_t e, F&& message) {
    if (e != cudaSuccess) fail(e, message());
  }

  std::string what(const std::string& action) const {
    return action + " [task " + T::Vehicle::kName + " x" + std::to_string(T::kVehicles) + ", K=" +
           std::to_string(k_) + ", T=" + std::to_string(t_) + ", device " + device_name_ + "]";
  }

  // finalize_blocks for `parts` chunks or blocks per step, after the kernel that wrote them.
  void launch_finalize(cudaStream_t st, int parts, float* plan_out, DeviceStats* stats) {
    const float* d_plan = reinterpret_cast<const float*>(d_in_.as<unsigned char>() + align16(sizeof(Input<T>)));
    cudaLaunchAttribute attr;
    const cudaLaunchConfig_t cfg = launch_config(dim3(static_cast<unsigned>(t_)), dim3(kReduceBlock), 0, st, plan_.pdl, &attr);
    const float* part = d_part_.as<float>();
    const StatsPart* stats_part = d_stats_part_.as<StatsPart>();
    const float* pmin = d_pmin_.as<float>();
    const int traj = trajectory_ ? 1 : 0;
    lazy_check(cudaLaunchKernelEx(&cfg, finalize_blocks<kNu>, d_plan, part, stats_part, pmin, parts, inv_lambda_, traj,
                                  plan_out, stats, c_),
               [&] { return what("launching the update kernel"); });
  }

  // The per-cycle input on the device, and its parts.
  const Input<T>* d_input() const { return d_in_.as<Input<T>>(); }
  const float* d_plan_in() const {
    return reinterpret_cast<const float*>(d_in_.as<unsigned char>() + align16(sizeof(Input<T>)));
  }
  DeviceStats* d_stats() const {
    return reinterpret_cast<DeviceStats*>(d_out_.as<unsigned char>() + align16(plan_floats_ * sizeof(float)));
  }

  // The work of one cycle on the stream (captured once into the graph).
  void enqueue() {
    cudaStream_t st = stream_.get();
    lazy_check(cudaMemcpyAsync(d_in_.as<void>(), h_in_.as<void>(), in_bytes_, cudaMemcpyHostToDevice, st),
               [&] { return what("cudaMemcpyAsync of the input"); });
    if (plan_.device_grid) enqueue_obstacle_grid_build(st);
    if (plan_.prepass) enqueue_prepass(st);
    if (plan_.chunked) enqueue_chunked(st);
    else enqueue_lanes(st);
    lazy_check(cudaMemcpyAsync(h_out_.as<void>(), d_out_.as<void>(), out_bytes_, cudaMemcpyDeviceToHost, st),
               [&] { return what("cudaMemcpyAsync of the output"); });
  }

  // The cycle's obstacle grid, packed into the parameters on the device (forest tasks).
  void enqueue_obstacle_grid_build(cudaStream_t st) {
    if constexpr (kForestTask<T>) {
      auto* params = reinterpret_cast<unsigned char*>(d_in_.as<unsigned char>() + offsetof(Input<T>, params));
      using C = typename T::Cost::Params;
      const std::size_t cost_at = offsetof(Params, cost);
      lazy_check(enqueue_obstacle_grid(
                     st, reinterpret_cast<const ObstacleSet*>(params + cost_at + offsetof(C, obstacles)),
                     reinterpret_cast<const ObstacleGridLayout*>(d_in_.as<unsigned char>() + layout_offset_),
                     d_grid_lists_.as<std::uint8_t>(), d_grid_counts_.as<int>(),
                     reinterpret_cast<ObstacleGrid*>(params + cost_at + offsetof(C, obstacle_grid)), plan_.pdl),
                 [&] { return what("launching the obstacle grid build"); });
    } else {
      (void)st;
    }
  }

  // The noise pre-pass: every (rollout, step)'s perturbed control and control cost.
  void enqueue_prepass(cudaStream_t st) {
    const dim3 sgrid(static_cast<unsigned>((active_ + kSampleBlock - 1) / kSampleBlock), static_cast<unsigned>(t_));
    sample<T><<<sgrid, kSampleBlock, 0, st>>>(d_input(), d_plan_in(), active_, d_u_.as<float>(), d_cc_.as<float>(), c_);
    lazy_check(cudaGetLastError(), [&] { return what("launching the noise pre-pass"); });
  }

  // Rollouts, costs and each block's weighted sums in one kernel; then the blocks combined.
  // Behind the device's obstacle grid, a programmatic dependent launch: the noise and the
  // first chunk's dynamics run while the grid is packed (griddep_wait before the costs).
  void enqueue_chunked(cudaStream_t st) {
    const int threads = 32 * plan_.chunk_warps;
    cudaLaunchAttribute attr;
    const cudaLaunchConfig_t cfg = launch_config(dim3(static_cast<unsigned>(run_.chunk_blocks)),
                                                 dim3(static_cast<unsigned>(threads)), plan_.chunk_smem, st,
                                                 plan_.pdl && plan_.device_grid, &attr);
    float* u_keep = plan_.keep_controls ? d_u_.as<float>() : nullptr;
    lazy_check(cudaLaunchKernelEx(&cfg, chunked_kernel(), d_input(), d_plan_in(), d_cost_.as<float>(),
                                  d_crashed_.as<unsigned char>(), d_pmin_.as<float>(), d_part_.as<float>(),
                                  d_stats_part_.as<StatsPart>(), u_keep, active_, t_, plan_.chunk_steps, dt_, substeps_,
                                  inv_lambda_, trajectory_ ? 1 : 0, c_),
               [&] { return what("launching the chunked rollout kernel"); });
    lazy_check(cudaGetLastError(), [&] {
      return what("launching the chunked rollout kernel (" + std::to_string(run_.chunk_blocks) + " blocks of " +
                  std::to_string(threads) + " threads, " + std::to_string(plan_.chunk_smem) + " bytes shared)");
    });
    launch_finalize(st, static_cast<int>(run_.chunk_blocks), d_out_.as<float>(), d_stats());
  }

  // The lane kernel, then weigh_local over chunks of rollouts, then the chunks combined.
  void enqueue_lanes(cudaStream_t st) {
    RolloutIo<kNu> io{nullptr, nullptr};
    if (plan_.prepass) io = RolloutIo<kNu>{d_u_.as<float>(), d_cc_.as<float>()};
    const dim3 rgrid(static_cast<unsigned>(run_.rollout_grid));
    float* u_keep = plan_.keep_controls && !kTeam ? d_u_.as<float>() : nullptr;
    with_rollout_kernel([&](auto kernel) {
      kernel<<<rgrid, plan_.rollout_block, plan_.rollout_smem, st>>>(d_input(), d_plan_in(), io, d_cost_.as<float>(),
                                                                     d_crashed_.as<unsigned char>(), u_keep, active_, t_,
                                                                     dt_, substeps_, c_);
    });
    lazy_check(cudaGetLastError(), [&] {
      return what("launching the rollout kernel (" + std::to_string(run_.rollout_grid) + " blocks of " +
                  std::to_string(plan_.rollout_block) + " threads, " + std::to_string(plan_.rollout_smem) +
                  " bytes shared)");
    });
    const float* u_stored = plan_.prepass || (plan_.keep_controls && !kTeam) ? d_u_.as<float>() : nullptr;
    weigh_local<T><<<dim3(static_cast<unsigned>(t_), static_cast<unsigned>(run_.weigh_chunks)), kReduceBlock, 0, st>>>(
        d_input(), d_plan_in(), u_stored, d_cost_.as<float>(), d_crashed_.as<unsigned char>(), active_, run_.weigh_chunk,
        inv_lambda_, trajectory_ ? 1 : 0, d_pmin_.as<float>(), d_part_.as<float>(), d_stats_part_.as<StatsPart>(), c_);
    lazy_check(cudaGetLastError(), [&] { return what("launching the weighting kernel"); });
    launch_finalize(st, run_.weigh_chunks, d_out_.as<float>(), d_stats());
  }

  void summarise(UpdateStats* stats, const float* plan) const {
    const auto& d = *reinterpret_cast<const DeviceStats*>(h_out_.as<unsigned char>() +
                                                          align16(plan_floats_ * sizeof(float)));
    stats->min_cost = d.min_cost;
    stats->mean_cost = d.finite > 0 ? d.sum_cost / static_cast<float>(d.finite) : kCostCeiling;
    // 1 / sum (w / sum w)^2 = (sum w)^2 / sum w^2
    stats->ess = d.sum_w2 > 0.0f ? d.sum_w * d.sum_w / d.sum_w2 : 0.0f;
    stats->crashed = d.crashed;
    stats->rollouts = active_;
    stats->partial = false;
    stats->updated = true;
    bool ok = ffinite(stats->ess);
    for (std::size_t n = 0; n < plan_floats_; ++n) ok = ok && ffinite(plan[n]);
    stats->finite = ok;
  }

  int k_, t_;
  int active_ = 0;  // the rollouts an update runs (set_active_rollouts), at most k_
  float dt_;
  int substeps_;
  std::uint64_t seed_;
  float inv_lambda_ = 1.0f;
  bool trajectory_ = false;
  SamplerConstants<kNu> c_{};
  std::size_t plan_floats_ = 0;
  int device_ = 0;
  std::string device_name_;

  CudaLaunchPlan plan_;  // at K: the buffers are sized by it
  CudaLaunchPlan run_;   // at the active count: what is launched
  std::size_t in_bytes_ = 0, out_bytes_ = 0;
  DeviceBuffer d_cost_, d_crashed_, d_u_, d_cc_, d_pmin_, d_part_, d_stats_part_, d_in_, d_out_;
  std::size_t layout_offset_ = 0;  // of the grid's layout in the per-cycle input
  std::vector<float> path_;        // the plan's path, xy per step and vehicle
  DeviceBuffer d_grid_lists_, d_grid_counts_;
  DeviceBuffer d_field_;                        // the distance field's cells (forest tasks)
  const std::int16_t* field_source_ = nullptr;  // the host cells and stamp d_field_ holds
  std::uint64_t field_stamp_ = 0;
  bool field_kernel_ = false;  // the chunked kernel in use (the graph's) reads the field
  PinnedBuffer h_in_, h_out_, h_costs_;
  std::unique_ptr<CUstream_st, StreamDeleter> stream_;
  std::unique_ptr<CUgraph_st, GraphDeleter> graph_;
  std::unique_ptr<CUgraphExec_st, GraphExecDeleter> exec_;
};

}  // namespace mppi::cuda_detail

namespace mppi {
template <class T>
std::unique_ptr<RolloutBackend<T>> make_cuda_backend(const MppiSettings& s, const CudaSettings& cuda) {
  return std::make_unique<cuda_detail::CudaBackend<T>>(s, cuda);
}
}  // namespace mppi

#define MPPI_CUDA_INSTANTIATE(T) \
  template std::unique_ptr<mppi::RolloutBackend<mppi::T>> mppi::make_cuda_backend<mppi::T>(const mppi::MppiSettings&, \
                                                                                      const mppi::CudaSettings&);
