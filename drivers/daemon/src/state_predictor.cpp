#include "mppi/daemon/state_predictor.hpp"

#include <algorithm>
#include <cstdint>

namespace mppi::daemon {

CommandHistory::CommandHistory(int nu, const std::vector<float>& initial)
    : nu_(nu),
      initial_(initial),
      base_(initial),
      u_(static_cast<std::size_t>(kCapacity) * static_cast<std::size_t>(nu)),
      t_(static_cast<std::size_t>(kCapacity)) {
  initial_.resize(static_cast<std::size_t>(nu), 0.0f);
  base_ = initial_;
}

void CommandHistory::reset() {
  head_ = 0;
  count_ = 0;
  base_ = initial_;
}

void CommandHistory::add(std::int64_t t_ns, const float* u) {
  if (count_ > 0) t_ns = std::max(t_ns, time(count_ - 1));
  if (count_ == kCapacity) {
    // The oldest command becomes what acts before the rest.
    std::copy_n(slot(0), nu_, base_.data());
    head_ = (head_ + 1) % kCapacity;
    --count_;
  }
  const auto k = static_cast<std::size_t>((head_ + count_) % kCapacity);
  std::copy_n(u, nu_, &u_[k * static_cast<std::size_t>(nu_)]);
  t_[k] = t_ns;
  ++count_;
}

const float* CommandHistory::at(std::int64_t t_ns, std::int64_t later_ns) const {
  const float* u = base_.data();
  for (int i = 0; i < count_ && time(i) + later_ns <= t_ns; ++i) u = slot(i);
  return u;
}

int CommandHistory::predict(const Controller& c, float* x, std::int64_t t0_ns, std::int64_t t1_ns,
                            std::int64_t later_ns) const {
  if (t1_ns <= t0_ns) return 0;
  int segments = 0;
  std::int64_t t = t0_ns;
  const float* u = at(t0_ns, later_ns);
  for (int i = 0; i < count_ && t < t1_ns; ++i) {
    const std::int64_t ti = time(i) + later_ns;
    if (ti <= t) continue;
    const std::int64_t end = std::min(ti, t1_ns);
    c.propagate(x, u, static_cast<float>(static_cast<double>(end - t) * 1e-9));
    ++segments;
    t = end;
    u = slot(i);
  }
  if (t < t1_ns) {
    c.propagate(x, u, static_cast<float>(static_cast<double>(t1_ns - t) * 1e-9));
    ++segments;
  }
  return segments;
}

}  // namespace mppi::daemon
