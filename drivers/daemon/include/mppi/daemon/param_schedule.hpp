// Parameter updates held until their time: an update may name the sample time of the state from
// which it takes effect (param_update_t.apply_utime; 0: at once). The loop holds it here and
// applies it on the first cycle whose state was sampled at or after that time, so a lock-step
// flight's updates land on the same cycle however fast the machine runs it, and a replay finds
// them there. Fixed capacity (the inbox's ring's), arrival order kept, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "mppi/transport/messages.hpp"

namespace mppi::daemon {

class ParamSchedule {
 public:
  static constexpr std::size_t kCapacity = 64;

  // False when full (the caller refuses the update).
  bool hold(const transport::ParamUpdate& p) {
    if (n_ == kCapacity) return false;
    held_[n_++] = p;
    return true;
  }
  // The oldest held update due at a state sampled at `sample_utime`, removed; false if none.
  bool pop_due(std::int64_t sample_utime, transport::ParamUpdate* out) {
    for (std::size_t i = 0; i < n_; ++i) {
      if (held_[i].apply_utime > sample_utime) continue;
      *out = held_[i];
      for (std::size_t j = i + 1; j < n_; ++j) held_[j - 1] = held_[j];
      --n_;
      return true;
    }
    return false;
  }
  std::size_t size() const { return n_; }

 private:
  std::array<transport::ParamUpdate, kCapacity> held_{};
  std::size_t n_ = 0;
};

}  // namespace mppi::daemon
