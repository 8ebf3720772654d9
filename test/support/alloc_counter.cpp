#include "alloc_counter.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<std::size_t> g_bytes{0};
std::atomic<std::size_t> g_count{0};
}  // namespace

namespace mppi::testing {
std::size_t allocated_bytes() { return g_bytes.load(std::memory_order_relaxed); }
std::size_t allocation_count() { return g_count.load(std::memory_order_relaxed); }
}  // namespace mppi::testing

void* operator new(std::size_t n) {
  g_bytes.fetch_add(n, std::memory_order_relaxed);
  g_count.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return ::operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
