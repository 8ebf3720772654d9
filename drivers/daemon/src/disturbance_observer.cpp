#include "mppi/daemon/disturbance_observer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mppi::daemon {

DisturbanceObserver::DisturbanceObserver(const DisturbanceSettings& s, int vehicles, int vehicle_nx, int vel)
    : s_(s),
      vehicles_(vehicles),
      vnx_(vehicle_nx),
      vel_(vel),
      prev_(static_cast<std::size_t>(vehicles * vehicle_nx)),
      pred_(prev_.size()) {}

void DisturbanceObserver::reset() {
  have_prev_ = false;
  std::fill(std::begin(est_), std::end(est_), 0.0f);
}

bool DisturbanceObserver::update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns) {
  bool changed = false;
  const std::int64_t gap = t_ns - t_prev_;
  if (have_prev_ && gap > 0 && gap <= s_.max_gap_ns) {
    std::copy(prev_.begin(), prev_.end(), pred_.begin());
    h.predict(c, pred_.data(), t_prev_, t_ns);
    const double dt = static_cast<double>(gap) * 1e-9;
    double r[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < vehicles_; ++j)
      for (int d = 0; d < 3; ++d) {
        const std::size_t i = static_cast<std::size_t>(j * vnx_ + vel_ + d);
        r[d] += (static_cast<double>(x[i]) - pred_[i]) / dt;
      }
    const double alpha = std::min(1.0, dt / std::max(1e-3, s_.time_constant_s));
    if (std::isfinite(r[0]) && std::isfinite(r[1]) && std::isfinite(r[2])) {
      for (int d = 0; d < 3; ++d) {
        const double next = est_[d] + alpha * r[d] / vehicles_;
        est_[d] = static_cast<float>(std::clamp(next, -static_cast<double>(s_.limit), static_cast<double>(s_.limit)));
      }
      ++updates_;
      changed = true;
    }
  }
  std::copy_n(x, prev_.size(), prev_.begin());
  t_prev_ = t_ns;
  have_prev_ = true;
  return changed;
}

}  // namespace mppi::daemon
