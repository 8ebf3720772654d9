// The plan's time: the plan the loop falls back on (the held plan), the optimizer's warm
// start (the controller's plan), and t0, the time on the loop's timeline at which step 0 of
// both acts. One owner for one invariant:
//
//   step 0 of the held plan and step 0 of the warm start both act at t0 (when timed).
//
// Every change to either plan or to t0 goes through one of the operations below, and each
// leaves the invariant true:
//   align(t_act)     time moved to t_act: both drop the steps that elapsed; t0 = t_act
//   detach()         no latency compensation: the plans are not tied to a time
//   advance()        one step went by without an update (stale state): both shift by one
//   iterate(x0, u)   one update: the warm start moves a step on (the optimizer shifts it), and
//                    so does the held plan, whose step for the old t0 is kept as due()
//   adopt()          the update is the plan to fall back on: held = warm start
//   revert()         the update is not trusted: the warm start restarts from the held plan
//   settle(outcome)  the cycle's outcome decides between the two: adopt() what was published
//                    or is good but late, revert() a bad or missing update
//   take_back(n, ok) the deadline guard flew n held steps through a stall: adopt() a good
//                    update, else drop those steps and restart the optimizer; untimed
//   restart()        start over (failsafe): the optimizer reset, held = its plan; untimed
//   rebase(...)      a live update swapped in another controller: both plans resampled
// The loop reaches either plan only through this class (the guard gets a copy of the held
// plan when armed). Unit-tested on its own in test/rt/test_plan_timeline.cpp. Loop thread
// only; allocates nothing after construction.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/cycle_outcome.hpp"
#include "mppi/held_plan.hpp"

namespace mppi::daemon {

class PlanTimeline {
 public:
  // The held plan starts as the controller's plan; untimed.
  explicit PlanTimeline(Controller* c);

  // Both plans shifted by the control steps between t0 and t_act (rounded, at most the
  // horizon), so step 0 is what acts at t_act; then t0 = t_act. Returns the steps dropped
  // (0 when untimed: t0 is just set).
  int align(std::int64_t t_act_ns);
  void detach() { timed_ = false; }
  // A step elapsed with no update: due() is the held plan's step for the old t0, both
  // plans then start a step later (the warm start through Controller::fallback).
  void advance();
  // One optimizer update into u_out (may throw: the held plan and t0 have moved on already,
  // and the caller revert()s). due() is the held step for the t0 before it. The update's
  // statistics stay as last_stats() (an update that threw leaves the last ones).
  const UpdateStats& iterate(const float* x0, float* u_out);
  void adopt() { held_.assign(c_->plan()); }
  void revert() { c_->set_plan(held_.data()); }
  void settle(Outcome o);
  // `steps` (>= 1) held steps went out from the guard's copy of the plan held before
  // iterate(); `good`: the update was good.
  void take_back(int steps, bool good);
  void restart();
  // A live update: `next` (which took the running controller's task state) replaces it;
  // both plans are resampled onto its horizon and dt (resample_plan), through `buffer`
  // (next's horizon x nu), which then carries the old held plan back. No allocation.
  void rebase(Controller* next, std::vector<float>& buffer);

  // The held step due at the last t0 (what a held command sends: after advance() or
  // iterate()).
  const float* due() const { return due_.data(); }
  const HeldPlan& held() const { return held_; }
  bool timed() const { return timed_; }
  std::int64_t t0_ns() const { return t0_ns_; }
  std::int64_t dt_ns() const { return dt_ns_; }
  const UpdateStats& last_stats() const { return stats_; }

 private:
  void step_on();  // due_ = held step 0; the held plan shifts by one; t0 += dt (timed)

  Controller* c_;
  HeldPlan held_;
  std::vector<float> due_;
  std::vector<float> scratch_;  // the warm start's fallback output (not sent)
  std::int64_t t0_ns_ = 0;
  bool timed_ = false;
  std::int64_t dt_ns_;
  UpdateStats stats_;
};

}  // namespace mppi::daemon
