// A plan held from one control cycle to the next: T control steps of nu channels, step 0
// the next command. Time moving on drops the first steps and refills the end with u_init
// (the warm start of Algorithm 1's last line). The optimizer holds its warm start in one;
// the daemon holds the plan it falls back on in another. This is the one shift of both.
#pragma once

#include <algorithm>
#include <cstddef>
#include <utility>
#include <vector>

namespace mppi {

class HeldPlan {
 public:
  HeldPlan() = default;
  // All steps u_init (nu = u_init.size() channels).
  HeldPlan(int horizon, std::vector<float> u_init)
      : u_init_(std::move(u_init)), values_(static_cast<std::size_t>(horizon) * u_init_.size()) {
    reset();
  }

  int nu() const { return static_cast<int>(u_init_.size()); }
  int horizon() const { return u_init_.empty() ? 0 : static_cast<int>(values_.size() / u_init_.size()); }

  // Step i's controls; past the end, u_init (what a shift would have put there).
  const float* step(int i) const {
    return i >= 0 && i < horizon() ? values_.data() + static_cast<std::size_t>(i) * u_init_.size() : u_init_.data();
  }

  // Drop the first `steps` controls and append u_init as often (clamped to [0, horizon]).
  void shift(int steps = 1) {
    steps = std::clamp(steps, 0, horizon());
    if (steps == 0) return;
    const auto used = static_cast<std::ptrdiff_t>(static_cast<std::size_t>(steps) * u_init_.size());
    std::copy(values_.begin() + used, values_.end(), values_.begin());
    fill_from(horizon() - steps);
  }

  void reset() { fill_from(0); }

  // What a shift appends from now on (nu floats; the values held stay as they are).
  void set_u_init(const float* u) { std::copy_n(u, u_init_.size(), u_init_.data()); }
  const std::vector<float>& u_init() const { return u_init_; }

  // A plan of the same length (copies, no allocation).
  void assign(const std::vector<float>& plan) { std::copy_n(plan.data(), values_.size(), values_.data()); }
  // Trade buffers with `other`: a plan of another horizon (a live update), or a scratch
  // buffer the new plan was written to (no allocation).
  void swap(std::vector<float>& other) { values_.swap(other); }

  float* data() { return values_.data(); }
  const float* data() const { return values_.data(); }
  std::size_t size() const { return values_.size(); }
  const std::vector<float>& values() const { return values_; }

 private:
  void fill_from(int first) {
    for (int i = first; i < horizon(); ++i)
      std::copy_n(u_init_.data(), u_init_.size(), values_.data() + static_cast<std::size_t>(i) * u_init_.size());
  }

  std::vector<float> u_init_;
  std::vector<float> values_;
};

}  // namespace mppi
