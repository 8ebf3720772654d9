// The anytime cycle: a stop flag read between chunks of rollouts. A stopped update is the
// update of the samples finished, bit for bit the update of a backend with that many
// rollouts; below min_rollouts the plan is left as it was and the optimizer sends the held
// plan. On the scalar code and on the SIMD target this CPU runs.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include "../core/fixtures.hpp"
#include "mppi/cpu_backend.hpp"
#include "mppi/optimizer.hpp"
#include "mppi/tasks.hpp"

namespace mppi {
namespace {

MppiSettings settings(const char* simd, int k, Weighting w = Weighting::kCostToGo) {
  MppiSettings s = testing::quadrotor_simd_settings(simd, k, w);
  s.chunk_rollouts = 64;
  s.min_rollouts = 64;
  return s;
}

std::vector<float> start_plan(const MppiSettings& s) {
  std::vector<float> plan(static_cast<std::size_t>(s.horizon) * 4);
  for (std::size_t n = 0; n < plan.size(); ++n) plan[n] = 3100.0f + 10.0f * static_cast<float>(n % 7);
  return plan;
}

// Sets the flag once `after` rollouts have finished.
struct StopAfter {
  std::atomic<bool>* flag;
  int after;
  int calls = 0;
  static void hook(void* self, int finished) {
    auto* s = static_cast<StopAfter*>(self);
    ++s->calls;
    if (finished >= s->after) s->flag->store(true);
  }
};

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

class Anytime : public ::testing::TestWithParam<const char*> {};

TEST_P(Anytime, StoppedAfterChunksEqualsTheUpdateOfThatManyRollouts) {
  for (Weighting w : {Weighting::kCostToGo, Weighting::kTrajectory}) {
    for (int chunks : {1, 2, 3}) {
      const MppiSettings full = settings(GetParam(), 256, w);
      CpuBackend<QuadrotorForest> stopped(full);
      std::atomic<bool> stop{false};
      StopAfter hook{&stop, 64 * chunks};
      stopped.set_stop_flag(&stop);
      stopped.set_chunk_hook(&StopAfter::hook, &hook);
      const MppiSettings small = settings(GetParam(), 64 * chunks, w);
      CpuBackend<QuadrotorForest> reference(small);
      ASSERT_STREQ(stopped.name(), reference.name());

      const auto p = testing::forest_with_two_trunks();
      const auto x = testing::cruising_state();
      std::vector<float> a = start_plan(full), b = a;
      UpdateStats sa, sb;
      stopped.update(x.data(), p, 5, a.data(), &sa);
      reference.update(x.data(), p, 5, b.data(), &sb);
      EXPECT_EQ(hook.calls, chunks);
      EXPECT_EQ(sa.rollouts, 64 * chunks);
      EXPECT_TRUE(sa.partial);
      EXPECT_TRUE(sa.updated);
      EXPECT_FALSE(sb.partial);
      EXPECT_EQ(sb.rollouts, 64 * chunks);
      EXPECT_TRUE(same_bits(a, b)) << GetParam() << " " << to_string(w) << " " << chunks << " chunks";
      EXPECT_NE(a, start_plan(full)) << "the update moved the plan";
      EXPECT_EQ(sa.ess, sb.ess);
      EXPECT_EQ(sa.min_cost, sb.min_cost);
      EXPECT_EQ(sa.mean_cost, sb.mean_cost);
      EXPECT_EQ(sa.crashed, sb.crashed);
      const auto ca = stopped.rollout_costs(), cb = reference.rollout_costs();
      ASSERT_EQ(ca.size(), 256u);
      EXPECT_TRUE(same_bits(std::vector<float>(ca.begin(), ca.begin() + 64 * chunks), cb));
      // ... and differs from the full update.
      CpuBackend<QuadrotorForest> all(full);
      std::vector<float> c = start_plan(full);
      UpdateStats sc;
      all.update(x.data(), p, 5, c.data(), &sc);
      EXPECT_EQ(sc.rollouts, 256);
      EXPECT_FALSE(sc.partial);
      EXPECT_NE(a, c);
    }
  }
}

TEST_P(Anytime, AFlagThatStaysClearRunsEveryChunk) {
  const MppiSettings s = settings(GetParam(), 200);  // not a multiple of the chunk
  CpuBackend<QuadrotorForest> chunked(s), plain(s);
  std::atomic<bool> stop{false};
  chunked.set_stop_flag(&stop);
  const auto p = testing::forest_with_two_trunks();
  const auto x = testing::cruising_state();
  std::vector<float> a = start_plan(s), b = a;
  UpdateStats sa, sb;
  chunked.update(x.data(), p, 1, a.data(), &sa);
  plain.update(x.data(), p, 1, b.data(), &sb);
  EXPECT_EQ(sa.rollouts, 200);
  EXPECT_FALSE(sa.partial);
  EXPECT_TRUE(same_bits(a, b));
}

TEST_P(Anytime, BelowTheMinimumThePlanIsLeftAndTheHeldPlanGoesOut) {
  MppiSettings s = settings(GetParam(), 256);
  s.min_rollouts = 100;  // one chunk of 64 is not enough
  auto mppi = std::make_unique<Mppi<QuadrotorForest>>(s, std::make_unique<CpuBackend<QuadrotorForest>>(s));
  std::atomic<bool> stop{false};
  mppi->set_stop_flag(&stop);
  const auto p = testing::forest_with_two_trunks();
  const auto x = testing::cruising_state();
  const auto held = start_plan(s);
  float u[4];
  for (bool before : {true, false}) {
    mppi->set_plan(held);
    auto& backend = static_cast<CpuBackend<QuadrotorForest>&>(mppi->backend());
    StopAfter hook{&stop, 64};
    stop.store(before);  // set before the cycle: no rollout at all
    backend.set_chunk_hook(before ? nullptr : &StopAfter::hook, &hook);
    const UpdateStats st = mppi->iterate(x.data(), p, u);
    EXPECT_FALSE(st.updated);
    EXPECT_TRUE(st.partial);
    EXPECT_EQ(st.rollouts, before ? 0 : 64);
    for (int j = 0; j < 4; ++j) EXPECT_EQ(u[j], held[static_cast<std::size_t>(j)]) << "u_0 of the held plan";
    for (std::size_t n = 0; n + 4 < held.size(); ++n) EXPECT_EQ(mppi->plan()[n], held[n + 4]) << "shifted";
  }
  // At the minimum the update goes through.
  stop.store(false);
  s.min_rollouts = 64;
  CpuBackend<QuadrotorForest> b(s);
  StopAfter hook{&stop, 64};
  b.set_stop_flag(&stop);
  b.set_chunk_hook(&StopAfter::hook, &hook);
  std::vector<float> plan = held;
  UpdateStats st;
  b.update(x.data(), p, 0, plan.data(), &st);
  EXPECT_TRUE(st.updated);
  EXPECT_EQ(st.rollouts, 64);
  EXPECT_NE(plan, held);
}

// The daemon's path: no hook, so no barrier per chunk; the flag is raised by another thread
// (the deadline guard) whenever it comes. Whatever prefix K' the threads agreed on, the
// update is bit for bit the update of a K'-sample backend (K' a whole number of chunks).
TEST_P(Anytime, AStopFromAnotherThreadAnyTimeIsTheUpdateOfThePrefixFinished) {
  const auto p = testing::forest_with_two_trunks();
  const auto x = testing::cruising_state();
  int partial = 0;
  for (int delay_us : {0, 200, 500, 1000, 2000, 4000, 100000}) {
    const MppiSettings full = settings(GetParam(), 2048);
    CpuBackend<QuadrotorForest> stopped(full);
    std::atomic<bool> stop{false};
    stopped.set_stop_flag(&stop);
    std::vector<float> a = start_plan(full);
    UpdateStats sa;
    std::thread raiser([&] {
      std::this_thread::sleep_for(std::chrono::microseconds(delay_us));  // when the stop comes, not a check
      stop.store(true);
    });
    stopped.update(x.data(), p, 3, a.data(), &sa);
    raiser.join();
    ASSERT_EQ(sa.rollouts % 64, 0) << "a whole number of chunks";
    if (sa.rollouts < 64) {
      EXPECT_FALSE(sa.updated);
      EXPECT_TRUE(same_bits(a, start_plan(full))) << "no update: the plan is untouched";
      continue;
    }
    partial += sa.partial ? 1 : 0;
    const MppiSettings small = settings(GetParam(), sa.rollouts);
    CpuBackend<QuadrotorForest> reference(small);
    std::vector<float> b = start_plan(full);
    UpdateStats sb;
    reference.update(x.data(), p, 3, b.data(), &sb);
    EXPECT_EQ(sa.partial, sa.rollouts < 2048);
    EXPECT_TRUE(same_bits(a, b)) << GetParam() << ": stopped at " << sa.rollouts << " after " << delay_us << " us";
    EXPECT_EQ(sa.ess, sb.ess);
  }
  RecordProperty("partial_updates", partial);
}

INSTANTIATE_TEST_SUITE_P(ScalarAndSimd, Anytime, ::testing::Values("off", "auto"));

TEST(AnytimeSettings, DefaultsAndLimits) {
  MppiSettings s = testing::quadrotor_settings(1000, 30, 10.0f, 150.0f);
  EXPECT_EQ(resolved_chunk_rollouts(s), 128);  // K/8 = 125, up to a multiple of 16
  EXPECT_EQ(resolved_min_rollouts(s), 250);    // K/4
  s.chunk_rollouts = 100;
  s.min_rollouts = 10;
  EXPECT_EQ(resolved_chunk_rollouts(s), 100);
  EXPECT_EQ(resolved_min_rollouts(s), 10);
  EXPECT_EQ(validate(s, 4), "");
  s.min_rollouts = 1001;
  EXPECT_EQ(validate(s, 4), "min_rollouts: must lie in [0, rollouts]");
  s.min_rollouts = 0;
  s.chunk_rollouts = -1;
  EXPECT_EQ(validate(s, 4), "chunk_rollouts: must lie in [0, rollouts]");
}

}  // namespace
}  // namespace mppi
