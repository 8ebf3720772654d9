// The simulated vehicles: M copies of one core model (M = 1 unless a team), integrated
// with RK4 from the model's own derivative() but with the plant's parameter values, which
// may differ from the controller's (mass, drag, motor constant) to test robustness.
//
// The rate-controlled quadrotor's plant is core's QuadrotorRate model: rigid-body
// translation with a quaternion attitude whose body rates follow the commanded rates as a
// first-order lag (time constant rate_tau), i.e. an autopilot's rate loop seen from outside.
// Its thrust and rate setpoints saturate at the plant's limits, as an autopilot's would.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "sim/scenario.hpp"

namespace sim {

enum class StateGroup { kPosition, kVelocity, kAttitude, kRate, kOther };

class Plant {
 public:
  virtual ~Plant() = default;
  virtual int nx() const = 0;  // per vehicle
  virtual int nu() const = 0;  // per vehicle
  virtual std::int8_t model_id() const = 0;      // vehicle_state_t.MODEL_*
  virtual std::int8_t command_kind() const = 0;  // command_t.KIND_*
  virtual bool flies() const = 0;                // has altitude, ground and obstacles

  int vehicles() const { return vehicles_; }
  std::vector<float>& state() { return x_; }
  const std::vector<float>& state() const { return x_; }
  std::uint32_t frozen = 0;  // vehicles that crashed stay where they are

  // Advance all vehicles by h seconds with controls u (nu * vehicles, already saturated)
  // and wind velocity `wind` (m/s, acting through the plant's drag).
  virtual void step(const float* u, const double* wind, double h) = 0;
  // Clamp a command to the plant's physical limits in place; false if not finite.
  virtual bool saturate(float* u) const = 0;
  virtual void position(int v, double* p) const = 0;
  // Body -> world rotation, unit quaternion w, x, y, z (what the sensors are mounted on);
  // the identity for the ground plants.
  virtual void attitude(int v, double* q) const {
    (void)v;
    q[0] = 1.0;
    q[1] = q[2] = q[3] = 0.0;
  }
  virtual double speed(int v) const = 0;
  virtual std::vector<float> hover() const = 0;  // the control that holds the vehicles
  // What an autopilot's failsafe would command now (timing.command_timeout): the
  // rate-controlled quadrotors level themselves and hold their altitude; the others hover.
  virtual std::vector<float> failsafe() const { return hover(); }
  virtual StateGroup group(int i) const = 0;     // for state noise
  // After noise is added to a published copy: renormalise quaternions etc.
  virtual void fix_published(float*) const {}

 protected:
  int vehicles_ = 1;
  std::vector<float> x_;
};

// Throws std::runtime_error on an unknown or out-of-range parameter.
std::unique_ptr<Plant> make_plant(const Scenario& s);

}  // namespace sim
