#include "mppi/daemon/delay_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace mppi::daemon {

DelayEstimator::DelayEstimator(const DelayEstimateSettings& s, int nx, std::vector<int> actuator_states)
    : s_(s),
      nx_(nx),
      idx_(std::move(actuator_states)),
      xs_(static_cast<std::size_t>((s.window + 1) * nx)),
      pred_(static_cast<std::size_t>(nx)),
      ts_(static_cast<std::size_t>(s.window + 1)) {}

// Summed squared error of the actuator states over the window's pairs, the commands acting
// later_ns later than recorded.
double DelayEstimator::error(const Controller& c, const CommandHistory& h, std::int64_t later_ns) {
  double sse = 0.0;
  for (int k = 0; k < s_.window; ++k) {
    const float* a = &xs_[static_cast<std::size_t>(k * nx_)];
    const float* b = a + nx_;
    const std::int64_t t0 = ts_[static_cast<std::size_t>(k)], t1 = ts_[static_cast<std::size_t>(k + 1)];
    if (t1 <= t0 || t1 - t0 > s_.max_gap_ns) continue;
    std::copy_n(a, nx_, pred_.begin());
    h.predict(c, pred_.data(), t0, t1, later_ns);
    for (int i : idx_) {
      const double e = static_cast<double>(b[i]) - pred_[static_cast<std::size_t>(i)];
      sse += e * e;
    }
  }
  return std::isfinite(sse) ? sse : std::numeric_limits<double>::infinity();
}

bool DelayEstimator::update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns,
                            std::int64_t current_ns) {
  if (!active()) return false;
  std::copy_n(x, nx_, &xs_[static_cast<std::size_t>(count_ * nx_)]);
  ts_[static_cast<std::size_t>(count_)] = t_ns;
  if (++count_ <= s_.window) return false;
  count_ = 0;
  const auto step = std::llround(s_.step_ms * 1e6), top = std::llround(s_.max_ms * 1e6);
  const double now = error(c, h, 0);
  double best = now;
  std::int64_t best_ns = current_ns;
  for (std::int64_t d = 0; d <= top; d += step) {
    if (d == current_ns) continue;
    const double e = error(c, h, d - current_ns);
    if (e < best) {
      best = e;
      best_ns = d;
    }
  }
  if (best_ns == current_ns || !(best < (1.0 - s_.min_gain) * now)) return false;
  delay_ns_ = best_ns;
  ++changes_;
  return true;
}

}  // namespace mppi::daemon
