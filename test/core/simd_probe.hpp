// Test access to the SIMD number type of each target (simd_probe.cpp.in, one translation
// unit per target with its instruction set): the pieces of a rollout step on a batch of
// samples laid out lane by lane (value n of lane l at [n * lanes + l]), with Highway's
// transcendentals (exact = false, as shipped) or the C library's in every lane (exact =
// true, which must reproduce the scalar code bit for bit); and the CPU kernels with the
// C library's transcendentals.
#pragma once

#include <cstdint>

#include "mppi/cpu_kernel.hpp"
#include "mppi/rng.hpp"
#include "mppi/simd.hpp"
#include "mppi/tasks.hpp"

namespace mppi::testing {

template <class T>
struct SimdProbe {
  int lanes;
  // Task::advance from x (NX per lane), with u (NU per lane), freezing vehicle j of lane l
  // where bit j of crashed[l] is set.
  void (*advance)(const typename T::Params& p, float* x, const float* u, float dt, int substeps,
                  const std::uint32_t* crashed, bool exact);
  // Task::running at time t, and Task::terminal: q[l], phi[l]; the crash bits it sets are
  // or-ed into crashed[l].
  void (*running)(const typename T::Params& p, const float* x, float t, float* q, float* phi,
                  std::uint32_t* crashed, bool exact);
};

struct NoiseProbe {
  int lanes;
  // Philox4x32-10 words of (sample k0 + l, step, block): out[w * lanes + l].
  void (*philox)(const NoiseKey& key, std::uint32_t k0, std::uint32_t step, std::uint32_t block,
                 std::uint32_t* out);
  // gaussian4 of the same: out[c * lanes + l].
  void (*gaussian4)(const NoiseKey& key, std::uint32_t k0, std::uint32_t step, std::uint32_t block, float* out,
                    bool exact);
  // u32_to_float lane-wise.
  void (*to_float)(const std::uint32_t* in, float* out);
};

template <class T, simd::Target kTarget>
const SimdProbe<T>* simd_probe();
template <simd::Target kTarget>
const NoiseProbe* noise_probe();
template <class T, simd::Target kTarget>
const cpu::KernelOps<T>* exact_kernel_ops();  // LibmMath

// The probes of the targets this build compiles and this CPU runs; f(target, name).
template <class F>
void for_each_simd_target([[maybe_unused]] F&& f) {
#ifdef MPPID_SIMD_SSE4
  if (simd::supported(simd::Target::kSse4)) f(std::integral_constant<simd::Target, simd::Target::kSse4>{});
#endif
#ifdef MPPID_SIMD_AVX2
  if (simd::supported(simd::Target::kAvx2)) f(std::integral_constant<simd::Target, simd::Target::kAvx2>{});
#endif
#ifdef MPPID_SIMD_AVX3
  if (simd::supported(simd::Target::kAvx3)) f(std::integral_constant<simd::Target, simd::Target::kAvx3>{});
#endif
#ifdef MPPID_SIMD_NEON
  if (simd::supported(simd::Target::kNeon)) f(std::integral_constant<simd::Target, simd::Target::kNeon>{});
#endif
}

}  // namespace mppi::testing
