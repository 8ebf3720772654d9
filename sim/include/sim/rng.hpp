// Seeded random numbers for the simulator. The conversions to uniform and normal numbers are
// written here rather than taken from <random>'s distributions, whose output differs between
// standard libraries: a seed must name the same forest and the same gusts everywhere.
#pragma once

#include <cmath>
#include <cstdint>

namespace sim {

class Rng {
 public:
  // `stream` separates independent uses of one seed (forest, wind, noise, ...).
  explicit Rng(std::uint64_t seed, std::uint64_t stream = 0) : s_(seed * 0x9E3779B97F4A7C15ull ^ (stream + 1) * 0xD1B54A32D192ED03ull) {
    for (int i = 0; i < 4; ++i) next();
  }
  // splitmix64: small, fast, and statistically fine for a simulator.
  std::uint64_t next() {
    std::uint64_t z = (s_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Standard normal (Box-Muller, one value per call).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }

 private:
  std::uint64_t s_;
};

}  // namespace sim
