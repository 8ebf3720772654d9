// Device discovery: whether a CUDA device can run this build's kernels, and its name.
#include <cuda_runtime.h>

#include <string>

#include "cuda_check.cuh"
#include "mppi/gpu/cuda_backend.hpp"

namespace mppi {
namespace {
__global__ void probe_kernel() {}
}  // namespace

bool cuda_device_available(std::string* why) {
  auto no = [&](const std::string& reason) {
    if (why != nullptr) *why = reason;
    cudaGetLastError();  // clear a non-sticky error so later calls start clean
    return false;
  };
  int count = 0;
  cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) return no("cudaGetDeviceCount failed (" + cuda_detail::describe(e) + ")");
  if (count == 0) return no("no CUDA device found");
  int dev = 0;
  e = cudaGetDevice(&dev);
  if (e != cudaSuccess) return no("cudaGetDevice failed (" + cuda_detail::describe(e) + ")");
  cudaDeviceProp prop{};
  e = cudaGetDeviceProperties(&prop, dev);
  if (e != cudaSuccess) return no("cudaGetDeviceProperties failed (" + cuda_detail::describe(e) + ")");
  // A device this build has no kernel image for (neither SASS nor PTX it can JIT).
  cudaFuncAttributes attr{};
  e = cudaFuncGetAttributes(&attr, probe_kernel);
  if (e != cudaSuccess)
    return no(std::string("no kernel image for ") + prop.name + " (sm_" + std::to_string(prop.major) +
              std::to_string(prop.minor) + "): " + cuda_detail::describe(e));
  if (why != nullptr) why->clear();
  return true;
}

std::string cuda_device_name() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess || count == 0) {
    cudaGetLastError();
    return {};
  }
  int dev = 0;
  cudaDeviceProp prop{};
  if (cudaGetDevice(&dev) != cudaSuccess || cudaGetDeviceProperties(&prop, dev) != cudaSuccess) {
    cudaGetLastError();
    return {};
  }
  return prop.name;
}

}  // namespace mppi
