#include <cstdint>
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mppi/rng.hpp"

namespace mppi {
namespace {

// Known-answer vectors of Philox4x32-10 published with Random123 (kat_vectors).
TEST(Philox, KnownAnswers) {
  r123::Philox4x32 gen;
  {
    const r123::Philox4x32::ctr_type c = {{0u, 0u, 0u, 0u}};
    const r123::Philox4x32::key_type k = {{0u, 0u}};
    const auto r = gen(c, k);
    EXPECT_EQ(r[0], 0x6627e8d5u);
    EXPECT_EQ(r[1], 0xe169c58du);
    EXPECT_EQ(r[2], 0xbc57ac4cu);
    EXPECT_EQ(r[3], 0x9b00dbd8u);
  }
  {
    const r123::Philox4x32::ctr_type c = {{0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu}};
    const r123::Philox4x32::key_type k = {{0xffffffffu, 0xffffffffu}};
    const auto r = gen(c, k);
    EXPECT_EQ(r[0], 0x408f276du);
    EXPECT_EQ(r[1], 0x41c83b0eu);
    EXPECT_EQ(r[2], 0xa20bc7c6u);
    EXPECT_EQ(r[3], 0x6d5451fdu);
  }
  {
    const r123::Philox4x32::ctr_type c = {{0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u}};
    const r123::Philox4x32::key_type k = {{0xa4093822u, 0x299f31d0u}};
    const auto r = gen(c, k);
    EXPECT_EQ(r[0], 0xd16cfe09u);
    EXPECT_EQ(r[1], 0x94fdccebu);
    EXPECT_EQ(r[2], 0x5001e420u);
    EXPECT_EQ(r[3], 0x24126ea1u);
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
