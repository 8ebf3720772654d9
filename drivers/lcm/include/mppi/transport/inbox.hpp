// Where a transport's receive thread leaves what arrived, for the control loop to take
// between cycles. States are validated here (shape, NaN/Inf, sequence) before they reach
// the latest-value slot, so every transport rejects and counts the same way.
#pragma once

#include <atomic>
#include <cstdint>

#include "mppi/rt/latest_value.hpp"
#include "mppi/rt/spsc_ring.hpp"
#include "mppi/rt/wakeup.hpp"
#include "mppi/transport/messages.hpp"

namespace mppi::transport {

enum class Reject { kNone, kNan, kDuplicate, kOutOfOrder, kShape, kUndecodable };
const char* to_string(Reject r);

struct InboxCounters {
  std::atomic<std::int64_t> states{0};  // accepted
  std::atomic<std::int64_t> rejected_nan{0};
  std::atomic<std::int64_t> rejected_duplicate{0};
  std::atomic<std::int64_t> rejected_out_of_order{0};
  std::atomic<std::int64_t> rejected_shape{0};        // wrong n / nx / vehicle count / model
  std::atomic<std::int64_t> rejected_undecodable{0};  // garbage bytes, wrong type
  std::atomic<std::int64_t> rejected_inputs{0};       // bad reference / obstacles
  std::atomic<std::int64_t> params_dropped{0};        // queue full
  std::atomic<std::int64_t> ticks{0};
  std::atomic<std::int64_t> ticks_dropped{0};
};

class Inbox {
 public:
  struct Expect {
    int nx = 0;               // states per vehicle
    int vehicles = 1;
    std::int8_t model = 0;    // vehicle_state_t::MODEL_*, 0 = do not check
    // A sequence number that steps back is accepted as a publisher restart only after the
    // stream was quiet this long; before that it is out of order.
    std::int64_t restart_after_ns = 100'000'000;
    bool tick_on_state = false;  // lock-step: each accepted state is also a tick
  };

  explicit Inbox(const Expect& e) : expect_(e) {}

  // ---- receive-thread side --------------------------------------------------------
  // Fill state_buffer(), then offer_state() validates it and hands it to the loop.
  StateSample& state_buffer() { return state.back(); }
  Reject offer_state();
  ReferenceInput& reference_buffer() { return reference.back(); }
  void offer_reference();
  ObstacleInput& obstacles_buffer() { return obstacles.back(); }
  void offer_obstacles();
  void offer_param(const ParamUpdate& p);
  void offer_tick(const ClockTick& t);
  void count_undecodable() { counters.rejected_undecodable.fetch_add(1, std::memory_order_relaxed); }
  void count_bad_input() { counters.rejected_inputs.fetch_add(1, std::memory_order_relaxed); }

  // ---- loop side -------------------------------------------------------------------
  rt::LatestValue<StateSample> state;
  rt::LatestValue<ReferenceInput> reference;
  rt::LatestValue<ObstacleInput> obstacles;
  rt::SpscRing<ParamUpdate, 64> params;
  rt::SpscRing<ClockTick, 256> ticks;
  rt::Wakeup wake;  // posted once per tick (lock-step)
  InboxCounters counters;

  const Expect& expect() const { return expect_; }

 private:
  Expect expect_;
  std::int64_t last_seq_ = -1;  // receive thread only
  std::int64_t last_recv_ns_ = 0;
  bool have_last_ = false;
};

}  // namespace mppi::transport
