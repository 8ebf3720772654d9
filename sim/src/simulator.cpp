#include "sim/simulator.hpp"

#include <cstdint>
#include <lcm/lcm-cpp.hpp>
#include <mppi_lcm/command_t.hpp>
#include <mppi_lcm/obstacles_t.hpp>
#include <mppi_lcm/reference_t.hpp>
#include <mppi_lcm/sim_clock_t.hpp>
#include <mppi_lcm/vehicle_state_t.hpp>
#include <sys/select.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

#include "mppi/transport/lcm_decode.hpp"
#include "sim/command_input.hpp"
#include "sim/plant.hpp"
#include "sim/rng.hpp"
#include "sim/sensor_rig.hpp"

namespace sim {
namespace {

std::atomic<bool> g_stop{false};

using Clock = std::chrono::steady_clock;

std::int64_t wall_utime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
std::int64_t to_us(double s) { return static_cast<std::int64_t>(std::llround(s * 1e6)); }

// A JSON file written line by line (no library: numbers and a few strings only).
class JsonWriter {
 public:
  explicit JsonWriter(const std::string& path) : f_(std::fopen(path.c_str(), "w")) {
    if (f_ == nullptr) throw std::runtime_error("cannot write " + path);
  }
  ~JsonWriter() {
    if (f_ != nullptr) std::fclose(f_);
  }
  JsonWriter(const JsonWriter&) = delete;
  JsonWriter& operator=(const JsonWriter&) = delete;
  std::FILE* get() { return f_; }

 private:
  std::FILE* f_;
};

void put_num(std::FILE* f, double v) {
  if (std::isfinite(v))
    std::fprintf(f, "%.9g", v);
  else
    std::fputs("null", f);
}
template <class T>
void put_array(std::FILE* f, const T* v, std::size_t n) {
  std::fputc('[', f);
  for (std::size_t i = 0; i < n; ++i) {
    if (i != 0) std::fputc(',', f);
    put_num(f, static_cast<double>(v[i]));
  }
  std::fputc(']', f);
}

struct PendingCommand {
  double apply_time;
  std::vector<float> u;
  std::int8_t mode;
  std::int64_t seq, state_seq;
};

class Simulation {
 public:
  Simulation(const Scenario& s, const RunOptions& o)
      : s_(s), o_(o), plant_(make_plant(s)), lcm_(o.lcm_url), wind_rng_(s.seed, 3), noise_rng_(s.seed, 4),
        sensor_lcm_(o.sensor_lcm_url.empty() ? nullptr : std::make_unique<lcm::LCM>(o.sensor_lcm_url)),
        sensors_(s, sensor_lcm_ ? sensor_lcm_.get() : &lcm_, o.channels.depth, o.channels.lidar) {
    if (sensor_lcm_ && !sensor_lcm_->good())
      throw std::runtime_error("LCM init failed for the sensor url '" + o.sensor_lcm_url + "'");
    if (!lcm_.good()) throw std::runtime_error("LCM init failed for url '" + o.lcm_url + "'");
    lcm_.subscribe(o.channels.command, &Simulation::on_command, this);
    nu_total_ = plant_->nu() * plant_->vehicles();
    u_applied_ = plant_->hover();
    positions_.resize(static_cast<std::size_t>(plant_->vehicles()));
    obstacles_ = s.obstacles;
    for (const auto& ob : obstacles_) any_moving_ = any_moving_ || ob.vx != 0.0 || ob.vy != 0.0;
    arena_[0] = s.forest.x_min;
    arena_[1] = s.forest.x_max;
    arena_[2] = s.forest.y_min;
    arena_[3] = s.forest.y_max;
  }

  int run();

 private:
  struct Cadence {
    double h;                                 // physics step, s
    std::int64_t per_state, per_world, total;  // physics steps per state, per world; in all
    double gust_a, gust_b;                    // the gust's decay and drive per step
  };
  Cadence cadence() const;
  std::optional<Outcome> step_once(std::int64_t step, const Cadence& c);
  std::optional<Outcome> exchange_state(std::int64_t step, const Cadence& c);
  void follow_wall_clock();
  void apply_due_commands(double h);
  std::optional<Outcome> judge(std::int64_t step, std::int64_t total);
  void advance(std::int64_t step, const Cadence& c);
  int finish(Outcome outcome);
  void on_command(const lcm::ReceiveBuffer* rb, const std::string&);
  void publish_state(std::int64_t seq, double t, bool republish);
  void publish_world(double t);
  bool wait_for_command(std::int64_t seq, double t);
  void pump_until(Clock::time_point deadline);
  int handle_within(std::int64_t us);
  void advance_obstacles(double h);
  void check_collisions(double t);
  void check_flying_collisions(double t);
  void check_obstacles(double t, int v, const std::array<double, 3>& p);
  void collide(double t, int v, const char* with);
  void sense(double t);
  bool at_goal() const;
  void write_world();
  void write_tick(std::int64_t seq, double t);
  void write_summary(Outcome outcome, double t_end);
  std::int64_t stamp(double t) const { return o_.lockstep ? to_us(t) : wall_utime(); }

  const Scenario& s_;
  const RunOptions& o_;
  std::unique_ptr<Plant> plant_;
  lcm::LCM lcm_;
  Rng wind_rng_, noise_rng_;
  std::unique_ptr<lcm::LCM> sensor_lcm_;  // the sensors' own bus (RunOptions::sensor_lcm_url)
  SensorRig sensors_;
  int nu_total_ = 0;
  std::vector<float> u_applied_;
  std::int8_t applied_mode_ = -1;  // -2: the simulator's own failsafe (timing.command_timeout)
  double last_command_t_ = 0.0;
  std::int64_t command_timeouts_ = 0;
  std::int64_t realtime_pauses_ = 0;  // real time: re-anchored after falling > 0.1 s behind
  double realtime_paused_s_ = 0.0;
  std::int64_t applied_seq_ = -1;
  std::deque<PendingCommand> pending_;
  mppi_lcm::command_t command_in_;  // decode scratch
  std::vector<float> published_state_;
  std::vector<Obstacle> obstacles_;
  std::vector<std::array<double, 3>> positions_;  // the vehicles' (collision checks' scratch)
  bool any_moving_ = false;
  double arena_[4] = {0, 0, 0, 0};
  double wind_[3] = {0, 0, 0};
  double gust_[3] = {0, 0, 0};

  // Lock-step bookkeeping.
  double now_ = 0.0;  // simulated time, s
  std::int64_t waiting_for_ = -1;
  bool answered_ = false;
  Clock::time_point published_at_;
  std::int64_t published_wall_us_ = 0;
  double last_latency_ms_ = std::numeric_limits<double>::quiet_NaN();
  double last_charged_ms_ = std::numeric_limits<double>::quiet_NaN();
  std::int64_t run_start_wall_us_ = 0;
  Clock::time_point run_start_;

  // Truth.
  std::unique_ptr<JsonWriter> truth_;
  std::int64_t commands_ = 0, ignored_commands_ = 0, rejected_commands_ = 0;
  std::int64_t states_ = 0, obstacle_msgs_ = 0;
  double min_clearance_ = std::numeric_limits<double>::infinity();
  double min_separation_ = std::numeric_limits<double>::infinity();
  double clearance_now_ = std::numeric_limits<double>::infinity();
  struct Collision {
    double t;
    int vehicle;
    std::string with;
  };
  std::vector<Collision> collisions_;
  std::int64_t ref_t0_ = 0;
  double time_to_goal_ = std::numeric_limits<double>::quiet_NaN();
};

void Simulation::on_command(const lcm::ReceiveBuffer* rb, const std::string&) {
  ++commands_;
  if (!mppi::transport::decode_message(rb->data, rb->data_size, &command_in_)) {
    // Nothing in it can be trusted, not even which state it answers: counted, not answered.
    ++rejected_commands_;
    if (!o_.quiet && rejected_commands_ <= 5)
      std::fprintf(stderr, "mppid-sim: undecodable command (%u bytes) rejected\n", rb->data_size);
    return;
  }
  const mppi_lcm::command_t* msg = &command_in_;
  if (o_.lockstep && msg->state_seq != waiting_for_) {
    ++ignored_commands_;  // an answer to an older state (e.g. a republished one)
    return;
  }
  // A malformed answer still answers its state (lock-step goes on, the previous control
  // stays applied); it is counted, and the score reports it.
  if (o_.lockstep) answered_ = true;
  std::vector<float> u;
  const CommandCheck check = check_command(*msg, *plant_, &u);
  if (check != CommandCheck::kAccepted) {
    ++rejected_commands_;
    if (!o_.quiet && rejected_commands_ <= 5)
      std::fprintf(stderr, "mppid-sim: command rejected, %s (n=%d kind=%d, expected n=%d kind=%d)\n", to_string(check),
                   msg->n, msg->kind, nu_total_, plant_->command_kind());
    return;
  }
  double reaches = now_;  // when the command reaches the plant, in simulated time
  if (o_.lockstep) {
    last_latency_ms_ = 1e3 * std::chrono::duration<double>(Clock::now() - published_at_).count();
    // Charged as in real time: the state's time plus the controller's latency, from the
    // tick's publish to the command's (its utime, on this host's wall clock), so the
    // simulator's own delays are not charged; its receipt time if utime is implausible.
    const double sent_ms = 1e-3 * static_cast<double>(msg->utime - published_wall_us_);
    const double measured = (sent_ms >= 0.0 && sent_ms <= last_latency_ms_) ? sent_ms : last_latency_ms_;
    last_charged_ms_ = o_.ideal ? 0.0 : (s_.controller_latency >= 0.0 ? 1e3 * s_.controller_latency : measured);
    reaches = now_ + 1e-3 * last_charged_ms_;
  } else {
    // Real time: its arrival on the wall clock (later than now_ if the physics lags).
    reaches = std::max(now_, seconds_since(run_start_));
  }
  pending_.push_back({reaches + s_.actuation_delay, std::move(u), msg->mode, msg->seq, msg->state_seq});
}

void Simulation::publish_state(std::int64_t seq, double t, bool republish) {
  mppi_lcm::vehicle_state_t m;
  m.utime = stamp(t);
  m.seq = seq;
  // The state's own time: simulated time in lock-step; in real time the wall time at which
  // the physics was at t (the publish may come later when the process was held up).
  m.sample_utime = o_.lockstep ? to_us(t) : run_start_wall_us_ + to_us(t);
  m.model = plant_->model_id();
  m.vehicle_count = static_cast<std::int16_t>(plant_->vehicles());
  m.nx = static_cast<std::int16_t>(plant_->nx());
  m.n = m.nx * m.vehicle_count;
  if (!republish || published_state_.empty()) {
    // The noise is drawn once per state, so a republished state is the same message.
    published_state_ = plant_->state();
    for (std::size_t i = 0; i < published_state_.size(); ++i) {
      double sd = 0.0;
      switch (plant_->group(static_cast<int>(i))) {
        case StateGroup::kPosition: sd = s_.noise.position; break;
        case StateGroup::kVelocity: sd = s_.noise.velocity; break;
        case StateGroup::kAttitude: sd = s_.noise.attitude; break;
        case StateGroup::kRate: sd = s_.noise.rate; break;
        case StateGroup::kOther: sd = s_.noise.other; break;
      }
      if (sd > 0.0) published_state_[i] += static_cast<float>(sd * noise_rng_.normal());
    }
    plant_->fix_published(published_state_.data());
  }
  m.x = published_state_;
  published_at_ = Clock::now();
  published_wall_us_ = wall_utime();
  lcm_.publish(o_.channels.state, &m);
  ++states_;
  // The tick goes after the state: a lock-step controller runs its cycle on the tick and
  // must find this state already in its inbox.
  if (o_.lockstep) {
    mppi_lcm::sim_clock_t clk;
    clk.utime = wall_utime();
    clk.seq = seq;
    clk.sim_utime = to_us(t);
    clk.step = seq;
    lcm_.publish(o_.channels.clock, &clk);
    // The controller's cycle starts on the tick: its latency is counted from here.
    published_wall_us_ = clk.utime;
  }
}

void Simulation::publish_world(double t) {
  const std::int64_t us = stamp(t);
  if (plant_->flies() && !obstacles_.empty() && s_.sensing.publish_obstacles) {
    // The nearest obstacles to any vehicle, at most max_published_obstacles.
    std::vector<std::pair<double, std::size_t>> order;
    for (std::size_t i = 0; i < obstacles_.size(); ++i) {
      double best = std::numeric_limits<double>::infinity();
      for (int v = 0; v < plant_->vehicles(); ++v) {
        double p[3];
        plant_->position(v, p);
        best = std::min(best, std::hypot(p[0] - obstacles_[i].x, p[1] - obstacles_[i].y) - obstacles_[i].radius);
      }
      order.emplace_back(best, i);
    }
    std::stable_sort(order.begin(), order.end());
    const std::size_t n = std::min(order.size(), static_cast<std::size_t>(s_.max_published_obstacles));
    std::sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(n),
              [](const auto& a, const auto& b) { return a.second < b.second; });  // stable ids order
    mppi_lcm::obstacles_t m;
    m.utime = us;
    m.seq = obstacle_msgs_++;
    m.n = static_cast<std::int32_t>(n);
    for (std::size_t k = 0; k < n; ++k) {
      const Obstacle& ob = obstacles_[order[k].second];
      mppi_lcm::cylinder_t c;
      c.x = static_cast<float>(ob.x);
      c.y = static_cast<float>(ob.y);
      c.radius = static_cast<float>(ob.radius);
      c.vx = static_cast<float>(ob.vx);
      c.vy = static_cast<float>(ob.vy);
      m.cylinders.push_back(c);
    }
    lcm_.publish(o_.channels.obstacles, &m);
  }
  const auto& r = s_.reference;
  if (r.kind != "none") {
    mppi_lcm::reference_t m;
    m.utime = us;
    m.seq = obstacle_msgs_;
    m.kind = r.kind == "hold"     ? mppi_lcm::reference_t::KIND_HOLD
             : r.kind == "circle" ? mppi_lcm::reference_t::KIND_CIRCLE
             : r.kind == "figure_eight" ? mppi_lcm::reference_t::KIND_FIGURE_EIGHT
                                        : mppi_lcm::reference_t::KIND_WAYPOINT;
    for (int i = 0; i < 3; ++i) m.center[i] = static_cast<float>(r.center[static_cast<std::size_t>(i)]);
    m.radius = static_cast<float>(r.radius);
    m.speed = static_cast<float>(r.speed);
    m.yaw = static_cast<float>(r.yaw);
    m.ramp_s = 0.0f;
    m.phase = 0.0f;
    m.end_s = 0.0f;
    m.t0_utime = ref_t0_;
    m.vehicle_count = static_cast<std::int16_t>(plant_->vehicles());
    m.goals.assign(static_cast<std::size_t>(plant_->vehicles()), std::vector<float>(3, 0.0f));
    for (int v = 0; v < plant_->vehicles(); ++v) {
      const Vec3 g = s_.goal_of(v);
      for (int i = 0; i < 3; ++i) m.goals[static_cast<std::size_t>(v)][i] = static_cast<float>(g[static_cast<std::size_t>(i)]);
    }
    lcm_.publish(o_.channels.reference, &m);
  }
}

// Handles LCM traffic until `deadline` (wall clock).
void Simulation::pump_until(Clock::time_point deadline) {
  for (;;) {
    const auto left = deadline - Clock::now();
    const auto us = std::max<std::int64_t>(0, std::chrono::duration_cast<std::chrono::microseconds>(left).count());
    if (g_stop) return;
    const int r = handle_within(us);
    // Late (the physics lags the wall clock): take what has arrived, then step on.
    if (us == 0 && r <= 0) return;
  }
}

// Waits up to `us` microseconds for LCM traffic and handles one message; select's result.
int Simulation::handle_within(std::int64_t us) {
  const int fd = lcm_.getFileno();
  fd_set fds;
  FD_ZERO(&fds);
  FD_SET(fd, &fds);
  timeval tv{static_cast<time_t>(us / 1000000), static_cast<suseconds_t>(us % 1000000)};
  const int r = select(fd + 1, &fds, nullptr, nullptr, &tv);
  if (r > 0) lcm_.handle();
  if (r < 0 && errno != EINTR) throw std::runtime_error("select failed on the LCM socket");
  return r;
}

bool Simulation::wait_for_command(std::int64_t seq, double t) {
  waiting_for_ = seq;
  answered_ = false;
  const double timeout = seq == 0 ? std::max(s_.startup_timeout, s_.lockstep_timeout) : s_.lockstep_timeout;
  const auto give_up = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout));
  auto republish = Clock::now() + std::chrono::milliseconds(500);
  while (!answered_) {
    if (g_stop) return false;
    const auto now = Clock::now();
    if (now >= give_up) return false;
    if (now >= republish) {
      // Nobody may have been listening yet (start-up): the same state, same seq, again.
      // The controller drops a seq it has already seen; an answer to it is ignored here.
      publish_world(t);
      publish_state(seq, t, true);
      republish = now + std::chrono::milliseconds(500);
    }
    const auto until = std::min(give_up, republish);
    handle_within(std::max<std::int64_t>(1, std::chrono::duration_cast<std::chrono::microseconds>(until - now).count()));
  }
  return true;
}

void Simulation::advance_obstacles(double h) {
  if (!any_moving_) return;
  for (auto& ob : obstacles_) {
    if (ob.vx == 0.0 && ob.vy == 0.0) continue;
    ob.x += ob.vx * h;
    ob.y += ob.vy * h;
    // Moving obstacles bounce off the forest corridor's walls, so they stay in the way.
    if ((ob.x < arena_[0] && ob.vx < 0) || (ob.x > arena_[1] && ob.vx > 0)) ob.vx = -ob.vx;
    if ((ob.y < arena_[2] && ob.vy < 0) || (ob.y > arena_[3] && ob.vy > 0)) ob.vy = -ob.vy;
  }
}

// Marks vehicle v as collided (with what) at t: it freezes where it is; once per vehicle.
void Simulation::collide(double t, int v, const char* with) {
  if ((plant_->frozen >> v) & 1u) return;
  collisions_.push_back({t, v, with});
  plant_->frozen |= 1u << v;
  if (truth_) std::fprintf(truth_->get(), "{\"event\":\"collision\",\"t\":%.6f,\"vehicle\":%d,\"with\":\"%s\"}\n", t, v, with);
}

void Simulation::check_collisions(double t) {
  clearance_now_ = std::numeric_limits<double>::infinity();
  if (plant_->flies()) {
    check_flying_collisions(t);
  } else if (s_.model == "cartpole") {
    const double x = plant_->state()[0];
    if (!std::isfinite(x) || (s_.track_limit > 0.0 && std::fabs(x) > s_.track_limit)) collide(t, 0, "track_limit");
  } else if (s_.model == "racecar") {
    const auto& x = plant_->state();
    const double d = std::pow(x[0] / 13.0, 2) + std::pow(x[1] / 6.0, 2) - 1.0;
    if (!std::isfinite(d) || (s_.off_track > 0.0 && std::fabs(d) > s_.off_track)) collide(t, 0, "off_track");
  }
}

// Each flying vehicle against the ground, the obstacles (their clearance kept) and the
// vehicles after it (their separation kept); a diverged state is a collision of its own.
void Simulation::check_flying_collisions(double t) {
  const int m = plant_->vehicles();
  for (int v = 0; v < m; ++v) plant_->position(v, positions_[static_cast<std::size_t>(v)].data());
  for (int v = 0; v < m; ++v) {
    const auto& p = positions_[static_cast<std::size_t>(v)];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      collide(t, v, "diverged");
      continue;
    }
    if (p[2] < s_.ground_z) collide(t, v, "ground");
    check_obstacles(t, v, p);
    for (int w = v + 1; w < m; ++w) {
      const auto& q = positions_[static_cast<std::size_t>(w)];
      const double d = std::sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]));
      min_separation_ = std::min(min_separation_, d);
      if (d < 2.0 * s_.vehicle_radius) {
        collide(t, v, "vehicle");
        collide(t, w, "vehicle");
      }
    }
  }
  min_clearance_ = std::min(min_clearance_, clearance_now_);
}

// Vehicle v at p against the obstacles it is not above.
void Simulation::check_obstacles(double t, int v, const std::array<double, 3>& p) {
  for (const auto& ob : obstacles_) {
    if (p[2] > s_.ground_z + ob.height + s_.vehicle_radius) continue;  // over its top
    const double c = std::hypot(p[0] - ob.x, p[1] - ob.y) - ob.radius - s_.vehicle_radius;
    clearance_now_ = std::min(clearance_now_, c);
    if (c < 0.0) collide(t, v, "obstacle");
  }
}

// Vehicle 0's sensors, from its true pose (sim/sensor_rig.hpp).
void Simulation::sense(double t) {
  if (!sensors_.any() || !plant_->flies()) return;
  Pose body;
  plant_->position(0, body.p.data());
  plant_->attitude(0, body.q.data());
  sensors_.step(t, body, obstacles_, o_.lockstep ? 0 : run_start_wall_us_);
}

bool Simulation::at_goal() const {
  if (!plant_->flies() || !s_.stop_at_goal) return false;
  if (s_.reference.kind != "waypoint" && s_.reference.kind != "hold") return false;
  for (int v = 0; v < plant_->vehicles(); ++v) {
    double p[3];
    plant_->position(v, p);
    const Vec3 g = s_.goal_of(v);
    if (std::sqrt((p[0] - g[0]) * (p[0] - g[0]) + (p[1] - g[1]) * (p[1] - g[1]) + (p[2] - g[2]) * (p[2] - g[2])) >
        s_.goal_radius)
      return false;
  }
  return true;
}

void Simulation::write_world() {
  JsonWriter w(o_.out_dir + "/world.json");
  std::FILE* f = w.get();
  std::fprintf(f, "{\"scenario\":\"%s\",\"task\":\"%s\",\"model\":\"%s\",\"seed\":%llu,", s_.name.c_str(),
               s_.task.c_str(), s_.model.c_str(), static_cast<unsigned long long>(s_.seed));
  std::fprintf(f, "\"vehicles\":%d,\"nx\":%d,\"nu\":%d,\"lockstep\":%s,", plant_->vehicles(), plant_->nx(),
               plant_->nu(), o_.lockstep ? "true" : "false");
  std::fprintf(f, "\"physics_hz\":%g,\"state_hz\":%g,\"actuation_delay\":%g,\"duration\":%g,", s_.physics_hz,
               s_.state_hz, s_.actuation_delay, s_.duration);
  // Lock-step latency charge: "ideal" (none), "measured", or fixed seconds.
  if (!o_.lockstep)
    std::fputs("\"latency_charge\":\"realtime\",", f);
  else if (o_.ideal)
    std::fputs("\"latency_charge\":\"ideal\",", f);
  else if (s_.controller_latency < 0.0)
    std::fputs("\"latency_charge\":\"measured\",", f);
  else
    std::fprintf(f, "\"latency_charge\":%g,", s_.controller_latency);
  std::fprintf(f, "\"ground_z\":%g,\"vehicle_radius\":%g,\"goal_radius\":%g,", s_.ground_z, s_.vehicle_radius,
               s_.goal_radius);
  std::fputs("\"starts\":[", f);
  for (int v = 0; v < plant_->vehicles(); ++v) {
    if (v != 0) std::fputc(',', f);
    put_array(f, s_.start_of(v).data(), 3);
  }
  std::fputs("],\"goals\":[", f);
  for (int v = 0; v < plant_->vehicles(); ++v) {
    if (v != 0) std::fputc(',', f);
    put_array(f, s_.goal_of(v).data(), 3);
  }
  std::fputs("],\"obstacles\":[", f);
  for (std::size_t i = 0; i < obstacles_.size(); ++i) {
    const auto& ob = obstacles_[i];
    const double v[5] = {ob.x, ob.y, ob.radius, ob.vx, ob.vy};
    if (i != 0) std::fputc(',', f);
    put_array(f, v, 5);
  }
  const auto& r = s_.reference;
  std::fprintf(f, "],\"reference\":{\"kind\":\"%s\",\"center\":", r.kind.c_str());
  put_array(f, r.center.data(), 3);
  std::fprintf(f, ",\"radius\":%g,\"speed\":%g,\"yaw\":%g}}\n", r.radius, r.speed, r.yaw);
}

void Simulation::write_tick(std::int64_t seq, double t) {
  if (!truth_) return;
  std::FILE* f = truth_->get();
  std::fprintf(f, "{\"t\":%.6f,\"seq\":%lld,\"x\":", t, static_cast<long long>(seq));
  put_array(f, plant_->state().data(), plant_->state().size());
  std::fputs(",\"u\":", f);
  put_array(f, u_applied_.data(), u_applied_.size());
  std::fprintf(f, ",\"mode\":%d,\"cmd_seq\":%lld,\"lat_ms\":", applied_mode_, static_cast<long long>(applied_seq_));
  put_num(f, last_latency_ms_);
  std::fputs(",\"charged_ms\":", f);
  put_num(f, last_charged_ms_);
  std::fputs(",\"clear\":", f);
  put_num(f, clearance_now_);
  std::fputs(",\"wind\":", f);
  put_array(f, wind_, 3);
  if (any_moving_) {
    std::fputs(",\"obs\":[", f);
    bool first = true;
    for (const auto& ob : obstacles_) {
      if (ob.vx == 0.0 && ob.vy == 0.0) continue;
      if (!first) std::fputc(',', f);
      first = false;
      const double p[2] = {ob.x, ob.y};
      put_array(f, p, 2);
    }
    std::fputc(']', f);
  }
  std::fputs("}\n", f);
}

void Simulation::write_summary(Outcome outcome, double t_end) {
  JsonWriter w(o_.out_dir + "/sim_summary.json");
  std::FILE* f = w.get();
  std::fprintf(f, "{\"outcome\":\"%s\",\"t_end\":%.6f,\"time_to_goal\":", to_string(outcome), t_end);
  put_num(f, time_to_goal_);
  std::fputs(",\"min_clearance\":", f);
  put_num(f, min_clearance_);
  std::fputs(",\"min_separation\":", f);
  put_num(f, min_separation_);
  std::fprintf(f, ",\"states\":%lld,\"commands\":%lld,\"ignored_commands\":%lld,\"rejected_commands\":%lld,",
               static_cast<long long>(states_), static_cast<long long>(commands_),
               static_cast<long long>(ignored_commands_), static_cast<long long>(rejected_commands_));
  std::fprintf(f, "\"command_timeouts\":%lld,\"realtime_pauses\":%lld,\"realtime_paused_s\":%.3f,",
               static_cast<long long>(command_timeouts_), static_cast<long long>(realtime_pauses_), realtime_paused_s_);
  sensors_.write_summary(f);
  std::fprintf(f, "\"wall_s\":%.3f,\"lockstep\":%s,\"collisions\":[", seconds_since(run_start_),
               o_.lockstep ? "true" : "false");
  for (std::size_t i = 0; i < collisions_.size(); ++i) {
    if (i != 0) std::fputc(',', f);
    std::fprintf(f, "{\"t\":%.6f,\"vehicle\":%d,\"with\":\"%s\"}", collisions_[i].t, collisions_[i].vehicle,
                 collisions_[i].with.c_str());
  }
  std::fputs("]}\n", f);
}

// The run's fixed cadence: physics step, states and worlds per step, the steps in all, and
// the wind's gust (an Ornstein-Uhlenbeck process per axis, exactly discretised).
Simulation::Cadence Simulation::cadence() const {
  Cadence c;
  c.h = 1.0 / s_.physics_hz;
  c.per_state = static_cast<std::int64_t>(std::llround(s_.physics_hz / s_.state_hz));
  c.per_world = std::max<std::int64_t>(1, std::llround(s_.state_hz / s_.obstacles_hz)) * c.per_state;
  c.total = static_cast<std::int64_t>(std::llround(s_.duration * s_.physics_hz));
  c.gust_a = std::exp(-c.h / s_.wind.gust_tau);
  c.gust_b = s_.wind.gust_std * std::sqrt(1.0 - c.gust_a * c.gust_a);
  return c;
}

int Simulation::run() {
  run_start_ = Clock::now();
  run_start_wall_us_ = wall_utime();
  write_world();
  truth_ = std::make_unique<JsonWriter>(o_.out_dir + "/truth.jsonl");
  ref_t0_ = o_.lockstep ? 0 : wall_utime();
  const Cadence c = cadence();
  for (int i = 0; i < 3; ++i) wind_[i] = s_.wind.mean[static_cast<std::size_t>(i)];

  Outcome outcome = Outcome::kDuration;
  check_collisions(0.0);
  for (std::int64_t step = 0;; ++step) {
    now_ = static_cast<double>(step) * c.h;
    if (g_stop) {
      outcome = Outcome::kInterrupted;
      break;
    }
    if (const std::optional<Outcome> end = step_once(step, c)) {
      outcome = *end;
      break;
    }
  }
  return finish(outcome);
}

// One physics step at now_: sense; at a state's step publish it (and in lock-step wait for
// its answer); follow the wall clock in real time; apply the commands due; log; judge; step.
// The outcome when the run ends here.
std::optional<Outcome> Simulation::step_once(std::int64_t step, const Cadence& c) {
  sense(now_);
  const bool state_step = step % c.per_state == 0;
  if (state_step) {
    if (const std::optional<Outcome> end = exchange_state(step, c)) return end;
  }
  if (!o_.lockstep) follow_wall_clock();
  apply_due_commands(c.h);
  if (state_step) write_tick(step / c.per_state, now_);
  if (const std::optional<Outcome> end = judge(step, c.total)) return end;
  advance(step, c);
  return std::nullopt;
}

// The state out (the world with it when due); in lock-step, its answer awaited: none is a
// timeout (or the interrupt that cut the wait short).
std::optional<Outcome> Simulation::exchange_state(std::int64_t step, const Cadence& c) {
  const std::int64_t seq = step / c.per_state;
  if (step % c.per_world == 0 || any_moving_) publish_world(now_);
  publish_state(seq, now_, false);
  if (!o_.lockstep || wait_for_command(seq, now_)) return std::nullopt;
  write_tick(seq, now_);
  return g_stop ? Outcome::kInterrupted : Outcome::kControllerTimeout;
}

// Real time: the physics follows the wall clock; commands arrive meanwhile. Fallen more than
// 0.1 s behind (stopped, SIGSTOP, or starved of CPU), it does not race the gap with no
// controller in the loop: the clock is re-anchored (and the reference's epoch with it), so
// the world paused while the simulator did.
void Simulation::follow_wall_clock() {
  const auto target = run_start_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(now_));
  const auto lag = Clock::now() - target;
  if (lag > std::chrono::milliseconds(100)) {
    run_start_ += lag;
    const std::int64_t lag_us = std::chrono::duration_cast<std::chrono::microseconds>(lag).count();
    ref_t0_ += lag_us;
    run_start_wall_us_ += lag_us;  // states keep their sample time on the wall clock: now, not before the pause
    ++realtime_pauses_;
    realtime_paused_s_ += std::chrono::duration<double>(lag).count();
  }
  pump_until(target + (lag > std::chrono::milliseconds(100) ? lag : Clock::duration::zero()));
}

// The commands whose time has come (within half a step) replace the applied one; none for
// longer than timing.command_timeout, the simulator's own failsafe holds.
void Simulation::apply_due_commands(double h) {
  while (!pending_.empty() && pending_.front().apply_time <= now_ + 0.5 * h) {
    u_applied_ = std::move(pending_.front().u);
    applied_mode_ = pending_.front().mode;
    applied_seq_ = pending_.front().seq;
    pending_.pop_front();
    last_command_t_ = now_;
  }
  if (s_.command_timeout > 0.0 && now_ - last_command_t_ > s_.command_timeout) {
    // The autopilot's offboard-loss failsafe, as it were: level and hold, every step.
    if (applied_mode_ != -2) ++command_timeouts_;
    applied_mode_ = -2;
    u_applied_ = plant_->failsafe();
  }
}

// A collision (when it ends runs), the goal, or the last step ends the run.
std::optional<Outcome> Simulation::judge(std::int64_t step, std::int64_t total) {
  if (!collisions_.empty() && s_.stop_on_collision) return Outcome::kCollision;
  if (at_goal()) {
    time_to_goal_ = now_;
    return Outcome::kGoal;
  }
  if (step >= total) return Outcome::kDuration;
  return std::nullopt;
}

// The plant, the obstacles and the wind one step on, and what collided there.
void Simulation::advance(std::int64_t step, const Cadence& c) {
  plant_->step(u_applied_.data(), wind_, c.h);
  advance_obstacles(c.h);
  for (int i = 0; i < 3; ++i) {
    gust_[i] = c.gust_a * gust_[i] + c.gust_b * wind_rng_.normal();
    wind_[i] = s_.wind.mean[static_cast<std::size_t>(i)] + gust_[i];
  }
  check_collisions(static_cast<double>(step + 1) * c.h);
}

// The logs closed and the summary written; the exit status for the outcome.
int Simulation::finish(Outcome outcome) {
  std::fflush(truth_->get());
  write_summary(outcome, now_);
  if (!o_.quiet)
    std::fprintf(stderr, "mppid-sim: %s at t=%.2f s (%lld states, %lld commands, %.2f s wall)\n", to_string(outcome),
                 now_, static_cast<long long>(states_), static_cast<long long>(commands_), seconds_since(run_start_));
  if (outcome == Outcome::kControllerTimeout) return 3;
  if (outcome == Outcome::kInterrupted) return 4;
  return 0;
}

}  // namespace

const char* to_string(Outcome o) {
  switch (o) {
    case Outcome::kGoal: return "goal";
    case Outcome::kDuration: return "duration";
    case Outcome::kCollision: return "collision";
    case Outcome::kControllerTimeout: return "controller_timeout";
    case Outcome::kInterrupted: return "interrupted";
    case Outcome::kError: return "error";
  }
  return "error";
}

void request_stop() { g_stop = true; }

int run_simulation(const Scenario& scenario, const RunOptions& options) {
  Simulation sim(scenario, options);
  return sim.run();
}

}  // namespace sim
