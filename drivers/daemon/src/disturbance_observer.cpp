#include "mppi/daemon/disturbance_observer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mppi::daemon {
namespace {

constexpr double kGravity = 9.81;      // m/s^2, the quadrotor models' gravity (their default)
constexpr double kNominalDt = 0.02;    // s: the state period the initial covariance is set for

// Inverse of a symmetric positive-definite 3x3 matrix; false if it is (numerically) singular.
bool invert3(const double a[3][3], double out[3][3]) {
  const double c00 = a[1][1] * a[2][2] - a[1][2] * a[2][1];
  const double c01 = a[1][2] * a[2][0] - a[1][0] * a[2][2];
  const double c02 = a[1][0] * a[2][1] - a[1][1] * a[2][0];
  const double det = a[0][0] * c00 + a[0][1] * c01 + a[0][2] * c02;
  if (!(std::fabs(det) > 1e-300) || !std::isfinite(det)) return false;
  const double inv = 1.0 / det;
  out[0][0] = c00 * inv;
  out[0][1] = (a[0][2] * a[2][1] - a[0][1] * a[2][2]) * inv;
  out[0][2] = (a[0][1] * a[1][2] - a[0][2] * a[1][1]) * inv;
  out[1][0] = c01 * inv;
  out[1][1] = (a[0][0] * a[2][2] - a[0][2] * a[2][0]) * inv;
  out[1][2] = (a[0][2] * a[1][0] - a[0][0] * a[1][2]) * inv;
  out[2][0] = c02 * inv;
  out[2][1] = (a[0][1] * a[2][0] - a[0][0] * a[2][1]) * inv;
  out[2][2] = (a[0][0] * a[1][1] - a[0][1] * a[1][0]) * inv;
  return true;
}

}  // namespace

DisturbanceObserver::DisturbanceObserver(const DisturbanceSettings& s, int vehicles, int vehicle_nx,
                                         float nominal_mass, int vel)
    : s_(s),
      vehicles_(vehicles),
      vnx_(vehicle_nx),
      vel_(vel),
      prev_(static_cast<std::size_t>(vehicles * vehicle_nx)),
      pred_(prev_.size()),
      mass_nominal_(nominal_mass) {
  reset();
}

void DisturbanceObserver::reset() {
  have_prev_ = false;
  std::fill(std::begin(est_), std::end(est_), 0.0f);
  theta_ = 1.0;
  for (auto& row : cov_) std::fill(std::begin(row), std::end(row), 0.0);
  // The prior: the nominal mass to prior_std; the external acceleration as settled as its
  // own random walk would leave it (gain dt / tau per state at the nominal state period).
  const double r = s_.mass.accel_noise * s_.mass.accel_noise;
  cov_[0][0] = s_.mass.prior_std * s_.mass.prior_std;
  for (int i = 1; i < 4; ++i) cov_[i][i] = r * kNominalDt / std::max(1e-3, s_.time_constant_s);
}

void DisturbanceObserver::set_nominal_mass(float kg) {
  mass_nominal_ = kg;
  reset();
}

void DisturbanceObserver::apply(Controller& c) const {
  c.set_external_accel(est_);
  if (estimates_mass()) c.set_mass(mass());
}

// The velocity change from `from` to `to` (all vehicles), as an acceleration averaged over them.
void DisturbanceObserver::mean_velocity_change(const float* from, const float* to, double dt, double out[3]) const {
  for (int d = 0; d < 3; ++d) out[d] = 0.0;
  for (int j = 0; j < vehicles_; ++j)
    for (int d = 0; d < 3; ++d) {
      const std::size_t i = static_cast<std::size_t>(j * vnx_ + vel_ + d);
      out[d] += (static_cast<double>(to[i]) - from[i]) / dt / vehicles_;
    }
}

bool DisturbanceObserver::update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns) {
  bool changed = false;
  const std::int64_t gap = t_ns - t_prev_;
  if (have_prev_ && gap > 0 && gap <= s_.max_gap_ns) {
    std::copy(prev_.begin(), prev_.end(), pred_.begin());
    h.predict(c, pred_.data(), t_prev_, t_ns);
    const double dt = static_cast<double>(gap) * 1e-9;
    double r[3];
    mean_velocity_change(pred_.data(), x, dt, r);
    if (std::isfinite(r[0]) && std::isfinite(r[1]) && std::isfinite(r[2])) {
      if (estimates_mass()) {
        // d(predicted acceleration)/d(theta): the quadrotor models' acceleration is
        // theta f / m0 + gravity + a (f: thrust and drag, m = m0 / theta), so it is the
        // predicted specific force over theta.
        double a[3], j[3];
        mean_velocity_change(prev_.data(), pred_.data(), dt, a);
        for (int d = 0; d < 3; ++d) j[d] = (a[d] - est_[d] + (d == 2 ? kGravity : 0.0)) / theta_;
        kalman(r, j, dt);
      } else {
        integrate(r, dt);
      }
      ++updates_;
      changed = true;
    }
  }
  std::copy_n(x, prev_.size(), prev_.begin());
  t_prev_ = t_ns;
  have_prev_ = true;
  return changed;
}

// The external acceleration alone: a first-order low-pass of the residual (integral action).
void DisturbanceObserver::integrate(const double r[3], double dt) {
  const double alpha = std::min(1.0, dt / std::max(1e-3, s_.time_constant_s));
  for (int d = 0; d < 3; ++d) {
    const double next = est_[d] + alpha * r[d];
    est_[d] = static_cast<float>(std::clamp(next, -static_cast<double>(s_.limit), static_cast<double>(s_.limit)));
  }
}

// One Kalman step over s = (theta, a_x, a_y, a_z), each a random walk, measuring the residual
// acceleration r = H (s_true - s) + noise with H = [j | I].
void DisturbanceObserver::kalman(const double r[3], const double j[3], double dt) {
  const double noise = s_.mass.accel_noise * s_.mass.accel_noise;
  add_process_noise(noise, dt);
  double ph[4][3], gain[4][3];
  if (!kalman_gain(j, noise, ph, gain)) return;
  double step[4];
  for (int i = 0; i < 4; ++i) step[i] = gain[i][0] * r[0] + gain[i][1] * r[1] + gain[i][2] * r[2];
  update_covariance(gain, ph);
  const double lo = 1.0 / (1.0 + s_.mass.max_change), hi = 1.0 / std::max(1e-3, 1.0 - s_.mass.max_change);
  theta_ = std::clamp(theta_ + step[0], lo, hi);
  const double limit = s_.limit;
  for (int d = 0; d < 3; ++d) est_[d] = static_cast<float>(std::clamp(est_[d] + step[d + 1], -limit, limit));
}

// The process noise is set so that, alone, each state would follow a step with its time
// constant (gain dt / tau per state).
void DisturbanceObserver::add_process_noise(double noise, double dt) {
  const double k_theta = dt / std::max(1e-3, s_.mass.time_constant_s) / kGravity;
  const double k_accel = dt / std::max(1e-3, s_.time_constant_s);
  cov_[0][0] += noise * k_theta * k_theta;
  for (int i = 1; i < 4; ++i) cov_[i][i] += noise * k_accel * k_accel;
}

// PH' (4x3) into ph, and the gain K = PH' S^-1 with S = H P H' + R (3x3); false when S is
// singular.
bool DisturbanceObserver::kalman_gain(const double j[3], double noise, double ph[4][3], double gain[4][3]) const {
  double hph[3][3], s_inv[3][3];
  for (int i = 0; i < 4; ++i)
    for (int m = 0; m < 3; ++m) ph[i][m] = cov_[i][0] * j[m] + cov_[i][m + 1];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) hph[a][b] = j[a] * ph[0][b] + ph[a + 1][b] + (a == b ? noise : 0.0);
  if (!invert3(hph, s_inv)) return false;
  for (int i = 0; i < 4; ++i)
    for (int m = 0; m < 3; ++m) gain[i][m] = ph[i][0] * s_inv[0][m] + ph[i][1] * s_inv[1][m] + ph[i][2] * s_inv[2][m];
  return true;
}

// P <- P - K (H P) with H P = (P H')', kept symmetric.
void DisturbanceObserver::update_covariance(const double gain[4][3], const double ph[4][3]) {
  double next[4][4];
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) next[a][b] = cov_[a][b] - (gain[a][0] * ph[b][0] + gain[a][1] * ph[b][1] + gain[a][2] * ph[b][2]);
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) cov_[a][b] = 0.5 * (next[a][b] + next[b][a]);
}

}  // namespace mppi::daemon
