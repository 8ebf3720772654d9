#include "mppi/daemon/identification.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

namespace mppi::daemon {
namespace {
constexpr int kThrust = 0;
constexpr int kPX = 0, kQX = 7, kQY = 8;  // the rate model's state layout
}  // namespace

IdentificationManoeuvre::IdentificationManoeuvre(const IdentificationSettings& s, std::vector<float> u_min,
                                                 std::vector<float> u_max)
    : s_(s), u_min_(std::move(u_min)), u_max_(std::move(u_max)) {
  // Per repeat: a doublet on each body axis (+a then -a), then a thrust step up and down,
  // each followed by a gap. Signs alternate between repeats, amplitudes grow.
  static const double kScale[3] = {0.6, 1.0, 1.4};
  double t = 0.0;
  const auto add = [&](int channel, double value) {
    pulses_.push_back({channel, value, t, t + s_.pulse_s});
    t += s_.pulse_s;
  };
  for (int r = 0; r < s_.repeats; ++r) {
    const double sign = (r % 2 == 0) ? 1.0 : -1.0, k = kScale[r % 3];
    for (int axis = 1; axis <= 3; ++axis) {
      const double a = sign * k * (axis == 3 ? s_.yaw_amplitude : s_.rate_amplitude);
      add(axis, a);
      add(axis, -a);
      t += s_.gap_s;
    }
    add(kThrust, sign * k * s_.thrust_step);
    add(kThrust, -sign * k * s_.thrust_step);
    t += s_.gap_s;
  }
}

double IdentificationManoeuvre::duration_s() const { return pulses_.empty() ? 0.0 : pulses_.back().end_s + s_.gap_s; }

void IdentificationManoeuvre::request(bool on) {
  on_ = on;
  started_ = false;
  paused_ = false;
  clock_s_ = 0.0;
  if (on)
    spdlog::info("identification manoeuvre requested ({:.1f} s of doublets and thrust steps inside +-{:.1f} m)",
                 duration_s(), s_.box_m);
  else
    spdlog::info("identification manoeuvre stopped");
}

// Inside the box around the start and below the tilt limit (half the box to resume).
bool IdentificationManoeuvre::inside(const float* x, bool resume) const {
  const double box = resume ? 0.5 * s_.box_m : s_.box_m;
  for (int d = 0; d < 3; ++d)
    if (std::fabs(static_cast<double>(x[kPX + d]) - origin_[d]) > box) return false;
  // cos(tilt) = 1 - 2 (qx^2 + qy^2) for a unit quaternion.
  const double c = 1.0 - 2.0 * (x[kQX] * x[kQX] + x[kQY] * x[kQY]);
  return c >= std::cos(s_.max_tilt_deg * M_PI / 180.0);
}

bool IdentificationManoeuvre::excite(const float* x, std::int64_t t_ns, float* u) {
  if (!on_) return false;
  if (!started_) {
    std::copy_n(x + kPX, 3, origin_);
    started_ = true;
    last_ns_ = t_ns;
  }
  const double dt = std::max<double>(0.0, static_cast<double>(t_ns - last_ns_) * 1e-9);
  last_ns_ = t_ns;
  if (paused_ ? !inside(x, true) : !inside(x, false)) {
    if (!paused_) {
      ++pauses_;
      spdlog::warn("identification manoeuvre paused: outside its safe box or tilt");
    }
    paused_ = true;
    return false;
  }
  if (paused_)
    paused_ = false;  // the time paused does not count
  else
    clock_s_ += dt;
  if (clock_s_ >= duration_s()) {
    on_ = false;
    spdlog::info("identification manoeuvre done ({} pauses)", pauses_);
    return false;
  }
  bool changed = false;
  for (const Pulse& p : pulses_) {
    if (clock_s_ < p.start_s || clock_s_ >= p.end_s) continue;
    const auto j = static_cast<std::size_t>(p.channel);
    const double v = p.channel == kThrust ? u[j] * (1.0 + p.value) : u[j] + p.value;
    u[j] = std::clamp(static_cast<float>(v), u_min_[j], u_max_[j]);
    changed = true;
  }
  return changed;
}

}  // namespace mppi::daemon
