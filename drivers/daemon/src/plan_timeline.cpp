#include "mppi/daemon/plan_timeline.hpp"

#include <algorithm>
#include <cmath>

#include "mppi/daemon/live_optimizer.hpp"

namespace mppi::daemon {

namespace {
std::int64_t dt_ns_of(const Controller& c) { return std::llround(static_cast<double>(c.dt()) * 1e9); }
}  // namespace

PlanTimeline::PlanTimeline(Controller* c)
    : c_(c),
      held_(c->horizon(), c->settings().u_init),
      due_(c->settings().u_init),
      scratch_(static_cast<std::size_t>(c->nu())),
      dt_ns_(dt_ns_of(*c)) {
  held_.assign(c->plan());
}

int PlanTimeline::align(std::int64_t t_act_ns) {
  int n = 0;
  if (timed_ && dt_ns_ > 0) {
    const double steps = static_cast<double>(t_act_ns - t0_ns_) / static_cast<double>(dt_ns_);
    n = static_cast<int>(std::min<double>(std::floor(steps + 0.5), c_->horizon()));
    if (n > 0) {
      c_->shift(n);
      held_.shift(n);
    } else {
      n = 0;
    }
  }
  t0_ns_ = t_act_ns;
  timed_ = true;
  return n;
}

void PlanTimeline::step_on() {
  std::copy_n(held_.step(0), due_.size(), due_.data());
  held_.shift();
  if (timed_) t0_ns_ += dt_ns_;
}

void PlanTimeline::advance() {
  step_on();
  c_->fallback(scratch_.data());
}

const UpdateStats& PlanTimeline::iterate(const float* x0, float* u_out) {
  step_on();
  stats_ = c_->iterate(x0, u_out);
  return stats_;
}

void PlanTimeline::settle(Outcome o) {
  switch (o) {
    case Outcome::kFresh:
    case Outcome::kLate: adopt(); break;  // a late update is the plan to fall back on
    case Outcome::kBadUpdate:
    case Outcome::kAnytimeHold: revert(); break;  // it may hold NaN, or was not updated
    case Outcome::kFailsafe:
    case Outcome::kStale:
    case Outcome::kGuardCovered: break;  // restart(), advance(), take_back() moved them
  }
}

void PlanTimeline::take_back(int steps, bool good) {
  if (good) {
    adopt();
  } else {
    held_.shift(steps - 1);  // iterate() shifted it by one already
    c_->reset();
  }
  timed_ = false;  // the next fresh cycle starts the plan's timeline again
}

void PlanTimeline::restart() {
  c_->reset();
  held_.assign(c_->plan());
  timed_ = false;
}

void PlanTimeline::rebase(Controller* next, std::vector<float>& buffer) {
  const int t_old = c_->horizon(), t_new = next->horizon(), nu = c_->nu();
  const double dt_old = c_->dt(), dt_new = next->dt();
  const float* fill = held_.u_init().data();
  // The warm start through `buffer` as scratch, then the held plan into it.
  resample_plan(c_->plan().data(), t_old, dt_old, buffer.data(), t_new, dt_new, nu, fill);
  next->set_plan(buffer.data());
  resample_plan(held_.data(), t_old, dt_old, buffer.data(), t_new, dt_new, nu, fill);
  held_.swap(buffer);
  c_ = next;
  dt_ns_ = dt_ns_of(*next);
}

}  // namespace mppi::daemon
