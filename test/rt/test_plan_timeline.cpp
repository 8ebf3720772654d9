// PlanTimeline on its own: a script of operations, one row each, and after every row the
// invariant checked: step 0 of the held plan and of the optimizer's warm start both act at
// t0. Each plan value says when it acts: 1000 + k acts at T0 + k dt (the scripted
// controller's updates write the same encoding), so "acts at t0" is "equals 1000 + (t0 - T0)
// / dt", and a plan that slipped a step shows as an off-by-one.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "fakes.hpp"
#include "mppi/daemon/plan_timeline.hpp"

using namespace mppi;
using mppi::test::FakeClock;
using mppi::test::FakeController;

namespace {

constexpr std::int64_t kDt = 20 * rt::kNsPerMs;  // FakeController's dt
constexpr std::int64_t kT0 = 5 * rt::kNsPerS;
constexpr float kInit = 3000.0f;                 // u_init: what a shift appends, what reset fills

enum class Op { kAlign, kDetach, kAdvance, kIterate, kIterateBad, kAdopt, kRevert, kTakeBackGood, kTakeBackBad, kRestart };

struct Row {
  const char* what;
  Op op;
  std::int64_t arg;  // align: t_act as (ns past T0); take_back: steps
  int result;        // align: the steps dropped
  bool timed;
  float held0, warm0;  // step 0 of each after the row (1000 + k: acts at T0 + k dt)
  float due;           // the held step due at the old t0 (advance, iterate); NaN: not checked
};

const float kNo = std::numeric_limits<float>::quiet_NaN();

// In order: each row starts from the plans the row before left.
const Row kScript[] = {
    {"first align: t0 set, nothing dropped", Op::kAlign, 0, 0, true, 1000, 1000, kNo},
    {"three steps later", Op::kAlign, 3 * kDt, 3, true, 1003, 1003, kNo},
    {"0.4 of a step later rounds to none", Op::kAlign, 3 * kDt + 8 * rt::kNsPerMs, 0, true, 1003, 1003, kNo},
    {"0.6 of a step after that rounds to one", Op::kAlign, 4 * kDt, 1, true, 1004, 1004, kNo},
    {"a stale cycle: both move a step on", Op::kAdvance, 0, 0, true, 1005, 1005, 1004},
    {"an update: the warm start moves on, the held plan with it", Op::kIterate, 0, 0, true, 1006, 1006, 1005},
    {"the update adopted", Op::kAdopt, 0, 0, true, 1006, 1006, kNo},
    {"a bad update: the warm start is garbage...", Op::kIterateBad, 0, 0, true, 1007, -1, 1006},
    {"... and restarts from the held plan", Op::kRevert, 0, 0, true, 1007, 1007, kNo},
    {"past the horizon (10): both all u_init", Op::kAlign, 30 * kDt, 10, true, kInit, kInit, kNo},
    {"start over", Op::kRestart, 0, 0, false, kInit, kInit, kNo},
    {"untimed: align only sets t0", Op::kAlign, 40 * kDt, 0, true, kInit, kInit, kNo},
    {"an update (the held plan is u_init still)", Op::kIterate, 0, 0, true, kInit, 1041, kInit},
    {"the guard flew 3 steps, the update good: adopted, untimed", Op::kTakeBackGood, 3, 0, false, 1041, 1041, kNo},
    {"re-timed", Op::kAlign, 41 * kDt, 0, true, 1041, 1041, kNo},
    {"an update", Op::kIterate, 0, 0, true, 1042, 1042, 1041},
    {"the guard flew 2 steps of a bad update: held drops them, the optimizer resets", Op::kTakeBackBad, 2, 0, false,
     1043, kInit, kNo},
    {"no latency compensation: untimed", Op::kDetach, 0, 0, false, 1043, kInit, kNo},
};

struct Rig {
  Rig() {
    std::vector<float> plan(40);
    for (int i = 0; i < 10; ++i)
      for (int j = 0; j < 4; ++j) plan[static_cast<std::size_t>(i * 4 + j)] = 1000.0f + static_cast<float>(i);
    ctl.set_plan(plan.data());
    // The update's plan acts from the t0 before it (iterate moved t0 a step on already).
    ctl.fault = [this](int, std::vector<float>* p, UpdateStats*) {
      const auto k = static_cast<float>((timeline->t0_ns() - kT0) / kDt - 1);
      for (std::size_t n = 0; n < p->size(); ++n) (*p)[n] = bad ? -1.0f : 1000.0f + k + static_cast<float>(n / 4);
      return false;
    };
  }
  FakeClock clock;
  FakeController ctl{&clock};
  daemon::PlanTimeline* timeline = nullptr;
  bool bad = false;
};

}  // namespace

TEST(PlanTimeline, KeepsStepZeroOfBothPlansAtT0) {
  Rig r;
  daemon::PlanTimeline t(&r.ctl);
  r.timeline = &t;
  EXPECT_FALSE(t.timed());
  EXPECT_FLOAT_EQ(t.held().step(0)[0], 1000.0f) << "the held plan starts as the controller's";
  const float x0[16] = {};
  float u[4];
  for (const Row& row : kScript) {
    SCOPED_TRACE(row.what);
    int result = 0;
    r.bad = row.op == Op::kIterateBad;
    switch (row.op) {
      case Op::kAlign: result = t.align(kT0 + row.arg); break;
      case Op::kDetach: t.detach(); break;
      case Op::kAdvance: t.advance(); break;
      case Op::kIterate:
      case Op::kIterateBad: t.iterate(x0, u); break;
      case Op::kAdopt: t.adopt(); break;
      case Op::kRevert: t.revert(); break;
      case Op::kTakeBackGood: t.take_back(static_cast<int>(row.arg), true); break;
      case Op::kTakeBackBad: t.take_back(static_cast<int>(row.arg), false); break;
      case Op::kRestart: t.restart(); break;
    }
    EXPECT_EQ(result, row.result);
    EXPECT_EQ(t.timed(), row.timed);
    EXPECT_FLOAT_EQ(t.held().step(0)[0], row.held0);
    EXPECT_FLOAT_EQ(r.ctl.plan()[0], row.warm0);
    if (!std::isnan(row.due)) {
      EXPECT_FLOAT_EQ(t.due()[0], row.due);
    }
    // The invariant: with a timed plan whose values are times, step 0 acts at t0.
    if (t.timed() && row.held0 != kInit && row.warm0 > 0.0f) {
      const std::int64_t k = (t.t0_ns() - kT0 + kDt / 2) / kDt;  // t0 on the grid, rounded
      EXPECT_FLOAT_EQ(row.held0, 1000.0f + static_cast<float>(k)) << "held plan off t0";
      EXPECT_FLOAT_EQ(row.warm0, 1000.0f + static_cast<float>(k)) << "warm start off t0";
    }
  }
}

// A live update: both plans onto the new controller's horizon and dt (here half the dt:
// each old step covers two new ones), t0 kept; the old held buffer comes back.
TEST(PlanTimeline, RebaseResamplesBothPlansOntoTheNewController) {
  Rig r;
  daemon::PlanTimeline t(&r.ctl);
  r.timeline = &t;
  t.align(kT0);
  FakeController next(&r.clock, 20);
  MppiSettings s = r.ctl.settings();
  s.horizon = 20;
  s.dt = 0.01f;
  next.use_settings(s);
  std::vector<float> buffer(80);
  t.rebase(&next, buffer);
  EXPECT_EQ(buffer.size(), 40u) << "the old held plan came back";
  EXPECT_EQ(t.dt_ns(), 10 * rt::kNsPerMs);
  EXPECT_EQ(t.t0_ns(), kT0);
  EXPECT_TRUE(t.timed());
  ASSERT_EQ(t.held().size(), 80u);
  for (int i = 0; i < 20; ++i) {
    EXPECT_FLOAT_EQ(t.held().step(i)[0], 1000.0f + static_cast<float>(i / 2)) << i;
    EXPECT_FLOAT_EQ(next.plan()[static_cast<std::size_t>(i * 4)], 1000.0f + static_cast<float>(i / 2)) << i;
  }
  // From now on the new controller's plan is the warm start.
  EXPECT_EQ(t.align(kT0 + 3 * 10 * rt::kNsPerMs), 3);
  EXPECT_FLOAT_EQ(next.plan()[0], 1001.0f);
  EXPECT_FLOAT_EQ(t.held().step(0)[0], 1001.0f);
}
