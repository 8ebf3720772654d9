// Where a transport's receive thread leaves what arrived, for the control loop to take
// between cycles. States are validated here (shape, NaN/Inf, sequence) before they reach
// the latest-value slot, so every transport rejects and counts the same way.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "mppi/rt/latest_value.hpp"
#include "mppi/rt/spsc_ring.hpp"
#include "mppi/rt/wakeup.hpp"
#include "mppi/transport/messages.hpp"

namespace mppi::transport {

enum class Reject { kNone, kNan, kDuplicate, kOutOfOrder, kShape, kUndecodable, kTime };

// The timestamps (us) a state, tick or reference epoch may carry: [0, kMaxUtime], i.e. up
// to the year 2116 on the wall clock, any simulated time from 0. In nanoseconds each of
// them, and the difference of any two, fits in int64; past it the loop's clock arithmetic
// would overflow (fuzz_clock found sim_utime * 1000 overflowing in the lock-step cycle).
constexpr std::int64_t kMaxUtime = INT64_MAX / 1000 / 2;
const char* to_string(Reject r);

struct InboxCounters {
  std::atomic<std::int64_t> states{0};  // accepted
  std::atomic<std::int64_t> rejected_nan{0};
  std::atomic<std::int64_t> rejected_duplicate{0};
  std::atomic<std::int64_t> rejected_out_of_order{0};
  std::atomic<std::int64_t> rejected_shape{0};        // wrong n / nx / vehicle count / model
  std::atomic<std::int64_t> rejected_undecodable{0};  // garbage bytes, wrong type
  std::atomic<std::int64_t> rejected_time{0};         // sample time outside [0, kMaxUtime]
  std::atomic<std::int64_t> rejected_inputs{0};       // bad reference / obstacles (epoch out of range too)
  std::atomic<std::int64_t> params_dropped{0};        // queue full
  std::atomic<std::int64_t> ticks{0};
  std::atomic<std::int64_t> ticks_dropped{0};   // queue full
  std::atomic<std::int64_t> ticks_rejected{0};  // sim time outside [0, kMaxUtime]
  // Local maps (local_map_t): taken, and rejected by reason.
  std::atomic<std::int64_t> maps{0};
  std::atomic<std::int64_t> maps_rejected_invalid{0};       // shape, non-finite, capacity (DistanceFieldGrid::invalid)
  std::atomic<std::int64_t> maps_rejected_out_of_order{0};  // seq or utime not after the last map's
  std::atomic<std::int64_t> maps_rejected_stale{0};         // older than map_timeout_ns behind the newest state
  std::atomic<std::int64_t> maps_rejected_time{0};          // utime outside [0, kMaxUtime]
  std::atomic<std::int64_t> maps_undecodable{0};            // garbage bytes, a count the bytes do not back
  std::int64_t maps_rejected() const {
    return maps_rejected_invalid.load(std::memory_order_relaxed) + maps_rejected_out_of_order.load(std::memory_order_relaxed) +
           maps_rejected_stale.load(std::memory_order_relaxed) + maps_rejected_time.load(std::memory_order_relaxed) +
           maps_undecodable.load(std::memory_order_relaxed);
  }
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
    bool wake_on_state = false;  // real time, state-triggered: post state_wake per accepted state
    // Local maps (local_map_t) are taken (the slot, three maps of 2 MiB, allocated here).
    // One whose utime is more than map_timeout_ns behind the newest state's sample time on
    // arrival is refused as stale.
    bool local_map = false;
    std::int64_t map_timeout_ns = 500'000'000;
  };

  explicit Inbox(const Expect& e)
      : map(e.local_map ? std::make_unique<rt::LatestValue<LocalMapInput>>() : nullptr), expect_(e) {}

  // ---- receive-thread side --------------------------------------------------------
  // One thread offers states, references, obstacles, parameters and ticks; maps may come
  // from a second one (LcmTransport's maps' thread): the only state the two share is the
  // newest state's sample time (an atomic) and the counters (atomics).
  // Fill state_buffer(), then offer_state() validates it and hands it to the loop.
  StateSample& state_buffer() { return state.back(); }
  Reject offer_state();
  ReferenceInput& reference_buffer() { return reference.back(); }
  void offer_reference();
  ObstacleInput& obstacles_buffer() { return obstacles.back(); }
  void offer_obstacles();
  // Null when no map is expected. Fill it, then offer_map() validates it and hands it over.
  LocalMapInput* map_buffer() { return map ? &map->back() : nullptr; }
  Reject offer_map();
  void count_undecodable_map() { counters.maps_undecodable.fetch_add(1, std::memory_order_relaxed); }
  void count_invalid_map() { counters.maps_rejected_invalid.fetch_add(1, std::memory_order_relaxed); }
  void offer_param(const ParamUpdate& p);
  void offer_tick(const ClockTick& t);
  void count_undecodable() { counters.rejected_undecodable.fetch_add(1, std::memory_order_relaxed); }
  void count_bad_input() { counters.rejected_inputs.fetch_add(1, std::memory_order_relaxed); }

  // ---- loop side -------------------------------------------------------------------
  rt::LatestValue<StateSample> state;
  rt::LatestValue<ReferenceInput> reference;
  rt::LatestValue<ObstacleInput> obstacles;
  // The newest valid map (null unless Expect::local_map). The loop's front() stays put until
  // its next update(), so the cost may point at its cells for a whole cycle.
  std::unique_ptr<rt::LatestValue<LocalMapInput>> map;
  rt::SpscRing<ParamUpdate, 64> params;
  rt::SpscRing<ClockTick, 256> ticks;
  rt::Wakeup wake;        // posted once per tick (lock-step)
  rt::Wakeup state_wake;  // posted once per accepted state (with wake_on_state)
  InboxCounters counters;
  // recv_ns of the newest accepted state (INT64_MIN before the first): the state-triggered
  // loop starts a cycle on a state received late enough in the period.
  std::int64_t last_state_recv_ns() const { return last_state_recv_ns_.load(std::memory_order_acquire); }

  const Expect& expect() const { return expect_; }

 private:
  Reject check_state(const StateSample& s) const;
  void accept_state(const StateSample& s);

  Expect expect_;
  std::int64_t last_seq_ = -1;  // states' receive thread only
  std::int64_t last_recv_ns_ = 0;
  bool have_last_ = false;
  // The newest accepted state's sample time: written by the states' thread, read by the maps'
  // (a map's stale check) when maps have a thread of their own.
  std::atomic<std::int64_t> last_sample_utime_{-1};
  std::int64_t last_map_seq_ = -1, last_map_utime_ = -1, last_map_recv_ns_ = 0;  // maps' thread
  bool have_map_ = false;
  std::atomic<std::int64_t> last_state_recv_ns_{INT64_MIN};
};

}  // namespace mppi::transport
