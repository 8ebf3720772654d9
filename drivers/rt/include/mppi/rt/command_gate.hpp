// The last check before a command leaves the process: every value finite and inside the
// per-channel limits. A command that fails is never published; the caller substitutes
// the held plan or the failsafe command, which pass through the gate too.
#pragma once

#include <cmath>
#include <vector>

namespace mppi::rt {

class CommandGate {
 public:
  CommandGate() = default;
  // Limits per control channel; a command of n values wraps around them (vehicle-major).
  CommandGate(std::vector<float> u_min, std::vector<float> u_max) : min_(std::move(u_min)), max_(std::move(u_max)) {}

  bool pass(const float* u, int n) const {
    const std::size_t m = min_.size();
    if (m == 0 || max_.size() != m || n <= 0) return false;
    for (int i = 0; i < n; ++i) {
      const float v = u[i];
      const std::size_t j = static_cast<std::size_t>(i) % m;
      if (!std::isfinite(v) || v < min_[j] || v > max_[j]) return false;
    }
    return true;
  }

  const std::vector<float>& u_min() const { return min_; }
  const std::vector<float>& u_max() const { return max_; }

 private:
  std::vector<float> min_, max_;
};

}  // namespace mppi::rt
