// mppid-peer: the other end of the daemon, for end-to-end tests and the daemon bench.
// Publishes vehicle_state_t at a fixed rate (absolute-time sleeps), optionally closing
// the loop through the quadrotor model with the commands it receives; listens to
// command_t and controller_status_t; measures state-out -> command-in latency by
// state_seq; injects faults on request; optionally publishes local maps (local_map_t, the
// mapper's default size) at a rate of their own from a second thread and LCM instance, as
// mppid-mapper would; prints one `mppid-peer {json}` line at the end.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "mppi/models/quadrotor.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/histogram.hpp"
#include "mppi_lcm/command_t.hpp"
#include "mppi_lcm/controller_status_t.hpp"
#include "mppi_lcm/local_map_t.hpp"
#include "mppi_lcm/obstacles_t.hpp"
#include "mppi_lcm/reference_t.hpp"
#include "mppi_lcm/vehicle_state_t.hpp"

namespace {

constexpr int kSeqRing = 4096;

struct Listener {
  std::mutex mu;
  std::vector<std::int64_t> sent_ns = std::vector<std::int64_t>(kSeqRing, -1);
  std::vector<std::int64_t> sent_seq = std::vector<std::int64_t>(kSeqRing, -1);
  mppi::rt::Histogram latency{10'000, 20'000};  // 10 us bins up to 200 ms
  std::int64_t commands = 0, nonfinite = 0, by_mode[3] = {0, 0, 0}, status = 0, status_failsafe = 0;
  std::int64_t last_command_seq = -1, command_seq_gaps = 0, answered = 0;
  std::int64_t last_status_misses = 0, last_status_cycles = 0, last_rejected_nan = 0, last_rejected_ooo = 0,
               last_rejected_undecodable = 0, last_rejected_params = 0, last_status_healthy = -1;
  float last_p99_jitter = 0, last_compute_p99 = 0;
  std::vector<float> u;  // last command
  std::int64_t last_answered_state = -1;

  void on_command(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::command_t* m) {
    const std::int64_t now = mppi::rt::monotonic_ns();
    std::lock_guard<std::mutex> lock(mu);
    ++commands;
    if (m->mode >= 0 && m->mode <= 2) ++by_mode[m->mode];
    bool finite = true;
    for (float v : m->u) finite = finite && std::isfinite(v);
    if (!finite) ++nonfinite;
    if (last_command_seq >= 0 && m->seq != last_command_seq + 1) ++command_seq_gaps;
    last_command_seq = m->seq;
    if (finite) u = m->u;
    const std::size_t slot = static_cast<std::size_t>(m->state_seq % kSeqRing);
    // Latency counts the first command answering each state.
    if (m->state_seq >= 0 && sent_seq[slot] == m->state_seq && m->state_seq != last_answered_state) {
      latency.add(now - sent_ns[slot]);
      ++answered;
      last_answered_state = m->state_seq;
    }
  }
  void on_status(const lcm::ReceiveBuffer*, const std::string&, const mppi_lcm::controller_status_t* m) {
    std::lock_guard<std::mutex> lock(mu);
    ++status;
    if (m->mode == 2) ++status_failsafe;
    last_status_misses = m->misses;
    last_status_cycles = m->cycles;
    last_rejected_nan = m->rejected_nan;
    last_rejected_ooo = m->rejected_out_of_order;
    last_rejected_undecodable = m->rejected_undecodable;
    last_rejected_params = m->rejected_params;
    last_status_healthy = m->healthy;
    last_p99_jitter = m->jitter_ms_p99;
    last_compute_p99 = m->compute_ms_p99;
  }
};

struct Options {
  std::string url = "udpm://239.255.76.67:7667?ttl=0", state_ch = "MPPI_STATE", command_ch = "MPPI_COMMAND",
              status_ch = "MPPI_STATUS";
  double rate = 100.0, duration = 10.0, nan_at = -1, garbage_at = -1, pause_at = -1, pause_for = 0;
  bool simulate = false;
  int forest = 0;
  float z0 = 1.0f;
  double maps_hz = 0.0;                 // local_map_t per second (0: none)
  std::vector<int> map_cells{128, 128, 32};  // mppid-mapper's default: 32 x 32 x 8 m at 0.25 m, 1 MB
};

// Local maps as mppid-mapper publishes them (free space: every cell at max_distance, the
// window around the start), on an LCM instance and thread of their own so that encoding and
// sending ~1 MB never delays a state.
class MapPublisher {
 public:
  explicit MapPublisher(const Options& o) : o_(o), lcm_(o.url) {
    auto& m = msg_;
    m.nx = o.map_cells[0], m.ny = o.map_cells[1], m.nz = o.map_cells[2];
    m.resolution = 0.25f;
    m.max_distance = 5.0f;
    m.origin[0] = -0.5f * m.resolution * static_cast<float>(m.nx);
    m.origin[1] = -0.5f * m.resolution * static_cast<float>(m.ny);
    m.origin[2] = 0.0f;
    m.n_cells = m.nx * m.ny * m.nz;
    m.distance_mm.assign(static_cast<std::size_t>(m.n_cells), static_cast<std::int16_t>(5000));
    buf_.resize(static_cast<std::size_t>(m.getEncodedSize()) + 64);
  }
  bool good() { return lcm_.good(); }
  void run(const std::atomic<bool>& stop) {
    const std::int64_t period = std::llround(1e9 / o_.maps_hz);
    mppi::rt::MonotonicClock clock;
    for (std::int64_t next = mppi::rt::monotonic_ns(); !stop.load(); next += period) {
      clock.sleep_until(next);
      msg_.utime = mppi::rt::wall_utime();
      msg_.seq = ++published_;
      const int size = msg_.getEncodedSize();
      msg_.encode(buf_.data(), 0, size);
      lcm_.publish("MPPI_LOCAL_MAP", buf_.data(), static_cast<unsigned>(size));
    }
  }
  std::int64_t published() const { return published_; }

 private:
  const Options& o_;
  lcm::LCM lcm_;
  mppi_lcm::local_map_t msg_{};
  std::vector<std::uint8_t> buf_;
  std::int64_t published_ = 0;
};

// The world: a grid of cylinders ahead of the vehicle and a goal beyond it, sent at 1 Hz.
struct World {
  World(int cylinders, float z0) {
    for (int i = 0; i < cylinders; ++i) {
      mppi_lcm::cylinder_t c{};
      c.x = 4.0f + 4.0f * static_cast<float>(i / 7);
      c.y = -12.0f + 4.0f * static_cast<float>(i % 7) + (i / 7 % 2 ? 2.0f : 0.0f);
      c.radius = 0.3f;
      obstacles.cylinders.push_back(c);
    }
    obstacles.n = static_cast<std::int32_t>(obstacles.cylinders.size());
    goal.kind = mppi_lcm::reference_t::KIND_WAYPOINT;
    goal.center[0] = 30.0f;
    goal.center[2] = z0;
    goal.vehicle_count = 1;
    goal.goals = {{30.0f, 0.0f, z0}};
  }
  void publish(lcm::LCM& lcm) {
    obstacles.utime = goal.utime = mppi::rt::wall_utime();
    obstacles.seq = goal.seq = ++seq;
    lcm.publish("MPPI_OBSTACLES", &obstacles);
    lcm.publish("MPPI_REFERENCE", &goal);
  }
  mppi_lcm::obstacles_t obstacles{};
  mppi_lcm::reference_t goal{};
  std::int64_t seq = 0;
};

// The publishing side: the vehicle (hovering, or flown through the quadrotor model with
// the commands received), its states at a fixed rate, the world, and the faults asked for.
class Publisher {
 public:
  Publisher(const Options& o, lcm::LCM* lcm, Listener* l)
      : o_(o), lcm_(lcm), l_(l), world_(o.forest, o.z0), hover_(mppi::Quadrotor::hover_speed(qp_)), u_(4, hover_) {
    x_[2] = o.z0;
    for (int i = 12; i < 16; ++i) x_[i] = hover_;
    msg_.model = mppi_lcm::vehicle_state_t::MODEL_QUADROTOR;
    msg_.vehicle_count = 1;
    msg_.nx = 16;
    msg_.n = 16;
  }

  // Absolute-time sleeps, one state a period; a late period is skipped, not caught up.
  void run() {
    const std::int64_t period = std::llround(1e9 / o_.rate);
    const std::int64_t t0 = mppi::rt::monotonic_ns();
    std::int64_t next = t0, last_world = -1;
    mppi::rt::MonotonicClock clock;
    while (true) {
      clock.sleep_until(next);
      const std::int64_t now = mppi::rt::monotonic_ns();
      max_late_ = std::max(max_late_, now - next);
      const double t = static_cast<double>(now - t0) * 1e-9;
      if (t >= o_.duration) break;
      next += period;
      if (next < now) next = now + period;
      if (o_.simulate) fly(static_cast<float>(period) * 1e-9f);
      if (o_.forest > 0 && static_cast<std::int64_t>(t) != last_world) {
        last_world = static_cast<std::int64_t>(t);
        world_.publish(*lcm_);
      }
      if (o_.pause_at >= 0 && t >= o_.pause_at && t < o_.pause_at + o_.pause_for) continue;
      if (o_.garbage_at >= 0 && !garbage_done_ && t >= o_.garbage_at) {
        const char junk[] = "\x01\x02garbage-not-an-lcm-message";
        lcm_->publish(o_.state_ch, junk, sizeof(junk));
        garbage_done_ = true;
      }
      publish_state(t);
    }
  }

  std::int64_t published() const { return published_; }
  std::int64_t max_late_ns() const { return max_late_; }
  float z() const { return x_[2]; }

 private:
  void fly(float dt) {
    {
      std::lock_guard<std::mutex> lock(l_->mu);
      if (l_->u.size() == 4) u_ = l_->u;
    }
    for (int s = 0; s < 10; ++s) mppi::Quadrotor::step(qp_, x_.data(), u_.data(), dt / 10.0f);
    if (x_[2] < 0.0f) x_[2] = 0.0f;
  }

  void publish_state(double t) {
    msg_.utime = mppi::rt::wall_utime();
    msg_.seq = ++seq_;
    msg_.sample_utime = msg_.utime;
    msg_.x = x_;
    if (o_.nan_at >= 0 && !nan_done_ && t >= o_.nan_at) {
      msg_.x[3] = std::nanf("");
      nan_done_ = true;
    }
    const int size = msg_.getEncodedSize();
    msg_.encode(buf_.data(), 0, size);
    {
      std::lock_guard<std::mutex> lock(l_->mu);
      const std::size_t slot = static_cast<std::size_t>(seq_ % kSeqRing);
      l_->sent_seq[slot] = seq_;
      l_->sent_ns[slot] = mppi::rt::monotonic_ns();
    }
    lcm_->publish(o_.state_ch, buf_.data(), static_cast<unsigned>(size));
    ++published_;
  }

  const Options& o_;
  lcm::LCM* lcm_;
  Listener* l_;
  World world_;
  mppi::Quadrotor::Params qp_;
  float hover_;
  std::vector<float> x_ = std::vector<float>(16, 0.0f);
  std::vector<float> u_;
  mppi_lcm::vehicle_state_t msg_;
  std::vector<std::uint8_t> buf_ = std::vector<std::uint8_t>(4096);
  std::int64_t seq_ = 0, published_ = 0, max_late_ = 0;
  bool nan_done_ = false, garbage_done_ = false;
};

void print_report(const Listener& l, const Publisher& p, std::int64_t maps) {
  const auto lat = l.latency.summary();
  std::printf(
      "mppid-peer {\"states\":%lld,\"commands\":%lld,\"answered\":%lld,\"nonfinite_commands\":%lld,"
      "\"normal\":%lld,\"hold\":%lld,\"failsafe\":%lld,\"command_seq_gaps\":%lld,\"status\":%lld,"
      "\"status_failsafe\":%lld,\"latency\":{\"n\":%lld,\"min_ms\":%.4f,\"mean_ms\":%.4f,\"p99_ms\":%.4f,"
      "\"max_ms\":%.4f},\"publisher_max_late_ms\":%.4f,\"last_status\":{\"cycles\":%lld,\"misses\":%lld,"
      "\"rejected_nan\":%lld,\"rejected_out_of_order\":%lld,\"rejected_undecodable\":%lld,"
      "\"rejected_params\":%lld,\"healthy\":%lld,\"jitter_ms_p99\":%.4f,\"compute_ms_p99\":%.4f},"
      "\"final_z\":%.3f,\"maps\":%lld}\n",
      static_cast<long long>(p.published()), static_cast<long long>(l.commands), static_cast<long long>(l.answered),
      static_cast<long long>(l.nonfinite), static_cast<long long>(l.by_mode[0]), static_cast<long long>(l.by_mode[1]),
      static_cast<long long>(l.by_mode[2]), static_cast<long long>(l.command_seq_gaps),
      static_cast<long long>(l.status), static_cast<long long>(l.status_failsafe), static_cast<long long>(lat.count),
      lat.min_ms, lat.mean_ms, lat.p99_ms, lat.max_ms, static_cast<double>(p.max_late_ns()) * 1e-6,
      static_cast<long long>(l.last_status_cycles), static_cast<long long>(l.last_status_misses),
      static_cast<long long>(l.last_rejected_nan), static_cast<long long>(l.last_rejected_ooo),
      static_cast<long long>(l.last_rejected_undecodable), static_cast<long long>(l.last_rejected_params),
      static_cast<long long>(l.last_status_healthy), static_cast<double>(l.last_p99_jitter),
      static_cast<double>(l.last_compute_p99), static_cast<double>(p.z()), static_cast<long long>(maps));
}

// The maps' thread, when asked for (null otherwise); it stops with *stop.
std::unique_ptr<std::thread> start_maps(MapPublisher* maps, const std::atomic<bool>& stop) {
  if (maps == nullptr) return nullptr;
  return std::make_unique<std::thread>([maps, &stop] { maps->run(stop); });
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mppid-peer: state publisher and command listener for mppid"};
  Options o;
  app.add_option("--lcm-url", o.url);
  app.add_option("--state-channel", o.state_ch);
  app.add_option("--command-channel", o.command_ch);
  app.add_option("--status-channel", o.status_ch);
  app.add_option("--rate", o.rate, "state messages per second");
  app.add_option("--duration", o.duration, "seconds of publishing");
  app.add_option("--nan-at", o.nan_at, "publish one state with a NaN at this time [s]");
  app.add_option("--garbage-at", o.garbage_at, "publish garbage bytes on the state channel at this time [s]");
  app.add_option("--pause-at", o.pause_at, "stop publishing states at this time [s] ...");
  app.add_option("--pause-for", o.pause_for, "... for this long [s]");
  app.add_flag("--simulate", o.simulate, "integrate the quadrotor model with the received commands");
  app.add_option("--z0", o.z0, "start height [m]");
  app.add_option("--forest", o.forest, "publish this many cylinders (4 m grid ahead) and a goal at (30, 0, z0), 1 Hz");
  app.add_option("--maps", o.maps_hz, "publish free-space local_map_t on MPPI_LOCAL_MAP this often [Hz] (0: none)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--map-cells", o.map_cells, "the maps' cells along x y z (default: the mapper's 128 128 32)")
      ->expected(3);
  CLI11_PARSE(app, argc, argv);

  lcm::LCM lcm(o.url);
  std::unique_ptr<MapPublisher> maps = o.maps_hz > 0.0 ? std::make_unique<MapPublisher>(o) : nullptr;
  if (!lcm.good() || (maps && !maps->good())) {
    std::fprintf(stderr, "mppid-peer: cannot open %s\n", o.url.c_str());
    return 1;
  }
  Listener l;
  lcm.subscribe(o.command_ch, &Listener::on_command, &l);
  lcm.subscribe(o.status_ch, &Listener::on_status, &l);
  std::atomic<bool> stop{false}, stop_maps{false};
  std::thread rx([&] {
    while (!stop) lcm.handleTimeout(20);
  });
  const auto map_thread = start_maps(maps.get(), stop_maps);
  Publisher pub(o, &lcm, &l);
  pub.run();
  stop_maps = true;
  if (map_thread) map_thread->join();
  // Let the last commands and a status arrive.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  stop = true;
  rx.join();
  print_report(l, pub, maps ? maps->published() : 0);
  return 0;
}
