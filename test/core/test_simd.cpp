// The CPU backend's SIMD targets against its scalar code, for every named task (so every
// model and cost), on every target this build compiles and this CPU runs:
//  - the noise: Philox words bit-identical to Random123; the integer-to-float conversion;
//  - one Euler step, the running and terminal costs and the crash bits of a batch of
//    samples: bit-identical to the scalar code with the C library's transcendentals in
//    every lane (the only difference the SIMD code may have), within kStepTolerance with
//    Highway's (as shipped);
//  - a whole update: bit-identical with the C library's transcendentals; with Highway's, the
//    tolerances of the CPU-GPU parity test (kCostTolerance for all but kDivergentFraction of
//    the rollouts, kPlanTolerance for the plan);
//  - determinism for any thread count on every target;
//  - the target selection and its errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/controller.hpp"
#include "mppi/costs/field_of_cylinders.hpp"
#include "mppi/cpu_backend.hpp"
#include "simd_probe.hpp"
#include "task_cases.hpp"
#include "tolerances.hpp"

namespace mppi {
namespace {
// A machine without a SIMD target leaves these tests nothing to compare. An x86-64 machine
// always has one (SSE4 at least), so there it is a failure; elsewhere (an Armv8-A core without
// AES, which Highway's NEON target needs) a skip: the scalar path is core_tests'.
#if defined(__x86_64__)
#define NO_SIMD_TARGET_HERE() FAIL() << "no SIMD target on an x86-64 machine (SSE4 at least is expected)"
#else
#define NO_SIMD_TARGET_HERE() GTEST_SKIP() << "no SIMD target on this machine (no NEON without AES); scalar: core_tests"
#endif


using testing::controller;
using testing::divergent_fraction;
using testing::for_each_simd_target;
using testing::for_each_task;
using testing::kCostTolerance;
using testing::kStepTolerance;
using testing::params_of;
using testing::plan_tolerance;
using testing::rel_error;
using testing::same_bits;
using testing::setup;
using testing::TaskSetup;

// ---------------------------------------------------------------------------------------
// Noise
// ---------------------------------------------------------------------------------------

TEST(SimdNoise, PhiloxWordsMatchRandom123AndGaussiansMatchTheScalarCode) {
  int targets = 0;
  for_each_simd_target([&](auto target) {
    ++targets;
    const testing::NoiseProbe& probe = *testing::noise_probe<target.value>();
    const int L = probe.lanes;
    EXPECT_EQ(L, simd::lanes(target.value));
    std::vector<std::uint32_t> words(4 * static_cast<std::size_t>(L));
    std::vector<float> exact(4 * static_cast<std::size_t>(L)), fast(4 * static_cast<std::size_t>(L));
    double worst = 0.0;
    for (const NoiseKey key : {NoiseKey{1, 0}, NoiseKey{0x123456789abcdefULL, 77}, NoiseKey{~0ULL, 0xffffffffu}}) {
      for (std::uint32_t k0 : {0u, 16u, 1000u, 0xfffffff8u}) {  // the last wraps past 2^32 in the lanes
        for (std::uint32_t step : {0u, 1u, 99u}) {
          for (std::uint32_t block : {0u, 2u}) {
            probe.philox(key, k0, step, block, words.data());
            probe.gaussian4(key, k0, step, block, exact.data(), true);
            probe.gaussian4(key, k0, step, block, fast.data(), false);
            for (int l = 0; l < L; ++l) {
              const std::uint32_t k = k0 + static_cast<std::uint32_t>(l);
              r123::Philox4x32 gen;
              const auto r = gen({{k, step, key.cycle, block}},
                                 {{static_cast<std::uint32_t>(key.seed), static_cast<std::uint32_t>(key.seed >> 32)}});
              float g[4];
              gaussian4(key, k, step, block, g);
              for (int w = 0; w < 4; ++w) {
                ASSERT_EQ(words[static_cast<std::size_t>(w * L + l)], r[w]) << simd::name(target.value) << " word " << w;
                ASSERT_TRUE(same_bits(exact[static_cast<std::size_t>(w * L + l)], g[w])) << simd::name(target.value);
                worst = std::max(worst, rel_error(fast[static_cast<std::size_t>(w * L + l)], g[w]));
              }
            }
          }
        }
      }
    }
    EXPECT_LT(worst, 1e-5) << simd::name(target.value) << ": Highway's log/sin/cos in Box-Muller";
  });
  if (targets == 0) NO_SIMD_TARGET_HERE();
}

TEST(SimdNoise, WordsConvertToTheNearestFloat) {
  for_each_simd_target([&](auto target) {
    const testing::NoiseProbe& probe = *testing::noise_probe<target.value>();
    const int L = probe.lanes;
    std::mt19937 rng(3);
    std::vector<std::uint32_t> in(static_cast<std::size_t>(L));
    std::vector<float> out(static_cast<std::size_t>(L));
    const std::uint32_t edges[] = {0u, 1u, 0xffffu, 0x10000u, 0xffffffu, 0x1000001u, 0x1000003u, 0x7fffffc0u,
                                   0x7fffffffu, 0x80000000u, 0xffffff7fu, 0xffffff80u, 0xffffffffu};
    for (int round = 0; round < 2000; ++round) {
      for (int l = 0; l < L; ++l)
        in[static_cast<std::size_t>(l)] = round < 13 ? edges[(round + l) % 13] : static_cast<std::uint32_t>(rng());
      probe.to_float(in.data(), out.data());
      for (int l = 0; l < L; ++l)
        ASSERT_TRUE(same_bits(out[static_cast<std::size_t>(l)], static_cast<float>(in[static_cast<std::size_t>(l)])))
            << in[static_cast<std::size_t>(l)];
    }
  });
}

// ---------------------------------------------------------------------------------------
// One step of every model and cost on a batch
// ---------------------------------------------------------------------------------------

// A batch of states around the scenario's start, spread wide enough to reach each model's
// branches (roll at +-90 degrees, tire saturation, the cart off its rail, the ground, the
// obstacles, a zero quaternion), controls inside the limits, random crash bits.
template <class T>
struct StepCase {
  std::vector<float> x, u;                 // lane-major: x[n * L + l]
  std::vector<std::uint32_t> crashed;      // per lane
};

template <class T>
StepCase<T> step_case(const TaskSetup& s, int lanes, std::mt19937& rng) {
  constexpr int NX = T::kNx, NU = T::kNu, VNX = T::kVehicleNx;
  using V = typename T::Vehicle;
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  StepCase<T> c;
  c.x.resize(static_cast<std::size_t>(NX * lanes));
  c.u.resize(static_cast<std::size_t>(NU * lanes));
  c.crashed.resize(static_cast<std::size_t>(lanes));
  for (int l = 0; l < lanes; ++l) {
    for (int n = 0; n < NX; ++n) {
      const float x0 = s.scenario.x0[static_cast<std::size_t>(n)];
      c.x[static_cast<std::size_t>(n * lanes + l)] = x0 + (1.0f + 0.5f * std::fabs(x0)) * unit(rng);
    }
    for (int j = 0; j < T::kVehicles; ++j) {
      const int base = j * VNX;
      auto at = [&](int n) -> float& { return c.x[static_cast<std::size_t>((base + n) * lanes + l)]; };
      if constexpr (std::is_same_v<V, Quadrotor> || std::is_same_v<V, QuadrotorRate>) {
        if (l % 2 == 0) at(2) -= s.scenario.x0[static_cast<std::size_t>(base + 2)] + 0.3f;  // z: some below the ground
        // Some lanes inside or near a cylinder, some vehicles of a team on top of each other.
        const auto& obs = s.scenario.inputs.obstacles;
        if (obs.count > 0 && l % 3 == 0) {
          const Cylinder& o = obs.items[(l / 3 + j) % obs.count];
          at(0) = o.x + (o.radius + 0.3f) * unit(rng);
          at(1) = o.y + (o.radius + 0.3f) * unit(rng);
        }
        if (j > 0 && l % 4 == 3)
          for (int n = 0; n < 3; ++n) at(n) = c.x[static_cast<std::size_t>(n * lanes + l)] + 0.1f * unit(rng);
      }
      if constexpr (std::is_same_v<V, Quadrotor>) {
        if (l % 4 == 1) at(Quadrotor::ROLL) = (l % 8 == 1 ? 1.0f : -1.0f) * 1.5707964f;  // cos(roll) ~ 0
        at(Quadrotor::YAW) *= 3.0f;
      } else if constexpr (std::is_same_v<V, QuadrotorRate>) {
        if (l % 5 == 2)
          for (int q = QuadrotorRate::QW; q <= QuadrotorRate::QZ; ++q) at(q) = 0.0f;  // a zero quaternion
      } else if constexpr (std::is_same_v<V, Racecar>) {
        at(Racecar::BETA) *= 0.6f;  // both tire regimes
        at(Racecar::R) *= 4.0f;
      } else if constexpr (std::is_same_v<V, Cartpole>) {
        at(Cartpole::THETA) *= 4.0f;
        at(Cartpole::X) *= 2.0f;
      }
    }
    for (int j = 0; j < NU; ++j) {
      const float lo = s.cfg.mppi.u_min[static_cast<std::size_t>(j)], hi = s.cfg.mppi.u_max[static_cast<std::size_t>(j)];
      c.u[static_cast<std::size_t>(j * lanes + l)] = lo + (hi - lo) * 0.5f * (1.0f + unit(rng));
    }
    c.crashed[static_cast<std::size_t>(l)] = static_cast<std::uint32_t>(rng()) & ((1u << T::kVehicles) - 1u) &
                                             static_cast<std::uint32_t>(rng());  // about a quarter
  }
  return c;
}

template <class T>
void check_step(const char* name, simd::Target target, const testing::SimdProbe<T>& probe, const TaskSetup& s,
                const typename T::Params& p) {
  constexpr int NX = T::kNx, NU = T::kNu;
  const int L = probe.lanes;
  std::mt19937 rng(11);
  const float dt = s.cfg.mppi.dt;
  const int substeps = s.cfg.mppi.substeps;
  const float t = 0.5f;
  double worst_state = 0.0, worst_cost = 0.0;
  int crash_lanes = 0;
  for (int round = 0; round < 40; ++round) {
    const StepCase<T> c = step_case<T>(s, L, rng);
    std::vector<float> xe = c.x, xf = c.x;
    probe.advance(p, xe.data(), c.u.data(), dt, substeps, c.crashed.data(), true);
    probe.advance(p, xf.data(), c.u.data(), dt, substeps, c.crashed.data(), false);
    std::vector<float> qe(static_cast<std::size_t>(L)), pe(qe.size()), qf(qe.size()), pf(qe.size());
    std::vector<std::uint32_t> ce = c.crashed, cf = c.crashed;
    probe.running(p, xe.data(), t, qe.data(), pe.data(), ce.data(), true);
    probe.running(p, xf.data(), t, qf.data(), pf.data(), cf.data(), false);
    for (int l = 0; l < L; ++l) {
      float x[NX], u[NU];
      for (int n = 0; n < NX; ++n) x[n] = c.x[static_cast<std::size_t>(n * L + l)];
      for (int n = 0; n < NU; ++n) u[n] = c.u[static_cast<std::size_t>(n * L + l)];
      std::uint32_t crashed = c.crashed[static_cast<std::size_t>(l)];
      T::advance(p, x, u, dt, substeps, crashed);
      const float q = T::running(p, x, t, &crashed);
      const float phi = T::terminal(p, x);
      for (int n = 0; n < NX; ++n) {
        const float e = xe[static_cast<std::size_t>(n * L + l)];
        ASSERT_TRUE(same_bits(e, x[n])) << name << " " << simd::name(target) << " lane " << l << " state " << n
                                        << ": " << e << " vs " << x[n];
        const double err = rel_error(xf[static_cast<std::size_t>(n * L + l)], x[n]);
        if (std::isfinite(x[n])) worst_state = std::max(worst_state, err);
      }
      ASSERT_TRUE(same_bits(qe[static_cast<std::size_t>(l)], q)) << name << " " << simd::name(target) << " lane " << l;
      ASSERT_TRUE(same_bits(pe[static_cast<std::size_t>(l)], phi)) << name << " " << simd::name(target);
      ASSERT_EQ(ce[static_cast<std::size_t>(l)], crashed) << name << " " << simd::name(target) << " lane " << l;
      EXPECT_EQ(cf[static_cast<std::size_t>(l)], crashed) << name << " " << simd::name(target) << " lane " << l;
      if (std::isfinite(q)) worst_cost = std::max(worst_cost, rel_error(qf[static_cast<std::size_t>(l)], q));
      worst_cost = std::max(worst_cost, rel_error(pf[static_cast<std::size_t>(l)], phi));
      crash_lanes += crashed != c.crashed[static_cast<std::size_t>(l)];
    }
  }
  EXPECT_LT(worst_state, kStepTolerance) << name << " " << simd::name(target) << ": Highway's math, state";
  EXPECT_LT(worst_cost, kStepTolerance) << name << " " << simd::name(target) << ": Highway's math, cost";
  EXPECT_GT(crash_lanes, 0) << name << ": no lane crashed: the crash terms went untested";
}

// The exact field of the scenario's trees (2.5 m tall) over their bounding box and the start,
// 2 m around, from the ground up, in 0.25 m cells.
void field_around(const TaskSetup& s, DistanceFieldGrid* grid) {
  const ObstacleSet& obs = s.scenario.inputs.obstacles;
  float lo[2] = {s.scenario.x0[0], s.scenario.x0[1]}, hi[2] = {lo[0], lo[1]};
  for (int i = 0; i < obs.count; ++i) {
    lo[0] = std::min(lo[0], obs.items[i].x), hi[0] = std::max(hi[0], obs.items[i].x);
    lo[1] = std::min(lo[1], obs.items[i].y), hi[1] = std::max(hi[1], obs.items[i].y);
  }
  const float res = 0.25f, origin[3] = {lo[0] - 2.0f, lo[1] - 2.0f, 0.0f};
  const int nx = static_cast<int>((hi[0] - lo[0] + 4.0f) / res) + 1, ny = static_cast<int>((hi[1] - lo[1] + 4.0f) / res) + 1;
  ASSERT_TRUE(fill_from_cylinders(obs, 2.5f, origin, res, nx, ny, 16, 6.0f, grid)) << nx << " x " << ny;
}

TEST(SimdStep, EveryModelAndCostBitIdenticalWithLibmAndCloseWithHighway) {
  int checked = 0;
  for_each_task([&](auto named) {
    using T = typename decltype(named)::Task;
    const TaskSetup s = setup(named.name, 64, 20);
    auto p = params_of<T>(s);
    if constexpr (std::is_same_v<typename T::Cost, SwingupCost>) {
      p.cost.track_limit = 1.5f;  // off by default: on here, so the crash term is tested
      p.cost.w_crash = 50.0f;
    }
    if constexpr (std::is_same_v<typename T::Cost, EllipseCost>) {
      p.cost.track_limit = 0.05f;  // off by default: on here (tight), so the crash, edge and drift terms are tested
      p.cost.w_crash = 50.0f;
      p.cost.edge = 0.02f;
      p.cost.w_edge = 200.0f;
      p.cost.line = 0.01f;
      p.cost.drift = 0.05f;
      p.cost.w_drift = 10.0f;
      p.cost.w_line = 5.0f;
    }
    // The forest tasks run the culled search (a grid from a straight path) in the batch and
    // the full scan in the scalar code: the same distances.
    if constexpr (T::kUsesPath) {
      p.cost.obstacles = s.scenario.inputs.obstacles;
      std::vector<float> path;
      for (int i = 0; i <= 20; ++i) {
        path.push_back(s.scenario.x0[0] + 0.5f * static_cast<float>(i));
        path.push_back(s.scenario.x0[1]);
      }
      auto culled = p;
      culled.cost.obstacle_grid.build(culled.cost.obstacles, path.data(), 21, 1.0f, 4.0f, 1.0f);
      ASSERT_GT(culled.cost.obstacle_grid.nx, 0);
      // And with a distance field (the same trees, 2.5 m tall, at 0.25 m) beside the
      // cylinders: the lanes read it through their gathers, the scalar code cell by cell.
      auto field = std::make_unique<DistanceFieldGrid>();
      field_around(s, field.get());
      auto sensed = culled;
      sensed.cost.field = field->view(1);
      sensed.cost.max_speed = 0.2f;  // and the speed limit (off by default), low enough to bite
      for_each_simd_target([&](auto target) {
        check_step<T>(named.name, target.value, *testing::simd_probe<T, target.value>(), s, culled);
        check_step<T>(named.name, target.value, *testing::simd_probe<T, target.value>(), s, sensed);
        ++checked;
      });
    } else {
      for_each_simd_target([&](auto target) {
        check_step<T>(named.name, target.value, *testing::simd_probe<T, target.value>(), s, p);
        ++checked;
      });
    }
  });
  if (checked == 0) NO_SIMD_TARGET_HERE();
}

// ---------------------------------------------------------------------------------------
// Whole updates
// ---------------------------------------------------------------------------------------

template <class T, simd::Target kTarget>
void check_update(const char* name) {
  constexpr simd::Target target = kTarget;
  // Teams: as many rollouts as the parity test's, the divergent fraction is a fraction of
  // many (any of M vehicles may cross a threshold).
  const TaskSetup s = setup(name, T::kVehicles > 1 ? 1024 : 256, 50);
  for (Weighting w : {Weighting::kCostToGo, Weighting::kTrajectory}) {
    TaskSetup sw = s;
    sw.cfg.mppi.weighting = w;
    auto scalar = controller<T>(sw, std::make_unique<CpuBackend<T>>(sw.cfg.mppi));
    auto exact = controller<T>(
        sw, std::make_unique<CpuBackend<T>>(sw.cfg.mppi, *testing::exact_kernel_ops<T, kTarget>(), "exact"));
    MppiSettings fs = sw.cfg.mppi;
    fs.simd = simd::name(target);
    auto fast = controller<T>(sw, std::make_unique<CpuBackend<T>>(fs));
    EXPECT_EQ(std::string(fast->backend()), std::string("cpu-") + simd::name(target));
    const std::vector<float> x0 = s.scenario.x0;
    std::vector<float> u(static_cast<std::size_t>(T::kNu));
    for (int cycle = 0; cycle < 3; ++cycle) {
      const std::vector<float> start = scalar->plan();
      fast->set_plan(start.data());
      const UpdateStats a = scalar->iterate(x0.data(), u.data());
      const UpdateStats b = exact->iterate(x0.data(), u.data());
      fast->iterate(x0.data(), u.data());
      ASSERT_EQ(scalar->plan().size(), exact->plan().size());
      for (std::size_t n = 0; n < scalar->plan().size(); ++n)
        ASSERT_TRUE(same_bits(scalar->plan()[n], exact->plan()[n]))
            << name << " " << simd::name(target) << " " << to_string(w) << " cycle " << cycle << " entry " << n;
      const auto ca = scalar->rollout_costs(), cb = exact->rollout_costs();
      for (std::size_t k = 0; k < ca.size(); ++k) ASSERT_TRUE(same_bits(ca[k], cb[k])) << name << " rollout " << k;
      EXPECT_TRUE(same_bits(a.ess, b.ess));
      EXPECT_TRUE(same_bits(a.min_cost, b.min_cost));
      EXPECT_TRUE(same_bits(a.mean_cost, b.mean_cost));
      EXPECT_EQ(a.crashed, b.crashed);
      // Highway's math, from the same plan.
      const auto cf = fast->rollout_costs();
      int over = 0;
      for (std::size_t k = 0; k < ca.size(); ++k) over += rel_error(cf[k], ca[k]) > kCostTolerance;
      EXPECT_LE(over, static_cast<int>(divergent_fraction<T>() * static_cast<double>(ca.size())))
          << name << " " << simd::name(target) << " " << to_string(w) << " cycle " << cycle;
      double worst = 0.0;
      for (std::size_t n = 0; n < start.size(); ++n)
        worst = std::max(worst, rel_error(fast->plan()[n], scalar->plan()[n]));
      EXPECT_LT(worst, plan_tolerance<T>()) << name << " " << simd::name(target) << " " << to_string(w) << " cycle " << cycle;
    }
  }
}

// One test per task, so that ctest runs them side by side (under emulation each takes long).
class SimdUpdate : public ::testing::TestWithParam<std::string> {};

TEST_P(SimdUpdate, BitIdenticalWithLibmAndWithinParityToleranceWithHighway) {
  int checked = 0;
  for_each_task([&](auto named) {
    using T = typename decltype(named)::Task;
    if (GetParam() != named.name) return;
    for_each_simd_target([&](auto target) {
      check_update<T, decltype(target)::value>(named.name);
      ++checked;
    });
  });
  if (checked == 0) NO_SIMD_TARGET_HERE();
}

INSTANTIATE_TEST_SUITE_P(EveryTask, SimdUpdate, ::testing::ValuesIn(testing::task_names()),
                         [](const ::testing::TestParamInfo<std::string>& task) { return task.param; });

// ---------------------------------------------------------------------------------------
// Determinism and selection
// ---------------------------------------------------------------------------------------

std::vector<float> plan_after(const std::string& simd, int threads) {
  TaskSetup s = setup("quadrotor_forest", 200, 40, threads);  // K not a multiple of 16
  s.cfg.mppi.simd = simd;
  auto c = controller<QuadrotorForest>(s, std::make_unique<CpuBackend<QuadrotorForest>>(s.cfg.mppi));
  std::vector<float> x = s.scenario.x0, u(4);
  for (int cycle = 0; cycle < 3; ++cycle) {
    c->iterate(x.data(), u.data());
    Quadrotor::step(c->params().vehicle, x.data(), u.data(), s.cfg.mppi.dt);
  }
  return c->plan();
}

TEST(SimdDeterminism, ThreadCountDoesNotChangeAnyBitOnAnyTarget) {
  std::vector<std::string> modes = {"off"};
  for_each_simd_target([&](auto target) { modes.push_back(simd::name(target.value)); });
  for (const auto& m : modes) {
    const auto one = plan_after(m, 1);
    EXPECT_EQ(one, plan_after(m, 2)) << m;
    EXPECT_EQ(one, plan_after(m, 3)) << m;
  }
}

TEST(SimdSelection, AutoOffAndNamedTargets) {
  MppiSettings s = setup("quadrotor_rate_track", 32, 10).cfg.mppi;
  s.simd = "off";
  EXPECT_STREQ(CpuBackend<RateQuadrotorTrack>(s).name(), "cpu");
  s.simd = "auto";
  const simd::Target best = simd::best();
  EXPECT_EQ(CpuBackend<RateQuadrotorTrack>(s).target(), best);
  EXPECT_EQ(std::string(CpuBackend<RateQuadrotorTrack>(s).name()),
            best == simd::Target::kScalar ? std::string("cpu") : std::string("cpu-") + simd::name(best));
  for_each_simd_target([&](auto target) {
    s.simd = simd::name(target.value);
    EXPECT_EQ(CpuBackend<RateQuadrotorTrack>(s).target(), target.value);
  });
  // A target that is not built or not supported here is refused, by name.
  for (simd::Target t : {simd::Target::kSse4, simd::Target::kAvx2, simd::Target::kAvx3, simd::Target::kNeon}) {
    if (simd::supported(t)) continue;
    s.simd = simd::name(t);
    try {
      CpuBackend<RateQuadrotorTrack> b(s);
      ADD_FAILURE() << "accepted " << simd::name(t);
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("simd: ") + simd::name(t)), std::string::npos) << e.what();
    }
  }
  s.simd = "avx9";
  EXPECT_NE(validate(s, 4).find("simd:"), std::string::npos);
  // A config file naming an unsupported target fails with the field's name.
  for (simd::Target t : {simd::Target::kSse4, simd::Target::kAvx2, simd::Target::kAvx3, simd::Target::kNeon}) {
    if (simd::supported(t)) continue;
    auto cfg = app::load_config(app::default_config_path("quadrotor_rate_track"),
                                {std::string("mppi.simd=") + simd::name(t), "backend=cpu"});
    try {
      app::make_controller(cfg);
      ADD_FAILURE() << "accepted " << simd::name(t);
    } catch (const app::ConfigError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("mppi.simd:", 0), 0u) << e.what();
    }
  }
}

}  // namespace
}  // namespace mppi
