#include "mppi/transport/lcm_transport.hpp"

#include <cstdint>
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <future>
#include <stdexcept>

namespace mppi::transport {

LcmTransport::LcmTransport(const std::string& url, LcmChannels channels, rt::Clock* recv_clock, int max_plan_floats,
                           int receive_timeout_ms)
    : lcm_(url),
      url_(url),
      ch_(std::move(channels)),
      recv_clock_(recv_clock),
      timeout_ms_(receive_timeout_ms),
      decoder_(recv_clock, LcmDecoder::MapScratch::kNone) {
  if (!lcm_.good()) throw std::runtime_error("lcm_url: cannot open '" + url + "'");
  command_out_.u.reserve(kMaxControls);
  plan_out_.u.reserve(static_cast<std::size_t>(std::max(0, max_plan_floats)));
  plan_out_.pos.assign(kMaxPlanPositions, std::vector<float>(3, 0.0f));
  status_out_.backend.reserve(16);
  status_out_.task.reserve(64);
  param_result_out_.key.reserve(sizeof(ParamResult::key));
  param_result_out_.reason.reserve(sizeof(ParamResult::reason));
  // Largest message out: the plan (header plus floats); commands and status are small.
  buf_.resize(4096 + (static_cast<std::size_t>(std::max(0, max_plan_floats)) + 3 * kMaxPlanPositions) * sizeof(float));
}

LcmTransport::~LcmTransport() { stop(); }

namespace {

// Publishes on a private channel and receives it on the same instance: "" or why not.
std::string loopback(lcm::LCM& lcm, const std::string& url) {
  const std::string channel = "MPPID_SELFTEST_" + std::to_string(::getpid());
  bool got = false;
  struct Probe {
    bool* got;
    void on(const lcm::ReceiveBuffer* rb, const std::string&) {
      if (rb->data_size == 8 && std::memcmp(rb->data, "mppid-ok", 8) == 0) *got = true;
    }
  } probe{&got};
  lcm::Subscription* sub = lcm.subscribe(channel, &Probe::on, &probe);
  for (int attempt = 0; attempt < 5 && !got; ++attempt) {
    if (lcm.publish(channel, "mppid-ok", 8) != 0) {
      lcm.unsubscribe(sub);
      return "lcm: publish on '" + url + "' failed";
    }
    for (int i = 0; i < 10 && !got; ++i) lcm.handleTimeout(20);
  }
  lcm.unsubscribe(sub);
  return got ? std::string() : "lcm: no loopback message on '" + url + "' within 1 s (multicast route? ttl?)";
}

}  // namespace

// On a probe instance of the URL, not the states' own: LCM's udpm starts an instance's socket
// read thread at its first subscription, with the scheduling policy of the thread that makes
// it, and start() makes the states' one from the receive thread, after its SCHED_FIFO.
std::string LcmTransport::self_test() {
  if (running_) return "self_test: receive thread already running";
  if (!lcm_.good()) return "lcm: not good";
  lcm::LCM probe(url_);
  if (!probe.good()) return "lcm: cannot open '" + url_ + "' a second time";
  if (std::string why = loopback(probe, url_); !why.empty()) return why;
  if (map_lcm_ && !map_lcm_->good()) return "lcm (maps): not good";
  return map_lcm_ ? loopback(*map_lcm_, url_) : std::string();
}

void LcmTransport::open_map_receiver() {
  if (map_lcm_ || map_thread_ != MapThread::kOwnThread) return;
  auto lcm = std::make_unique<lcm::LCM>(url_);
  if (!lcm->good()) throw std::runtime_error("lcm_url: cannot open '" + url_ + "' for local maps");
  map_lcm_ = std::move(lcm);
}

// The maps' decoder, and the subscription on the instance that receives them.
void LcmTransport::subscribe_maps() {
  open_map_receiver();
  if (!map_decoder_) map_decoder_ = std::make_unique<LcmDecoder>(recv_clock_);
  map_lcm().subscribe(ch_.local_map, &LcmTransport::on_local_map, this);
}

// On the receive thread: the states' instance starts its socket read thread here.
void LcmTransport::subscribe_states() {
  lcm_.subscribe(ch_.state, &LcmTransport::on_state, this);
  lcm_.subscribe(ch_.reference, &LcmTransport::on_reference, this);
  lcm_.subscribe(ch_.obstacles, &LcmTransport::on_obstacles, this);
  lcm_.subscribe(ch_.params, &LcmTransport::on_param, this);
  lcm_.subscribe(ch_.clock, &LcmTransport::on_clock, this);
  if (inbox_->map && map_thread_ == MapThread::kStateThread) subscribe_maps();
}

void LcmTransport::start(Inbox* inbox) {
  if (running_) return;
  inbox_ = inbox;
  const bool maps_apart = inbox->map && map_thread_ == MapThread::kOwnThread;
  if (maps_apart) subscribe_maps();  // their socket read thread keeps the caller's policy
  running_ = true;
  std::promise<void> subscribed;
  std::future<void> ready = subscribed.get_future();
  thread_ = std::thread([this, &subscribed] {
    if (receive_fifo_ > 0) {
      sched_param sp{};
      sp.sched_priority = receive_fifo_;
      receive_fifo_ok_.store(pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0);
    }
    subscribe_states();
    subscribed.set_value();
    receive(&lcm_, receive_spin_ ? 0 : timeout_ms_);
  });
  ready.wait();  // subscribed before start() returns: nothing published after it is missed
  if (maps_apart) map_receiver_ = std::thread([this] { receive(map_lcm_.get(), timeout_ms_); });
}

void LcmTransport::receive(lcm::LCM* lcm, int timeout_ms) {
  while (running_.load(std::memory_order_relaxed))
    if (lcm->handleTimeout(timeout_ms) < 0) break;
}

void LcmTransport::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
  if (map_receiver_.joinable()) map_receiver_.join();
}

// Decoding and validation live in LcmDecoder (lcm_decode.cpp), reachable without a socket.
void LcmTransport::on_state(const lcm::ReceiveBuffer* rb, const std::string&) {
  decoder_.state(rb->data, rb->data_size, inbox_);
}
void LcmTransport::on_reference(const lcm::ReceiveBuffer* rb, const std::string&) {
  decoder_.reference(rb->data, rb->data_size, inbox_);
}
void LcmTransport::on_local_map(const lcm::ReceiveBuffer* rb, const std::string&) {
  map_decoder_->local_map(rb->data, rb->data_size, inbox_);
}

void LcmTransport::on_obstacles(const lcm::ReceiveBuffer* rb, const std::string&) {
  decoder_.obstacles(rb->data, rb->data_size, inbox_);
}
void LcmTransport::on_param(const lcm::ReceiveBuffer* rb, const std::string&) {
  decoder_.param(rb->data, rb->data_size, inbox_);
}
void LcmTransport::on_clock(const lcm::ReceiveBuffer* rb, const std::string&) {
  decoder_.clock(rb->data, rb->data_size, inbox_);
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
  m.rollouts = c.rollouts;
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
  m.rollouts_active = s.rollouts_active;
  m.work_size_changes = s.work_size_changes;
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
  m.late_start_misses = s.late_start_misses;
  m.consecutive_misses = s.consecutive_misses;
  m.state_to_command_ms_p99 = s.state_to_command_ms_p99;
  m.state_age_ms_p99 = s.state_age_ms_p99;
  m.latency_expected_ms = s.latency_expected_ms;
  m.lead_ms_mean = s.lead_ms_mean;
  m.lead_ms_p99 = s.lead_ms_p99;
  for (int i = 0; i < 3; ++i) m.disturbance_accel[i] = s.disturbance_accel[i];
  m.model_mass = s.model_mass;
  m.actuation_delay_ms = s.actuation_delay_ms;
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
  m.maps_accepted = s.maps_accepted;
  m.maps_rejected = s.maps_rejected;
  m.map_age_ms = s.map_age_ms;
  m.map_stale_cycles = s.map_stale_cycles;
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

void LcmTransport::reserve_rollouts(int rollouts, int floats) {
  auto& m = rollouts_out_;
  const auto n = static_cast<std::size_t>(std::max(0, rollouts)), f = static_cast<std::size_t>(std::max(0, floats));
  m.index.reserve(n);
  m.cost.reserve(n);
  m.weight.reserve(n);
  m.crashed.reserve(n);
  m.pos.reserve(f);
  const std::size_t bytes = 4096 + n * (3 * sizeof(float) + sizeof(std::int32_t) + 1) + f * sizeof(float);
  if (bytes > buf_.size()) buf_.resize(bytes);
}

bool LcmTransport::publish_rollouts(const RolloutsView& r) {
  auto& m = rollouts_out_;
  const auto n = static_cast<std::size_t>(r.count);
  const std::size_t f = n * static_cast<std::size_t>(r.vehicles) * static_cast<std::size_t>(r.steps) * 3;
  if (n > m.index.capacity() || f > m.pos.capacity()) return false;  // sized by reserve_rollouts
  m.utime = r.utime;
  m.seq = r.seq;
  m.state_seq = r.state_seq;
  m.cycle = r.cycle;
  m.total = r.total;
  m.vehicles = r.vehicles;
  m.steps = r.steps;
  m.dt = r.dt;
  m.temperature = r.lambda;
  m.count = r.count;
  m.top = r.top;
  m.index.assign(r.index, r.index + n);
  m.cost.assign(r.cost, r.cost + n);
  m.weight.assign(r.weight, r.weight + n);
  m.crashed.assign(r.crashed, r.crashed + n);
  m.npos = static_cast<std::int32_t>(f);
  m.pos.assign(r.xyz, r.xyz + f);
  return send(ch_.rollouts, m);
}

bool LcmTransport::publish_param_result(const ParamResult& r) {
  auto& m = param_result_out_;
  m.utime = rt::wall_utime();
  ++m.seq;
  m.update_seq = r.update_seq;
  // Within the reserved capacity (the fields are bounded, NUL-terminated arrays).
  m.key.assign(r.key, ::strnlen(r.key, sizeof(r.key)));
  m.value = r.value;
  m.status = r.applied ? mppi_lcm::param_result_t::STATUS_APPLIED : mppi_lcm::param_result_t::STATUS_REFUSED;
  m.cycle = r.cycle;
  m.reason.assign(r.reason, ::strnlen(r.reason, sizeof(r.reason)));
  return send(ch_.param_result, m);
}

}  // namespace mppi::transport
