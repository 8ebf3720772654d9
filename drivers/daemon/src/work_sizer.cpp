#include "mppi/daemon/work_sizer.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "mppi/app/config.hpp"

namespace mppi::daemon {

namespace {

[[noreturn]] void fail(const std::string& field, const std::string& why) {
  throw app::ConfigError("daemon.work." + field + ": " + why);
}

std::string shown(double v) {
  std::string s = std::to_string(v);
  s.erase(s.find_last_not_of('0') + 1);
  if (!s.empty() && s.back() == '.') s.pop_back();
  return s;
}

double number(const YAML::Node& parent, const std::string& field, double def, double lo, double hi) {
  const YAML::Node n = parent[field];
  if (!n) return def;
  if (!n.IsScalar()) fail(field, "expected a number");
  double v = 0.0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    fail(field, "cannot read '" + n.Scalar() + "'");
  }
  if (!std::isfinite(v) || v < lo || v > hi)
    fail(field, "must be in [" + shown(lo) + ", " + shown(hi) + "], got " + n.Scalar());
  return v;
}

int whole(const YAML::Node& parent, const std::string& field, int def, int lo, int hi) {
  const double v = number(parent, field, def, lo, hi);
  if (v != std::floor(v)) fail(field, "must be a whole number, got " + parent[field].Scalar());
  return static_cast<int>(v);
}

// The 99th percentile's rank (1-based, ascending) among n samples.
int p99_rank(int n) { return (99 * n + 99) / 100; }

}  // namespace

void parse_work_settings(const YAML::Node& n, WorkSizerSettings* w) {
  if (!n.IsMap()) throw app::ConfigError("daemon.work: expected a map");
  const std::set<std::string> known{"enabled", "target", "grow_below", "floor", "window", "shrink", "grow"};
  for (const auto& kv : n) {
    if (!kv.first.IsScalar()) throw app::ConfigError("daemon.work: keys must be plain names");
    if (!known.count(kv.first.Scalar())) fail(kv.first.Scalar(), "unknown field");
  }
  if (const YAML::Node e = n["enabled"]) {
    try {
      w->enabled = e.as<bool>();
    } catch (const YAML::Exception&) {
      fail("enabled", "expected true or false, got '" + (e.IsScalar() ? e.Scalar() : std::string("a list or map")) + "'");
    }
  }
  w->target = number(n, "target", w->target, 0.01, 1.0);
  w->grow_below = number(n, "grow_below", w->grow_below, 0.001, 1.0);
  w->floor = whole(n, "floor", w->floor, 1, 1 << 26);
  w->window = whole(n, "window", w->window, 1, 100000);
  w->shrink = number(n, "shrink", w->shrink, 0.1, 0.95);
  w->grow = number(n, "grow", w->grow, 1.05, 4.0);
  // The grown count's compute must stay under the target, or a steady load would swing.
  if (w->grow_below * w->grow >= w->target)
    fail("grow_below", "must be below target / grow (" + shown(w->target / w->grow) + "), got " + shown(w->grow_below));
}

WorkSizer::WorkSizer(const WorkSizerSettings& s, std::int64_t period_ns)
    : s_(s),
      target_ns_(std::llround(s.target * static_cast<double>(period_ns))),
      grow_ns_(std::llround(s.grow_below * static_cast<double>(period_ns))),
      over_limit_(std::max(1, s.window) - p99_rank(std::max(1, s.window)) + 1),
      window_(static_cast<std::size_t>(std::max(1, s.window))),
      scratch_(window_.size()) {}

int WorkSizer::floor() const { return std::max(1, std::min(s_.floor, ceiling_)); }

void WorkSizer::follow_ceiling(int ceiling, int quantum) {
  quantum_ = quantum;
  if (ceiling == ceiling_) return;
  ceiling_ = ceiling;
  size_ = size_ == 0 ? ceiling : std::clamp(size_, floor(), ceiling);
  filled_ = over_ = high_ = 0;
}

void WorkSizer::before_update(Controller& c) {
  follow_ceiling(c.settings().rollouts, c.rollout_quantum());
  if (quantum_ == 0) return;  // no rollouts to size (DDP)
  const int want = pinned_ > 0 ? std::min(pinned_, ceiling_) : s_.enabled ? size_ : ceiling_;
  if (c.active_rollouts() != want) c.set_active_rollouts(want);
}

void WorkSizer::after_update(std::int64_t compute_ns) {
  if (!s_.enabled || pinned_ > 0 || ceiling_ == 0 || quantum_ == 0) return;
  window_[static_cast<std::size_t>(filled_++)] = compute_ns;
  if (compute_ns > target_ns_) ++over_;
  if (compute_ns >= grow_ns_) ++high_;
  // Enough samples over the target put the window's p99 over it, whatever the rest will be.
  if (over_ >= over_limit_) decide(true);
  else if (filled_ == static_cast<int>(window_.size())) decide(false);
}

std::int64_t WorkSizer::window_p99() {
  std::copy_n(window_.begin(), filled_, scratch_.begin());
  const auto nth = scratch_.begin() + (p99_rank(filled_) - 1);
  std::nth_element(scratch_.begin(), nth, scratch_.begin() + filled_);
  return *nth;
}

void WorkSizer::decide(bool over_target) {
  const std::int64_t p99 = window_p99();
  if (over_target) {
    const int q = std::max(1, quantum_);
    const int down = static_cast<int>(std::floor(size_ * s_.shrink / q)) * q;
    change_to(std::max(floor(), down), "over the target", p99, target_ns_);
  } else if (high_ < over_limit_) {
    const int q = std::max(1, quantum_);
    const int up = static_cast<int>(std::ceil(size_ * s_.grow / q)) * q;
    change_to(std::min(ceiling_, std::max(up, size_ + 1)), "below the growth bound", p99, grow_ns_);
  }
  filled_ = over_ = high_ = 0;  // a new window, at the new count
}

void WorkSizer::change_to(int n, const char* why, std::int64_t p99_ns, std::int64_t bound_ns) {
  if (n == size_) return;
  spdlog::info("work: {} -> {} rollouts (compute p99 {:.2f} ms over {} cycles, {} {:.2f} ms)", size_, n,
               static_cast<double>(p99_ns) / 1e6, filled_, why, static_cast<double>(bound_ns) / 1e6);
  size_ = n;
  ++changes_;
}

}  // namespace mppi::daemon
