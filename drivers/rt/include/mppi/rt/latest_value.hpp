// Latest-value slot between one writer thread and one reader thread: a triple buffer.
// Wait-free on both sides (one atomic exchange each), no locks, no allocation; the
// reader always gets the newest complete value and never a torn one. Older values the
// reader did not take are dropped, which is what a controller wants from a state stream.
#pragma once

#include <atomic>
#include <cstdint>
#include <type_traits>

namespace mppi::rt {

template <class T>
class LatestValue {
  static_assert(std::is_trivially_copyable_v<T>, "slots are copied as plain data");

 public:
  // Writer: fill the back buffer, then publish it.
  T& back() { return buf_[back_]; }
  void publish() {
    const std::uint8_t old = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = old & kIndex;
    writes_.fetch_add(1, std::memory_order_relaxed);
  }
  void write(const T& v) {
    back() = v;
    publish();
  }

  // Reader: true (and the value swapped to the front) if something new was published
  // since the last call.
  bool update() {
    if ((middle_.load(std::memory_order_relaxed) & kFresh) == 0) return false;
    const std::uint8_t old = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = old & kIndex;
    return true;
  }
  // The newest value taken by update(); default-constructed until the first.
  const T& front() const { return buf_[front_]; }

  std::uint64_t writes() const { return writes_.load(std::memory_order_relaxed); }

 private:
  static constexpr std::uint8_t kIndex = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;
  T buf_[3]{};
  std::uint8_t back_ = 0;                 // writer only
  std::uint8_t front_ = 1;                // reader only
  std::atomic<std::uint8_t> middle_{2};   // shared: index, plus kFresh when unread
  std::atomic<std::uint64_t> writes_{0};
};

}  // namespace mppi::rt
