// Fixed-bin histogram of durations with exact min/max/mean: percentiles without storing
// samples and without allocating after construction.
#pragma once

#include <cstdint>
#include <vector>

namespace mppi::rt {

struct DurationSummary {
  std::int64_t count = 0;
  double min_ms = 0.0, mean_ms = 0.0, max_ms = 0.0, p99_ms = 0.0;
};

class Histogram {
 public:
  // bins of bin_ns each; values past the last bin land in it (the max stays exact).
  Histogram(std::int64_t bin_ns, int bins);

  void add(std::int64_t ns);
  void clear();
  std::int64_t count() const { return count_; }
  // The q-quantile (0 < q <= 1), as the upper edge of its bin clamped to [min, max].
  std::int64_t quantile_ns(double q) const;
  DurationSummary summary() const;

 private:
  std::int64_t bin_ns_;
  std::vector<std::int64_t> counts_;
  std::int64_t count_ = 0;
  std::int64_t min_ = 0, max_ = 0;
  double sum_ = 0.0;
};

}  // namespace mppi::rt
