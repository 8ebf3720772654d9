// Disturbance observer: what the model does not know (a heavier vehicle, weaker motors,
// wind through drag) shows as a steady difference between the velocity the model predicts
// from the last state through the commands sent and the velocity then measured. Its
// low-passed integral is an external acceleration (world frame) that the model adds to
// every vehicle (Controller::set_external_accel), so the optimizer plans with it: integral
// action, without which a mismatched quadrotor sinks at a steady rate. Fixed buffers.
//
// With the mass estimate on (daemon.disturbance.mass.estimate) the same residual also moves
// the mass the model flies with (Controller::set_mass), as PX4's hover-thrust estimator does
// on the vertical axis: a Kalman filter over (theta, a_x, a_y, a_z), theta = m0 / m the thrust
// each newton of the model's command really buys, a the external acceleration. A mass
// error shows in proportion to the thrust (when the vehicle banks, climbs or brakes); an
// external acceleration does not: the filter tells them apart by the thrust's direction and
// size, which the prediction gives (its specific force). A payload then changes what every
// rollout's thrust does, and the control cost's nominal follows the hover it needs
// (Controller::set_mass), instead of a constant pull the model would keep at any thrust.
#pragma once

#include <cstdint>
#include <vector>

#include "mppi/controller.hpp"
#include "mppi/daemon/state_predictor.hpp"

namespace mppi::daemon {

struct MassEstimateSettings {
  bool estimate = false;
  double time_constant_s = 1.0;  // steady-state response of the estimate, at hover
  double prior_std = 0.2;        // how well the nominal mass is known (fraction, 1 sigma)
  double max_change = 0.5;       // the estimate stays within m0 (1 +- max_change)
  double accel_noise = 1.0;      // m/s^2, std of one state's acceleration residual
};

struct DisturbanceSettings {
  bool estimate = true;
  double time_constant_s = 0.5;            // of the low-pass on the residual acceleration
  float limit = 4.0f;                      // |estimate| per axis, m/s^2
  std::int64_t max_gap_ns = 100'000'000;   // states further apart restart the comparison
  MassEstimateSettings mass;
};

class DisturbanceObserver {
 public:
  // nx states per vehicle, velocity at [vel, vel + 3) of each (the quadrotor models: 3);
  // nominal_mass: the model's mass at start (the mass estimate's prior; 0: no mass).
  DisturbanceObserver(const DisturbanceSettings& s, int vehicles, int vehicle_nx, float nominal_mass = 0.0f,
                      int vel = 3);

  // A new state x (all vehicles), sampled at t_ns on the loop's timeline. Compares it with
  // the previous state predicted to t_ns through the commands in `h`, with the model as it
  // is now (its current estimates included): the residual moves the estimates. Returns true
  // when they changed.
  bool update(const Controller& c, const CommandHistory& h, const float* x, std::int64_t t_ns);
  // The estimates into the model: the external acceleration, and the mass when estimated.
  void apply(Controller& c) const;
  void reset();
  // A new nominal mass (a model.mass update at run time): the estimate starts from it.
  void set_nominal_mass(float kg);
  const float* estimate() const { return est_; }
  // The mass the model flies with: the estimate when on, else the nominal mass.
  float mass() const { return static_cast<float>(mass_nominal_ / theta_); }
  bool estimates_mass() const { return s_.mass.estimate && mass_nominal_ > 0.0; }
  std::int64_t updates() const { return updates_; }

 private:
  void integrate(const double r[3], double dt);
  void kalman(const double r[3], const double j_theta[3], double dt);
  void add_process_noise(double noise, double dt);
  bool kalman_gain(const double j[3], double noise, double ph[4][3], double gain[4][3]) const;
  void update_covariance(const double gain[4][3], const double ph[4][3]);
  void mean_velocity_change(const float* from, const float* to, double dt, double out[3]) const;

  DisturbanceSettings s_;
  int vehicles_, vnx_, vel_;
  std::vector<float> prev_, pred_;
  std::int64_t t_prev_ = 0;
  bool have_prev_ = false;
  float est_[3] = {0.0f, 0.0f, 0.0f};
  double mass_nominal_ = 0.0, theta_ = 1.0;
  double cov_[4][4] = {};  // of (theta, a_x, a_y, a_z)
  std::int64_t updates_ = 0;
};

}  // namespace mppi::daemon
