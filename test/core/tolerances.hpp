// How close a plan computed another way must come to the scalar code's: the SIMD targets
// against the scalar backend (test_simd.cpp), another machine's plans against this one's
// (plan_reference.cpp). The bounds are the CPU-GPU parity test's
// (test/gpu/test_cuda_backend.cpp): an ulp apart, a rollout that crosses a crash threshold
// at another step, or flips, takes another path.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "mppi/tasks.hpp"

namespace mppi::testing {

// Highway's sin, cos, exp, log, atan are within 2-3 ulp of the C library's; one Euler step
// or one cost evaluation then differs by a few ulp of its terms.
constexpr double kStepTolerance = 2e-5;   // relative to max(1, |value|)
constexpr double kCostTolerance = 1e-5;   // relative to max(1, |S|), per rollout
constexpr double kPlanTolerance = 1e-4;   // relative to max(1, |u|)
constexpr double kDivergentFraction = 0.015;
// Highway's transcendentals are 2-3 ulp from the C library's (CUDA's 1): measured, 2/256
// single-vehicle rollouts, 12/1024 of team3's, 21/1024 of team9's take another path.
template <class T>
double divergent_fraction() {
  return T::kVehicles > 3 ? 2 * kDivergentFraction : kDivergentFraction;
}

// The race car's temperature (lambda = 2, against costs of hundreds) turns its costs
// differences of a few ulp into weights a few per mille apart, and the update averages a
// few samples of steering noise 0.35 rad wide: its plan agrees to a few milliradians.
template <class T>
double plan_tolerance() {
  return std::is_same_v<T, RacecarEllipse> ? 5e-3 : kPlanTolerance;
}

inline bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof(float)) == 0; }

inline double rel_error(double a, double b) { return std::fabs(a - b) / std::max(1.0, std::fabs(b)); }

}  // namespace mppi::testing
