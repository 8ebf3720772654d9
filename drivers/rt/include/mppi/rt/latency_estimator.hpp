// The controller's expected latency: how long the next cycle will take from its start to
// its command leaving. A high quantile of the last `window` measured cycles, kept inside
// [floor, ceiling], so a burst of slow cycles raises it quickly and one outlier does not
// move it. Sized at construction; add() and estimate_ns() allocate nothing.
#pragma once

#include <cstdint>
#include <vector>

namespace mppi::rt {

struct LatencyEstimatorSettings {
  double quantile = 0.9;          // of the window, (0, 1]
  int window = 50;                // cycles
  std::int64_t floor_ns = 1'000'000;
  std::int64_t ceiling_ns = 20'000'000;
};

class LatencyEstimator {
 public:
  explicit LatencyEstimator(const LatencyEstimatorSettings& s);

  // One cycle's measured duration. Negative or longer than ten ceilings (the clock jumped,
  // or the process was stopped) is not a latency: it is ignored, counted, and false.
  bool add(std::int64_t ns);
  // The current estimate, always finite and inside [floor, ceiling]; before any
  // measurement, the middle of that range.
  std::int64_t estimate_ns() const { return estimate_; }
  std::int64_t samples() const { return count_; }
  std::int64_t rejected() const { return rejected_; }
  const LatencyEstimatorSettings& settings() const { return s_; }

 private:
  LatencyEstimatorSettings s_;
  std::vector<std::int64_t> ring_, scratch_;
  std::int64_t count_ = 0, rejected_ = 0;
  std::int64_t estimate_;
};

}  // namespace mppi::rt
