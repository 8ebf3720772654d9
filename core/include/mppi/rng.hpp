// Counter-based Gaussian noise keyed by (seed, cycle, sample, step): the CPU and CUDA
// backends draw the same numbers without sharing state, and a run replays bit for bit.
// Philox4x32-10 comes from Random123 (Debian librandom123-dev), which compiles under nvcc.
#pragma once

#include <Random123/philox.h>

#include "mppi/hd.hpp"

namespace mppi {

struct NoiseKey {
  std::uint64_t seed;
  std::uint32_t cycle;
};

// Four uniform-derived standard normals for block `block` of (sample, step). Channel c of a
// control vector uses block c / 4, lane c % 4.
MPPI_HD void gaussian4(const NoiseKey& key, std::uint32_t sample, std::uint32_t step,
                       std::uint32_t block, float out[4]) {
  r123::Philox4x32 gen;
  const r123::Philox4x32::ctr_type ctr = {{sample, step, key.cycle, block}};
  const r123::Philox4x32::key_type k = {
      {static_cast<std::uint32_t>(key.seed), static_cast<std::uint32_t>(key.seed >> 32)}};
  const r123::Philox4x32::ctr_type r = gen(ctr, k);
  constexpr float kTwoPi = 6.28318530717958647692f;
  constexpr float kInv32 = 2.3283064365386963e-10f;  // 2^-32
  for (int p = 0; p < 2; ++p) {
    // (r + 0.5) * 2^-32 lies in (0, 1): log never sees 0.
    const float u1 = (static_cast<float>(r[2 * p]) + 0.5f) * kInv32;
    const float u2 = (static_cast<float>(r[2 * p + 1]) + 0.5f) * kInv32;
    const float rad = fsqrt(-2.0f * flog(u1));
    out[2 * p] = rad * fcos(kTwoPi * u2);
    out[2 * p + 1] = rad * fsin(kTwoPi * u2);
  }
}

// Standard-normal noise for all NU channels of (sample, step).
template <int NU>
MPPI_HD void gaussian(const NoiseKey& key, std::uint32_t sample, std::uint32_t step, float out[NU]) {
  float buf[4];
  for (int b = 0; b * 4 < NU; ++b) {
    gaussian4(key, sample, step, static_cast<std::uint32_t>(b), buf);
    for (int l = 0; l < 4 && b * 4 + l < NU; ++l) out[b * 4 + l] = buf[l];
  }
}

}  // namespace mppi
