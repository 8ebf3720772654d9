// Adaptation and identification in the daemon: the mass estimate beside the disturbance
// observer (a Kalman filter over the thrust each newton buys and an external acceleration,
// on both quadrotor models), and the identification manoeuvre (doublets and thrust steps
// inside a safe box, started by the parameter daemon.identify).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "fakes.hpp"
#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/delay_estimator.hpp"
#include "mppi/daemon/disturbance_observer.hpp"
#include "mppi/daemon/identification.hpp"
#include "mppi/daemon/state_predictor.hpp"
#include "source_dir.hpp"

using namespace mppi;

namespace {
constexpr std::int64_t kMs = rt::kNsPerMs;

std::unique_ptr<Controller> controller(const char* task, std::vector<std::string> sets) {
  sets.insert(sets.end(), {"mppi.rollouts=16", "mppi.horizon=5", "mppi.threads=1", "mppi.simd=off"});
  const auto cfg = app::load_config(mppi::testing::source_dir() + "/config/tasks/" + task + ".yaml", sets);
  return app::make_controller(cfg);
}

daemon::DisturbanceSettings with_mass() {
  daemon::DisturbanceSettings s;
  s.mass.estimate = true;
  return s;
}

// The model flies `u` from x for `seconds` in 20 ms states while the plant (another
// controller's model: the truth) flies it; the observer, whose estimates enter the model,
// compares each state with its prediction.
void fly(Controller& model, Controller& plant, daemon::DisturbanceObserver& obs, float* x, const float* u,
         double seconds) {
  daemon::CommandHistory h(model.nu(), std::vector<float>(u, u + model.nu()));
  std::int64_t t = 0;
  for (int k = 0; k * 0.02 < seconds; ++k) {
    if (obs.update(model, h, x, t)) obs.apply(model);
    plant.propagate(x, u, 0.02f);
    t += 20 * kMs;
  }
}

// The rate model's state, level (or rolled by `roll`) at 2 m.
std::vector<float> rate_state(float roll = 0.0f) {
  std::vector<float> x(13, 0.0f);
  x[2] = 2.0f;
  x[6] = std::cos(roll / 2);
  x[7] = std::sin(roll / 2);
  return x;
}

}  // namespace

TEST(MassEstimate, APayloadOnTheRateModelIsFoundAsMassNotAsAPull) {
  // 20 % heavier than the vehicle file says; the plant hovers on its own hover thrust, which
  // the nominal model reads as a climb. The estimate finds the mass, not a constant pull.
  auto model = controller("quadrotor_rate_track", {});
  auto plant = controller("quadrotor_rate_track", {"vehicle=~", "model.mass=1.2"});
  daemon::DisturbanceObserver obs(with_mass(), 1, 13, model->mass());
  auto x = rate_state();
  const float u[4] = {1.2f * 9.81f, 0.0f, 0.0f, 0.0f};
  fly(*model, *plant, obs, x.data(), u, 3.0);
  EXPECT_NEAR(obs.mass(), 1.2f, 0.012f);
  EXPECT_NEAR(model->mass(), obs.mass(), 1e-6f);  // applied to the model
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(obs.estimate()[d], 0.0f, 0.05f);
}

TEST(MassEstimate, ThrustWhileBankedTellsMassFromAnExternalAcceleration) {
  // Banked by 0.3 rad with the thrust that holds the heavier plant's altitude: the residual
  // has a horizontal part in proportion to the thrust. The observer alone would call it all
  // an external acceleration (a sideways pull); with the mass estimate, it is the mass.
  auto model = controller("quadrotor_rate_track", {});
  auto plant = controller("quadrotor_rate_track", {"vehicle=~", "model.mass=1.2"});
  daemon::DisturbanceObserver obs(with_mass(), 1, 13, model->mass());
  auto x = rate_state(0.3f);
  const float u[4] = {1.2f * 9.81f / std::cos(0.3f), 0.0f, 0.0f, 0.0f};
  fly(*model, *plant, obs, x.data(), u, 3.0);
  EXPECT_NEAR(obs.mass(), 1.2f, 0.012f);
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(obs.estimate()[d], 0.0f, 0.1f);

  auto model2 = controller("quadrotor_rate_track", {});
  daemon::DisturbanceObserver accel_only(daemon::DisturbanceSettings{}, 1, 13, model2->mass());
  auto y = rate_state(0.3f);
  fly(*model2, *plant, accel_only, y.data(), u, 3.0);
  EXPECT_GT(std::fabs(accel_only.estimate()[1]), 0.3f);  // the sideways pull the mass estimate avoids
  EXPECT_FLOAT_EQ(model2->mass(), 1.0f);                  // and the mass is not touched when off
}

TEST(MassEstimate, WindIsAnExternalAccelerationAndLeavesTheMass) {
  // The right mass and a steady 0.6 m/s^2 push along x (wind): the mass stays, the push is found.
  auto model = controller("quadrotor_rate_track", {});
  auto plant = controller("quadrotor_rate_track", {"model.accel_x=0.6"});
  daemon::DisturbanceObserver obs(with_mass(), 1, 13, model->mass());
  auto x = rate_state();
  const float u[4] = {9.81f, 0.0f, 0.0f, 0.0f};
  fly(*model, *plant, obs, x.data(), u, 4.0);
  EXPECT_NEAR(obs.mass(), 1.0f, 0.01f);
  EXPECT_NEAR(obs.estimate()[0], 0.6f, 0.03f);
}

// The 16-state quadrotor (mass, k_force) hovering at 2 m on its own motor speeds, flown on
// them against the nominal model for 3 s: the observer's mass estimate then.
float motor_model_mass_estimate(daemon::DisturbanceObserver& obs, Controller& model, float mass, float k_force) {
  char sets[2][64];
  std::snprintf(sets[0], sizeof(sets[0]), "model.mass=%.9g", static_cast<double>(mass));
  std::snprintf(sets[1], sizeof(sets[1]), "model.k_force=%.9g", static_cast<double>(k_force));
  auto plant = controller("quadrotor_forest", {sets[0], sets[1]});
  Quadrotor::Params p;
  p.mass = mass;
  p.k_force = k_force;
  const float w = Quadrotor::hover_speed(p);
  std::vector<float> x(16, 0.0f);
  x[2] = 2.0f;
  for (int i = 12; i < 16; ++i) x[static_cast<std::size_t>(i)] = w;
  const float u[4] = {w, w, w, w};
  obs.reset();
  fly(model, *plant, obs, x.data(), u, 3.0);
  return obs.mass();
}

TEST(MassEstimate, TheMotorModelFindsItsMassTooAndStaysInItsBounds) {
  // 10 % heavier with 5 % weaker motors: to the nominal model as heavy as 0.25 * 1.1 / 0.95 kg.
  auto model = controller("quadrotor_forest", {});
  daemon::DisturbanceObserver obs(with_mass(), 1, 16, model->mass());
  EXPECT_NEAR(motor_model_mass_estimate(obs, *model, 0.275f, 5.8045e-8f), 0.25f * 1.1f / 0.95f, 0.003f);
  // Twice as heavy: the estimate stops at max_change (+50 %), never beyond.
  EXPECT_NEAR(motor_model_mass_estimate(obs, *model, 0.5f, 6.11e-8f), 0.25f * 1.5f, 1e-4f);
}

// ---- the actuation delay estimate -----------------------------------------------------------

namespace {
// The plant takes every command `true_ms` later than the loop's history says; the commands
// change every state (random steps around `u0`, `spread` wide). The estimator's delay after
// `seconds` of states (0 while it has not moved).
double estimated_delay_ms(const char* task, const std::vector<float>& u0, const std::vector<float>& spread,
                          double true_ms, double seconds) {
  auto model = controller(task, {});
  const int nx = model->nx(), nu = model->nu();
  std::vector<int> act;
  for (int i = nx == 16 ? 12 : 10; i < (nx == 16 ? 16 : 13); ++i) act.push_back(i);
  daemon::DelayEstimateSettings s;
  s.estimate = true;
  daemon::DelayEstimator est(s, nx, act);
  daemon::CommandHistory loop_history(nu, u0), plant_history(nu, u0);
  std::vector<float> x(static_cast<std::size_t>(nx), 0.0f), u(u0);
  x[2] = 2.0f;
  if (nx == 13) x[6] = 1.0f;
  for (int i = 12; nx == 16 && i < 16; ++i) x[static_cast<std::size_t>(i)] = u0[0];
  std::uint32_t seed = 12345;
  double delay_ms = 0.0;
  const auto lag = static_cast<std::int64_t>(true_ms * 1e6);
  for (std::int64_t k = 0, t = 0; static_cast<double>(k) * 0.02 < seconds; ++k, t += 20 * kMs) {
    if (est.update(*model, loop_history, x.data(), t, 0)) delay_ms = static_cast<double>(est.delay_ns()) * 1e-6;
    for (int j = 0; j < nu; ++j) {
      seed = seed * 1664525u + 1013904223u;
      u[static_cast<std::size_t>(j)] = u0[static_cast<std::size_t>(j)] +
                                       spread[static_cast<std::size_t>(j)] * (static_cast<float>(seed >> 8) / 16777216.0f - 0.5f);
    }
    loop_history.add(t + 5 * kMs, u.data());  // what the loop believes: acting 5 ms after this state
    plant_history.add(t + 5 * kMs + lag, u.data());
    plant_history.predict(*model, x.data(), t, t + 20 * kMs);
  }
  return delay_ms;
}
}  // namespace

TEST(DelayEstimate, FindsTheDelayTheVehicleReallyHas) {
  // The rate model's body rates and the 16-state model's motor speeds both show it.
  const std::vector<float> thrust_rates = {9.81f, 0.0f, 0.0f, 0.0f}, rate_spread = {1.0f, 2.0f, 2.0f, 1.0f};
  EXPECT_NEAR(estimated_delay_ms("quadrotor_rate_track", thrust_rates, rate_spread, 20.0, 1.2), 20.0, 1.0);
  EXPECT_NEAR(estimated_delay_ms("quadrotor_rate_track", thrust_rates, rate_spread, 8.0, 1.2), 8.0, 1.0);
  const std::vector<float> motors(4, 3168.4f), motor_spread(4, 200.0f);
  EXPECT_NEAR(estimated_delay_ms("quadrotor_forest", motors, motor_spread, 14.0, 1.2), 14.0, 1.0);
  // None to find: the estimate does not move.
  EXPECT_EQ(estimated_delay_ms("quadrotor_rate_track", thrust_rates, rate_spread, 0.0, 3.0), 0.0);
}

// ---- the identification manoeuvre -----------------------------------------------------------

namespace {
const std::vector<float> kMin = {0.0f, -6.0f, -6.0f, -3.0f}, kMax = {25.0f, 6.0f, 6.0f, 3.0f};
}

TEST(Identification, DoubletsOnEachAxisThenThrustStepsAndThenItIsDone) {
  daemon::IdentificationSettings s;
  daemon::IdentificationManoeuvre m(s, kMin, kMax);
  auto x = rate_state();
  float u[4] = {10.0f, 0.1f, 0.0f, 0.0f};
  EXPECT_FALSE(m.excite(x.data(), 0, u));  // not requested: nothing
  m.request(true);
  const double dt = 0.01;
  std::vector<std::vector<float>> seen;
  for (int k = 0; m.active(); ++k) {
    float v[4] = {10.0f, 0.1f, 0.0f, 0.0f};
    m.excite(x.data(), static_cast<std::int64_t>(k * dt * 1e9), v);
    seen.push_back({v[0] - 10.0f, v[1] - 0.1f, v[2], v[3]});
    ASSERT_LT(k, 10000);
  }
  EXPECT_NEAR(static_cast<double>(seen.size()) * dt, m.duration_s(), 0.02);
  // The first pulse: +0.6 x the roll amplitude, then -0.6 x; pitch and yaw after the gap;
  // then the thrust step, relative to the thrust commanded.
  const auto at = [&](double t) { return seen[static_cast<std::size_t>(t / dt)]; };
  EXPECT_NEAR(at(0.1)[1], 0.6 * s.rate_amplitude, 1e-5);
  EXPECT_NEAR(at(0.35)[1], -0.6 * s.rate_amplitude, 1e-5);
  EXPECT_FLOAT_EQ(at(0.6)[1], 0.0f);  // the gap
  EXPECT_NEAR(at(1.4)[2], 0.6 * s.rate_amplitude, 1e-5);
  EXPECT_NEAR(at(2.7)[3], 0.6 * s.yaw_amplitude, 1e-5);
  EXPECT_NEAR(at(4.0)[0], 10.0 * 0.6 * s.thrust_step, 1e-4);
  EXPECT_NEAR(at(4.3)[0], -10.0 * 0.6 * s.thrust_step, 1e-4);
  // The second repeat's sign is the other way.
  EXPECT_NEAR(at(5.3)[1], -1.0 * s.rate_amplitude, 1e-5);
}

TEST(Identification, ClampedToTheLimitsAndPausedOutsideTheBox) {
  daemon::IdentificationSettings s;
  s.rate_amplitude = 5.0;
  daemon::IdentificationManoeuvre m(s, kMin, kMax);
  auto x = rate_state();
  m.request(true);
  float u[4] = {10.0f, 4.0f, 0.0f, 0.0f};
  ASSERT_TRUE(m.excite(x.data(), 0, u));
  ASSERT_TRUE(m.excite(x.data(), 50 * kMs, u));
  EXPECT_FLOAT_EQ(u[1], 6.0f);  // 4 + 0.6 * 5 clamped to u_max
  // Drifted 2 m off (the box is +-1.5 m): paused, the command untouched, the clock held.
  x[0] += 2.0f;
  float v[4] = {10.0f, 0.0f, 0.0f, 0.0f};
  EXPECT_FALSE(m.excite(x.data(), 100 * kMs, v));
  EXPECT_FALSE(m.excite(x.data(), 2000 * kMs, v));
  EXPECT_FLOAT_EQ(v[1], 0.0f);
  EXPECT_EQ(m.pauses(), 1);
  // Back, but only 1 m off: still paused (it resumes inside half the box); then resumes
  // where it stopped, 50 ms into the first doublet's first half.
  x[0] -= 1.0f;
  EXPECT_FALSE(m.excite(x.data(), 2100 * kMs, v));
  x[0] -= 1.0f;
  EXPECT_TRUE(m.excite(x.data(), 2200 * kMs, v));
  EXPECT_NEAR(v[1], 0.6 * s.rate_amplitude, 1e-5);
  // Tilted past 40 degrees: paused.
  auto tilted = rate_state(0.8f);
  float w[4] = {10.0f, 0.0f, 0.0f, 0.0f};
  EXPECT_FALSE(m.excite(tilted.data(), 2220 * kMs, w));
  m.request(false);
  EXPECT_FALSE(m.active());
}

TEST(Identification, TheDaemonStartsItOnRequestOnRateTasksOnly) {
  for (const bool rate_task : {true, false}) {
    test::FakeClock clock;
    test::RecordingTransport tx;
    test::FakeController ctl(&clock);
    transport::Inbox::Expect e;
    e.nx = 16;
    e.vehicles = 1;
    e.model = 1;
    transport::Inbox inbox(e);
    daemon::LoopSettings s;
    if (rate_task) s.command_kind = 2;  // KIND_THRUST_RATES
    daemon::ControlLoop loop(&ctl, &clock, &tx, &inbox, s);
    std::atomic<bool> run{false};
    transport::ParamUpdate p;
    std::strncpy(p.key, "daemon.identify", sizeof(p.key) - 1);
    p.value = 1.0;
    inbox.offer_param(p);
    for (int k = 1; k <= 10; ++k) {
      auto& st = inbox.state_buffer();
      test::shape_state(st, k);
      st.recv_ns = clock.now_ns();
      st.sample_utime = clock.now_ns() / 1000;
      for (int i = 0; i < 16; ++i) st.x[i] = 0.0f;
      st.x[6] = 1.0f;
      inbox.offer_state();
      ASSERT_TRUE(loop.step_realtime(run));
    }
    EXPECT_EQ(loop.counters().params_applied.load(), rate_task ? 1 : 0);
    // The fake plans base + 10 cycle + step on every channel: the roll channel's first
    // doublet half shows as +0.72 rad/s against the thrust channel.
    const auto& c = tx.commands.back();
    if (rate_task)
      EXPECT_NEAR(c.u[1] - c.u[0], 0.6 * daemon::IdentificationSettings{}.rate_amplitude, 1e-3);
    else
      EXPECT_FLOAT_EQ(c.u[1], c.u[0]);
  }
}

// ---- estimates from commands that were never flown ------------------------------------------

TEST(RestartEstimates, ForgetsWhatCommandsNeverFlownTaught) {
  // Before the bridge engages, the autopilot flies its own take-off and mppid's commands go
  // nowhere: a vehicle climbing at 2 m/s^2 whatever mppid sends reads as an upward push or a
  // lighter vehicle. daemon.restart_estimates (the bridge sends it on engaging) forgets it all.
  auto ctl = controller("quadrotor_rate_track", {});
  const float nominal_mass = ctl->mass();
  test::FakeClock clock;
  test::RecordingTransport tx;
  transport::Inbox::Expect e;
  e.nx = 13;
  e.vehicles = 1;
  e.model = 2;  // MODEL_QUADROTOR_RATE
  transport::Inbox inbox(e);
  daemon::LoopSettings s;
  s.command_kind = 2;
  s.disturbance = with_mass();
  s.latency.actuation_delay_ns = 20 * kMs;
  s.latency.delay_estimate.estimate = true;
  daemon::ControlLoop loop(ctl.get(), &clock, &tx, &inbox, s);
  std::atomic<bool> run{false};
  const auto state = [&](int k) {
    auto& st = inbox.state_buffer();
    test::shape_state(st, k, 13, 2);
    st.recv_ns = clock.now_ns();
    st.sample_utime = clock.now_ns() / 1000;
    const double t = 0.02 * k;
    const auto x = rate_state();
    std::copy(x.begin(), x.end(), st.x);
    st.x[2] = static_cast<float>(1.0 + t * t);  // climbing at 2 m/s^2
    st.x[5] = static_cast<float>(2.0 * t);
    inbox.offer_state();
  };
  for (int k = 1; k <= 60; ++k) {
    state(k);
    ASSERT_TRUE(loop.step_realtime(run));
  }
  const float* d = loop.disturbance_estimate();
  ASSERT_TRUE(std::fabs(d[2]) > 0.3f || std::fabs(ctl->mass() - nominal_mass) > 0.05f * nominal_mass)
      << "the climb taught the estimates nothing: d_z " << d[2] << ", mass " << ctl->mass();

  transport::ParamUpdate p;
  std::strncpy(p.key, "daemon.restart_estimates", sizeof(p.key) - 1);
  p.value = 1.0;
  inbox.offer_param(p);
  state(61);
  ASSERT_TRUE(loop.step_realtime(run));
  EXPECT_EQ(loop.counters().params_applied.load(), 1);
  // The restart, then one cycle's update from a single state (which the observer needs two of).
  for (int i = 0; i < 3; ++i) EXPECT_FLOAT_EQ(loop.disturbance_estimate()[i], 0.0f);
  EXPECT_FLOAT_EQ(ctl->mass(), nominal_mass);
  EXPECT_EQ(loop.counters().actuation_delay_ns.load(), 20 * kMs);
}
