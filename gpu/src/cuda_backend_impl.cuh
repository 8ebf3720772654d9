// CudaBackend<T>: device buffers and pinned staging allocated once, one stream, the whole
// cycle (copy in, [obstacle table], [noise pre-pass], roll out, weigh, update, copy out)
// captured in one CUDA graph, and one synchronisation per update. Included by the per-task
// instantiation units.
//
// Chosen at construction: for single vehicles the rollout kernel, rollout_chunked
// (chunked.cuh: only the dynamics serial, costs and noise parallel over (rollout, step), the
// weighting in the same kernel) up to K = 128 x multiprocessors when its shared memory fits,
// else rollout_single with G lanes per rollout (1 to 8: about 8 warps per multiprocessor
// while the rollouts alone leave it idle); for teams where the noise is drawn (kernels.cuh,
// NoiseMode: the pre-pass when its buffer fits in the noise budget).
// Single vehicles keep the perturbed controls for the update: the chunked kernel while they
// fit in about the L2 cache, the lane kernel while they fit in the noise budget (else the
// update draws them again). The weighting (weigh_local, or the chunked kernel itself) weighs
// each chunk of rollouts against its own minimum and finalize_blocks combines the chunks.
// Forest tasks build the cycle's obstacle grid on the device (obstacle_grid.cuh) from the plan's
// path, which update() computes on the host with the layout (prepares_params(): the optimizer
// skips its host build); MPPID_CUDA_GRID=host searches the grid of the parameters given instead.
// For measurements, MPPID_CUDA_KERNEL=chunked|lanes, MPPID_CUDA_CHUNK=<steps>,
// MPPID_CUDA_WARPS=<warps per chunked block, 1-8>, MPPID_CUDA_NOISE=prepass|inline (teams),
// keep|redraw (single vehicles) and
// MPPID_CUDA_LANES=1|2|4|8 override the choices; the plan is the same either way (rollout
// costs bit for bit).
#pragma once

#include <cstdint>
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdlib>
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
#include "mppi/gpu/cuda_backend.hpp"
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

  explicit CudaBackend(const MppiSettings& s)
      : k_(s.rollouts), t_(s.horizon), dt_(s.dt), substeps_(s.substeps), seed_(s.seed) {
    // Settings first: the sampler constants index every per-channel vector.
    const std::string err = validate(s, kNu);
    if (!err.empty()) throw std::runtime_error("cuda backend: invalid settings: " + err);
    device_ = current_device_checked(&device_name_);
    cudaDeviceProp prop{};
    check(cudaGetDeviceProperties(&prop, device_), "cudaGetDeviceProperties");
    c_ = make_sampler_constants<kNu>(s);
    inv_lambda_ = 1.0f / s.lambda;
    trajectory_ = s.weighting == Weighting::kTrajectory;
    plan_floats_ = static_cast<std::size_t>(t_) * kNu;

    // Where the noise is drawn.
    const std::size_t kt_floats = static_cast<std::size_t>(k_) * static_cast<std::size_t>(t_);
    const std::size_t u_bytes = kt_floats * kNu * sizeof(float), cc_bytes = kt_floats * sizeof(float);
    std::size_t free_bytes = 0, total_bytes = 0;
    check(cudaMemGetInfo(&free_bytes, &total_bytes), "cudaMemGetInfo");
    const std::size_t budget = std::min<std::size_t>(free_bytes / 4, kNoiseBudgetMax);
    mode_ = kTeam && u_bytes + cc_bytes <= budget ? NoiseMode::kPrepass : NoiseMode::kInline;
    // Single vehicles (chunked kernel): keep the controls for the update while they fit in
    // about the L2 cache; past that, drawing them again costs less than the memory traffic.
    keep_u_ = !kTeam && u_bytes <= kKeepControlsMax;
    if (const char* m = std::getenv("MPPID_CUDA_NOISE")) {
      const std::string v(m);
      if (v == "prepass" && u_bytes + cc_bytes <= budget) mode_ = NoiseMode::kPrepass;
      else if (v == "inline") mode_ = NoiseMode::kInline;
      if (v == "keep" && u_bytes <= budget) keep_u_ = true;
      else if (v == "redraw") keep_u_ = false;
    }

    // Launch shapes.
    const int sms = prop.multiProcessorCount;
    if constexpr (kTeam) {
      // The chunked team kernel (chunked_team.cuh) for teams of up to four vehicles (eight or
      // more rollouts a block), or while its blocks are few (at most 4 a multiprocessor), when
      // its shared memory fits; else the lane kernel (rollout_team). Measured on an H100
      // (gpu/NOTES.md, v6): team3 K = 1200 chunked ~100 us against lanes 222 us; team9
      // (three rollouts a block) K = 1024 chunked 342 us against lanes 735 us, but K = 6000
      // (2000 blocks) chunked 1.46-2.3 ms against lanes 1.12 ms.
      chunk_blocks_ = (static_cast<long long>(k_) + TeamChunkLayout<T>::R - 1) / TeamChunkLayout<T>::R;
      chunked_ = TeamChunkLayout<T>::R >= 8 || chunk_blocks_ <= 4LL * sms;
      if (const char* v = std::getenv("MPPID_CUDA_KERNEL")) chunked_ = std::string(v) == "chunked";
      // Chunks of 20 steps with a multiprocessor for every block (team3 K = 1200 on an H100:
      // 97-99 us at 16-25 steps, 104-107 at 8 and 12, 112 at 6), else 8 (shared memory).
      chunk_steps_ = chunk_blocks_ <= sms ? 20 : 8;
      if (const char* v = std::getenv("MPPID_CUDA_CHUNK")) chunk_steps_ = std::max(1, std::atoi(v));
      chunk_steps_ = std::min(chunk_steps_, std::max(1, t_));
      chunk_smem_ = TeamChunkLayout<T>(chunk_steps_, t_).bytes;
      if (chunk_smem_ > prop.sharedMemPerBlockOptin) chunked_ = false;
      // 16 warps while there is a multiprocessor for every block, 8 while two blocks share
      // one, else 4.
      chunk_warps_ = chunk_blocks_ <= sms ? 16 : chunk_blocks_ <= 2LL * sms ? 8 : 4;
      if (const char* v = std::getenv("MPPID_CUDA_WARPS"))
        chunk_warps_ = std::clamp(std::atoi(v), 1, kTeamMaxThreads / 32);
      if (chunked_) {
        // The chunked kernel draws the noise itself and keeps the controls for the update
        // while they fit in the noise budget.
        mode_ = NoiseMode::kInline;
        keep_u_ = u_bytes <= budget;
        if (const char* m = std::getenv("MPPID_CUDA_NOISE")) {
          if (std::string(m) == "redraw") keep_u_ = false;
        }
      }
      constexpr int per_warp = team_rollouts_per_warp<T>();
      // One warp per block while that spreads the warps over more multiprocessors.
      warps_per_block_ = (static_cast<long long>(k_) + per_warp - 1) / per_warp <= 2LL * sms ? 1 : 2;
      rollout_block_ = 32 * warps_per_block_;
      rollout_grid_ = (static_cast<long long>(k_) + per_warp * warps_per_block_ - 1) / (per_warp * warps_per_block_);
      rollout_smem_ = align16(staged_param_bytes<T>()) + sizeof(TeamRollout<T>) * per_warp * warps_per_block_;
    } else {
      // The chunked kernel while the lane kernel's one thread per rollout leaves the GPU short
      // of warps (up to four blocks of 32 rollouts per multiprocessor); past that the lane
      // kernel, whose threads then fill the GPU with less overhead a rollout. Measured on an
      // H100 (gpu/NOTES.md): K = 16,384 chunked 187 us vs lanes 249 us; K = 65,536 lanes
      // ~500 us vs chunked ~720 us; K = 1,048,576 lanes 6.9 ms vs chunked 10.1 ms.
      chunked_ = static_cast<long long>(k_) <= 128LL * sms;
      if (const char* v = std::getenv("MPPID_CUDA_KERNEL")) chunked_ = std::string(v) != "lanes";
      chunk_blocks_ = (static_cast<long long>(k_) + ChunkLayout<T>::R - 1) / ChunkLayout<T>::R;
      // 8 warps while there is a multiprocessor for every block (the consumers are then the
      // only warps beside the producer), else 4 (four blocks a multiprocessor).
      chunk_warps_ = chunk_blocks_ <= sms ? 8 : 4;
      if (const char* v = std::getenv("MPPID_CUDA_CHUNK")) chunk_steps_ = std::max(1, std::atoi(v));
      if (const char* v = std::getenv("MPPID_CUDA_WARPS"))
        chunk_warps_ = std::clamp(std::atoi(v), 1, kChunkMaxThreads / 32);
      chunk_steps_ = std::min(chunk_steps_, std::max(1, t_));
      chunk_smem_ = ChunkLayout<T>(chunk_steps_, t_).bytes;
      if (chunk_smem_ > prop.sharedMemPerBlockOptin) chunked_ = false;
      if (!chunked_) {
        // The lane kernel keeps the controls while they fit in the noise budget: reading them
        // back costs less than drawing them again.
        keep_u_ = u_bytes <= budget;
        if (const char* m = std::getenv("MPPID_CUDA_NOISE")) {
          if (std::string(m) == "redraw") keep_u_ = false;
        }
      }
      // Lanes per rollout: up to about 8 warps per multiprocessor (forest tasks only). On an
      // H100, quadrotor_forest K=16384 took 403/339/363/576 us with G = 1/2/4/8 and K=4096
      // 380/290/240/240 us: past ~8 warps the G-fold repeated dynamics cost more issue slots
      // than the shorter obstacle loop saves.
      lanes_ = 1;
      if constexpr (kForestTask<T>) {
        while (lanes_ < 8 && static_cast<long long>(k_) * lanes_ * 2 <= 256LL * sms) lanes_ *= 2;
        if (const char* l = std::getenv("MPPID_CUDA_LANES")) {
          const int v = std::atoi(l);
          if (v == 1 || v == 2 || v == 4 || v == 8) lanes_ = v;
        }
      }
      const long long threads = static_cast<long long>(k_) * lanes_;
      // Small blocks while that spreads the rollouts over more multiprocessors: each
      // thread runs the whole horizon, so the latency of one rollout sets the time.
      rollout_block_ = 128;
      while (rollout_block_ > 32 && (threads + rollout_block_ - 1) / rollout_block_ < 4LL * sms) rollout_block_ /= 2;
      rollout_grid_ = (threads + rollout_block_ - 1) / rollout_block_;
      rollout_smem_ = align16(staged_param_bytes<T>());
    }
    // Chunks of rollouts per block of the weighting kernels: enough blocks to fill the
    // device, at most 65535 chunks (grid.y).
    chunk_ = kReduceBlock * (k_ <= 65536 ? 4 : 16);
    while ((static_cast<long long>(k_) + chunk_ - 1) / chunk_ > 65535) chunk_ *= 2;
    chunks_ = static_cast<int>((static_cast<long long>(k_) + chunk_ - 1) / chunk_);
    check_launch_size(prop);

    // Buffers, the big one first so an absurd K fails on it with a clear message.
    const std::size_t kt = static_cast<std::size_t>(k_) * static_cast<std::size_t>(t_);
    d_cost_ = DeviceBuffer(kt * sizeof(float), "the cost-to-go S~ (K x T = " + std::to_string(k_) + " x " +
                                                   std::to_string(t_) + " floats)");
    d_crashed_ = DeviceBuffer(static_cast<std::size_t>(k_), "the crash flags (K bytes)");
    if (keep_u_ && mode_ != NoiseMode::kPrepass) d_u_ = DeviceBuffer(u_bytes, "the sampled controls (K x T x NU floats)");
    if (mode_ == NoiseMode::kPrepass) {
      d_u_ = DeviceBuffer(u_bytes, "the sampled controls (K x T x NU floats)");
      d_cc_ = DeviceBuffer(cc_bytes, "the control costs (K x T floats)");
    }
    // Per-chunk (weigh_local) or per-block (chunked kernel) minima, sums and statistics.
    const std::size_t parts = chunked_ ? static_cast<std::size_t>(chunk_blocks_) : static_cast<std::size_t>(chunks_);
    d_pmin_ = DeviceBuffer(static_cast<std::size_t>(t_) * parts * sizeof(float), "the per-chunk minima");
    d_part_ = DeviceBuffer(static_cast<std::size_t>(t_) * parts * (kNu + 1) * sizeof(float), "the per-chunk sums");
    d_stats_part_ = DeviceBuffer(parts * sizeof(StatsPart), "the per-chunk statistics");
    in_bytes_ = align16(sizeof(Input<T>)) + plan_floats_ * sizeof(float);
    if constexpr (kForestTask<T>) {
      const char* g = std::getenv("MPPID_CUDA_GRID");
      device_grid_ = g == nullptr || std::string(g) != "host";
    }
    if (device_grid_) {
      layout_offset_ = align16(in_bytes_);
      in_bytes_ = layout_offset_ + sizeof(ObstacleGridLayout);
      path_.resize(static_cast<std::size_t>(t_ + 1) * T::kVehicles * 2);
      d_grid_lists_ = DeviceBuffer(kGridListBytes, "the obstacle grid's lists (every cell of every cell side tried)");
      d_grid_counts_ = DeviceBuffer(kGridCountBytes, "the obstacle grid's list lengths");
    }
    out_bytes_ = align16(plan_floats_ * sizeof(float)) + sizeof(DeviceStats);
    d_in_ = DeviceBuffer(in_bytes_, "the per-cycle input");
    d_out_ = DeviceBuffer(out_bytes_, "the per-cycle output");
    h_in_ = PinnedBuffer(in_bytes_, "the per-cycle input staging");
    h_out_ = PinnedBuffer(out_bytes_, "the per-cycle output staging");
    h_costs_ = PinnedBuffer(static_cast<std::size_t>(k_) * sizeof(float), "the step-0 costs staging (K floats)");
    std::memset(h_in_.as<void>(), 0, in_bytes_);

    cudaStream_t stream = nullptr;
    check(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), "cudaStreamCreateWithFlags");
    stream_.reset(stream);
    if (chunked_ && chunk_smem_ > 48 * 1024) {
      check(cudaFuncSetAttribute(chunked_kernel(), cudaFuncAttributeMaxDynamicSharedMemorySize,
                                 static_cast<int>(chunk_smem_)),
            "cudaFuncSetAttribute (chunked rollout, dynamic shared memory " + std::to_string(chunk_smem_) + " bytes)");
    }
    if (!chunked_ && rollout_smem_ > 48 * 1024) {
      const std::string what = "cudaFuncSetAttribute (dynamic shared memory " + std::to_string(rollout_smem_) + " bytes)";
      with_rollout_kernel([&](auto kernel) {
        check(cudaFuncSetAttribute(kernel, cudaFuncAttributeMaxDynamicSharedMemorySize, static_cast<int>(rollout_smem_)),
              what);
      });
    }

    // finalize_blocks as a programmatic dependent launch (sm_90 on): launched while the last
    // blocks of the kernel before it run, it waits for them on the device.
    pdl_ = prop.major >= 9;
    if (const char* v = std::getenv("MPPID_CUDA_PDL")) pdl_ = std::string(v) != "0";
    const char* env = std::getenv("MPPID_CUDA_GRAPH");
    use_graph_ = env == nullptr || std::string(env) != "0";
    if (use_graph_) capture_graph();
  }

  const char* name() const override { return "cuda"; }
  bool prepares_params() const override { return device_grid_; }

  // The kernels take the sampler constants by value: the graph holds them, so it is captured
  // again (rare: the daemon moves the nominal only when its hover estimate moved).
  void set_nominal(const float* u_nominal) override {
    std::copy_n(u_nominal, kNu, c_.u_nominal);
    if (use_graph_) capture_graph();
  }

  void update(const float* x0, const Params& params, std::uint32_t cycle, float* plan, UpdateStats* stats) override {
    auto* in = h_in_.as<Input<T>>();
    in->key = NoiseKey{seed_, cycle};
    std::memcpy(in->x0, x0, sizeof(in->x0));
    // With the grid built on the device, its ~10 KB stay behind (staged_param_bytes: all before it).
    std::memcpy(static_cast<void*>(&in->params), &params, device_grid_ ? staged_param_bytes<T>() : sizeof(Params));
    std::memcpy(h_in_.as<unsigned char>() + align16(sizeof(Input<T>)), plan, plan_floats_ * sizeof(float));
    if (device_grid_) plan_obstacle_grid(x0, params, plan);
    // Messages are built only on failure: update() allocates nothing.
    if (use_graph_) {
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

  std::vector<float> rollout_costs() const override {
    std::vector<float> out(static_cast<std::size_t>(k_));
    check(cudaMemcpy(out.data(), d_cost_.as<float>(), out.size() * sizeof(float), cudaMemcpyDeviceToHost),
          what("cudaMemcpy of the rollout costs"));
    return out;
  }

  // Row 0 of the cost-to-go through a pinned staging buffer, only when asked (the display
  // sample of the cycle's rollouts): K floats, one copy on the update's stream.
  void step0_costs(float* out) const override {
    const std::size_t bytes = static_cast<std::size_t>(k_) * sizeof(float);
    cudaError_t e = cudaMemcpyAsync(h_costs_.as<void>(), d_cost_.as<void>(), bytes, cudaMemcpyDeviceToHost, stream_.get());
    if (e == cudaSuccess) e = cudaStreamSynchronize(stream_.get());
    if (e != cudaSuccess) fail(e, what("the copy of the step-0 costs"));
    std::memcpy(out, h_costs_.as<void>(), bytes);
  }

  std::size_t host_bytes() const override { return h_in_.bytes() + h_out_.bytes() + h_costs_.bytes(); }
  std::size_t device_bytes() const override {
    return d_cost_.bytes() + d_crashed_.bytes() + d_u_.bytes() + d_cc_.bytes() + d_pmin_.bytes() + d_part_.bytes() +
           d_stats_part_.bytes() + d_in_.bytes() + d_out_.bytes() + d_grid_lists_.bytes() + d_grid_counts_.bytes();
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

  // At most this much device memory for the stored controls (and at most 1/4 of the free).
  static constexpr std::size_t kNoiseBudgetMax = std::size_t{16} << 30;
  static constexpr int kReduceBlock = 256;
  static constexpr int kSampleBlock = 256;
  static constexpr std::size_t kKeepControlsMax = std::size_t{48} << 20;

  // The chunked rollout kernel of this task (single vehicle or team), controls kept or not.
  using ChunkedKernel = void (*)(const Input<T>*, const float*, float*, unsigned char*, float*, float*, StatsPart*,
                                 float*, int, int, int, float, int, float, int, SamplerConstants<kNu>);
  ChunkedKernel chunked_kernel() const {
    if constexpr (kTeam) return keep_u_ ? rollout_chunked_team<T, true> : rollout_chunked_team<T, false>;
    else return keep_u_ ? rollout_chunked<T, true> : rollout_chunked<T, false>;
  }

  // Calls f with the rollout kernel of this task, noise mode and lanes per rollout.
  template <class F>
  void with_rollout_kernel(F&& f) const {
    if constexpr (kTeam) {
      if (mode_ == NoiseMode::kPrepass) f(rollout_team<T, NoiseMode::kPrepass>);
      else f(rollout_team<T, NoiseMode::kInline>);
    } else if constexpr (kForestTask<T>) {
      switch (lanes_) {
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

  void check_launch_size(const cudaDeviceProp& prop) const {
    auto bad = [&](const std::string& why) {
      throw std::runtime_error("cuda backend: invalid launch size: " + why + " [K=" + std::to_string(k_) +
                               ", T=" + std::to_string(t_) + "]");
    };
    if (k_ < 1) bad("rollouts must be >= 1");
    if (t_ < 2) bad("horizon must be >= 2");
    if (chunked_ && chunk_blocks_ > prop.maxGridSize[0]) bad("chunked rollout grid exceeds the device limits");
    if (!chunked_ && rollout_grid_ > prop.maxGridSize[0]) bad("rollout grid of " + std::to_string(rollout_grid_) + " blocks exceeds " +
                                                std::to_string(prop.maxGridSize[0]));
    if (t_ > prop.maxGridSize[0] || chunks_ > prop.maxGridSize[1]) bad("weighting grid exceeds the device limits");
    if (mode_ == NoiseMode::kPrepass && t_ > prop.maxGridSize[1]) bad("noise pre-pass grid exceeds the device limits");
    if (rollout_smem_ > prop.sharedMemPerBlockOptin)
      bad("rollout kernel needs " + std::to_string(rollout_smem_) + " bytes of shared memory, the device allows " +
          std::to_string(prop.sharedMemPerBlockOptin));
  }

  // finalize_blocks for `parts` chunks or blocks per step, after the kernel that wrote them.
  void launch_finalize(cudaStream_t st, int parts, float* plan_out, DeviceStats* stats) {
    const float* d_plan = reinterpret_cast<const float*>(d_in_.as<unsigned char>() + align16(sizeof(Input<T>)));
    cudaLaunchAttribute attr;
    const cudaLaunchConfig_t cfg = launch_config(dim3(static_cast<unsigned>(t_)), dim3(kReduceBlock), 0, st, pdl_, &attr);
    const float* part = d_part_.as<float>();
    const StatsPart* stats_part = d_stats_part_.as<StatsPart>();
    const float* pmin = d_pmin_.as<float>();
    const int traj = trajectory_ ? 1 : 0;
    lazy_check(cudaLaunchKernelEx(&cfg, finalize_blocks<kNu>, d_plan, part, stats_part, pmin, parts, inv_lambda_, traj,
                                  plan_out, stats, c_),
               [&] { return what("launching the update kernel"); });
  }

  // The work of one cycle on the stream (captured once into the graph).
  void enqueue() {
    cudaStream_t st = stream_.get();
    const auto* d_in = d_in_.as<Input<T>>();
    const float* d_plan = reinterpret_cast<const float*>(d_in_.as<unsigned char>() + align16(sizeof(Input<T>)));
    float* d_plan_out = d_out_.as<float>();
    auto* d_stats = reinterpret_cast<DeviceStats*>(d_out_.as<unsigned char>() + align16(plan_floats_ * sizeof(float)));
    lazy_check(cudaMemcpyAsync(d_in_.as<void>(), h_in_.as<void>(), in_bytes_, cudaMemcpyHostToDevice, st),
               [&] { return what("cudaMemcpyAsync of the input"); });
    if constexpr (kForestTask<T>) {
      if (device_grid_) {
        auto* params = reinterpret_cast<unsigned char*>(d_in_.as<unsigned char>() + offsetof(Input<T>, params));
        using C = typename T::Cost::Params;
        const std::size_t cost_at = offsetof(Params, cost);
        lazy_check(enqueue_obstacle_grid(
                       st, reinterpret_cast<const ObstacleSet*>(params + cost_at + offsetof(C, obstacles)),
                       reinterpret_cast<const ObstacleGridLayout*>(d_in_.as<unsigned char>() + layout_offset_),
                       d_grid_lists_.as<std::uint8_t>(), d_grid_counts_.as<int>(),
                       reinterpret_cast<ObstacleGrid*>(params + cost_at + offsetof(C, obstacle_grid)), pdl_),
                   [&] { return what("launching the obstacle grid build"); });
      }
    }
    RolloutIo<kNu> io{nullptr, nullptr};
    if (mode_ == NoiseMode::kPrepass) {
      io.u_in = d_u_.as<float>();
      io.cc_in = d_cc_.as<float>();
      const dim3 sgrid(static_cast<unsigned>((k_ + kSampleBlock - 1) / kSampleBlock), static_cast<unsigned>(t_));
      sample<T><<<sgrid, kSampleBlock, 0, st>>>(d_in, d_plan, k_, d_u_.as<float>(), d_cc_.as<float>(), c_);
      lazy_check(cudaGetLastError(), [&] { return what("launching the noise pre-pass"); });
    }
    if (chunked_) {
      // Rollouts, costs and each block's weighted sums in one kernel; then the blocks combined.
      // Behind the device's obstacle grid, a programmatic dependent launch: the noise and the
      // first chunk's dynamics run while the grid is packed (griddep_wait before the costs).
      const int threads = 32 * chunk_warps_;
      cudaLaunchAttribute attr;
      const cudaLaunchConfig_t cfg = launch_config(dim3(static_cast<unsigned>(chunk_blocks_)),
                                                   dim3(static_cast<unsigned>(threads)), chunk_smem_, st,
                                                   pdl_ && device_grid_, &attr);
      float* u_keep = keep_u_ ? d_u_.as<float>() : nullptr;
      lazy_check(cudaLaunchKernelEx(&cfg, chunked_kernel(), d_in, d_plan, d_cost_.as<float>(),
                                    d_crashed_.as<unsigned char>(), d_pmin_.as<float>(), d_part_.as<float>(),
                                    d_stats_part_.as<StatsPart>(), u_keep, k_, t_, chunk_steps_, dt_, substeps_,
                                    inv_lambda_, trajectory_ ? 1 : 0, c_),
                 [&] { return what("launching the chunked rollout kernel"); });
      lazy_check(cudaGetLastError(), [&] {
        return what("launching the chunked rollout kernel (" + std::to_string(chunk_blocks_) + " blocks of " +
                    std::to_string(threads) + " threads, " + std::to_string(chunk_smem_) + " bytes shared)");
      });
      launch_finalize(st, static_cast<int>(chunk_blocks_), d_plan_out, d_stats);
    } else {
      const dim3 rgrid(static_cast<unsigned>(rollout_grid_));
      float* u_keep = keep_u_ && !kTeam ? d_u_.as<float>() : nullptr;
      with_rollout_kernel([&](auto kernel) {
        kernel<<<rgrid, rollout_block_, rollout_smem_, st>>>(d_in, d_plan, io, d_cost_.as<float>(),
                                                             d_crashed_.as<unsigned char>(), u_keep, k_, t_, dt_,
                                                             substeps_, c_);
      });
      lazy_check(cudaGetLastError(), [&] {
        return what("launching the rollout kernel (" + std::to_string(rollout_grid_) + " blocks of " +
                    std::to_string(rollout_block_) + " threads, " + std::to_string(rollout_smem_) + " bytes shared)");
      });
      const float* u_stored = mode_ == NoiseMode::kPrepass || (keep_u_ && !kTeam) ? d_u_.as<float>() : nullptr;
      weigh_local<T><<<dim3(static_cast<unsigned>(t_), static_cast<unsigned>(chunks_)), kReduceBlock, 0, st>>>(
          d_in, d_plan, u_stored, d_cost_.as<float>(), d_crashed_.as<unsigned char>(), k_, chunk_, inv_lambda_,
          trajectory_ ? 1 : 0, d_pmin_.as<float>(), d_part_.as<float>(), d_stats_part_.as<StatsPart>(), c_);
      lazy_check(cudaGetLastError(), [&] { return what("launching the weighting kernel"); });
      launch_finalize(st, chunks_, d_plan_out, d_stats);
    }
    lazy_check(cudaMemcpyAsync(h_out_.as<void>(), d_out_.as<void>(), out_bytes_, cudaMemcpyDeviceToHost, st),
               [&] { return what("cudaMemcpyAsync of the output"); });
  }

  void summarise(UpdateStats* stats, const float* plan) const {
    const auto& d = *reinterpret_cast<const DeviceStats*>(h_out_.as<unsigned char>() +
                                                          align16(plan_floats_ * sizeof(float)));
    stats->min_cost = d.min_cost;
    stats->mean_cost = d.finite > 0 ? d.sum_cost / static_cast<float>(d.finite) : kCostCeiling;
    // 1 / sum (w / sum w)^2 = (sum w)^2 / sum w^2
    stats->ess = d.sum_w2 > 0.0f ? d.sum_w * d.sum_w / d.sum_w2 : 0.0f;
    stats->crashed = d.crashed;
    stats->rollouts = k_;
    stats->partial = false;
    stats->updated = true;
    bool ok = ffinite(stats->ess);
    for (std::size_t n = 0; n < plan_floats_; ++n) ok = ok && ffinite(plan[n]);
    stats->finite = ok;
  }

  int k_, t_;
  float dt_;
  int substeps_;
  std::uint64_t seed_;
  float inv_lambda_ = 1.0f;
  bool trajectory_ = false;
  SamplerConstants<kNu> c_{};
  std::size_t plan_floats_ = 0;
  int device_ = 0;
  std::string device_name_;

  int rollout_block_ = 0;
  long long rollout_grid_ = 0;
  std::size_t rollout_smem_ = 0;
  int warps_per_block_ = 0;
  int chunk_ = 0, chunks_ = 0;

  std::size_t in_bytes_ = 0, out_bytes_ = 0;
  NoiseMode mode_ = NoiseMode::kInline;
  int lanes_ = 1;
  bool chunked_ = false;
  bool keep_u_ = false;
  int chunk_steps_ = 4, chunk_warps_ = 4;
  std::size_t chunk_smem_ = 0;
  long long chunk_blocks_ = 0;
  DeviceBuffer d_cost_, d_crashed_, d_u_, d_cc_, d_pmin_, d_part_, d_stats_part_, d_in_, d_out_;
  bool device_grid_ = false;       // forest tasks: the obstacle grid built on the device
  std::size_t layout_offset_ = 0;  // of the grid's layout in the per-cycle input
  std::vector<float> path_;        // the plan's path, xy per step and vehicle
  DeviceBuffer d_grid_lists_, d_grid_counts_;
  PinnedBuffer h_in_, h_out_, h_costs_;
  std::unique_ptr<CUstream_st, StreamDeleter> stream_;
  std::unique_ptr<CUgraph_st, GraphDeleter> graph_;
  std::unique_ptr<CUgraphExec_st, GraphExecDeleter> exec_;
  bool use_graph_ = true;
  bool pdl_ = false;
};

}  // namespace mppi::cuda_detail

namespace mppi {
template <class T>
std::unique_ptr<RolloutBackend<T>> make_cuda_backend(const MppiSettings& s) {
  return std::make_unique<cuda_detail::CudaBackend<T>>(s);
}
}  // namespace mppi

#define MPPI_CUDA_INSTANTIATE(T) \
  template std::unique_ptr<mppi::RolloutBackend<mppi::T>> mppi::make_cuda_backend<mppi::T>(const mppi::MppiSettings&);
