#include "mppi/rt/histogram.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mppi::rt {

Histogram::Histogram(std::int64_t bin_ns, int bins)
    : bin_ns_(std::max<std::int64_t>(1, bin_ns)), counts_(static_cast<std::size_t>(std::max(1, bins)), 0) {}

void Histogram::add(std::int64_t ns) {
  if (ns < 0) ns = 0;
  const std::int64_t last = static_cast<std::int64_t>(counts_.size()) - 1;
  ++counts_[static_cast<std::size_t>(std::min(ns / bin_ns_, last))];
  if (count_ == 0 || ns < min_) min_ = ns;
  if (count_ == 0 || ns > max_) max_ = ns;
  sum_ += static_cast<double>(ns);
  ++count_;
}

void Histogram::clear() {
  std::fill(counts_.begin(), counts_.end(), 0);
  count_ = 0;
  min_ = max_ = 0;
  sum_ = 0.0;
}

std::int64_t Histogram::quantile_ns(double q) const {
  if (count_ == 0) return 0;
  const auto need = static_cast<std::int64_t>(std::ceil(q * static_cast<double>(count_)));
  std::int64_t seen = 0;
  for (std::size_t i = 0; i < counts_.size(); ++i) {
    seen += counts_[i];
    if (seen >= need) return std::clamp((static_cast<std::int64_t>(i) + 1) * bin_ns_, min_, max_);
  }
  return max_;
}

DurationSummary Histogram::summary() const {
  DurationSummary s;
  s.count = count_;
  if (count_ == 0) return s;
  s.min_ms = static_cast<double>(min_) * 1e-6;
  s.max_ms = static_cast<double>(max_) * 1e-6;
  s.mean_ms = sum_ / static_cast<double>(count_) * 1e-6;
  s.p99_ms = static_cast<double>(quantile_ns(0.99)) * 1e-6;
  return s;
}

}  // namespace mppi::rt
