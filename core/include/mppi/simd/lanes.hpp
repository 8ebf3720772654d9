// The SIMD number type: a batch of samples, one per lane of a Google Highway vector, with
// the operations of the number-type layer (hd.hpp), so that every model, cost, the sampler
// and the noise run on it unchanged. Only the per-target kernel translation units include
// this (core/src/simd/, each compiled with its target's instruction set); everything here
// lives in Highway's per-target namespace, so no two targets share a symbol.
//
// Exactness. +, -, *, /, sqrt, comparisons and selects are IEEE operations lane by lane,
// bit-identical to the scalar code (FMA contraction is off, -ffp-contract=off). The
// transcendentals are Highway's (hwy/contrib/math, within a few ulp of libm's) under
// HwyMath; under LibmMath every lane calls the C library as the scalar code does, which
// makes a batch bit-identical to the samples run one at a time (the tests use it).
#pragma once

#include <hwy/highway.h>
#include <hwy/contrib/math/math-inl.h>

#include <cstdint>

#include "mppi/hd.hpp"
#include "mppi/rng.hpp"

namespace mppi {
namespace HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using DF = hn::CappedTag<float, 16>;  // at most 16 lanes: the reductions' 16 partial sums
using DU = hn::RebindToUnsigned<DF>;
using DI = hn::RebindToSigned<DF>;
using DU64 = hn::RepartitionToWide<DU>;
using VecF = hn::Vec<DF>;
using VecU = hn::Vec<DU>;
constexpr int kLanes = static_cast<int>(hn::MaxLanes(DF()));
static_assert(16 % kLanes == 0, "the reductions assume 1, 2, 4, 8 or 16 lanes");

struct LaneMask {
  hn::Mask<DF> m;
  LaneMask() = default;
  LaneMask(bool b) : m(hn::FirstN(DF(), b ? static_cast<std::size_t>(kLanes) : 0u)) {}  // NOLINT: like bool
  explicit LaneMask(hn::Mask<DF> x) : m(x) {}
  friend LaneMask mask_and(LaneMask a, LaneMask b) { return LaneMask(hn::And(a.m, b.m)); }
  friend LaneMask mask_or(LaneMask a, LaneMask b) { return LaneMask(hn::Or(a.m, b.m)); }
  friend LaneMask mask_not(LaneMask a) { return LaneMask(hn::Not(a.m)); }
  friend bool any_of(LaneMask a) { return !hn::AllFalse(DF(), a.m); }
  friend bool all_of(LaneMask a) { return hn::AllTrue(DF(), a.m); }
};

// Transcendentals of Highway (contrib/math): Sin, Cos, Exp, Log, Atan; tan and atan2 built
// on them.
struct HwyMath {
  static VecF sin(VecF x) { return hn::Sin(DF(), x); }
  static VecF cos(VecF x) { return hn::Cos(DF(), x); }
  static VecF exp(VecF x) { return hn::Exp(DF(), x); }
  static VecF log(VecF x) { return hn::Log(DF(), x); }
  static VecF atan(VecF x) { return hn::Atan(DF(), x); }
  static VecF tan(VecF x) { return hn::Div(hn::Sin(DF(), x), hn::Cos(DF(), x)); }
  static VecF atan2(VecF y, VecF x) {
    const DF d;
    const auto zero = hn::Zero(d);
    const auto pi = hn::Set(d, 3.14159265358979323846f), half_pi = hn::Set(d, 1.57079632679489661923f);
    const auto x_zero = hn::Eq(x, zero);
    // atan(y / x), then into the quadrant of (x, y); x = 0 gives +-pi/2 (0 at the origin).
    auto r = hn::Atan(d, hn::Div(y, hn::IfThenElse(x_zero, hn::Set(d, 1.0f), x)));
    r = hn::IfThenElse(hn::Lt(x, zero), hn::Add(r, hn::IfThenElse(hn::Lt(y, zero), hn::Neg(pi), pi)), r);
    const auto axis = hn::IfThenElse(hn::Gt(y, zero), half_pi, hn::IfThenElse(hn::Lt(y, zero), hn::Neg(half_pi), zero));
    return hn::IfThenElse(x_zero, axis, r);
  }
};

// The C library's functions lane by lane: what the scalar code computes, bit for bit.
struct LibmMath {
  template <class F>
  static VecF each(VecF x, F f) {
    alignas(64) float a[16];
    hn::Store(x, DF(), a);
    for (int l = 0; l < kLanes; ++l) a[l] = f(a[l]);
    return hn::Load(DF(), a);
  }
  static VecF sin(VecF x) { return each(x, [](float v) { return ::sinf(v); }); }
  static VecF cos(VecF x) { return each(x, [](float v) { return ::cosf(v); }); }
  static VecF exp(VecF x) { return each(x, [](float v) { return ::expf(v); }); }
  static VecF log(VecF x) { return each(x, [](float v) { return ::logf(v); }); }
  static VecF atan(VecF x) { return each(x, [](float v) { return ::atanf(v); }); }
  static VecF tan(VecF x) { return each(x, [](float v) { return ::tanf(v); }); }
  static VecF atan2(VecF y, VecF x) {
    alignas(64) float a[16], b[16];
    hn::Store(y, DF(), a);
    hn::Store(x, DF(), b);
    for (int l = 0; l < kLanes; ++l) a[l] = ::atan2f(a[l], b[l]);
    return hn::Load(DF(), a);
  }
};

// kLanes floats: a batch of samples. Math supplies the transcendentals.
template <class Math>
struct LaneF {
  VecF v;
  LaneF() = default;
  LaneF(float s) : v(hn::Set(DF(), s)) {}  // NOLINT: a float is the same number in every lane
  explicit LaneF(VecF x) : v(x) {}

  LaneF& operator+=(LaneF b) { v = hn::Add(v, b.v); return *this; }
  LaneF& operator-=(LaneF b) { v = hn::Sub(v, b.v); return *this; }
  LaneF& operator*=(LaneF b) { v = hn::Mul(v, b.v); return *this; }
  LaneF& operator/=(LaneF b) { v = hn::Div(v, b.v); return *this; }
  friend LaneF operator+(LaneF a, LaneF b) { return LaneF(hn::Add(a.v, b.v)); }
  friend LaneF operator-(LaneF a, LaneF b) { return LaneF(hn::Sub(a.v, b.v)); }
  friend LaneF operator*(LaneF a, LaneF b) { return LaneF(hn::Mul(a.v, b.v)); }
  friend LaneF operator/(LaneF a, LaneF b) { return LaneF(hn::Div(a.v, b.v)); }
  friend LaneF operator-(LaneF a) { return LaneF(hn::Neg(a.v)); }
  friend LaneMask operator<(LaneF a, LaneF b) { return LaneMask(hn::Lt(a.v, b.v)); }
  friend LaneMask operator<=(LaneF a, LaneF b) { return LaneMask(hn::Le(a.v, b.v)); }
  friend LaneMask operator>(LaneF a, LaneF b) { return LaneMask(hn::Gt(a.v, b.v)); }
  friend LaneMask operator>=(LaneF a, LaneF b) { return LaneMask(hn::Ge(a.v, b.v)); }
  friend LaneMask operator==(LaneF a, LaneF b) { return LaneMask(hn::Eq(a.v, b.v)); }
  friend LaneMask operator!=(LaneF a, LaneF b) { return LaneMask(hn::Ne(a.v, b.v)); }

  friend LaneF select(LaneMask m, LaneF a, LaneF b) { return LaneF(hn::IfThenElse(m.m, a.v, b.v)); }
  // The scalar definitions (hd.hpp), lane-wise, including their NaN behaviour.
  friend LaneF fmin_(LaneF a, LaneF b) { return LaneF(hn::IfThenElse(hn::Lt(a.v, b.v), a.v, b.v)); }
  friend LaneF fmax_(LaneF a, LaneF b) { return LaneF(hn::IfThenElse(hn::Gt(a.v, b.v), a.v, b.v)); }
  friend LaneF fclamp(LaneF x, LaneF lo, LaneF hi) { return select(x < lo, lo, select(x > hi, hi, x)); }
  friend LaneF fsq(LaneF a) { return a * a; }
  friend LaneF fabs_(LaneF a) { return LaneF(hn::Abs(a.v)); }
  friend LaneF fsqrt(LaneF a) { return LaneF(hn::Sqrt(a.v)); }
  friend LaneF ffloor(LaneF a) { return LaneF(hn::Floor(a.v)); }
  friend LaneF fsin(LaneF a) { return LaneF(Math::sin(a.v)); }
  friend LaneF fcos(LaneF a) { return LaneF(Math::cos(a.v)); }
  friend LaneF fexp(LaneF a) { return LaneF(Math::exp(a.v)); }
  friend LaneF flog(LaneF a) { return LaneF(Math::log(a.v)); }
  friend LaneF fatan(LaneF a) { return LaneF(Math::atan(a.v)); }
  friend LaneF ftan(LaneF a) { return LaneF(Math::tan(a.v)); }
  friend LaneF fatan2(LaneF y, LaneF x) { return LaneF(Math::atan2(y.v, x.v)); }

  // Cell indices of a grid lookup (costs/obstacles.hpp): fx, fy inside [0, nx) x [0, ny).
  friend void store_cell_indices(LaneF fx, LaneF fy, int nx, int* out) {
    const DI di;
    const auto c = hn::Add(hn::ConvertTo(di, fx.v), hn::Mul(hn::Set(di, nx), hn::ConvertTo(di, fy.v)));
    hn::StoreU(c, di, out);
  }

  // Distance-field corners (costs/distance_field.hpp): per lane, cells[index + offsets[k]]
  // and the cell after it as floats in out[2k], out[2k + 1]. The two cells are one 32-bit
  // word (little-endian: the first in the low half), so a pair is one gather at a byte offset.
  friend void gather_cell_pairs(const std::int16_t* cells, LaneF index, const int* offsets, int n, LaneF* out) {
    const DI di;
    const auto bytes = hn::ShiftLeft<1>(hn::ConvertTo(di, index.v));
    const auto* words = reinterpret_cast<const std::int32_t*>(cells);  // read through the gather only
    for (int k = 0; k < n; ++k) {
      const auto w = hn::GatherOffset(di, words, hn::Add(bytes, hn::Set(di, 2 * offsets[k])));
      out[2 * k] = LaneF(hn::ConvertTo(DF(), hn::ShiftRight<16>(hn::ShiftLeft<16>(w))));
      out[2 * k + 1] = LaneF(hn::ConvertTo(DF(), hn::ShiftRight<16>(w)));
    }
  }
};

// kLanes unsigned 32-bit words: sample indices, Philox counters.
struct LaneU {
  VecU v;
};

// The words as the nearest floats, exactly as static_cast<float>(std::uint32_t): both
// 16-bit halves convert exactly, hi * 2^16 is exact, and the sum rounds once.
inline VecF u32_to_float(const LaneU& r) {
  const DF df;
  const DI di;
  const auto hi = hn::ConvertTo(df, hn::BitCast(di, hn::ShiftRight<16>(r.v)));
  const auto lo = hn::ConvertTo(df, hn::BitCast(di, hn::And(r.v, hn::Set(DU(), 0xFFFFu))));
  return hn::Add(hn::Mul(hi, hn::Set(df, 65536.0f)), lo);
}

// rng.hpp's sample_group lane-wise: sample mod groups, as floats.
inline VecF sample_group(const LaneU& sample, std::uint32_t groups) {
  alignas(64) std::uint32_t a[16];
  alignas(64) float f[16];
  hn::Store(sample.v, DU(), a);
  for (int l = 0; l < kLanes; ++l) f[l] = static_cast<float>(a[l] % groups);
  return hn::Load(DF(), f);
}

// lo = m * b mod 2^32, hi = the high word of the 64-bit product, lane-wise.
inline VecU mulhilo(std::uint32_t m, VecU b, VecU* hi) {
  const DU du;
  const DU64 d64;
  const auto mv = hn::Set(du, m);
  const auto even = hn::MulEven(mv, b);                                             // lanes 0, 2, ...
  const auto odd = hn::MulEven(mv, hn::BitCast(du, hn::ShiftRight<32>(hn::BitCast(d64, b))));  // lanes 1, 3, ...
  *hi = hn::OddEven(hn::BitCast(du, odd), hn::BitCast(du, hn::ShiftRight<32>(even)));
  return hn::Mul(mv, b);
}

// Philox4x32-10 of the counters (sample, step, cycle, block) for a batch of sample
// indices, round by round as Random123's philox.h: the four output words.
inline void philox4x32_10(const NoiseKey& key, const LaneU& sample, std::uint32_t step, std::uint32_t block,
                          LaneU out[4]) {
  const DU du;
  VecU c0 = sample.v, c1 = hn::Set(du, step), c2 = hn::Set(du, key.cycle), c3 = hn::Set(du, block);
  std::uint32_t k0 = static_cast<std::uint32_t>(key.seed), k1 = static_cast<std::uint32_t>(key.seed >> 32);
  for (int round = 0; round < 10; ++round) {
    if (round > 0) {
      k0 += kPhiloxW0;
      k1 += kPhiloxW1;
    }
    VecU hi0, hi1;
    const VecU lo0 = mulhilo(kPhiloxM0, c0, &hi0);
    const VecU lo1 = mulhilo(kPhiloxM1, c2, &hi1);
    c0 = hn::Xor(hn::Xor(hi1, c1), hn::Set(du, k0));
    c1 = lo1;
    c2 = hn::Xor(hn::Xor(hi0, c3), hn::Set(du, k1));
    c3 = lo0;
  }
  out[0].v = c0;
  out[1].v = c1;
  out[2].v = c2;
  out[3].v = c3;
}

// rng.hpp's gaussian4 for a batch of sample indices: the same words, the shared
// Box-Muller transform.
template <class Math>
void gaussian4(const NoiseKey& key, const LaneU& sample, std::uint32_t step, std::uint32_t block, LaneF<Math> out[4]) {
  LaneU words[4];
  philox4x32_10(key, sample, step, block, words);
  box_muller4(words, out);
}

// Per vehicle, the lanes whose vehicle has crashed (task.hpp's crash state for a batch).
template <int M>
struct LaneCrash {
  LaneMask vehicle[M];
  LaneCrash() {
    for (int j = 0; j < M; ++j) vehicle[j] = LaneMask(false);
  }
  friend LaneMask vehicle_crashed(const LaneCrash& c, int j) { return c.vehicle[j]; }
  friend void mark_crashed(LaneCrash* c, int j, LaneMask hit) { c->vehicle[j] = mask_or(c->vehicle[j], hit); }
  LaneMask any() const {
    LaneMask m = vehicle[0];
    for (int j = 1; j < M; ++j) m = mask_or(m, vehicle[j]);
    return m;
  }
};

// The CPU kernels' view of a SIMD batch (cpu_kernel.hpp; ScalarLanes is the scalar one).
template <class Math>
struct SimdLanes {
  using F = LaneF<Math>;
  using Index = LaneU;
  template <int M>
  using Crash = LaneCrash<M>;
  static constexpr int kLanes = ::mppi::HWY_NAMESPACE::kLanes;

  static F load(const float* p) { return F(hn::LoadU(DF(), p)); }
  static void store(const F& v, float* p) { hn::StoreU(v.v, DF(), p); }
  static Index samples(int k0) { return LaneU{hn::Iota(DU(), static_cast<std::uint32_t>(k0))}; }
  // v in the first n lanes, 0 in the others.
  static F keep_first(const F& v, int n) {
    return F(hn::IfThenElseZero(hn::FirstN(DF(), static_cast<std::size_t>(n)), v.v));
  }
  static float min_of(const F& v) { return hn::GetLane(hn::MinOfLanes(DF(), v.v)); }
  template <int M>
  static void store_crashed(const Crash<M>& c, unsigned char* out) {
    alignas(64) float a[16];
    hn::Store(hn::IfThenElseZero(c.any().m, hn::Set(DF(), 1.0f)), DF(), a);
    for (int l = 0; l < kLanes; ++l) out[l] = a[l] != 0.0f;
  }
};

}  // namespace HWY_NAMESPACE

template <class Math>
struct LaneCount<HWY_NAMESPACE::LaneF<Math>> {
  static constexpr int value = HWY_NAMESPACE::kLanes;
};

}  // namespace mppi
