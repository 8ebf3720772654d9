// HD marks a function usable on the host and, under nvcc, on the device. Every model and
// cost in core/ is written once with it, so the CPU and CUDA backends run the same code.
//
// The number-type layer. Models, costs, the sampler and the noise are templates on their
// number type V: float here (one sample per CUDA thread, or per CPU loop iteration), or a
// SIMD batch of samples on the CPU (mppi/simd/lanes.hpp: the same operations, lane-wise).
// Code written for V uses only what both provide:
//   arithmetic + - * / (a float operand converts to V), comparisons giving a mask_t<V>,
//   fsin fcos fsincos fexp flog fsqrt fatan fatan2 ftan fabs_ fmin_ fmax_ fclamp fsq ffloor,
//   select(mask, a, b), mask_and/mask_or/mask_not, any_of/all_of.
// A branch on a per-sample value becomes a select of both results (`q = select(hit, q + w, q)`
// is `if (hit) q += w;` exactly); a branch on a parameter stays a branch. For float, a mask
// is a bool and every function below is the plain scalar one, so the float instantiation is
// the code as it reads.
#pragma once

#if defined(__CUDACC__)
#define MPPI_HD __host__ __device__ __forceinline__
#else
#define MPPI_HD inline
#endif

#include <cmath>
#include <cstdint>

namespace mppi {

using Scalar = float;

// Float math that resolves to the same-named CUDA intrinsics on the device and to the
// C library on the host. Explicit float overloads keep -Wdouble-promotion quiet.
MPPI_HD float fsin(float a) { return ::sinf(a); }
MPPI_HD float fcos(float a) { return ::cosf(a); }
MPPI_HD float fexp(float a) { return ::expf(a); }
MPPI_HD float flog(float a) { return ::logf(a); }
MPPI_HD float fsqrt(float a) { return ::sqrtf(a); }
MPPI_HD float fatan(float a) { return ::atanf(a); }
MPPI_HD float fatan2(float y, float x) { return ::atan2f(y, x); }
MPPI_HD float ftan(float a) { return ::tanf(a); }
MPPI_HD float fabs_(float a) { return ::fabsf(a); }
MPPI_HD float fmin_(float a, float b) { return a < b ? a : b; }
MPPI_HD float fmax_(float a, float b) { return a > b ? a : b; }
MPPI_HD float fclamp(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }
MPPI_HD float fsq(float a) { return a * a; }
MPPI_HD float ffloor(float a) { return ::floorf(a); }
MPPI_HD bool ffinite(float a) { return a == a && a - a == 0.0f; }
// Sine and cosine of one argument. On the device one range reduction serves both (CUDA's
// sincosf gives exactly sinf's and cosf's results); on the host the two C library calls.
MPPI_HD void fsincos(float a, float* s, float* c) {
#if defined(__CUDA_ARCH__)
  ::sincosf(a, s, c);
#else
  *s = ::sinf(a);
  *c = ::cosf(a);
#endif
}

// The same functions in double, host and device: the DDP baseline (mppi/ddp/) differentiates
// the models and costs by finite differences in double, through these same templates.
MPPI_HD double fsin(double a) { return ::sin(a); }
MPPI_HD double fcos(double a) { return ::cos(a); }
MPPI_HD double fexp(double a) { return ::exp(a); }
MPPI_HD double flog(double a) { return ::log(a); }
MPPI_HD double fsqrt(double a) { return ::sqrt(a); }
MPPI_HD double fatan(double a) { return ::atan(a); }
MPPI_HD double fatan2(double y, double x) { return ::atan2(y, x); }
MPPI_HD double ftan(double a) { return ::tan(a); }
MPPI_HD double fabs_(double a) { return ::fabs(a); }
MPPI_HD double fmin_(double a, double b) { return a < b ? a : b; }
MPPI_HD double fmax_(double a, double b) { return a > b ? a : b; }
MPPI_HD double fclamp(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }
MPPI_HD double fsq(double a) { return a * a; }
MPPI_HD double ffloor(double a) { return ::floor(a); }
MPPI_HD bool ffinite(double a) { return a == a && a - a == 0.0; }
MPPI_HD double select(bool m, double a, double b) { return m ? a : b; }
MPPI_HD void fsincos(double a, double* s, double* c) {
  *s = ::sin(a);
  *c = ::cos(a);
}
// Any other number type (a SIMD batch): its own fsin and fcos.
template <class V>
MPPI_HD void fsincos(const V& a, V* s, V* c) {
  *s = fsin(a);
  *c = fcos(a);
}

// Masks of scalar numbers are bools.
MPPI_HD float select(bool m, float a, float b) { return m ? a : b; }
MPPI_HD bool mask_and(bool a, bool b) { return a && b; }
MPPI_HD bool mask_or(bool a, bool b) { return a || b; }
MPPI_HD bool mask_not(bool a) { return !a; }
MPPI_HD bool any_of(bool m) { return m; }
MPPI_HD bool all_of(bool m) { return m; }

// The mask type of number type V (bool for float).
template <class V>
using mask_t = decltype(V() < V());

// Samples per number (1 for float); a SIMD number type specialises this.
template <class V>
struct LaneCount {
  static constexpr int value = 1;
};

}  // namespace mppi
