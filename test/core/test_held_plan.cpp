// HeldPlan: the one shift-and-refill of the optimizer's warm start and the daemon's held
// plan (mppi/held_plan.hpp).
#include <gtest/gtest.h>

#include <vector>

#include "mppi/held_plan.hpp"

using mppi::HeldPlan;

namespace {

// A 4-step, 2-channel plan whose step i is (10 i, 10 i + 1); u_init (-1, -2).
HeldPlan numbered() {
  HeldPlan p(4, {-1.0f, -2.0f});
  p.assign({0.0f, 1.0f, 10.0f, 11.0f, 20.0f, 21.0f, 30.0f, 31.0f});
  return p;
}

TEST(HeldPlan, StartsAllUInit) {
  const HeldPlan p(3, {0.5f, 7.0f});
  EXPECT_EQ(p.horizon(), 3);
  EXPECT_EQ(p.nu(), 2);
  EXPECT_EQ(p.values(), (std::vector<float>{0.5f, 7.0f, 0.5f, 7.0f, 0.5f, 7.0f}));
}

TEST(HeldPlan, ShiftDropsStepsAndRefillsWithUInit) {
  struct Row {
    int steps;
    std::vector<float> expected;
  };
  const Row rows[] = {
      {0, {0, 1, 10, 11, 20, 21, 30, 31}},
      {1, {10, 11, 20, 21, 30, 31, -1, -2}},
      {3, {30, 31, -1, -2, -1, -2, -1, -2}},
      {4, {-1, -2, -1, -2, -1, -2, -1, -2}},
      {9, {-1, -2, -1, -2, -1, -2, -1, -2}},   // clamped to the horizon
      {-2, {0, 1, 10, 11, 20, 21, 30, 31}},    // time never runs back
  };
  for (const Row& r : rows) {
    HeldPlan p = numbered();
    p.shift(r.steps);
    EXPECT_EQ(p.values(), r.expected) << "shift(" << r.steps << ")";
  }
}

TEST(HeldPlan, StepPastTheEndIsUInit) {
  const HeldPlan p = numbered();
  EXPECT_EQ(p.step(2)[0], 20.0f);
  EXPECT_EQ(p.step(3)[1], 31.0f);
  EXPECT_EQ(p.step(4)[0], -1.0f);
  EXPECT_EQ(p.step(4)[1], -2.0f);
}

TEST(HeldPlan, SwapTakesAPlanOfAnotherHorizon) {
  HeldPlan p = numbered();
  std::vector<float> longer(12, 3.0f);
  p.swap(longer);
  EXPECT_EQ(p.horizon(), 6);
  EXPECT_EQ(longer.size(), 8u);  // the old buffer leaves with the other side
  p.shift(6);
  EXPECT_EQ(p.step(5)[1], -2.0f);
}

TEST(HeldPlan, ResetRefillsEveryStep) {
  HeldPlan p = numbered();
  p.reset();
  EXPECT_EQ(p.values(), (std::vector<float>{-1, -2, -1, -2, -1, -2, -1, -2}));
}

}  // namespace
