#include "mppi/rt/latency_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mppi::rt {

LatencyEstimator::LatencyEstimator(const LatencyEstimatorSettings& s)
    : s_(s),
      ring_(static_cast<std::size_t>(std::max(1, s.window))),
      scratch_(ring_.size()),
      estimate_(s.floor_ns + (s.ceiling_ns - s.floor_ns) / 2) {
  s_.window = static_cast<int>(ring_.size());
  s_.quantile = std::clamp(s.quantile, 1e-6, 1.0);
  if (s_.ceiling_ns < s_.floor_ns) s_.ceiling_ns = s_.floor_ns;
  estimate_ = std::clamp(estimate_, s_.floor_ns, s_.ceiling_ns);
}

bool LatencyEstimator::add(std::int64_t ns) {
  if (ns < 0 || ns > 10 * std::max<std::int64_t>(s_.ceiling_ns, 1)) {
    ++rejected_;
    return false;
  }
  ring_[static_cast<std::size_t>(count_ % s_.window)] = ns;
  ++count_;
  const auto n = static_cast<std::size_t>(std::min<std::int64_t>(count_, s_.window));
  std::copy_n(ring_.begin(), n, scratch_.begin());
  // The sample at rank ceil(q n) - 1 (q = 1: the maximum).
  const auto k = static_cast<std::size_t>(std::max(0.0, std::ceil(s_.quantile * static_cast<double>(n)) - 1.0));
  std::nth_element(scratch_.begin(), scratch_.begin() + static_cast<std::ptrdiff_t>(k),
                   scratch_.begin() + static_cast<std::ptrdiff_t>(n));
  estimate_ = std::clamp(scratch_[k], s_.floor_ns, s_.ceiling_ns);
  return true;
}

}  // namespace mppi::rt
