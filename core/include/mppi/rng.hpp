// Counter-based Gaussian noise keyed by (seed, cycle, sample, step): the CPU and CUDA
// backends draw the same numbers without sharing state, and a run replays bit for bit.
// Philox4x32-10 comes from Random123 (Debian librandom123-dev), which compiles under nvcc.
// A SIMD batch of samples runs the same ten rounds lane-wise (mppi/simd/lanes.hpp, tested
// bit-identical to Random123) and shares the Box-Muller transform below.
#pragma once

#include <Random123/philox.h>
#include <cstdint>

#include "mppi/hd.hpp"

namespace mppi {

struct NoiseKey {
  std::uint64_t seed;
  std::uint32_t cycle;
};

// The group of sample `sample` among `groups` (sample mod groups), as a float (a SIMD
// index type overloads this, lane-wise).
MPPI_HD float sample_group(std::uint32_t sample, std::uint32_t groups) { return static_cast<float>(sample % groups); }

// Philox4x32 constants (Salmon et al. 2011), as Random123 defines them.
constexpr std::uint32_t kPhiloxM0 = 0xD2511F53u, kPhiloxM1 = 0xCD9E8D57u;
constexpr std::uint32_t kPhiloxW0 = 0x9E3779B9u, kPhiloxW1 = 0xBB67AE85u;

// An unsigned 32-bit integer as the nearest float (a SIMD integer type overloads this).
MPPI_HD float u32_to_float(std::uint32_t r) { return static_cast<float>(r); }

// Box-Muller: four uniform 32-bit words to four standard normals. U is the word type
// (std::uint32_t, or a SIMD batch of them), V the number type.
template <class U, class V>
MPPI_HD void box_muller4(const U r[4], V out[4]) {
  constexpr float kTwoPi = 6.28318530717958647692f;
  constexpr float kInv32 = 2.3283064365386963e-10f;  // 2^-32
  for (int p = 0; p < 2; ++p) {
    // (r + 0.5) * 2^-32 lies in (0, 1): log never sees 0.
    const V u1 = (V(u32_to_float(r[2 * p])) + 0.5f) * kInv32;
    const V u2 = (V(u32_to_float(r[2 * p + 1])) + 0.5f) * kInv32;
    const V rad = fsqrt(-2.0f * flog(u1));
    V s, c;
    fsincos(kTwoPi * u2, &s, &c);
    out[2 * p] = rad * c;
    out[2 * p + 1] = rad * s;
  }
}

// Four uniform-derived standard normals for block `block` of (sample, step). Channel c of a
// control vector uses block c / 4, lane c % 4.
MPPI_HD void gaussian4(const NoiseKey& key, std::uint32_t sample, std::uint32_t step,
                       std::uint32_t block, float out[4]) {
  r123::Philox4x32 gen;
  const r123::Philox4x32::ctr_type ctr = {{sample, step, key.cycle, block}};
  const r123::Philox4x32::key_type k = {
      {static_cast<std::uint32_t>(key.seed), static_cast<std::uint32_t>(key.seed >> 32)}};
  const r123::Philox4x32::ctr_type r = gen(ctr, k);
  const std::uint32_t words[4] = {r[0], r[1], r[2], r[3]};
  box_muller4(words, out);
}

// Standard-normal noise for all NU channels of (sample, step). S is the sample index type
// (std::uint32_t, or a SIMD batch of indices with its own gaussian4), V the number type.
template <int NU, class S, class V>
MPPI_HD void gaussian(const NoiseKey& key, S sample, std::uint32_t step, V out[NU]) {
  V buf[4];
  for (int b = 0; b * 4 < NU; ++b) {
    gaussian4(key, sample, step, static_cast<std::uint32_t>(b), buf);
    for (int l = 0; l < 4 && b * 4 + l < NU; ++l) out[b * 4 + l] = buf[l];
  }
}

}  // namespace mppi
