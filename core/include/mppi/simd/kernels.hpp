// Included by the per-target kernel translation units only (core/src/simd/kernels.cpp.in,
// each compiled with its target's instruction set): instantiates the CPU kernels of one
// task on SimdLanes and defines cpu::simd_kernel_ops for it.
#pragma once

#include "mppi/cpu_backend.hpp"
#include "mppi/cpu_kernel.hpp"
#include "mppi/simd/lanes.hpp"
#include "mppi/tasks.hpp"

namespace mppi::cpu {

// The Highway target the compiler flags of this translation unit give, as simd::Target.
constexpr simd::Target this_target() {
#if HWY_TARGET == HWY_AVX3
  return simd::Target::kAvx3;
#elif HWY_TARGET == HWY_AVX2
  return simd::Target::kAvx2;
#elif HWY_TARGET == HWY_SSE4
  return simd::Target::kSse4;
#elif HWY_TARGET == HWY_NEON
  return simd::Target::kNeon;
#else
  return simd::Target::kScalar;
#endif
}

}  // namespace mppi::cpu

// Defines simd_kernel_ops<TASK, TARGET> with Math (HwyMath, or LibmMath for the tests'
// bit-exact comparison) as FUNCTION<TASK, TARGET>.
#define MPPI_SIMD_KERNELS(FUNCTION, TASK, TARGET, MATH)                                        \
  namespace mppi::cpu {                                                                       \
  static_assert(this_target() == simd::Target::TARGET,                                        \
                "the compiler flags of this translation unit do not give Highway's " #TARGET); \
  template <>                                                                                 \
  const KernelOps<TASK>* FUNCTION<TASK, simd::Target::TARGET>() {                             \
    static constexpr KernelOps<TASK> kOps = kernel_ops<TASK, HWY_NAMESPACE::SimdLanes<HWY_NAMESPACE::MATH>>(); \
    return &kOps;                                                                             \
  }                                                                                           \
  }
