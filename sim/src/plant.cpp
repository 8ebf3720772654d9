#include "sim/plant.hpp"

#include <mppi_lcm/command_t.hpp>
#include <mppi_lcm/vehicle_state_t.hpp>

#include <cmath>
#include <stdexcept>

#include "mppi/models/cartpole.hpp"
#include "mppi/models/quadrotor.hpp"
#include "mppi/models/quadrotor_rate.hpp"
#include "mppi/models/racecar.hpp"
#include "mppi/params.hpp"
#include "sim/rk4.hpp"

namespace sim {
namespace {

using mppi_lcm::command_t;
using mppi_lcm::vehicle_state_t;

template <class Params>
Params plant_params(const Scenario& s) {
  Params p;
  for (const auto& [key, value] : s.params) {
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
      rk4_model<Model>(p_, xv, uv, hf, accel, vel);
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
  double speed(int v) const override;
  std::vector<float> hover() const override;
  StateGroup group(int i) const override;
  void fix_published(float* x) const override;

 private:
  void init(int v, float* x) const;
  int wind_accel(const double* wind, float* accel) const;
  void post_step(float*) const {}
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
template <> double ModelPlant<Quadrotor>::speed(int v) const {
  const float* x = x_.data() + v * Quadrotor::kNx;
  return std::sqrt(double(x[3]) * x[3] + double(x[4]) * x[4] + double(x[5]) * x[5]);
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
template <> void ModelPlant<QuadrotorRate>::post_step(float* x) const {
  float n = 0.0f;
  for (int i = QuadrotorRate::QW; i <= QuadrotorRate::QZ; ++i) n += x[i] * x[i];
  n = std::sqrt(n);
  if (n > 0.0f)
    for (int i = QuadrotorRate::QW; i <= QuadrotorRate::QZ; ++i) x[i] /= n;
}
template <> void ModelPlant<QuadrotorRate>::clamp(float* u) const {
  u[0] = clampf(u[0], 0.0f, static_cast<float>(s_.max_thrust));
  const auto r = static_cast<float>(s_.max_body_rate);
  for (int i = 1; i < 4; ++i) u[i] = clampf(u[i], -r, r);
}
template <> void ModelPlant<QuadrotorRate>::position(int v, double* pos) const {
  for (int i = 0; i < 3; ++i) pos[i] = x_[static_cast<std::size_t>(v * QuadrotorRate::kNx + i)];
}
template <> double ModelPlant<QuadrotorRate>::speed(int v) const {
  const float* x = x_.data() + v * QuadrotorRate::kNx;
  return std::sqrt(double(x[3]) * x[3] + double(x[4]) * x[4] + double(x[5]) * x[5]);
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

}  // namespace

std::unique_ptr<Plant> make_plant(const Scenario& s) {
  if (s.model == "quadrotor") return std::make_unique<ModelPlant<Quadrotor>>(s);
  if (s.model == "quadrotor_rate") return std::make_unique<ModelPlant<QuadrotorRate>>(s);
  if (s.model == "cartpole") return std::make_unique<ModelPlant<Cartpole>>(s);
  if (s.model == "racecar") return std::make_unique<ModelPlant<Racecar>>(s);
  throw std::runtime_error("plant.model: unknown model '" + s.model + "'");
}

}  // namespace sim
