// HD marks a function usable on the host and, under nvcc, on the device. Every model and
// cost in core/ is written once with it, so the CPU and CUDA backends run the same code.
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
MPPI_HD float ftan(float a) { return ::tanf(a); }
MPPI_HD float fabs_(float a) { return ::fabsf(a); }
MPPI_HD float fmin_(float a, float b) { return a < b ? a : b; }
MPPI_HD float fmax_(float a, float b) { return a > b ? a : b; }
MPPI_HD float fclamp(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }
MPPI_HD float fsq(float a) { return a * a; }
MPPI_HD bool ffinite(float a) { return a == a && a - a == 0.0f; }

}  // namespace mppi
