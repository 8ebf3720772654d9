// mppid-peer: the other end of the daemon, for end-to-end tests and the daemon bench.
// Publishes vehicle_state_t at a fixed rate (absolute-time sleeps), optionally closing
// the loop through the quadrotor model with the commands it receives; listens to
// command_t and controller_status_t; measures state-out -> command-in latency by
// state_seq; injects faults on request; prints one `mppid-peer {json}` line at the end.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <thread>
#include <vector>

#include "mppi/models/quadrotor.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/histogram.hpp"
#include "mppi_lcm/command_t.hpp"
#include "mppi_lcm/controller_status_t.hpp"
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

  void on_command(const lcm::ReceiveBuffer* rb, const std::string&, const mppi_lcm::command_t* m) {
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
    (void)rb;
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

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mppid-peer: state publisher and command listener for mppid"};
  std::string url = "udpm://239.255.76.67:7667?ttl=0", state_ch = "MPPI_STATE", command_ch = "MPPI_COMMAND",
              status_ch = "MPPI_STATUS";
  double rate = 100.0, duration = 10.0, wait_s = 0.0, nan_at = -1, garbage_at = -1, pause_at = -1, pause_for = 0;
  bool simulate = false;
  int forest = 0;
  float z0 = 1.0f;
  app.add_option("--lcm-url", url);
  app.add_option("--state-channel", state_ch);
  app.add_option("--command-channel", command_ch);
  app.add_option("--status-channel", status_ch);
  app.add_option("--rate", rate, "state messages per second");
  app.add_option("--duration", duration, "seconds of publishing");
  app.add_option("--wait", wait_s, "seconds to wait for the first command before publishing starts counting");
  app.add_option("--nan-at", nan_at, "publish one state with a NaN at this time [s]");
  app.add_option("--garbage-at", garbage_at, "publish garbage bytes on the state channel at this time [s]");
  app.add_option("--pause-at", pause_at, "stop publishing states at this time [s] ...");
  app.add_option("--pause-for", pause_for, "... for this long [s]");
  app.add_flag("--simulate", simulate, "integrate the quadrotor model with the received commands");
  app.add_option("--z0", z0, "start height [m]");
  app.add_option("--forest", forest, "publish this many cylinders (4 m grid ahead) and a goal at (30, 0, z0), 1 Hz");
  CLI11_PARSE(app, argc, argv);

  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::fprintf(stderr, "mppid-peer: cannot open %s\n", url.c_str());
    return 1;
  }
  Listener l;
  lcm.subscribe(command_ch, &Listener::on_command, &l);
  lcm.subscribe(status_ch, &Listener::on_status, &l);
  std::atomic<bool> stop{false};
  std::thread rx([&] {
    while (!stop) lcm.handleTimeout(20);
  });

  mppi::Quadrotor::Params qp;
  const float hover = mppi::Quadrotor::hover_speed(qp);
  std::vector<float> x(16, 0.0f);
  x[2] = z0;
  for (int i = 12; i < 16; ++i) x[i] = hover;
  std::vector<float> u(4, hover);

  mppi_lcm::vehicle_state_t msg;
  msg.model = mppi_lcm::vehicle_state_t::MODEL_QUADROTOR;
  msg.vehicle_count = 1;
  msg.nx = 16;
  msg.n = 16;
  std::vector<std::uint8_t> buf(4096);

  // The world: a grid of cylinders ahead of the vehicle and a goal beyond it.
  mppi_lcm::obstacles_t world{};
  for (int i = 0; i < forest; ++i) {
    mppi_lcm::cylinder_t c{};
    c.x = 4.0f + 4.0f * static_cast<float>(i / 7);
    c.y = -12.0f + 4.0f * static_cast<float>(i % 7) + (i / 7 % 2 ? 2.0f : 0.0f);
    c.radius = 0.3f;
    world.cylinders.push_back(c);
  }
  world.n = static_cast<std::int32_t>(world.cylinders.size());
  mppi_lcm::reference_t goal{};
  goal.kind = mppi_lcm::reference_t::KIND_WAYPOINT;
  goal.center[0] = 30.0f;
  goal.center[2] = z0;
  goal.vehicle_count = 1;
  goal.goals = {{30.0f, 0.0f, z0}};
  std::int64_t world_seq = 0, last_world = -1;

  const std::int64_t period = std::llround(1e9 / rate);
  const std::int64_t t0 = mppi::rt::monotonic_ns();
  std::int64_t next = t0, seq = 0, published = 0, max_late = 0;
  bool nan_done = false, garbage_done = false;
  mppi::rt::MonotonicClock clock;
  while (true) {
    clock.sleep_until(next);
    const std::int64_t now = mppi::rt::monotonic_ns();
    max_late = std::max(max_late, now - next);
    const double t = static_cast<double>(now - t0) * 1e-9;
    if (t >= duration) break;
    next += period;
    if (next < now) next = now + period;  // skip, don't catch up
    if (simulate) {
      {
        std::lock_guard<std::mutex> lock(l.mu);
        if (l.u.size() == 4) u = l.u;
      }
      const float dt = static_cast<float>(period) * 1e-9f;
      for (int s = 0; s < 10; ++s) mppi::Quadrotor::step(qp, x.data(), u.data(), dt / 10.0f);
      if (x[2] < 0.0f) x[2] = 0.0f;
    }
    if (forest > 0 && static_cast<std::int64_t>(t) != last_world) {
      last_world = static_cast<std::int64_t>(t);
      world.utime = goal.utime = mppi::rt::wall_utime();
      world.seq = goal.seq = ++world_seq;
      lcm.publish("MPPI_OBSTACLES", &world);
      lcm.publish("MPPI_REFERENCE", &goal);
    }
    if (pause_at >= 0 && t >= pause_at && t < pause_at + pause_for) continue;
    if (garbage_at >= 0 && !garbage_done && t >= garbage_at) {
      const char junk[] = "\x01\x02garbage-not-an-lcm-message";
      lcm.publish(state_ch, junk, sizeof(junk));
      garbage_done = true;
    }
    msg.utime = mppi::rt::wall_utime();
    msg.seq = ++seq;
    msg.sample_utime = msg.utime;
    msg.x = x;
    if (nan_at >= 0 && !nan_done && t >= nan_at) {
      msg.x[3] = std::nanf("");
      nan_done = true;
    }
    const int size = msg.getEncodedSize();
    msg.encode(buf.data(), 0, size);
    {
      std::lock_guard<std::mutex> lock(l.mu);
      const std::size_t slot = static_cast<std::size_t>(seq % kSeqRing);
      l.sent_seq[slot] = seq;
      l.sent_ns[slot] = mppi::rt::monotonic_ns();
    }
    lcm.publish(state_ch, buf.data(), static_cast<unsigned>(size));
    ++published;
  }
  // Let the last commands and a status arrive.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  stop = true;
  rx.join();

  std::lock_guard<std::mutex> lock(l.mu);
  const auto lat = l.latency.summary();
  std::printf(
      "mppid-peer {\"states\":%lld,\"commands\":%lld,\"answered\":%lld,\"nonfinite_commands\":%lld,"
      "\"normal\":%lld,\"hold\":%lld,\"failsafe\":%lld,\"command_seq_gaps\":%lld,\"status\":%lld,"
      "\"status_failsafe\":%lld,\"latency\":{\"n\":%lld,\"min_ms\":%.4f,\"mean_ms\":%.4f,\"p99_ms\":%.4f,"
      "\"max_ms\":%.4f},\"publisher_max_late_ms\":%.4f,\"last_status\":{\"cycles\":%lld,\"misses\":%lld,"
      "\"rejected_nan\":%lld,\"rejected_out_of_order\":%lld,\"rejected_undecodable\":%lld,"
      "\"rejected_params\":%lld,\"healthy\":%lld,\"jitter_ms_p99\":%.4f,\"compute_ms_p99\":%.4f},"
      "\"final_z\":%.3f}\n",
      static_cast<long long>(published), static_cast<long long>(l.commands), static_cast<long long>(l.answered),
      static_cast<long long>(l.nonfinite), static_cast<long long>(l.by_mode[0]), static_cast<long long>(l.by_mode[1]),
      static_cast<long long>(l.by_mode[2]), static_cast<long long>(l.command_seq_gaps),
      static_cast<long long>(l.status), static_cast<long long>(l.status_failsafe), static_cast<long long>(lat.count),
      lat.min_ms, lat.mean_ms, lat.p99_ms, lat.max_ms, static_cast<double>(max_late) * 1e-6,
      static_cast<long long>(l.last_status_cycles), static_cast<long long>(l.last_status_misses),
      static_cast<long long>(l.last_rejected_nan), static_cast<long long>(l.last_rejected_ooo),
      static_cast<long long>(l.last_rejected_undecodable), static_cast<long long>(l.last_rejected_params),
      static_cast<long long>(l.last_status_healthy), static_cast<double>(l.last_p99_jitter),
      static_cast<double>(l.last_compute_p99), static_cast<double>(x[2]));
  (void)wait_s;
  return 0;
}
