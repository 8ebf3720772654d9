// plan_launch (launch_plan.hpp): the CUDA backend's launch choices, pure. The measurements
// behind each choice are in gpu/NOTES.md.
#include "mppi/gpu/launch_plan.hpp"

#include <algorithm>
#include <string>

namespace mppi {
namespace {

using Settings = CudaSettings;

std::size_t align16(std::size_t n) { return (n + 15) / 16 * 16; }
long long ceil_div(long long a, long long b) { return (a + b - 1) / b; }

// The sizes the noise and controls choices weigh.
struct Sizes {
  long long k, t;
  std::size_t u_bytes, cc_bytes, budget;
};

Sizes sizes_of(const MppiSettings& s, const CudaTaskShape& task, const CudaDeviceLimits& device) {
  Sizes z{};
  z.k = s.rollouts;
  z.t = s.horizon;
  const std::size_t kt = static_cast<std::size_t>(s.rollouts) * static_cast<std::size_t>(s.horizon);
  z.u_bytes = kt * static_cast<std::size_t>(task.nu) * sizeof(float);
  z.cc_bytes = kt * sizeof(float);
  z.budget = std::min<std::size_t>(device.free_bytes / 4, kCudaNoiseBudgetMax);
  return z;
}

// Where the noise is drawn: a pre-pass for teams while its buffers fit in the budget. Single
// vehicles (chunked kernel) keep the controls for the update while they fit in about the L2
// cache; past that, drawing them again costs less than the memory traffic.
void plan_noise(const Sizes& z, bool team, const Settings& cuda, CudaLaunchPlan* p) {
  const bool prepass_fits = z.u_bytes + z.cc_bytes <= z.budget;
  p->prepass = team && prepass_fits;
  p->keep_controls = !team && z.u_bytes <= kCudaKeepControlsMax;
  if (cuda.noise == Settings::Noise::kPrepass && prepass_fits) p->prepass = true;
  if (cuda.noise == Settings::Noise::kInline) p->prepass = false;
  if (cuda.controls == Settings::Controls::kKeep && z.u_bytes <= z.budget) p->keep_controls = true;
  if (cuda.controls == Settings::Controls::kRedraw) p->keep_controls = false;
}

// The chunked kernel's steps a chunk (never past the horizon) and its shared memory; the
// kernel falls back to the lanes when that does not fit.
void fit_chunks(const Sizes& z, const CudaTaskShape& task, const CudaDeviceLimits& device, CudaLaunchPlan* p) {
  p->chunk_steps = std::min(p->chunk_steps, std::max(1, static_cast<int>(z.t)));
  p->chunk_smem = task.chunk_smem_bytes != nullptr ? task.chunk_smem_bytes(p->chunk_steps, static_cast<int>(z.t)) : 0;
  if (p->chunk_smem > device.shared_per_block_optin) p->chunked = false;
}

// Teams. The chunked team kernel (chunked_team.cuh) for teams of up to four vehicles (eight or
// more rollouts a block), or while its blocks are few (at most 4 a multiprocessor), when its
// shared memory fits; else the lane kernel (rollout_team). Measured on an H100 (gpu/NOTES.md,
// v6): team3 K = 1200 chunked ~100 us against lanes 222 us; team9 (three rollouts a block)
// K = 1024 chunked 342 us against lanes 735 us, but K = 6000 (2000 blocks) chunked 1.46-2.3 ms
// against lanes 1.12 ms.
void plan_team(const Sizes& z, const CudaTaskShape& task, const CudaDeviceLimits& device, const Settings& cuda,
               CudaLaunchPlan* p) {
  const long long sms = device.multiprocessors;
  p->chunk_blocks = ceil_div(z.k, task.chunk_rollouts);
  p->chunked = task.chunk_rollouts >= 8 || p->chunk_blocks <= 4 * sms;
  if (cuda.kernel != Settings::Kernel::kAuto) p->chunked = cuda.kernel == Settings::Kernel::kChunked;
  // Chunks of 20 steps with a multiprocessor for every block (team3 K = 1200 on an H100:
  // 97-99 us at 16-25 steps, 104-107 at 8 and 12, 112 at 6), else 8 (shared memory).
  p->chunk_steps = p->chunk_blocks <= sms ? 20 : 8;
  if (cuda.chunk_steps > 0) p->chunk_steps = cuda.chunk_steps;
  fit_chunks(z, task, device, p);
  // 16 warps while there is a multiprocessor for every block, 8 while two blocks share one, else 4.
  p->chunk_warps = p->chunk_blocks <= sms ? 16 : p->chunk_blocks <= 2 * sms ? 8 : 4;
  if (cuda.warps > 0) p->chunk_warps = std::clamp(cuda.warps, 1, kCudaTeamChunkMaxWarps);
  if (p->chunked) {
    // The chunked kernel draws the noise itself and keeps the controls for the update while
    // they fit in the noise budget.
    p->prepass = false;
    p->keep_controls = z.u_bytes <= z.budget && cuda.controls != Settings::Controls::kRedraw;
  }
  const long long per_warp = task.team_rollouts_per_warp;
  // One warp per block while that spreads the warps over more multiprocessors.
  p->warps_per_block = ceil_div(z.k, per_warp) <= 2 * sms ? 1 : 2;
  p->rollout_block = 32 * p->warps_per_block;
  p->rollout_grid = ceil_div(z.k, per_warp * p->warps_per_block);
  p->rollout_smem = align16(task.staged_param_bytes) +
                    task.team_rollout_bytes * static_cast<std::size_t>(per_warp * p->warps_per_block);
}

// Single vehicles. The chunked kernel while the lane kernel's one thread per rollout leaves
// the GPU short of warps (up to four blocks of 32 rollouts per multiprocessor); past that the
// lane kernel, whose threads then fill the GPU with less overhead a rollout. Measured on an
// H100 (gpu/NOTES.md): K = 16,384 chunked 187 us vs lanes 249 us; K = 65,536 lanes ~500 us vs
// chunked ~720 us; K = 1,048,576 lanes 6.9 ms vs chunked 10.1 ms.
void plan_single(const Sizes& z, const CudaTaskShape& task, const CudaDeviceLimits& device, const Settings& cuda,
                 CudaLaunchPlan* p) {
  const long long sms = device.multiprocessors;
  p->chunked = z.k <= 128 * sms;
  if (cuda.kernel != Settings::Kernel::kAuto) p->chunked = cuda.kernel != Settings::Kernel::kLanes;
  p->chunk_blocks = ceil_div(z.k, task.chunk_rollouts);
  // 8 warps while there is a multiprocessor for every block (the consumers are then the only
  // warps beside the producer), else 4 (four blocks a multiprocessor).
  p->chunk_warps = p->chunk_blocks <= sms ? 8 : 4;
  p->chunk_steps = 4;
  if (cuda.chunk_steps > 0) p->chunk_steps = cuda.chunk_steps;
  if (cuda.warps > 0) p->chunk_warps = std::clamp(cuda.warps, 1, kCudaChunkMaxWarps);
  fit_chunks(z, task, device, p);
  // The lane kernel keeps the controls while they fit in the noise budget: reading them back
  // costs less than drawing them again.
  if (!p->chunked) p->keep_controls = z.u_bytes <= z.budget && cuda.controls != Settings::Controls::kRedraw;
  // Lanes per rollout: up to about 8 warps per multiprocessor (forest tasks only). On an H100,
  // quadrotor_forest K=16384 took 403/339/363/576 us with G = 1/2/4/8 and K=4096
  // 380/290/240/240 us: past ~8 warps the G-fold repeated dynamics cost more issue slots than
  // the shorter obstacle loop saves.
  p->lanes = 1;
  if (task.forest) {
    while (p->lanes < 8 && z.k * p->lanes * 2 <= 256 * sms) p->lanes *= 2;
    if (cuda.lanes > 0) p->lanes = cuda.lanes;
  }
  // Small blocks while that spreads the rollouts over more multiprocessors: each thread runs
  // the whole horizon, so the latency of one rollout sets the time.
  const long long threads = z.k * p->lanes;
  p->rollout_block = 128;
  while (p->rollout_block > 32 && ceil_div(threads, p->rollout_block) < 4 * sms) p->rollout_block /= 2;
  p->rollout_grid = ceil_div(threads, p->rollout_block);
  p->rollout_smem = align16(task.staged_param_bytes);
}

// Chunks of rollouts per block of the weighting kernels: enough blocks to fill the device, at
// most 65535 chunks (grid.y).
void plan_weighting(const Sizes& z, CudaLaunchPlan* p) {
  long long chunk = kCudaReduceBlock * (z.k <= 65536 ? 4 : 16);
  while (ceil_div(z.k, chunk) > 65535) chunk *= 2;
  p->weigh_chunk = static_cast<int>(chunk);
  p->weigh_chunks = static_cast<int>(ceil_div(z.k, chunk));
}

// Why the launch cannot run on the device, or "".
std::string launch_error(const Sizes& z, const CudaDeviceLimits& device, const CudaLaunchPlan& p) {
  if (z.k < 1) return "rollouts must be >= 1";
  if (z.t < 2) return "horizon must be >= 2";
  if (p.chunked && p.chunk_blocks > device.max_grid_x) return "chunked rollout grid exceeds the device limits";
  if (!p.chunked && p.rollout_grid > device.max_grid_x)
    return "rollout grid of " + std::to_string(p.rollout_grid) + " blocks exceeds " + std::to_string(device.max_grid_x);
  if (z.t > device.max_grid_x || p.weigh_chunks > device.max_grid_y) return "weighting grid exceeds the device limits";
  if (p.prepass && z.t > device.max_grid_y) return "noise pre-pass grid exceeds the device limits";
  if (p.rollout_smem > device.shared_per_block_optin)
    return "rollout kernel needs " + std::to_string(p.rollout_smem) + " bytes of shared memory, the device allows " +
           std::to_string(device.shared_per_block_optin);
  return {};
}

std::string kib(std::size_t bytes) { return std::to_string((bytes + 512) / 1024) + " KiB"; }

}  // namespace

CudaLaunchPlan plan_launch(const MppiSettings& s, const CudaTaskShape& task, const CudaDeviceLimits& device,
                           const CudaSettings& cuda) {
  const Sizes z = sizes_of(s, task, device);
  CudaLaunchPlan p;
  const bool team = task.vehicles > 1;
  plan_noise(z, team, cuda, &p);
  if (team) plan_team(z, task, device, cuda, &p);
  else plan_single(z, task, device, cuda, &p);
  plan_weighting(z, &p);
  p.device_grid = task.forest && cuda.grid == CudaSettings::Grid::kDevice;
  // finalize_blocks (and the chunked kernels behind the device's grid) as programmatic
  // dependent launches from sm_90 on: launched while the kernel before runs, they wait on the device.
  p.pdl = cuda.pdl == CudaSettings::Switch::kAuto ? device.compute_major >= 9 : cuda.pdl == CudaSettings::Switch::kOn;
  p.graph = cuda.graph;
  p.error = launch_error(z, device, p);
  return p;
}

CudaLaunchPlan resize_launch(const CudaLaunchPlan& at_k, const CudaTaskShape& task, long long rollouts) {
  CudaLaunchPlan p = at_k;
  const long long n = std::max(1LL, rollouts);
  p.chunk_blocks = ceil_div(n, std::max(1, task.chunk_rollouts));
  if (task.vehicles > 1)
    p.rollout_grid = ceil_div(n, static_cast<long long>(std::max(1, task.team_rollouts_per_warp)) * p.warps_per_block);
  else
    p.rollout_grid = ceil_div(n * p.lanes, std::max(1, p.rollout_block));
  if (p.weigh_chunk > 0) p.weigh_chunks = static_cast<int>(ceil_div(n, p.weigh_chunk));
  return p;
}

const char* CudaLaunchPlan::kernel_name(const CudaTaskShape& task) const {
  if (task.vehicles > 1) return chunked ? "rollout_chunked_team" : "rollout_team";
  return chunked ? "rollout_chunked" : "rollout_single";
}

std::string describe(const CudaLaunchPlan& p, const CudaTaskShape& task) {
  std::string out = std::string("kernel ") + p.kernel_name(task);
  if (p.chunked) {
    out += " (" + std::to_string(p.chunk_blocks) + " blocks of " + std::to_string(32 * p.chunk_warps) + " threads, " +
           std::to_string(p.chunk_steps) + " steps a chunk, " + kib(p.chunk_smem) + " shared; weighing in the kernel)";
  } else {
    out += " (" + std::to_string(p.rollout_grid) + " blocks of " + std::to_string(p.rollout_block) + " threads";
    if (task.vehicles == 1) out += ", " + std::to_string(p.lanes) + (p.lanes == 1 ? " lane" : " lanes") + " a rollout";
    out += ", " + kib(p.rollout_smem) + " shared; weigh_local over " + std::to_string(p.weigh_chunks) + " chunks of " +
           std::to_string(p.weigh_chunk) + ")";
  }
  out += std::string(", noise ") + (p.prepass ? "pre-pass" : "inline") + ", controls " +
         (p.keep_controls ? "kept" : "drawn again") + " for the update";
  if (task.forest) out += std::string(", obstacle grid built on the ") + (p.device_grid ? "device" : "host");
  out += std::string(", PDL ") + (p.pdl ? "on" : "off") + ", graph " + (p.graph ? "on" : "off");
  return out;
}

}  // namespace mppi
