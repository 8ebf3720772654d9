#include "sim/plant.hpp"

#include <cstdint>
#include <mppi_lcm/command_t.hpp>
#include <mppi_lcm/vehicle_state_t.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "mppi/models/cartpole.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"
#include "mppi/models/racecar.hpp"
#include "mppi/params.hpp"
#include "mppi/rk4.hpp"

namespace sim {
namespace {

using mppi_lcm::command_t;
using mppi_lcm::vehicle_state_t;

template <class Params>
Params plant_params(const Scenario& s) {
  Params p;
  for (const auto& kv : s.params) {
    const std::string& key = kv.first;  // not a structured binding: C++17 lambdas cannot capture those
    const double value = kv.second;
    bool found = false;
    mppi::visit_fields(p, [&](const char* name, float& field, float lo, float hi) {
      if (key != name) return;
      found = true;
      const auto v = static_cast<float>(value);
      if (!(v >= lo && v <= hi))
        throw std::runtime_error("plant.params." + key + ": " + std::to_string(value) + " outside [" +
                                 std::to_string(lo) + ", " + std::to_string(hi) + "]");
      field = v;
    });
    if (!found) throw std::runtime_error("plant.params." + key + ": unknown parameter of " + s.model);
  }
  return p;
}

float clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

// q = qz(yaw) qx(roll) qy(pitch): core's ZXY Euler convention, R_WB = Rz Rx Ry.
void zxy_quaternion(double roll, double pitch, double yaw, double* q) {
  const double cz = std::cos(0.5 * yaw), sz = std::sin(0.5 * yaw), cx = std::cos(0.5 * roll), sx = std::sin(0.5 * roll);
  const double cy = std::cos(0.5 * pitch), sy = std::sin(0.5 * pitch);
  // qz * qx = (cz cx, cz sx, sz sx, sz cx); then * qy.
  const double aw = cz * cx, ax = cz * sx, ay = sz * sx, az = sz * cx;
  q[0] = aw * cy - ay * sy;
  q[1] = ax * cy - az * sy;
  q[2] = aw * sy + ay * cy;
  q[3] = az * cy + ax * sy;
}

// M vehicles of one core model.
template <class Model>
class ModelPlant : public Plant {
 public:
  explicit ModelPlant(const Scenario& s) : p_(plant_params<typename Model::Params>(s)), s_(s) {
    vehicles_ = s.vehicles;
    x_.assign(static_cast<std::size_t>(Model::kNx * vehicles_), 0.0f);
    for (int v = 0; v < vehicles_; ++v) init(v, x_.data() + v * Model::kNx);
  }
  int nx() const override { return Model::kNx; }
  int nu() const override { return Model::kNu; }
  std::int8_t model_id() const override;
  std::int8_t command_kind() const override;
  bool flies() const override;

  void step(const float* u, const double* wind, double h) override {
    const float hf = static_cast<float>(h);
    for (int v = 0; v < vehicles_; ++v) {
      if ((frozen >> v) & 1u) continue;
      float* xv = x_.data() + v * Model::kNx;
      const float* uv = u + v * Model::kNu;
      float accel[3] = {0.0f, 0.0f, 0.0f};
      const int vel = wind_accel(wind, accel);
      mppi::rk4_model<Model>(p_, xv, uv, hf, accel, vel);
      post_step(xv);
    }
  }
  bool saturate(float* u) const override {
    for (int i = 0; i < Model::kNu * vehicles_; ++i)
      if (!std::isfinite(u[i])) return false;
    for (int v = 0; v < vehicles_; ++v) clamp(u + v * Model::kNu);
    return true;
  }
  void position(int v, double* pos) const override;
  void attitude(int v, double* q) const override { Plant::attitude(v, q); }
  double speed(int v) const override;
  std::vector<float> hover() const override;
  std::vector<float> failsafe() const override { return hover(); }
  StateGroup group(int i) const override;
  void fix_published(float* x) const override;

 private:
  void init(int v, float* x) const;
  int wind_accel(const double* wind, float* accel) const;
  // Back onto the model's manifold (unit quaternion) after a step: core's own projection.
  void post_step(float* x) const { Model::project(x); }
  void clamp(float* u) const;

  typename Model::Params p_;
  const Scenario& s_;
};

// ---- quadrotor (16 states, motor speeds) ---------------------------------------------
using mppi::Quadrotor;
template <> std::int8_t ModelPlant<Quadrotor>::model_id() const { return vehicle_state_t::MODEL_QUADROTOR; }
template <> std::int8_t ModelPlant<Quadrotor>::command_kind() const { return command_t::KIND_MOTOR_SPEEDS; }
template <> bool ModelPlant<Quadrotor>::flies() const { return true; }
template <> void ModelPlant<Quadrotor>::init(int v, float* x) const {
  for (std::size_t i = 0; i < s_.initial_state.size() && i < Quadrotor::kNx; ++i)
    x[i] = static_cast<float>(s_.initial_state[i]);
  const Vec3 st = s_.start_of(v);
  for (int i = 0; i < 3; ++i) x[Quadrotor::PX + i] = static_cast<float>(st[static_cast<std::size_t>(i)]);
  if (s_.initial_state.empty())
    for (int i = 0; i < 4; ++i) x[Quadrotor::M1 + i] = Quadrotor::hover_speed(p_);
}
template <> int ModelPlant<Quadrotor>::wind_accel(const double* wind, float* accel) const {
  for (int i = 0; i < 3; ++i) accel[i] = static_cast<float>(p_.drag / p_.mass * wind[i]);
  return Quadrotor::VX;
}
template <> void ModelPlant<Quadrotor>::clamp(float* u) const {
  for (int i = 0; i < 4; ++i) u[i] = clampf(u[i], 0.0f, static_cast<float>(s_.max_motor_speed));
}
template <> void ModelPlant<Quadrotor>::position(int v, double* pos) const {
  for (int i = 0; i < 3; ++i) pos[i] = x_[static_cast<std::size_t>(v * Quadrotor::kNx + i)];
}
template <> void ModelPlant<Quadrotor>::attitude(int v, double* q) const {
  const float* x = x_.data() + v * Quadrotor::kNx;
  zxy_quaternion(x[Quadrotor::ROLL], x[Quadrotor::PITCH], x[Quadrotor::YAW], q);
}
template <> double ModelPlant<Quadrotor>::speed(int v) const {
  const float* x = x_.data() + v * Quadrotor::kNx;
  const double vx = x[Quadrotor::VX], vy = x[Quadrotor::VY], vz = x[Quadrotor::VZ];
  return std::sqrt(vx * vx + vy * vy + vz * vz);
}
template <> std::vector<float> ModelPlant<Quadrotor>::hover() const {
  return std::vector<float>(static_cast<std::size_t>(4 * vehicles_), Quadrotor::hover_speed(p_));
}
template <> StateGroup ModelPlant<Quadrotor>::group(int i) const {
  const int k = i % Quadrotor::kNx;
  if (k < 3) return StateGroup::kPosition;
  if (k < 6) return StateGroup::kVelocity;
  if (k < 9) return StateGroup::kAttitude;
  if (k < 12) return StateGroup::kRate;
  return StateGroup::kOther;
}
template <> void ModelPlant<Quadrotor>::fix_published(float*) const {}

// ---- rate-controlled quadrotor (13 states, thrust + body rates) -----------------------
using mppi::QuadrotorRate;
template <> std::int8_t ModelPlant<QuadrotorRate>::model_id() const { return vehicle_state_t::MODEL_QUADROTOR_RATE; }
template <> std::int8_t ModelPlant<QuadrotorRate>::command_kind() const { return command_t::KIND_THRUST_RATES; }
template <> bool ModelPlant<QuadrotorRate>::flies() const { return true; }
template <> void ModelPlant<QuadrotorRate>::init(int v, float* x) const {
  for (std::size_t i = 0; i < s_.initial_state.size() && i < QuadrotorRate::kNx; ++i)
    x[i] = static_cast<float>(s_.initial_state[i]);
  if (s_.initial_state.empty()) x[QuadrotorRate::QW] = 1.0f;
  const Vec3 st = s_.start_of(v);
  for (int i = 0; i < 3; ++i) x[QuadrotorRate::PX + i] = static_cast<float>(st[static_cast<std::size_t>(i)]);
}
template <> int ModelPlant<QuadrotorRate>::wind_accel(const double* wind, float* accel) const {
  for (int i = 0; i < 3; ++i) accel[i] = static_cast<float>(p_.drag / p_.mass * wind[i]);
  return QuadrotorRate::VX;
}
template <> void ModelPlant<QuadrotorRate>::clamp(float* u) const {
  u[0] = clampf(u[0] * static_cast<float>(s_.thrust_gain), 0.0f, static_cast<float>(s_.max_thrust));
  const auto r = static_cast<float>(s_.max_body_rate);
  for (int i = 1; i < 4; ++i) u[i] = clampf(u[i], -r, r);
}
template <> void ModelPlant<QuadrotorRate>::position(int v, double* pos) const {
  for (int i = 0; i < 3; ++i) pos[i] = x_[static_cast<std::size_t>(v * QuadrotorRate::kNx + i)];
}
template <> void ModelPlant<QuadrotorRate>::attitude(int v, double* q) const {
  for (int i = 0; i < 4; ++i) q[i] = x_[static_cast<std::size_t>(v * QuadrotorRate::kNx + QuadrotorRate::QW + i)];
}
template <> double ModelPlant<QuadrotorRate>::speed(int v) const {
  const float* x = x_.data() + v * QuadrotorRate::kNx;
  const double vx = x[QuadrotorRate::VX], vy = x[QuadrotorRate::VY], vz = x[QuadrotorRate::VZ];
  return std::sqrt(vx * vx + vy * vy + vz * vz);
}
// An autopilot's failsafe for a 13-state rate quadrotor view x: body rates that turn the
// thrust axis back to vertical (P on the tilt, yaw rate 0) and the thrust that holds the
// altitude (P on the vertical speed, divided by the tilt's cosine).
void level_and_hold(const float* x, float mass, float gravity, float* u) {
  using Q = QuadrotorRate;
  const float qw = x[Q::QW], qx = x[Q::QX], qy = x[Q::QY], qz = x[Q::QZ];
  const float r1[3] = {1.0f - 2.0f * (qy * qy + qz * qz), 2.0f * (qx * qy + qw * qz), 2.0f * (qx * qz - qw * qy)};
  const float r2[3] = {2.0f * (qx * qy - qw * qz), 1.0f - 2.0f * (qx * qx + qz * qz), 2.0f * (qy * qz + qw * qx)};
  const float b3[3] = {2.0f * (qx * qz + qw * qy), 2.0f * (qy * qz - qw * qx), 1.0f - 2.0f * (qx * qx + qy * qy)};
  const float e[3] = {b3[1], -b3[0], 0.0f};  // b3 x e_z: the axis that turns b3 up
  constexpr float kLevel = 4.0f, kClimb = 2.0f;
  u[0] = std::max(0.0f, mass * (gravity - kClimb * x[Q::VZ]) / std::max(b3[2], 0.5f));
  u[1] = kLevel * (r1[0] * e[0] + r1[1] * e[1] + r1[2] * e[2]);
  u[2] = kLevel * (r2[0] * e[0] + r2[1] * e[1] + r2[2] * e[2]);
  u[3] = 0.0f;
}
template <> std::vector<float> ModelPlant<QuadrotorRate>::failsafe() const {
  std::vector<float> u(static_cast<std::size_t>(4 * vehicles_));
  for (int v = 0; v < vehicles_; ++v)
    level_and_hold(x_.data() + v * QuadrotorRate::kNx, p_.mass, p_.gravity, u.data() + 4 * v);
  saturate(u.data());
  return u;
}
template <> std::vector<float> ModelPlant<QuadrotorRate>::hover() const {
  std::vector<float> u(static_cast<std::size_t>(4 * vehicles_), 0.0f);
  for (int v = 0; v < vehicles_; ++v) u[static_cast<std::size_t>(4 * v)] = QuadrotorRate::hover_thrust(p_);
  return u;
}
template <> StateGroup ModelPlant<QuadrotorRate>::group(int i) const {
  const int k = i % QuadrotorRate::kNx;
  if (k < 3) return StateGroup::kPosition;
  if (k < 6) return StateGroup::kVelocity;
  if (k < 10) return StateGroup::kAttitude;
  return StateGroup::kRate;
}
template <> void ModelPlant<QuadrotorRate>::fix_published(float* x) const {
  for (int v = 0; v < vehicles_; ++v) post_step(x + v * QuadrotorRate::kNx);
}

// ---- cart-pole ------------------------------------------------------------------------
using mppi::Cartpole;
template <> std::int8_t ModelPlant<Cartpole>::model_id() const { return vehicle_state_t::MODEL_CARTPOLE; }
template <> std::int8_t ModelPlant<Cartpole>::command_kind() const { return command_t::KIND_GENERIC; }
template <> bool ModelPlant<Cartpole>::flies() const { return false; }
template <> void ModelPlant<Cartpole>::init(int, float* x) const {
  for (std::size_t i = 0; i < s_.initial_state.size() && i < Cartpole::kNx; ++i)
    x[i] = static_cast<float>(s_.initial_state[i]);
}
template <> int ModelPlant<Cartpole>::wind_accel(const double*, float*) const { return -1; }
template <> void ModelPlant<Cartpole>::clamp(float*) const {}
template <> void ModelPlant<Cartpole>::position(int, double* pos) const {
  pos[0] = x_[Cartpole::X];
  pos[1] = 0.0;
  pos[2] = 0.0;
}
template <> double ModelPlant<Cartpole>::speed(int) const { return std::fabs(double(x_[Cartpole::XDOT])); }
template <> std::vector<float> ModelPlant<Cartpole>::hover() const { return {0.0f}; }
template <> StateGroup ModelPlant<Cartpole>::group(int i) const {
  switch (i) {
    case Cartpole::X: return StateGroup::kPosition;
    case Cartpole::XDOT: return StateGroup::kVelocity;
    case Cartpole::THETA: return StateGroup::kAttitude;
    case Cartpole::THETADOT: return StateGroup::kRate;
    default: return StateGroup::kOther;
  }
}
template <> void ModelPlant<Cartpole>::fix_published(float*) const {}

// ---- race car ---------------------------------------------------------------------------
using mppi::Racecar;
template <> std::int8_t ModelPlant<Racecar>::model_id() const { return vehicle_state_t::MODEL_RACECAR; }
template <> std::int8_t ModelPlant<Racecar>::command_kind() const { return command_t::KIND_GENERIC; }
template <> bool ModelPlant<Racecar>::flies() const { return false; }
template <> void ModelPlant<Racecar>::init(int, float* x) const {
  for (std::size_t i = 0; i < s_.initial_state.size() && i < Racecar::kNx; ++i)
    x[i] = static_cast<float>(s_.initial_state[i]);
}
template <> int ModelPlant<Racecar>::wind_accel(const double*, float*) const { return -1; }
template <> void ModelPlant<Racecar>::clamp(float* u) const {
  u[Racecar::STEER] = clampf(u[Racecar::STEER], -0.6f, 0.6f);  // steering lock, rad
}
template <> void ModelPlant<Racecar>::position(int, double* pos) const {
  pos[0] = x_[Racecar::X];
  pos[1] = x_[Racecar::Y];
  pos[2] = 0.0;
}
template <> double ModelPlant<Racecar>::speed(int) const {
  return std::hypot(double(x_[Racecar::VX]), double(x_[Racecar::VY]));
}
template <> std::vector<float> ModelPlant<Racecar>::hover() const { return {0.0f, 0.0f}; }
template <> StateGroup ModelPlant<Racecar>::group(int i) const {
  switch (i) {
    case Racecar::X:
    case Racecar::Y: return StateGroup::kPosition;
    case Racecar::VX:
    case Racecar::VY: return StateGroup::kVelocity;
    case Racecar::PSI:
    case Racecar::BETA: return StateGroup::kAttitude;
    case Racecar::R: return StateGroup::kRate;
    default: return StateGroup::kOther;
  }
}
template <> void ModelPlant<Racecar>::fix_published(float*) const {}


// ---- rate-controlled quadrotor as a rigid body with an autopilot -----------------------
// The 16-state quadrotor (motors with their lag included) under a P body-rate loop and a
// mixer, as an autopilot runs it, at the physics rate: it takes the rate-controlled tasks'
// commands (thrust, body rates) and publishes their 13-state view (position, velocity,
// attitude quaternion, body rates). Unlike the quadrotor_rate plant, its rate response is
// not the controller's first-order lag but a P loop through the motor lag: a real mismatch.
class RateBodyPlant : public Plant {
 public:
  explicit RateBodyPlant(const Scenario& s) : p_(plant_params<Quadrotor::Params>(s)), s_(s) {
    vehicles_ = s.vehicles;
    body_.assign(static_cast<std::size_t>(Quadrotor::kNx * vehicles_), 0.0f);
    x_.assign(static_cast<std::size_t>(QuadrotorRate::kNx * vehicles_), 0.0f);
    for (int v = 0; v < vehicles_; ++v) {
      float* b = body_.data() + v * Quadrotor::kNx;
      const Vec3 st = s.start_of(v);
      for (int i = 0; i < 3; ++i) b[i] = static_cast<float>(st[static_cast<std::size_t>(i)]);
      for (int i = 0; i < 4; ++i) b[Quadrotor::M1 + i] = Quadrotor::hover_speed(p_);
    }
    publish_view();
  }
  int nx() const override { return QuadrotorRate::kNx; }
  int nu() const override { return QuadrotorRate::kNu; }
  std::int8_t model_id() const override { return vehicle_state_t::MODEL_QUADROTOR_RATE; }
  std::int8_t command_kind() const override { return command_t::KIND_THRUST_RATES; }
  bool flies() const override { return true; }

  void step(const float* u, const double* wind, double h) override {
    float accel[3];
    for (int i = 0; i < 3; ++i) accel[i] = static_cast<float>(p_.drag / p_.mass * wind[i]);
    for (int v = 0; v < vehicles_; ++v) {
      if ((frozen >> v) & 1u) continue;
      float* b = body_.data() + v * Quadrotor::kNx;
      float motors[4];
      autopilot(b, u + v * QuadrotorRate::kNu, motors);
      mppi::rk4_model<Quadrotor>(p_, b, motors, static_cast<float>(h), accel, Quadrotor::VX);
    }
    publish_view();
  }
  bool saturate(float* u) const override {
    for (int i = 0; i < QuadrotorRate::kNu * vehicles_; ++i)
      if (!std::isfinite(u[i])) return false;
    const auto r = static_cast<float>(s_.max_body_rate);
    for (int v = 0; v < vehicles_; ++v) {
      float* uv = u + v * QuadrotorRate::kNu;
      uv[0] = clampf(uv[0] * static_cast<float>(s_.thrust_gain), 0.0f, static_cast<float>(s_.max_thrust));
      for (int i = 1; i < 4; ++i) uv[i] = clampf(uv[i], -r, r);
    }
    return true;
  }
  void position(int v, double* pos) const override {
    for (int i = 0; i < 3; ++i) pos[i] = body_[static_cast<std::size_t>(v * Quadrotor::kNx + i)];
  }
  void attitude(int v, double* q) const override {
    const float* b = body_.data() + v * Quadrotor::kNx;
    zxy_quaternion(b[Quadrotor::ROLL], b[Quadrotor::PITCH], b[Quadrotor::YAW], q);
  }
  double speed(int v) const override {
    const float* b = body_.data() + v * Quadrotor::kNx;
    return std::sqrt(double(b[3]) * b[3] + double(b[4]) * b[4] + double(b[5]) * b[5]);
  }
  std::vector<float> hover() const override {
    std::vector<float> u(static_cast<std::size_t>(4 * vehicles_), 0.0f);
    for (int v = 0; v < vehicles_; ++v) u[static_cast<std::size_t>(4 * v)] = p_.mass * p_.gravity;
    return u;
  }
  std::vector<float> failsafe() const override {
    std::vector<float> u(static_cast<std::size_t>(4 * vehicles_));
    for (int v = 0; v < vehicles_; ++v)
      level_and_hold(x_.data() + v * QuadrotorRate::kNx, p_.mass, p_.gravity, u.data() + 4 * v);
    saturate(u.data());
    return u;
  }
  StateGroup group(int i) const override {
    const int k = i % QuadrotorRate::kNx;
    if (k < 3) return StateGroup::kPosition;
    if (k < 6) return StateGroup::kVelocity;
    if (k < 10) return StateGroup::kAttitude;
    return StateGroup::kRate;
  }
  void fix_published(float* x) const override {
    for (int v = 0; v < vehicles_; ++v) {
      float* q = x + v * QuadrotorRate::kNx + QuadrotorRate::QW;
      const float n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      if (n > 0.0f)
        for (int i = 0; i < 4; ++i) q[i] /= n;
    }
  }

 private:
  // Desired torques from the P rate loop (plus the gyroscopic term), then the mixer:
  // T = sum F, tx = L (F2 - F4), ty = L (F3 - F1), tz = (kM / kF)(F1 - F2 + F3 - F4).
  void autopilot(const float* b, const float* u, float* motors) const {
    const float k = static_cast<float>(s_.rate_gain);
    const float wx = b[Quadrotor::WX], wy = b[Quadrotor::WY], wz = b[Quadrotor::WZ];
    const float tx = p_.ixx * k * (u[1] - wx) + (wy * p_.izz * wz - wz * p_.iyy * wy);
    const float ty = p_.iyy * k * (u[2] - wy) + (wz * p_.ixx * wx - wx * p_.izz * wz);
    const float tz = p_.izz * k * (u[3] - wz) + (wx * p_.iyy * wy - wy * p_.ixx * wx);
    const float half = 0.5f * u[0], c = p_.k_moment / p_.k_force;
    const float f[4] = {0.5f * (half + tz / (2.0f * c) - ty / p_.arm), 0.5f * (half - tz / (2.0f * c) + tx / p_.arm),
                        0.5f * (half + tz / (2.0f * c) + ty / p_.arm), 0.5f * (half - tz / (2.0f * c) - tx / p_.arm)};
    for (int i = 0; i < 4; ++i)
      motors[i] = clampf(std::sqrt(std::max(f[i], 0.0f) / p_.k_force), 0.0f, static_cast<float>(s_.max_motor_speed));
  }
  // The 13-state view: position, velocity, q = qz(yaw) qx(roll) qy(pitch) (core's ZXY
  // Euler convention, R_WB = Rz Rx Ry), body rates.
  void publish_view() {
    for (int v = 0; v < vehicles_; ++v) {
      const float* b = body_.data() + v * Quadrotor::kNx;
      float* x = x_.data() + v * QuadrotorRate::kNx;
      for (int i = 0; i < 6; ++i) x[i] = b[i];
      const double hr = 0.5 * b[Quadrotor::ROLL], hp = 0.5 * b[Quadrotor::PITCH], hy = 0.5 * b[Quadrotor::YAW];
      const double cz = std::cos(hy), sz = std::sin(hy), cx = std::cos(hr), sx = std::sin(hr);
      const double cy = std::cos(hp), sy = std::sin(hp);
      // qz * qx = (cz cx, cz sx, sz sx, sz cx); then * qy.
      const double aw = cz * cx, ax = cz * sx, ay = sz * sx, az = sz * cx;
      x[QuadrotorRate::QW] = static_cast<float>(aw * cy - ay * sy);
      x[QuadrotorRate::QX] = static_cast<float>(ax * cy - az * sy);
      x[QuadrotorRate::QY] = static_cast<float>(aw * sy + ay * cy);
      x[QuadrotorRate::QZ] = static_cast<float>(az * cy + ax * sy);
      x[QuadrotorRate::WX] = b[Quadrotor::WX];
      x[QuadrotorRate::WY] = b[Quadrotor::WY];
      x[QuadrotorRate::WZ] = b[Quadrotor::WZ];
    }
  }

  Quadrotor::Params p_;
  const Scenario& s_;
  std::vector<float> body_;  // 16 states per vehicle: the truth
};

}  // namespace

std::unique_ptr<Plant> make_plant(const Scenario& s) {
  if (s.model == "quadrotor") return std::make_unique<ModelPlant<Quadrotor>>(s);
  if (s.model == "quadrotor_rate") return std::make_unique<ModelPlant<QuadrotorRate>>(s);
  if (s.model == "quadrotor_rate_body") return std::make_unique<RateBodyPlant>(s);
  if (s.model == "cartpole") return std::make_unique<ModelPlant<Cartpole>>(s);
  if (s.model == "racecar") return std::make_unique<ModelPlant<Racecar>>(s);
  throw std::runtime_error("plant.model: unknown model '" + s.model + "'");
}

}  // namespace sim
