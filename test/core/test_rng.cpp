#include <cstdint>
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mppi/rng.hpp"

namespace mppi {
namespace {

// Known-answer vectors of Philox4x32-10 published with Random123 (kat_vectors).
TEST(Philox, KnownAnswers) {
  struct Kat {
    r123::Philox4x32::ctr_type ctr;
    r123::Philox4x32::key_type key;
    r123::Philox4x32::ctr_type expected;
  };
  const Kat kats[] = {
      {{{0u, 0u, 0u, 0u}}, {{0u, 0u}}, {{0x6627e8d5u, 0xe169c58du, 0xbc57ac4cu, 0x9b00dbd8u}}},
      {{{0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu}},
       {{0xffffffffu, 0xffffffffu}},
       {{0x408f276du, 0x41c83b0eu, 0xa20bc7c6u, 0x6d5451fdu}}},
      {{{0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u}},
       {{0xa4093822u, 0x299f31d0u}},
       {{0xd16cfe09u, 0x94fdccebu, 0x5001e420u, 0x24126ea1u}}},
  };
  r123::Philox4x32 gen;
  for (const Kat& kat : kats) {
    const auto r = gen(kat.ctr, kat.key);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(r[i], kat.expected[i]) << "word " << i << " of ctr " << kat.ctr[0];
  }
}

TEST(Noise, KeyedAndReproducible) {
  const NoiseKey key{42, 7};
  float a[8], b[8], c[8];
  gaussian<8>(key, 3, 5, a);
  gaussian<8>(key, 3, 5, b);
  gaussian<8>(NoiseKey{42, 8}, 3, 5, c);
  for (int i = 0; i < 8; ++i) {
    EXPECT_EQ(a[i], b[i]);
    EXPECT_NE(a[i], c[i]);
    EXPECT_TRUE(std::isfinite(a[i]));
  }
}

TEST(Noise, StandardNormalMoments) {
  const NoiseKey key{1, 0};
  double sum = 0.0, sq = 0.0, quart = 0.0;
  const int n = 200000;
  for (int s = 0; s < n / 4; ++s) {
    float v[4];
    gaussian<4>(key, static_cast<std::uint32_t>(s), 0, v);
    for (float xf : v) {
      const double x = xf;
      sum += x;
      sq += x * x;
      quart += x * x * x * x;
    }
  }
  const double mean = sum / n, var = sq / n - mean * mean;
  EXPECT_NEAR(mean, 0.0, 0.01);
  EXPECT_NEAR(var, 1.0, 0.01);
  EXPECT_NEAR(quart / n, 3.0, 0.06);
}

}  // namespace
}  // namespace mppi
