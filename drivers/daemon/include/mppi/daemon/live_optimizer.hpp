// Live optimizer updates: `mppi.*` settings (rollouts, horizon, lambda, nu, sigma, threads,
// ...) change while the daemon runs. The loop forwards each update to a builder thread,
// which checks it, builds a whole new controller with the new settings (allocating what it
// needs, off the loop thread) and leaves it in a one-slot hand-over (an atomic pointer).
// Between two cycles the loop takes it, carries the running controller's state over (the
// task's inputs and run-time parameters, the noise counter, the plan resampled onto the
// new horizon) and swaps it in: pointer and vector swaps, no allocation, no lock. The old
// controller goes back through a second slot and is destroyed on the builder thread.
//
//   loop:    request(update) ............ take_ready() -> swap -> retire(old)
//   builder:          check, build, publish ready ...........  destroy old
//
// Without a builder thread (Mode::kSynchronous: replay, tests) take_ready() builds what was
// requested on the calling thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/rt/spsc_ring.hpp"
#include "mppi/rt/wakeup.hpp"
#include "mppi/settings.hpp"
#include "mppi/transport/messages.hpp"

namespace mppi::daemon {

// What a live update may ask for (the daemon's `live:` section).
struct LiveSettings {
  bool enabled = true;      // false: mppi.* is refused, as before
  int max_horizon = 500;    // sizes the plan message buffer at start
  int max_rollouts = 65536;
  int max_threads = 0;      // 0: the CPUs this process may run on
};

// Applies `key = value` to `s` if the key may change at run time and the result is valid
// (mppi::validate, and the limits); else leaves `s` as it was and returns "key: reason".
std::string apply_live_update(MppiSettings* s, const std::string& key, double value, int nu,
                              const LiveSettings& limits);

// The plan `in` (t_in steps of dt_in, nu controls each) on a new time grid: step i of `out`
// (t_out steps of dt_out) takes the control in effect at the middle of its interval, and
// `fill` (u_init) past the old plan's end. With dt_in == dt_out it keeps the first
// min(t_in, t_out) steps exactly. `in` and `out` must not overlap. Allocates nothing.
void resample_plan(const float* in, int t_in, double dt_in, float* out, int t_out, double dt_out, int nu,
                   const float* fill);

// The OpenMP team of the calling thread resized to `threads` (workers started or ended
// now, and given the calling thread's SCHED_FIFO priority less one, as the warm-up does).
void resize_worker_team(int threads);

// A controller built off the loop thread, with its own plan-sized buffers; after the swap it
// carries the old controller and the old buffers back to be destroyed off the loop thread.
struct OptimizerBundle {
  static constexpr int kMaxUpdates = 64;
  std::unique_ptr<Controller> controller;
  std::vector<float> held, guard;  // horizon x nu each: the loop's held plan and the guard's copy
  int threads = 0;                 // resolved OpenMP team size of `controller`
  int count = 0;                   // the updates it applies
  transport::ParamUpdate updates[kMaxUpdates];
};

class LiveOptimizer {
 public:
  using Factory = std::function<std::unique_ptr<Controller>(const MppiSettings&)>;
  enum class Mode { kBuilderThread, kSynchronous };

  LiveOptimizer(std::unique_ptr<Controller> initial, Factory factory, LiveSettings limits,
                Mode mode = Mode::kBuilderThread);
  ~LiveOptimizer();
  LiveOptimizer(const LiveOptimizer&) = delete;
  LiveOptimizer& operator=(const LiveOptimizer&) = delete;

  // The controller in service (the loop's; swapped by the loop thread only).
  Controller* current() const { return current_.get(); }
  const LiveSettings& limits() const { return limits_; }
  // OpenMP team size of the controller in service.
  int current_threads() const { return current_threads_; }

  // ---- loop thread --------------------------------------------------------------------
  // Queues an mppi.* update for the builder. False when the queue is full (refuse it).
  bool request(const transport::ParamUpdate& p);
  // A controller ready to swap in, or null. Its `held`/`guard` are sized for its horizon.
  OptimizerBundle* take_ready();
  // After the swap: `b` holds the controller and buffers swapped out; they are destroyed
  // on the builder thread. The caller swaps b->controller with current (see swap_current).
  void swap_current(OptimizerBundle* b);
  void retire(OptimizerBundle* b);
  // Updates the builder refused (with the field and the reason), for the loop to answer.
  bool pop_refusal(transport::ParamResult* out);

  // ---- any thread -----------------------------------------------------------------------
  std::int64_t builds() const { return builds_.load(std::memory_order_relaxed); }
  std::int64_t build_failures() const { return build_failures_.load(std::memory_order_relaxed); }
  // Tests and tools: blocks until the builder can do nothing more without the loop: every
  // update requested so far built or refused, or a build ready to take (the builder takes the
  // updates queued when it wakes, so updates queued one by one may take two builds, the
  // second after the loop took the first).
  void wait_idle() const;
  // True on a builder thread (an allocation counter tells its allocations from the loop's).
  static bool on_builder_thread();

 private:
  void builder_main();
  // Checks and builds the updates in `pending` (up to kMaxUpdates of them, removed);
  // returns the bundle (null when all were refused).
  OptimizerBundle* build(std::vector<transport::ParamUpdate>* pending);
  void refuse(const transport::ParamUpdate& p, const std::string& why);
  void collect_retired();

  std::unique_ptr<Controller> current_;
  int current_threads_ = 1;
  Factory factory_;
  LiveSettings limits_;
  Mode mode_;
  int nu_;
  std::string task_;

  // Builder-thread state (the calling thread's in kSynchronous mode).
  MppiSettings base_;  // the settings of the last controller built
  std::vector<transport::ParamUpdate> pending_;

  rt::SpscRing<transport::ParamUpdate, 64> requests_;
  rt::SpscRing<transport::ParamResult, 64> refusals_;
  std::atomic<OptimizerBundle*> ready_{nullptr};
  std::atomic<OptimizerBundle*> retired_{nullptr};
  std::atomic<std::int64_t> requested_{0}, handled_{0};
  std::atomic<std::int64_t> builds_{0}, build_failures_{0}, refusals_dropped_{0};
  std::atomic<bool> quit_{false};
  rt::Wakeup wake_;
  std::thread thread_;
};

}  // namespace mppi::daemon
