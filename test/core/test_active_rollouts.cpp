// The active rollout count (RolloutBackend::set_active_rollouts, the daemon's work sizer): a
// backend of K running its first n samples is, bit for bit, a backend built with K = n; an
// optimizer that changes n between cycles carries only its plan and its noise counter, so its
// cycle is that of a fresh optimizer of n given that plan and counter. On the scalar code and
// on the SIMD target this CPU runs.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <memory>
#include <vector>

#include "../core/fixtures.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/optimizer.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

MppiSettings settings(const char* simd, int k, Weighting w = Weighting::kCostToGo) {
  return testing::quadrotor_simd_settings(simd, k, w);
}

std::vector<float> start_plan(const MppiSettings& s) {
  std::vector<float> plan(static_cast<std::size_t>(s.horizon) * 4);
  for (std::size_t n = 0; n < plan.size(); ++n) plan[n] = 3100.0f + 10.0f * static_cast<float>(n % 7);
  return plan;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

class ActiveRollouts : public ::testing::TestWithParam<const char*> {};

// Counts that fill whole SIMD batches and counts that do not (the last batch's extra lanes
// are real samples, kept out of every sum), under both weightings.
TEST_P(ActiveRollouts, AnUpdateOfTheFirstNIsTheUpdateOfABackendOfN) {
  const auto p = testing::forest_with_two_trunks();
  const auto x = testing::cruising_state();
  for (Weighting w : {Weighting::kCostToGo, Weighting::kTrajectory}) {
    for (int n : {1, 7, 16, 100, 255, 256}) {
      CpuBackend<QuadrotorForest> big(settings(GetParam(), 256, w));
      CpuBackend<QuadrotorForest> small(settings(GetParam(), n, w));
      EXPECT_EQ(big.set_active_rollouts(n), n);
      EXPECT_EQ(big.active_rollouts(), n);
      std::vector<float> a = start_plan(settings(GetParam(), 256)), b = a;
      UpdateStats sa, sb;
      big.update(x.data(), p, 9, a.data(), &sa);
      small.update(x.data(), p, 9, b.data(), &sb);
      const std::string at = std::string(GetParam()) + " " + to_string(w) + " n=" + std::to_string(n);
      EXPECT_TRUE(same_bits(a, b)) << at;
      EXPECT_TRUE(same_bits(big.rollout_costs(), small.rollout_costs())) << at;
      EXPECT_EQ(sa.rollouts, n) << at;
      EXPECT_FALSE(sa.partial) << at;
      EXPECT_TRUE(sa.updated) << at;
      EXPECT_EQ(sa.ess, sb.ess) << at;
      EXPECT_EQ(sa.min_cost, sb.min_cost) << at;
      EXPECT_EQ(sa.mean_cost, sb.mean_cost) << at;
      EXPECT_EQ(sa.crashed, sb.crashed) << at;
      if (n > 16) {
        EXPECT_NE(a, start_plan(settings(GetParam(), 256))) << at << ": the update moved the plan";
      }
    }
  }
}

// The count is clamped into [1, K] and a full run of the active rollouts updates the plan
// even below mppi.min_rollouts (which is for an update the anytime stop cut short).
TEST_P(ActiveRollouts, ClampedIntoOneToKAndAFullRunAlwaysUpdates) {
  MppiSettings s = settings(GetParam(), 256);
  s.min_rollouts = 128;
  CpuBackend<QuadrotorForest> b(s);
  EXPECT_EQ(b.set_active_rollouts(0), 1);
  EXPECT_EQ(b.set_active_rollouts(-5), 1);
  EXPECT_EQ(b.set_active_rollouts(1000), 256);
  EXPECT_EQ(b.active_rollouts(), 256);
  EXPECT_EQ(b.set_active_rollouts(64), 64);
  std::atomic<bool> stop{false};
  b.set_stop_flag(&stop);  // the anytime path, never stopped
  const auto p = testing::forest_with_two_trunks();
  const auto x = testing::cruising_state();
  std::vector<float> plan = start_plan(s);
  UpdateStats st;
  b.update(x.data(), p, 2, plan.data(), &st);
  EXPECT_TRUE(st.updated);
  EXPECT_FALSE(st.partial);
  EXPECT_EQ(st.rollouts, 64);
  EXPECT_NE(plan, start_plan(s));
  EXPECT_EQ(b.rollout_costs().size(), 64u);
}

// An optimizer of K whose count changes every cycle (down, up, back to K): each cycle is the
// cycle of a fresh optimizer of that count given the same plan and noise counter: the same
// command and the same plan after the shift, bit for bit. The plan and the noise go on.
TEST_P(ActiveRollouts, TheOptimizerCarriesOnlyItsPlanAndCounterAcrossAChange) {
  const auto p = testing::forest_with_two_trunks();
  std::vector<float> x = testing::cruising_state();
  MppiSettings s = settings(GetParam(), 512);
  s.smoothing_window = 3;
  Mppi<QuadrotorForest> sized(s, std::make_unique<CpuBackend<QuadrotorForest>>(s));
  std::vector<float> u(4), v(4);
  for (int n : {512, 128, 128, 48, 320, 512, 16, 512}) {
    MppiSettings fresh_s = s;
    fresh_s.rollouts = n;
    Mppi<QuadrotorForest> fresh(fresh_s, std::make_unique<CpuBackend<QuadrotorForest>>(fresh_s));
    fresh.set_plan(sized.plan());
    fresh.set_cycle(sized.cycle());
    EXPECT_EQ(sized.set_active_rollouts(n), n);
    const UpdateStats a = sized.iterate(x.data(), p, u.data());
    const UpdateStats b = fresh.iterate(x.data(), p, v.data());
    EXPECT_EQ(b.rollouts, n);
    const std::string at = std::string(GetParam()) + " n=" + std::to_string(n) + " cycle " + std::to_string(fresh.cycle());
    EXPECT_EQ(a.rollouts, n) << at;
    EXPECT_TRUE(same_bits(u, v)) << at;
    EXPECT_TRUE(same_bits(sized.plan(), fresh.plan())) << at;
    EXPECT_EQ(sized.cycle(), fresh.cycle()) << at;
    Quadrotor::step(p.vehicle, x.data(), u.data(), s.dt);
  }
}

INSTANTIATE_TEST_SUITE_P(ScalarAndSimd, ActiveRollouts, ::testing::Values("off", "auto"));

}  // namespace
}  // namespace mppi
