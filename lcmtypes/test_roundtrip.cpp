// Every mppi_lcm type survives encode/decode with all fields intact, decoding rejects
// truncated or foreign data, and a vehicle_state_t travels through an in-process
// (memq://) LCM instance linked statically from the lcm wheel.
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

#include <mppi_lcm/command_t.hpp>
#include <mppi_lcm/controller_status_t.hpp>
#include <mppi_lcm/cylinder_t.hpp>
#include <mppi_lcm/obstacles_t.hpp>
#include <mppi_lcm/param_update_t.hpp>
#include <mppi_lcm/plan_t.hpp>
#include <mppi_lcm/reference_t.hpp>
#include <mppi_lcm/sim_clock_t.hpp>
#include <mppi_lcm/vehicle_state_t.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace {

// Distinct, exactly representable values so equality is exact.
std::vector<float> ramp(int n, float start) {
  std::vector<float> v(static_cast<std::size_t>(n));
  for (std::size_t i = 0; i < v.size(); ++i) {
    v[i] = start + 0.25f * static_cast<float>(i);
  }
  return v;
}

template <typename T>
std::vector<std::uint8_t> encode(const T& msg) {
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(msg.getEncodedSize()));
  const int written = msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
  EXPECT_EQ(written, static_cast<int>(buf.size()));
  return buf;
}

// Encodes, decodes and checks the decoder consumed exactly what the encoder wrote.
template <typename T>
T roundtrip(const T& msg) {
  const std::vector<std::uint8_t> buf = encode(msg);
  T out{};
  EXPECT_EQ(out.decode(buf.data(), 0, static_cast<int>(buf.size())), static_cast<int>(buf.size()));
  // A datagram cut short must be rejected, never half-decoded into a valid message.
  if (buf.size() > 8) {
    T cut{};
    EXPECT_LT(cut.decode(buf.data(), 0, static_cast<int>(buf.size()) - 1), 0);
  }
  return out;
}

mppi_lcm::vehicle_state_t make_state() {
  mppi_lcm::vehicle_state_t s;
  s.utime = 1'700'000'000'123'456;
  s.seq = 42;
  s.sample_utime = 1'700'000'000'120'000;
  s.model = mppi_lcm::vehicle_state_t::MODEL_QUADROTOR;
  s.vehicle_count = 2;
  s.nx = 16;
  s.n = s.vehicle_count * s.nx;
  s.x = ramp(s.n, -3.0f);
  return s;
}

}  // namespace

TEST(LcmTypes, VehicleState) {
  const auto s = make_state();
  const auto d = roundtrip(s);
  EXPECT_EQ(d.utime, s.utime);
  EXPECT_EQ(d.seq, s.seq);
  EXPECT_EQ(d.sample_utime, s.sample_utime);
  EXPECT_EQ(d.model, mppi_lcm::vehicle_state_t::MODEL_QUADROTOR);
  EXPECT_EQ(d.vehicle_count, 2);
  EXPECT_EQ(d.nx, 16);
  EXPECT_EQ(d.n, 32);
  EXPECT_EQ(d.x, s.x);
}

TEST(LcmTypes, Command) {
  mppi_lcm::command_t c;
  c.utime = 11;
  c.seq = 12;
  c.state_seq = 41;
  c.mode = mppi_lcm::command_t::MODE_HOLD_PLAN;
  c.kind = mppi_lcm::command_t::KIND_THRUST_RATES;
  c.n = 4;
  c.u = ramp(c.n, 9.5f);
  const auto d = roundtrip(c);
  EXPECT_EQ(d.utime, 11);
  EXPECT_EQ(d.seq, 12);
  EXPECT_EQ(d.state_seq, 41);
  EXPECT_EQ(d.mode, mppi_lcm::command_t::MODE_HOLD_PLAN);
  EXPECT_EQ(d.kind, mppi_lcm::command_t::KIND_THRUST_RATES);
  EXPECT_EQ(d.n, 4);
  EXPECT_EQ(d.u, c.u);
}

TEST(LcmTypes, Reference) {
  mppi_lcm::reference_t r;
  r.utime = 21;
  r.seq = 22;
  r.kind = mppi_lcm::reference_t::KIND_FIGURE_EIGHT;
  r.center[0] = 1.0f;
  r.center[1] = -2.0f;
  r.center[2] = 1.5f;
  r.radius = 2.5f;
  r.speed = 1.25f;
  r.yaw = -0.5f;
  r.ramp_s = 2.0f;
  r.phase = 1.25f;
  r.end_s = 12.5f;
  r.t0_utime = 1'000'000;
  r.vehicle_count = 3;
  r.goals.resize(3);
  for (std::size_t v = 0; v < r.goals.size(); ++v) {
    r.goals[v] = ramp(3, static_cast<float>(v));
  }
  const auto d = roundtrip(r);
  EXPECT_EQ(d.utime, 21);
  EXPECT_EQ(d.seq, 22);
  EXPECT_EQ(d.kind, mppi_lcm::reference_t::KIND_FIGURE_EIGHT);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(d.center[i], r.center[i]);
  }
  EXPECT_EQ(d.radius, r.radius);
  EXPECT_EQ(d.speed, r.speed);
  EXPECT_EQ(d.yaw, r.yaw);
  EXPECT_EQ(d.ramp_s, r.ramp_s);
  EXPECT_EQ(d.phase, r.phase);
  EXPECT_EQ(d.end_s, r.end_s);
  EXPECT_EQ(d.t0_utime, r.t0_utime);
  EXPECT_EQ(d.vehicle_count, 3);
  ASSERT_EQ(d.goals.size(), 3u);
  for (std::size_t v = 0; v < 3; ++v) {
    EXPECT_EQ(d.goals[v], r.goals[v]);
  }
}

TEST(LcmTypes, Obstacles) {
  mppi_lcm::obstacles_t o;
  o.utime = 31;
  o.seq = 32;
  o.n = 3;
  o.cylinders.resize(3);
  for (std::size_t i = 0; i < o.cylinders.size(); ++i) {
    const float f = static_cast<float>(i);
    o.cylinders[i].x = f;
    o.cylinders[i].y = -f;
    o.cylinders[i].radius = 0.25f + f;
    o.cylinders[i].vx = 0.5f * f;
    o.cylinders[i].vy = -0.5f;
  }
  const auto d = roundtrip(o);
  EXPECT_EQ(d.utime, 31);
  EXPECT_EQ(d.seq, 32);
  ASSERT_EQ(d.n, 3);
  ASSERT_EQ(d.cylinders.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(d.cylinders[i].x, o.cylinders[i].x);
    EXPECT_EQ(d.cylinders[i].y, o.cylinders[i].y);
    EXPECT_EQ(d.cylinders[i].radius, o.cylinders[i].radius);
    EXPECT_EQ(d.cylinders[i].vx, o.cylinders[i].vx);
    EXPECT_EQ(d.cylinders[i].vy, o.cylinders[i].vy);
  }
  // An empty set is valid: it clears the obstacles.
  mppi_lcm::obstacles_t empty{};
  empty.n = 0;
  EXPECT_EQ(roundtrip(empty).n, 0);
}

TEST(LcmTypes, ControllerStatus) {
  mppi_lcm::controller_status_t s{};
  s.utime = 41;
  s.seq = 42;
  s.mode = mppi_lcm::command_t::MODE_FAILSAFE;
  s.backend = "cuda";
  s.task = "quadrotor_forest";
  s.rollouts = 4096;
  s.horizon = 50;
  s.compute_ms_last = 1.5f;
  s.compute_ms_min = 1.0f;
  s.compute_ms_mean = 1.25f;
  s.compute_ms_max = 3.0f;
  s.compute_ms_p99 = 2.75f;
  s.period_ms_min = 9.5f;
  s.period_ms_mean = 10.0f;
  s.period_ms_max = 10.5f;
  s.period_ms_p99 = 10.25f;
  s.jitter_ms_p99 = 0.25f;
  s.cycles = 100'000;
  s.misses = 3;
  s.late_start_misses = 2;
  s.consecutive_misses = 1;
  s.ess = 123.5f;
  s.min_cost = 17.25f;
  s.rejected_nan = 1;
  s.rejected_stale = 2;
  s.rejected_out_of_order = 3;
  s.rejected_undecodable = 4;
  s.rejected_params = 5;
  s.healthy = 1;
  const auto d = roundtrip(s);
  EXPECT_EQ(d.utime, 41);
  EXPECT_EQ(d.seq, 42);
  EXPECT_EQ(d.mode, mppi_lcm::command_t::MODE_FAILSAFE);
  EXPECT_EQ(d.backend, "cuda");
  EXPECT_EQ(d.task, "quadrotor_forest");
  EXPECT_EQ(d.rollouts, 4096);
  EXPECT_EQ(d.horizon, 50);
  EXPECT_EQ(d.compute_ms_last, s.compute_ms_last);
  EXPECT_EQ(d.compute_ms_min, s.compute_ms_min);
  EXPECT_EQ(d.compute_ms_mean, s.compute_ms_mean);
  EXPECT_EQ(d.compute_ms_max, s.compute_ms_max);
  EXPECT_EQ(d.compute_ms_p99, s.compute_ms_p99);
  EXPECT_EQ(d.period_ms_min, s.period_ms_min);
  EXPECT_EQ(d.period_ms_mean, s.period_ms_mean);
  EXPECT_EQ(d.period_ms_max, s.period_ms_max);
  EXPECT_EQ(d.period_ms_p99, s.period_ms_p99);
  EXPECT_EQ(d.jitter_ms_p99, s.jitter_ms_p99);
  EXPECT_EQ(d.cycles, 100'000);
  EXPECT_EQ(d.misses, 3);
  EXPECT_EQ(d.late_start_misses, 2);
  EXPECT_EQ(d.consecutive_misses, 1);
  EXPECT_EQ(d.ess, s.ess);
  EXPECT_EQ(d.min_cost, s.min_cost);
  EXPECT_EQ(d.rejected_nan, 1);
  EXPECT_EQ(d.rejected_stale, 2);
  EXPECT_EQ(d.rejected_out_of_order, 3);
  EXPECT_EQ(d.rejected_undecodable, 4);
  EXPECT_EQ(d.rejected_params, 5);
  EXPECT_EQ(d.healthy, 1);
}

TEST(LcmTypes, Plan) {
  mppi_lcm::plan_t p;
  p.utime = 51;
  p.seq = 52;
  p.state_seq = 50;
  p.horizon = 5;
  p.nu = 4;
  p.dt = 0.02f;
  p.n = p.horizon * p.nu;
  p.u = ramp(p.n, 0.0f);
  p.npos = p.horizon + 1;
  p.pos.resize(static_cast<std::size_t>(p.npos));
  for (std::size_t k = 0; k < p.pos.size(); ++k) {
    p.pos[k] = ramp(3, static_cast<float>(k));
  }
  const auto d = roundtrip(p);
  EXPECT_EQ(d.utime, 51);
  EXPECT_EQ(d.seq, 52);
  EXPECT_EQ(d.state_seq, 50);
  EXPECT_EQ(d.horizon, 5);
  EXPECT_EQ(d.nu, 4);
  EXPECT_EQ(d.dt, p.dt);
  EXPECT_EQ(d.n, 20);
  EXPECT_EQ(d.u, p.u);
  ASSERT_EQ(d.npos, 6);
  ASSERT_EQ(d.pos.size(), 6u);
  for (std::size_t k = 0; k < d.pos.size(); ++k) {
    EXPECT_EQ(d.pos[k], p.pos[k]);
  }
}

TEST(LcmTypes, ParamUpdate) {
  mppi_lcm::param_update_t p;
  p.utime = 61;
  p.seq = 62;
  p.key = "mppi.lambda";
  p.value = 0.125;
  p.apply_utime = 63;
  const auto d = roundtrip(p);
  EXPECT_EQ(d.utime, 61);
  EXPECT_EQ(d.seq, 62);
  EXPECT_EQ(d.key, "mppi.lambda");
  EXPECT_EQ(d.value, 0.125);
  EXPECT_EQ(d.apply_utime, 63);
}

TEST(LcmTypes, SimClock) {
  mppi_lcm::sim_clock_t c;
  c.utime = 71;
  c.seq = 72;
  c.sim_utime = 20'000;
  c.step = 1;
  const auto d = roundtrip(c);
  EXPECT_EQ(d.utime, 71);
  EXPECT_EQ(d.seq, 72);
  EXPECT_EQ(d.sim_utime, 20'000);
  EXPECT_EQ(d.step, 1);
}

TEST(LcmTypes, CylinderAlone) {
  mppi_lcm::cylinder_t c{};
  c.x = 1.0f;
  c.radius = 0.5f;
  const auto d = roundtrip(c);
  EXPECT_EQ(d.x, 1.0f);
  EXPECT_EQ(d.radius, 0.5f);
}

// Every type has its own fingerprint, so a message on the wrong channel fails to decode
// instead of being misread.
TEST(LcmTypes, ForeignTypeIsRejected) {
  const auto buf = encode(make_state());
  mppi_lcm::command_t c{};
  EXPECT_LT(c.decode(buf.data(), 0, static_cast<int>(buf.size())), 0);
  EXPECT_NE(mppi_lcm::vehicle_state_t::getHash(), mppi_lcm::command_t::getHash());
}

TEST(LcmMemq, PublishSubscribeVehicleState) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());

  int received = 0;
  mppi_lcm::vehicle_state_t got{};
  std::string got_channel;
  lcm::LCM::HandlerFunction<mppi_lcm::vehicle_state_t> on_state =
      [&](const lcm::ReceiveBuffer*, const std::string& channel,
          const mppi_lcm::vehicle_state_t* msg) {
        ++received;
        got = *msg;
        got_channel = channel;
      };
  lcm::Subscription* sub = lcm.subscribe("MPPI_STATE", on_state);
  ASSERT_NE(sub, nullptr);

  const auto sent = make_state();
  ASSERT_EQ(lcm.publish("MPPI_STATE", &sent), 0);
  // handleTimeout returns >0 when a message was handled, 0 on timeout: never block forever.
  ASSERT_GT(lcm.handleTimeout(1000), 0);

  EXPECT_EQ(received, 1);
  EXPECT_EQ(got_channel, "MPPI_STATE");
  EXPECT_EQ(got.utime, sent.utime);
  EXPECT_EQ(got.seq, sent.seq);
  EXPECT_EQ(got.sample_utime, sent.sample_utime);
  EXPECT_EQ(got.model, sent.model);
  EXPECT_EQ(got.vehicle_count, sent.vehicle_count);
  EXPECT_EQ(got.nx, sent.nx);
  EXPECT_EQ(got.n, sent.n);
  EXPECT_EQ(got.x, sent.x);

  // Nothing else is queued, and other channels do not reach this subscription.
  mppi_lcm::command_t cmd{};
  cmd.n = 0;
  ASSERT_EQ(lcm.publish("MPPI_COMMAND", &cmd), 0);
  lcm.handleTimeout(10);
  EXPECT_EQ(lcm.handleTimeout(10), 0);
  EXPECT_EQ(received, 1);

  EXPECT_EQ(lcm.unsubscribe(sub), 0);
}
