// CUDA error handling and owning buffers for the backend. Every failure becomes a
// std::runtime_error that names the CUDA error and what was being attempted.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>

namespace mppi::cuda_detail {

inline std::string describe(cudaError_t e) {
  return std::string(cudaGetErrorName(e)) + ": " + cudaGetErrorString(e);
}

[[noreturn]] inline void fail(cudaError_t e, const std::string& what) {
  throw std::runtime_error("cuda backend: " + what + " failed (" + describe(e) + ")");
}

inline void check(cudaError_t e, const std::string& what) {
  if (e != cudaSuccess) fail(e, what);
}

// Memory from one CUDA allocator, freed on destruction. A failed allocation is not sticky:
// the error is cleared so nothing is left behind for the next launch.
template <class Allocator>
class CudaBuffer {
 public:
  CudaBuffer() = default;
  CudaBuffer(std::size_t bytes, const std::string& what) : bytes_(bytes) {
    if (bytes == 0) return;
    const cudaError_t e = Allocator::allocate(&ptr_, bytes);
    if (e != cudaSuccess) {
      ptr_ = nullptr;
      cudaGetLastError();
      fail(e, std::string(Allocator::kName) + " of " + std::to_string(bytes) + " bytes for " + what);
    }
  }
  CudaBuffer(const CudaBuffer&) = delete;
  CudaBuffer& operator=(const CudaBuffer&) = delete;
  CudaBuffer(CudaBuffer&& o) noexcept : ptr_(o.ptr_), bytes_(o.bytes_) { o.ptr_ = nullptr; o.bytes_ = 0; }
  CudaBuffer& operator=(CudaBuffer&& o) noexcept {
    std::swap(ptr_, o.ptr_);
    std::swap(bytes_, o.bytes_);
    return *this;
  }
  ~CudaBuffer() {
    if (ptr_ != nullptr) Allocator::release(ptr_);
  }
  template <class U>
  U* as() const { return static_cast<U*>(ptr_); }
  std::size_t bytes() const { return bytes_; }

 private:
  void* ptr_ = nullptr;
  std::size_t bytes_ = 0;
};

struct DeviceAllocator {
  static constexpr const char* kName = "cudaMalloc";
  static cudaError_t allocate(void** p, std::size_t n) { return cudaMalloc(p, n); }
  static void release(void* p) { cudaFree(p); }
};
struct PinnedAllocator {
  static constexpr const char* kName = "cudaMallocHost";
  static cudaError_t allocate(void** p, std::size_t n) { return cudaMallocHost(p, n); }
  static void release(void* p) { cudaFreeHost(p); }
};

// Device memory; page-locked host memory (the staging area of the per-cycle copies).
using DeviceBuffer = CudaBuffer<DeviceAllocator>;
using PinnedBuffer = CudaBuffer<PinnedAllocator>;

}  // namespace mppi::cuda_detail
