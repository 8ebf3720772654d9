#include "mppi/transport/lcm_transport.hpp"

#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace mppi::transport {

LcmTransport::LcmTransport(const std::string& url, LcmChannels channels, rt::Clock* recv_clock, int max_plan_floats,
                           int receive_timeout_ms)
    : lcm_(url), url_(url), ch_(std::move(channels)), recv_clock_(recv_clock), timeout_ms_(receive_timeout_ms) {
  if (!lcm_.good()) throw std::runtime_error("lcm_url: cannot open '" + url + "'");
  command_out_.u.reserve(kMaxControls);
  plan_out_.u.reserve(static_cast<std::size_t>(std::max(0, max_plan_floats)));
  plan_out_.pos.assign(kMaxPlanPositions, std::vector<float>(3, 0.0f));
  state_in_.x.reserve(kMaxStates);
  obstacles_in_.cylinders.reserve(kMaxObstaclesIn);
  reference_in_.goals.reserve(kMaxVehicles);
  status_out_.backend.reserve(16);
  status_out_.task.reserve(64);
  // Largest message out: the plan (header plus floats); commands and status are small.
  buf_.resize(4096 + (static_cast<std::size_t>(std::max(0, max_plan_floats)) + 3 * kMaxPlanPositions) * sizeof(float));
}

LcmTransport::~LcmTransport() { stop(); }

std::string LcmTransport::self_test() {
  if (running_) return "self_test: receive thread already running";
  if (!lcm_.good()) return "lcm: not good";
  // Loopback: publish on a private channel and receive it on the same URL.
  const std::string channel = "MPPID_SELFTEST_" + std::to_string(::getpid());
  bool got = false;
  struct Probe {
    bool* got;
    void on(const lcm::ReceiveBuffer* rb, const std::string&) {
      if (rb->data_size == 8 && std::memcmp(rb->data, "mppid-ok", 8) == 0) *got = true;
    }
  } probe{&got};
  lcm::Subscription* sub = lcm_.subscribe(channel, &Probe::on, &probe);
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    if (lcm_.publish(channel, "mppid-ok", 8) != 0) {
      lcm_.unsubscribe(sub);
      return "lcm: publish on '" + url_ + "' failed";
    }
    for (int i = 0; i < 10 && !got; ++i) lcm_.handleTimeout(20);
  }
  lcm_.unsubscribe(sub);
  return got ? std::string() : "lcm: no loopback message on '" + url_ + "' within 1 s (multicast route? ttl?)";
}

void LcmTransport::start(Inbox* inbox) {
  if (running_) return;
  inbox_ = inbox;
  lcm_.subscribe(ch_.state, &LcmTransport::on_state, this);
  lcm_.subscribe(ch_.reference, &LcmTransport::on_reference, this);
  lcm_.subscribe(ch_.obstacles, &LcmTransport::on_obstacles, this);
  lcm_.subscribe(ch_.params, &LcmTransport::on_param, this);
  lcm_.subscribe(ch_.clock, &LcmTransport::on_clock, this);
  running_ = true;
  thread_ = std::thread([this] {
    if (receive_fifo_ > 0) {
      sched_param sp{};
      sp.sched_priority = receive_fifo_;
      receive_fifo_ok_.store(pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0);
    }
    while (running_.load(std::memory_order_relaxed)) {
      if (lcm_.handleTimeout(timeout_ms_) < 0) break;
    }
  });
}

void LcmTransport::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
}

template <class Msg>
bool LcmTransport::decode(Msg* msg, const lcm::ReceiveBuffer* rb) {
  const auto size = static_cast<int>(rb->data_size);
  // A wrong type fails the fingerprint; truncated or padded bytes fail the length check.
  if (msg->decode(rb->data, 0, size) != size) {
    inbox_->count_undecodable();
    return false;
  }
  return true;
}

void LcmTransport::on_state(const lcm::ReceiveBuffer* rb, const std::string&) {
  const std::int64_t now = recv_clock_->now_ns();
  if (!decode(&state_in_, rb)) return;
  const auto& m = state_in_;
  if (m.n != static_cast<std::int32_t>(m.x.size()) || m.n > kMaxStates || m.n < 0) {
    inbox_->count_undecodable();
    return;
  }
  StateSample& s = inbox_->state_buffer();
  s.utime = m.utime;
  s.seq = m.seq;
  s.sample_utime = m.sample_utime;
  s.recv_ns = now;
  s.recv_utime = rt::wall_utime();
  s.model = m.model;
  s.vehicle_count = m.vehicle_count;
  s.nx = m.nx;
  s.n = m.n;
  std::copy(m.x.begin(), m.x.end(), s.x);
  inbox_->offer_state();
}

void LcmTransport::on_reference(const lcm::ReceiveBuffer* rb, const std::string&) {
  if (!decode(&reference_in_, rb)) return;
  const auto& m = reference_in_;
  if (m.vehicle_count < 0 || m.vehicle_count > kMaxVehicles) return inbox_->count_bad_input();
  ReferenceInput& r = inbox_->reference_buffer();
  r.seq = m.seq;
  r.kind = m.kind;
  std::copy_n(m.center, 3, r.center);
  r.radius = m.radius;
  r.speed = m.speed;
  r.yaw = m.yaw;
  r.t0_utime = m.t0_utime;
  r.vehicle_count = m.vehicle_count;
  for (int v = 0; v < m.vehicle_count; ++v)
    for (int d = 0; d < 3; ++d) r.goals[v][d] = m.goals[static_cast<std::size_t>(v)][static_cast<std::size_t>(d)];
  inbox_->offer_reference();
}

void LcmTransport::on_obstacles(const lcm::ReceiveBuffer* rb, const std::string&) {
  if (!decode(&obstacles_in_, rb)) return;
  const auto& m = obstacles_in_;
  if (m.n < 0 || m.n > kMaxObstaclesIn) return inbox_->count_bad_input();
  ObstacleInput& o = inbox_->obstacles_buffer();
  o.seq = m.seq;
  o.utime = m.utime;
  o.count = m.n;
  for (int i = 0; i < m.n; ++i) {
    const auto& c = m.cylinders[static_cast<std::size_t>(i)];
    o.items[i] = Cylinder{c.x, c.y, c.radius, c.vx, c.vy};
  }
  inbox_->offer_obstacles();
}

void LcmTransport::on_param(const lcm::ReceiveBuffer* rb, const std::string&) {
  if (!decode(&param_in_, rb)) return;
  ParamUpdate p;
  p.seq = param_in_.seq;
  p.value = param_in_.value;
  if (param_in_.key.size() >= sizeof(p.key)) {
    // Too long for any known key: let the loop reject it by name (truncated, marked).
    std::memcpy(p.key, param_in_.key.data(), sizeof(p.key) - 4);
    std::memcpy(p.key + sizeof(p.key) - 4, "...", 4);
  } else {
    std::memcpy(p.key, param_in_.key.c_str(), param_in_.key.size() + 1);
  }
  inbox_->offer_param(p);
}

void LcmTransport::on_clock(const lcm::ReceiveBuffer* rb, const std::string&) {
  if (!decode(&clock_in_, rb)) return;
  ClockTick t;
  t.seq = clock_in_.seq;
  t.sim_utime = clock_in_.sim_utime;
  t.step = clock_in_.step;
  inbox_->offer_tick(t);
}

template <class Msg>
bool LcmTransport::send(const std::string& channel, const Msg& msg) {
  const int size = msg.getEncodedSize();
  if (size <= 0 || static_cast<std::size_t>(size) > buf_.size()) return false;
  if (msg.encode(buf_.data(), 0, size) != size) return false;
  return lcm_.publish(channel, buf_.data(), static_cast<unsigned int>(size)) == 0;
}

bool LcmTransport::publish_command(const Command& c) {
  auto& m = command_out_;
  m.utime = c.utime;
  m.seq = c.seq;
  m.state_seq = c.state_seq;
  m.mode = static_cast<std::int8_t>(c.mode);
  m.kind = c.kind;
  m.age_us = c.age_us;
  m.compute_us = c.compute_us;
  m.lead_us = c.lead_us;
  m.n = c.n;
  m.u.assign(c.u, c.u + c.n);  // within the reserved capacity
  return send(ch_.command, m);
}

bool LcmTransport::publish_status(const StatusReport& s) {
  auto& m = status_out_;
  m.utime = s.utime;
  m.seq = s.seq;
  m.mode = static_cast<std::int8_t>(s.mode);
  m.backend.assign(s.backend);
  m.task.assign(s.task);
  m.rollouts = s.rollouts;
  m.horizon = s.horizon;
  m.compute_ms_last = s.compute_ms_last;
  m.compute_ms_min = s.compute_ms_min;
  m.compute_ms_mean = s.compute_ms_mean;
  m.compute_ms_max = s.compute_ms_max;
  m.compute_ms_p99 = s.compute_ms_p99;
  m.period_ms_min = s.period_ms_min;
  m.period_ms_mean = s.period_ms_mean;
  m.period_ms_max = s.period_ms_max;
  m.period_ms_p99 = s.period_ms_p99;
  m.jitter_ms_p99 = s.jitter_ms_p99;
  m.cycles = s.cycles;
  m.misses = s.misses;
  m.consecutive_misses = s.consecutive_misses;
  m.state_to_command_ms_p99 = s.state_to_command_ms_p99;
  m.state_age_ms_p99 = s.state_age_ms_p99;
  m.latency_expected_ms = s.latency_expected_ms;
  m.lead_ms_mean = s.lead_ms_mean;
  m.lead_ms_p99 = s.lead_ms_p99;
  for (int i = 0; i < 3; ++i) m.disturbance_accel[i] = s.disturbance_accel[i];
  m.partial_updates = s.partial_updates;
  m.anytime_holds = s.anytime_holds;
  m.ess = s.ess;
  m.min_cost = s.min_cost;
  m.rejected_nan = s.rejected_nan;
  m.rejected_stale = s.rejected_stale;
  m.rejected_out_of_order = s.rejected_out_of_order;
  m.rejected_undecodable = s.rejected_undecodable;
  m.rejected_params = s.rejected_params;
  m.rejected_future = s.rejected_future;
  m.healthy = s.healthy ? 1 : 0;
  return send(ch_.status, m);
}

bool LcmTransport::publish_plan(const PlanView& p) {
  auto& m = plan_out_;
  const std::size_t n = static_cast<std::size_t>(p.horizon) * static_cast<std::size_t>(p.nu);
  if (n > m.u.capacity()) return false;  // sized at construction; never grow in the loop
  m.utime = p.utime;
  m.seq = p.seq;
  m.state_seq = p.state_seq;
  m.horizon = p.horizon;
  m.nu = p.nu;
  m.dt = p.dt;
  m.n = static_cast<std::int32_t>(n);
  m.u.assign(p.u, p.u + n);
  // pos keeps its start-up size (inner vectors of 3); only the first npos are encoded.
  if (static_cast<std::size_t>(p.npos) > m.pos.size()) return false;
  m.npos = p.npos;
  for (std::int32_t i = 0; i < p.npos; ++i)
    for (int d = 0; d < 3; ++d) m.pos[static_cast<std::size_t>(i)][static_cast<std::size_t>(d)] = p.pos[3 * i + d];
  return send(ch_.plan, m);
}

}  // namespace mppi::transport
