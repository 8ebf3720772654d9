// plan_launch (mppi/gpu/launch_plan.hpp) from tables: the CUDA backend's launch choices for
// the task sizes it flies and the `mppi.cuda` settings over them, on an H100's limits and on
// a smaller device. Plain C++: no CUDA runtime, no GPU (runs in CI).
#include <gtest/gtest.h>

#include <cstddef>
#include <string>
#include <vector>

#include "mppi/gpu/cuda_settings.hpp"
#include "mppi/gpu/launch_plan.hpp"

namespace mppi {
namespace {

// An H100 SXM: 132 multiprocessors, 227 KiB of shared memory a block, compute 9.0.
CudaDeviceLimits h100() {
  CudaDeviceLimits d;
  d.multiprocessors = 132;
  d.shared_per_block_optin = 232448;
  d.max_grid_x = 2147483647;
  d.max_grid_y = 65535;
  d.compute_major = 9;
  d.free_bytes = std::size_t{79} << 30;
  return d;
}

// A Jetson Orin-like device: 16 multiprocessors, 163 KiB a block, compute 8.7, 8 GiB free.
CudaDeviceLimits orin() {
  CudaDeviceLimits d = h100();
  d.multiprocessors = 16;
  d.shared_per_block_optin = 166912;
  d.compute_major = 8;
  d.free_bytes = std::size_t{8} << 30;
  return d;
}

// The chunked kernels' shared memory, of the layouts' form: a fixed part, a part per step of
// a chunk and the cost table (horizon x (R + 1) floats).
std::size_t single_smem(int steps, int horizon) {
  return 2048 + static_cast<std::size_t>(steps) * 32 * 4 * (2 * 20 + 3 * 4 + 4) + std::size_t(horizon) * 33 * 4;
}
std::size_t team3_smem(int steps, int horizon) {
  return 4096 + static_cast<std::size_t>(steps) * 10 * 4 * (2 * 3 * 20 + 3 * 12 + 3 + 12 + 6 + 1) +
         std::size_t(horizon) * 11 * 4;
}
std::size_t team9_smem(int steps, int horizon) {
  return 8192 + static_cast<std::size_t>(steps) * 3 * 4 * (2 * 9 * 20 + 3 * 36 + 3 + 36 + 45 + 1) +
         std::size_t(horizon) * 4 * 4;
}
std::size_t huge_smem(int, int) { return std::size_t{1} << 20; }

CudaTaskShape quadrotor_forest() {
  CudaTaskShape t;
  t.name = "quadrotor";
  t.nu = 4;
  t.forest = true;
  t.staged_param_bytes = 1200;
  t.chunk_smem_bytes = single_smem;
  return t;
}
CudaTaskShape quadrotor_track() {
  CudaTaskShape t = quadrotor_forest();
  t.forest = false;
  return t;
}
CudaTaskShape team(int vehicles) {
  CudaTaskShape t;
  t.name = "quadrotor";
  t.vehicles = vehicles;
  t.nu = 4 * vehicles;
  t.forest = true;
  t.chunk_rollouts = 32 / vehicles;
  t.team_rollouts_per_warp = 32 / vehicles;
  t.staged_param_bytes = 2400;
  t.team_rollout_bytes = 400 * static_cast<std::size_t>(vehicles);
  t.chunk_smem_bytes = vehicles == 3 ? team3_smem : team9_smem;
  return t;
}

MppiSettings sized(int k, int t) {
  MppiSettings s;
  s.rollouts = k;
  s.horizon = t;
  return s;
}

// One row: the task, K, T, device, settings, and what the plan must say.
struct Row {
  const char* what;
  CudaTaskShape task;
  int k, t;
  CudaDeviceLimits device;
  CudaSettings cuda;
  const char* kernel;
  long long blocks;  // chunk_blocks (chunked) or rollout_grid (lanes)
  int threads;       // a block
  int chunk_steps;   // chunked only (else ignored)
  int lanes;         // single-vehicle lanes only (else ignored)
  bool prepass, keep;
};

CudaSettings with(void (*f)(CudaSettings&)) {
  CudaSettings c;
  f(c);
  return c;
}

std::vector<Row> single_rows() {
  const CudaSettings none;
  return {
      // Single vehicles: chunked up to 128 rollouts a multiprocessor, 4 warps once the blocks
      // outnumber the multiprocessors (8 while not), 4 steps a chunk; the controls kept up to 48 MiB.
      {"quadrotor K=16384", quadrotor_forest(), 16384, 100, h100(), none, "rollout_chunked", 512, 128, 4, 1, false, true},
      {"quadrotor K=4096", quadrotor_forest(), 4096, 100, h100(), none, "rollout_chunked", 128, 256, 4, 1, false, true},
      {"quadrotor K=16896 (the last chunked)", quadrotor_forest(), 16896, 100, h100(), none, "rollout_chunked", 528, 128,
       4, 1, false, true},
      // Past that the lane kernel; at 1 M the controls (1.6 GB) are still within the 16 GiB budget.
      {"quadrotor K=1M", quadrotor_forest(), 1048576, 100, h100(), none, "rollout_single", 8192, 128, 0, 1, false, true},
      {"quadrotor K=65536", quadrotor_forest(), 65536, 100, h100(), none, "rollout_single", 1024, 64, 0, 1, false, true},
      // Lanes: doubled while K x lanes x 2 <= 256 x multiprocessors; small blocks spread them.
      {"quadrotor K=4096 lanes", quadrotor_forest(), 4096, 100, h100(),
       with([](CudaSettings& c) { c.kernel = CudaSettings::Kernel::kLanes; }), "rollout_single", 1024, 32, 0, 8, false,
       true},
      {"quadrotor K=16384 lanes", quadrotor_forest(), 16384, 100, h100(),
       with([](CudaSettings& c) { c.kernel = CudaSettings::Kernel::kLanes; }), "rollout_single", 1024, 32, 0, 2, false,
       true},
      {"quadrotor K=4096 lanes=2", quadrotor_forest(), 4096, 100, h100(),
       with([](CudaSettings& c) {
         c.kernel = CudaSettings::Kernel::kLanes;
         c.lanes = 2;
       }),
       "rollout_single", 256, 32, 0, 2, false, true},
      // No obstacle search: one lane whatever is asked.
      {"quadrotor_track K=4096 lanes=4", quadrotor_track(), 4096, 100, h100(),
       with([](CudaSettings& c) {
         c.kernel = CudaSettings::Kernel::kLanes;
         c.lanes = 4;
       }),
       "rollout_single", 128, 32, 0, 1, false, true},
      // The chunked kernel's shared memory past the device's: the lane kernel.
      {"single, chunks too big", [] { auto t = quadrotor_forest(); t.chunk_smem_bytes = huge_smem; return t; }(), 4096,
       100, h100(), none, "rollout_single", 1024, 32, 0, 8, false, true},
      // Settings: chunk steps (capped at the horizon), warps, the controls drawn again.
      {"quadrotor chunk=7 warps=2 redraw", quadrotor_forest(), 16384, 100, h100(),
       with([](CudaSettings& c) {
         c.chunk_steps = 7;
         c.warps = 2;
         c.controls = CudaSettings::Controls::kRedraw;
       }),
       "rollout_chunked", 512, 64, 7, 1, false, false},
      {"quadrotor chunk=500 at T=20", quadrotor_forest(), 16384, 20, h100(),
       with([](CudaSettings& c) { c.chunk_steps = 500; }), "rollout_chunked", 512, 128, 20, 1, false, true},
      // A whole horizon of 100 steps a chunk needs more shared memory than the device has.
      {"quadrotor chunk=100 at T=100", quadrotor_forest(), 16384, 100, h100(),
       with([](CudaSettings& c) { c.chunk_steps = 100; }), "rollout_single", 1024, 32, 0, 2, false, true},
      {"quadrotor K=262144 chunked keep", quadrotor_forest(), 262144, 100, h100(),
       with([](CudaSettings& c) {
         c.kernel = CudaSettings::Kernel::kChunked;
         c.controls = CudaSettings::Controls::kKeep;
       }),
       "rollout_chunked", 8192, 128, 4, 1, false, true},
      {"quadrotor K=262144 chunked", quadrotor_forest(), 262144, 100, h100(),
       with([](CudaSettings& c) { c.kernel = CudaSettings::Kernel::kChunked; }), "rollout_chunked", 8192, 128, 4, 1,
       false, false},
  };
}

std::vector<Row> team_rows() {
  const CudaSettings none;
  return {
      // Teams: team3 (10 rollouts a block) always chunked, 20 steps and 16 warps while every
      // block has a multiprocessor; team9 (3 a block) chunked while its blocks are at most 4 a
      // multiprocessor, else the lane kernel with the noise drawn by the pre-pass.
      {"team3 K=1200", team(3), 1200, 100, h100(), none, "rollout_chunked_team", 120, 512, 20, 0, false, true},
      {"team3 K=1200 T=50", team(3), 1200, 50, h100(), none, "rollout_chunked_team", 120, 512, 20, 0, false, true},
      {"team3 K=4000", team(3), 4000, 100, h100(), none, "rollout_chunked_team", 400, 128, 8, 0, false, true},
      {"team9 K=1024", team(9), 1024, 100, h100(), none, "rollout_chunked_team", 342, 128, 8, 0, false, true},
      {"team9 K=6000", team(9), 6000, 100, h100(), none, "rollout_team", 1000, 64, 0, 0, true, false},
      {"team9 K=600", team(9), 600, 100, h100(), none, "rollout_chunked_team", 200, 256, 8, 0, false, true},
      {"team9 K=6000 chunked, 7 steps, 2 warps, redraw", team(9), 6000, 100, h100(),
       with([](CudaSettings& c) {
         c.kernel = CudaSettings::Kernel::kChunked;
         c.chunk_steps = 7;
         c.warps = 2;
         c.controls = CudaSettings::Controls::kRedraw;
       }),
       "rollout_chunked_team", 2000, 64, 7, 0, false, false},
      {"team3 K=1200 lanes inline", team(3), 1200, 100, h100(),
       with([](CudaSettings& c) {
         c.kernel = CudaSettings::Kernel::kLanes;
         c.noise = CudaSettings::Noise::kInline;
       }),
       "rollout_team", 120, 32, 0, 0, false, false},
      {"team3 K=1200 lanes", team(3), 1200, 100, h100(),
       with([](CudaSettings& c) { c.kernel = CudaSettings::Kernel::kLanes; }), "rollout_team", 120, 32, 0, 0, true,
       false},
      // A device of 16 multiprocessors: the thresholds follow it.
      {"team9 K=1024 on 16 SMs", team(9), 1024, 100, orin(), none, "rollout_team", 171, 64, 0, 0, true, false},
  };
}

std::vector<Row> device_rows() {
  const CudaSettings none;
  return {
      {"quadrotor K=4096 on 16 SMs", quadrotor_forest(), 4096, 100, orin(), none, "rollout_single", 64, 64, 0, 1, false,
       true},
      {"quadrotor K=2048 on 16 SMs", quadrotor_forest(), 2048, 100, orin(), none, "rollout_chunked", 64, 128, 4, 1, false,
       true},
  };
}

std::vector<Row> rows() {
  std::vector<Row> all = single_rows();
  for (auto part : {team_rows(), device_rows()}) all.insert(all.end(), part.begin(), part.end());
  return all;
}

TEST(CudaLaunchPlan, Table) {
  for (const Row& r : rows()) {
    SCOPED_TRACE(r.what);
    const CudaLaunchPlan p = plan_launch(sized(r.k, r.t), r.task, r.device, r.cuda);
    EXPECT_EQ(p.error, "");
    EXPECT_STREQ(p.kernel_name(r.task), r.kernel);
    EXPECT_EQ(p.prepass, r.prepass);
    EXPECT_EQ(p.keep_controls, r.keep);
    if (p.chunked) {
      EXPECT_EQ(p.chunk_blocks, r.blocks);
      EXPECT_EQ(32 * p.chunk_warps, r.threads);
      EXPECT_EQ(p.chunk_steps, r.chunk_steps);
      EXPECT_EQ(p.chunk_smem, r.task.chunk_smem_bytes(p.chunk_steps, r.t));
      EXPECT_EQ(p.parts(), p.chunk_blocks);
    } else {
      EXPECT_EQ(p.rollout_grid, r.blocks);
      EXPECT_EQ(p.rollout_block, r.threads);
      if (r.task.vehicles == 1) {
        EXPECT_EQ(p.lanes, r.lanes);
      }
      EXPECT_EQ(p.parts(), p.weigh_chunks);
    }
  }
}

TEST(CudaLaunchPlan, TeamLaneKernelSharedMemoryHoldsItsRolloutsAndParameters) {
  // team9 K=6000: 2 warps a block (more than two warps' worth of blocks per multiprocessor).
  const CudaTaskShape t = team(9);
  const CudaLaunchPlan p = plan_launch(sized(6000, 100), t, h100(), {});
  EXPECT_EQ(p.warps_per_block, 2);
  EXPECT_EQ(p.rollout_smem, (t.staged_param_bytes + 15) / 16 * 16 + t.team_rollout_bytes * 3 * 2);
  // team9 K=600: one warp a block.
  EXPECT_EQ(plan_launch(sized(600, 100), t, h100(), with([](CudaSettings& c) {
              c.kernel = CudaSettings::Kernel::kLanes;
            })).warps_per_block,
            1);
}

TEST(CudaLaunchPlan, WeighingChunksFillTheDeviceWithinGridY) {
  struct {
    int k, chunk, chunks;
  } cases[] = {{4096, 1024, 4}, {65536, 1024, 64}, {65537, 4096, 17}, {1048576, 4096, 256}};
  for (const auto& c : cases) {
    const CudaLaunchPlan p = plan_launch(sized(c.k, 100), quadrotor_forest(), h100(), {});
    EXPECT_EQ(p.weigh_chunk, c.chunk) << "K=" << c.k;
    EXPECT_EQ(p.weigh_chunks, c.chunks) << "K=" << c.k;
  }
  // 2e9 rollouts: the chunk doubles until at most 65535 of them.
  const CudaLaunchPlan p = plan_launch(sized(2000000000, 100), team(9), h100(), {});
  EXPECT_LE(p.weigh_chunks, 65535);
  EXPECT_GE(static_cast<long long>(p.weigh_chunk) * p.weigh_chunks, 2000000000LL);
}

// The active rollout count (CudaBackend::set_active_rollouts): the launch at K with its counts
// for n. Every choice stays K's (the buffers were sized for them); the blocks and the weighting
// chunks cover exactly the n rollouts, and never need more partial sums than K's launch.
TEST(CudaLaunchPlan, ResizedLaunchKeepsTheChoicesAndCoversTheActiveRollouts) {
  struct {
    const char* what;
    CudaTaskShape task;
    int k;
    CudaSettings cuda;
  } cases[] = {{"single chunked", quadrotor_forest(), 4096, {}},
               {"single lanes", quadrotor_forest(), 100000, {}},
               {"single lanes past 65536", quadrotor_track(), 1048576, {}},
               {"team3 chunked", team(3), 1200, {}},
               {"team9 lanes", team(9), 6000, {}}};
  for (const auto& c : cases) {
    const CudaLaunchPlan at_k = plan_launch(sized(c.k, 100), c.task, h100(), c.cuda);
    ASSERT_TRUE(at_k.error.empty()) << c.what;
    EXPECT_EQ(resize_launch(at_k, c.task, c.k).parts(), at_k.parts()) << c.what;
    for (int n : {1, 31, 32, 33, c.k / 4, c.k / 2 + 7, c.k - 1}) {
      const CudaLaunchPlan p = resize_launch(at_k, c.task, n);
      const std::string at = std::string(c.what) + " K=" + std::to_string(c.k) + " n=" + std::to_string(n);
      EXPECT_EQ(p.chunked, at_k.chunked) << at;
      EXPECT_EQ(p.prepass, at_k.prepass) << at;
      EXPECT_EQ(p.keep_controls, at_k.keep_controls) << at;
      EXPECT_EQ(p.chunk_steps, at_k.chunk_steps) << at;
      EXPECT_EQ(p.chunk_warps, at_k.chunk_warps) << at;
      EXPECT_EQ(p.chunk_smem, at_k.chunk_smem) << at;
      EXPECT_EQ(p.lanes, at_k.lanes) << at;
      EXPECT_EQ(p.rollout_block, at_k.rollout_block) << at;
      EXPECT_EQ(p.weigh_chunk, at_k.weigh_chunk) << at;
      EXPECT_LE(p.parts(), at_k.parts()) << at;
      // The blocks hold the n rollouts, and one block fewer would not.
      const long long per_chunk_block = c.task.chunk_rollouts;
      EXPECT_GE(p.chunk_blocks * per_chunk_block, n) << at;
      EXPECT_LT((p.chunk_blocks - 1) * per_chunk_block, n) << at;
      const long long per_lane_block = c.task.vehicles > 1
                                           ? static_cast<long long>(c.task.team_rollouts_per_warp) * p.warps_per_block
                                           : p.rollout_block / p.lanes;
      EXPECT_GE(p.rollout_grid * per_lane_block, n) << at;
      EXPECT_GE(static_cast<long long>(p.weigh_chunks) * p.weigh_chunk, n) << at;
      EXPECT_LT(static_cast<long long>(p.weigh_chunks - 1) * p.weigh_chunk, n) << at;
    }
  }
}

TEST(CudaLaunchPlan, NoiseBudgetIsAQuarterOfTheFreeMemoryAtMost16GiB) {
  // team9 K=6000: 6000 x 100 x 37 floats = 89 MB of pre-pass buffers.
  CudaDeviceLimits small = h100();
  small.free_bytes = std::size_t{300} << 20;  // budget 75 MiB: no pre-pass
  EXPECT_FALSE(plan_launch(sized(6000, 100), team(9), small, {}).prepass);
  const CudaSettings prepass = with([](CudaSettings& c) { c.noise = CudaSettings::Noise::kPrepass; });
  EXPECT_FALSE(plan_launch(sized(6000, 100), team(9), small, prepass).prepass) << "asked for, but it does not fit";
  small.free_bytes = std::size_t{400} << 20;  // 100 MiB
  EXPECT_TRUE(plan_launch(sized(6000, 100), team(9), small, {}).prepass);
  EXPECT_FALSE(plan_launch(sized(6000, 100), team(9), small, with([](CudaSettings& c) {
                 c.noise = CudaSettings::Noise::kInline;
               })).prepass);
  // Single vehicles past 48 MiB of controls redraw them (chunked), unless told to keep them
  // and they fit the budget.
  const CudaSettings chunked = with([](CudaSettings& c) { c.kernel = CudaSettings::Kernel::kChunked; });
  EXPECT_FALSE(plan_launch(sized(32768, 100), quadrotor_forest(), h100(), chunked).keep_controls);  // 52 MB
  EXPECT_TRUE(plan_launch(sized(30000, 100), quadrotor_forest(), h100(), chunked).keep_controls);   // 48 MB
}

TEST(CudaLaunchPlan, ObstacleGridPdlAndGraph) {
  const CudaLaunchPlan forest = plan_launch(sized(4096, 100), quadrotor_forest(), h100(), {});
  EXPECT_TRUE(forest.device_grid);
  EXPECT_TRUE(forest.pdl);
  EXPECT_TRUE(forest.graph);
  EXPECT_FALSE(plan_launch(sized(4096, 100), quadrotor_track(), h100(), {}).device_grid);
  EXPECT_FALSE(plan_launch(sized(4096, 100), quadrotor_forest(), orin(), {}).pdl) << "compute 8: no PDL";
  const CudaLaunchPlan set = plan_launch(sized(4096, 100), quadrotor_forest(), orin(), with([](CudaSettings& c) {
                                           c.grid = CudaSettings::Grid::kHost;
                                           c.pdl = CudaSettings::Switch::kOn;
                                           c.graph = false;
                                         }));
  EXPECT_FALSE(set.device_grid);
  EXPECT_TRUE(set.pdl);
  EXPECT_FALSE(set.graph);
  EXPECT_FALSE(plan_launch(sized(4096, 100), quadrotor_forest(), h100(), with([](CudaSettings& c) {
                 c.pdl = CudaSettings::Switch::kOff;
               })).pdl);
}

TEST(CudaLaunchPlan, LaunchesTheDeviceCannotRunAreErrors) {
  EXPECT_EQ(plan_launch(sized(0, 100), quadrotor_forest(), h100(), {}).error, "rollouts must be >= 1");
  EXPECT_EQ(plan_launch(sized(1024, 1), quadrotor_forest(), h100(), {}).error, "horizon must be >= 2");
  CudaDeviceLimits tiny = h100();
  tiny.max_grid_x = 100;
  EXPECT_EQ(plan_launch(sized(1048576, 50), quadrotor_forest(), tiny, {}).error,
            "rollout grid of 8192 blocks exceeds 100");
  EXPECT_EQ(plan_launch(sized(16384, 50), quadrotor_forest(), tiny, {}).error,
            "chunked rollout grid exceeds the device limits");
  EXPECT_EQ(plan_launch(sized(1024, 200), quadrotor_forest(), tiny, {}).error,
            "weighting grid exceeds the device limits");
  CudaDeviceLimits no_shared = h100();
  no_shared.shared_per_block_optin = 1024;
  EXPECT_EQ(plan_launch(sized(1024, 100), quadrotor_forest(), no_shared, {}).error,
            "rollout kernel needs 1200 bytes of shared memory, the device allows 1024");
}

TEST(CudaLaunchPlan, DescribeNamesTheKernelAndItsShape) {
  const CudaTaskShape t = quadrotor_forest();
  const std::string chunked = describe(plan_launch(sized(16384, 100), t, h100(), {}), t);
  EXPECT_NE(chunked.find("kernel rollout_chunked (512 blocks of 128 threads, 4 steps a chunk"), std::string::npos)
      << chunked;
  EXPECT_NE(chunked.find("controls kept"), std::string::npos) << chunked;
  EXPECT_NE(chunked.find("obstacle grid built on the device, PDL on, graph on"), std::string::npos) << chunked;
  const std::string lanes = describe(plan_launch(sized(1048576, 100), t, h100(), {}), t);
  EXPECT_NE(lanes.find("kernel rollout_single (8192 blocks of 128 threads, 1 lane a rollout"), std::string::npos)
      << lanes;
  const CudaTaskShape t9 = team(9);
  const std::string team9 = describe(plan_launch(sized(6000, 100), t9, h100(), {}), t9);
  EXPECT_NE(team9.find("kernel rollout_team (1000 blocks of 64 threads"), std::string::npos) << team9;
  EXPECT_NE(team9.find("noise pre-pass"), std::string::npos) << team9;
}

TEST(CudaSettings, NamesRoundTripAndValidation) {
  CudaSettings s;
  EXPECT_EQ(describe(s),
            "kernel=auto chunk_steps=auto warps=auto noise=auto controls=auto lanes=auto grid=device pdl=auto graph=true");
  for (const char* k : {"auto", "chunked", "lanes"}) {
    ASSERT_TRUE(parse_cuda_setting(k, &s.kernel)) << k;
    EXPECT_STREQ(to_string(s.kernel), k);
  }
  EXPECT_FALSE(parse_cuda_setting("lane", &s.kernel));
  EXPECT_EQ(s.kernel, CudaSettings::Kernel::kLanes) << "untouched by a bad name";
  for (const char* v : {"auto", "on", "off"}) {
    ASSERT_TRUE(parse_cuda_setting(v, &s.pdl)) << v;
    EXPECT_STREQ(to_string(s.pdl), v);
  }
  EXPECT_EQ(validate(CudaSettings{}, 1), "");
  CudaSettings bad;
  bad.warps = 9;
  EXPECT_EQ(validate(bad, 1).rfind("warps: must be 1 to 8 for one vehicle", 0), 0u) << validate(bad, 1);
  EXPECT_EQ(validate(bad, 3), "");
  bad.warps = 17;
  EXPECT_EQ(validate(bad, 9).rfind("warps: must be 1 to 16 for a team", 0), 0u) << validate(bad, 9);
  bad = CudaSettings{};
  bad.lanes = 3;
  EXPECT_EQ(validate(bad, 1).rfind("lanes:", 0), 0u);
  bad = CudaSettings{};
  bad.chunk_steps = -1;
  EXPECT_EQ(validate(bad, 1).rfind("chunk_steps:", 0), 0u);
}

}  // namespace
}  // namespace mppi
