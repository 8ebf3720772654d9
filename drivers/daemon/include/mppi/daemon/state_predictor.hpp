// Latency compensation: the measured state predicted to the time this cycle's command will
// act. The commands sent lately are kept with the time each takes (took) effect; the
// state is rolled forward from its sample time through them, piecewise, with the task's
// model under RK4 (Controller::propagate). Fixed capacity: nothing allocates after
// construction.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"

namespace mppi::daemon {

class CommandHistory {
 public:
  static constexpr int kCapacity = 32;

  // nu controls per command; `initial` is what acts before the first command (u_init).
  CommandHistory(int nu, const std::vector<float>& initial);

  // Forget every command: `initial` acts from now on (after a failsafe or a restart).
  void reset();
  // A command acting from t_ns on (non-decreasing: an earlier time is moved up to the
  // last one's, as a plant applies commands in the order they arrive).
  void add(std::int64_t t_ns, const float* u);

  // x (the state sampled at t0_ns) advanced in place to t1_ns through the commands in
  // effect over [t0, t1]; nothing happens when t1 <= t0. Returns the number of segments.
  // `later_ns`: every command taken to act that much later than it was recorded (the
  // actuation delay estimate's candidates; may be negative).
  int predict(const Controller& c, float* x, std::int64_t t0_ns, std::int64_t t1_ns, std::int64_t later_ns = 0) const;

  int size() const { return count_; }
  // The control in effect at t_ns (the latest command that acts at or before it).
  const float* at(std::int64_t t_ns, std::int64_t later_ns = 0) const;

 private:
  const float* slot(int i) const { return &u_[static_cast<std::size_t>((head_ + i) % kCapacity) * nu_]; }
  std::int64_t time(int i) const { return t_[static_cast<std::size_t>((head_ + i) % kCapacity)]; }

  int nu_;
  std::vector<float> initial_, base_;  // base_: what acts before the oldest kept command
  std::vector<float> u_;               // kCapacity x nu ring
  std::vector<std::int64_t> t_;
  int head_ = 0, count_ = 0;
};

}  // namespace mppi::daemon
