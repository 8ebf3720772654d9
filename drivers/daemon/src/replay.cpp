// mppid-replay: reruns the controller on a recorded lock-step flight and checks every
// command against the log, bit for bit.
//
// The log (lcm-logger's, e.g. tools/sitl run's flight.lcmlog) holds what went into the
// daemon (states, clock ticks, obstacles, references, parameter updates) and what came out
// (commands, status, parameter answers). A lock-step cycle is a function of its inputs and
// of the daemon's state, with two exceptions that the log also records:
//   - the expected latency (the estimator's, from measured compute times unless pinned
//     with daemon.latency.floor_ms = ceiling_ms): command_t.lead_us gives it back exactly
//     (the daemon keeps it in whole microseconds), cycle by cycle;
//   - when a parameter update took effect (mppi.* ones after the builder thread): each
//     param_result_t names the cycle.
// The noise is keyed by (seed, cycle), the seed from the settings, the cycle counter
// starting after daemon.warmup_iterations as in the daemon. So the same settings, the same
// inputs in the same order (fed through the daemon's own LCM decoder, over memq://) and the
// same ControlLoop reproduce every command; the replay compares state_seq, mode, kind, u
// (bitwise), age_us and lead_us, and stops at the first difference (cycle, field, values).
#include <CLI/CLI.hpp>
#include <cstdint>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/transport/lcm_transport.hpp"

namespace {

using mppi::transport::Command;

struct Event {
  std::string channel;
  std::vector<std::uint8_t> data;
};

// The loop's transport: the daemon's LCM decoder on memq:// for what comes in, and the
// commands it publishes kept for the comparison.
class ReplayTransport final : public mppi::transport::Transport {
 public:
  explicit ReplayTransport(mppi::transport::LcmTransport* in) : in_(in) {}
  std::string self_test() override { return {}; }
  void start(mppi::transport::Inbox* inbox) override { in_->start(inbox); }
  void stop() override { in_->stop(); }
  bool publish_command(const Command& c) override {
    out.push_back(c);
    return true;
  }
  bool publish_status(const mppi::transport::StatusReport&) override { return true; }
  bool publish_plan(const mppi::transport::PlanView&) override { return true; }
  bool publish_param_result(const mppi::transport::ParamResult&) override { return true; }
  std::vector<Command> out;

 private:
  mppi::transport::LcmTransport* in_;
};

template <class Msg>
bool decode(const Event& e, Msg* m) {
  return m->decode(e.data.data(), 0, static_cast<int>(e.data.size())) == static_cast<int>(e.data.size());
}

std::string hex(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, 4);
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%08x", b);
  return buf;
}

// "" when equal, else the first field that differs with both values.
std::string compare(const mppi_lcm::command_t& log, const Command& run) {
  char buf[256];
  auto num = [&](const char* field, long long a, long long b) {
    std::snprintf(buf, sizeof(buf), "%s: logged %lld, replayed %lld", field, a, b);
    return std::string(buf);
  };
  if (log.state_seq != run.state_seq) return num("state_seq", log.state_seq, run.state_seq);
  if (log.mode != static_cast<std::int8_t>(run.mode)) return num("mode", log.mode, static_cast<int>(run.mode));
  if (log.kind != run.kind) return num("kind", log.kind, run.kind);
  if (log.n != run.n) return num("n", log.n, run.n);
  for (int i = 0; i < log.n; ++i) {
    const float a = log.u[static_cast<std::size_t>(i)], b = run.u[i];
    if (std::memcmp(&a, &b, 4) != 0) {
      std::snprintf(buf, sizeof(buf), "u[%d]: logged %.9g (%s), replayed %.9g (%s)", i, static_cast<double>(a),
                    hex(a).c_str(), static_cast<double>(b), hex(b).c_str());
      return buf;
    }
  }
  if (log.age_us != run.age_us) return num("age_us", log.age_us, run.age_us);
  if (log.lead_us != run.lead_us) return num("lead_us", log.lead_us, run.lead_us);
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mppid-replay: rerun the controller on a recorded lock-step flight, compare every command bit for bit"};
  std::string log_path, config_path, backend;
  std::vector<std::string> sets;
  std::int64_t max_cycles = -1;
  bool verbose = false;
  app.add_option("log", log_path, "LCM log of the flight (flight.lcmlog)")->required()->check(CLI::ExistingFile);
  app.add_option("--config", config_path, "the daemon's settings file")->required();
  app.add_option("--set", sets, "the daemon's overrides, key.path=value (repeatable), in its order");
  app.add_option("--backend", backend, "cpu (the replay runs the CPU backend)");
  app.add_option("--max-cycles", max_cycles, "stop after this many cycles (default: all)");
  app.add_flag("--verbose", verbose, "log the daemon's messages");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(verbose ? spdlog::level::info : spdlog::level::err);

  // ---- the log -------------------------------------------------------------------------
  std::vector<Event> events;
  {
    lcm::LogFile log(log_path, "r");
    if (!log.good()) {
      std::fprintf(stderr, "replay: cannot read %s\n", log_path.c_str());
      return 2;
    }
    while (const lcm::LogEvent* e = log.readNextEvent()) {
      const auto* p = static_cast<const std::uint8_t*>(e->data);
      events.push_back({e->channel, std::vector<std::uint8_t>(p, p + e->datalen)});
    }
  }

  // ---- the daemon's settings -------------------------------------------------------------
  std::vector<std::string> overrides = sets;
  if (!backend.empty()) overrides.push_back("backend=" + backend);
  mppi::app::AppConfig cfg;
  mppi::daemon::DaemonSettings ds;
  try {
    cfg = mppi::app::load_config(config_path, overrides);
    ds = mppi::daemon::parse_daemon_settings(cfg.root["daemon"], cfg.task, static_cast<int>(cfg.mppi.u_init.size()));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "replay: invalid settings: %s\n", e.what());
    return 2;
  }
  const auto& ch = ds.channels;

  // What came out of the daemon: its commands by seq, its status (backend), its answers.
  std::map<std::int64_t, mppi_lcm::command_t> logged;
  std::map<std::int64_t, std::vector<std::int64_t>> params_at;  // cycle -> param_update seqs
  std::map<std::int64_t, const Event*> updates;                  // param_update seq -> event
  std::map<std::int64_t, std::int64_t> sample_utime;             // state seq -> sample time
  std::string recorded_backend;
  std::int64_t last_cmd_seq = 0;
  for (const Event& e : events) {
    if (e.channel == ch.command) {
      mppi_lcm::command_t c;
      if (!decode(e, &c)) continue;
      if (c.seq < last_cmd_seq) {
        std::fprintf(stderr, "replay: command seq steps back (%" PRId64 " after %" PRId64
                     "): the log holds more than one controller run; replaying the first\n", c.seq, last_cmd_seq);
        break;
      }
      last_cmd_seq = c.seq;
      logged.emplace(c.seq, c);
    } else if (e.channel == ch.status && recorded_backend.empty()) {
      mppi_lcm::controller_status_t s;
      if (decode(e, &s)) recorded_backend = s.backend;
    } else if (e.channel == ch.param_result) {
      mppi_lcm::param_result_t r;
      if (decode(e, &r)) params_at[r.cycle].push_back(r.update_seq);
    } else if (e.channel == ch.params) {
      mppi_lcm::param_update_t p;
      if (decode(e, &p)) updates[p.seq] = &e;
    } else if (e.channel == ch.state) {
      mppi_lcm::vehicle_state_t s;
      if (decode(e, &s)) sample_utime[s.seq] = s.sample_utime;
    }
  }
  if (logged.empty()) {
    std::fprintf(stderr, "replay: no commands on %s in %s\n", ch.command.c_str(), log_path.c_str());
    return 2;
  }
  // The same kernels: the SIMD target the flight ran (targets differ in the last ulp).
  if (recorded_backend.rfind("cuda", 0) == 0) {
    std::fprintf(stderr, "replay: the flight ran on %s; the replay runs the CPU backend, whose numbers differ\n",
                 recorded_backend.c_str());
    return 2;
  }
  if (recorded_backend.rfind("cpu-", 0) == 0 || recorded_backend == "cpu") {
    overrides.push_back(recorded_backend == "cpu" ? "mppi.simd=off" : "mppi.simd=" + recorded_backend.substr(4));
    overrides.push_back("backend=cpu");
    try {
      cfg = mppi::app::load_config(config_path, overrides);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "replay: the flight's backend %s: %s\n", recorded_backend.c_str(), e.what());
      return 2;
    }
  }
  ds.loop.lockstep = true;
  ds.loop.deadline_guard = false;

  // ---- the controller, as the daemon built and warmed it up ---------------------------------
  std::unique_ptr<mppi::Controller> first;
  try {
    first = mppi::app::make_controller(cfg);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "replay: cannot build the controller: %s\n", e.what());
    return 2;
  }
  {
    std::vector<float> x0(static_cast<std::size_t>(first->nx()), 0.0f), u(static_cast<std::size_t>(first->nu()));
    for (int i = 0; i < ds.warmup_iterations; ++i) first->iterate(x0.data(), u.data());
    first->reset();
  }
  mppi::Controller* initial = first.get();
  mppi::daemon::LiveOptimizer live(
      std::move(first),
      [cfg](const mppi::MppiSettings& s) {
        return mppi::app::make_controller(cfg.with_mppi(s));
      },
      ds.live, mppi::daemon::LiveOptimizer::Mode::kSynchronous);

  mppi::rt::MonotonicClock clock;
  mppi::transport::LcmTransport lcm_in("memq://", ch, &clock, 4096, 5);
  // A marker on a channel of our own: once it is handled, everything published before it has
  // reached the inbox (memq:// is one FIFO, handled by one thread).
  std::atomic<std::int64_t> marks{0};
  struct Marker {
    std::atomic<std::int64_t>* n;
    void on(const lcm::ReceiveBuffer*, const std::string&) { n->fetch_add(1); }
  } marker{&marks};
  lcm_in.lcm().subscribe("MPPID_REPLAY_MARK", &Marker::on, &marker);
  ReplayTransport tx(&lcm_in);
  mppi::transport::Inbox::Expect expect;
  expect.vehicles = initial->vehicles();
  expect.nx = initial->nx() / initial->vehicles();
  expect.model = ds.expect_model;
  expect.restart_after_ns = ds.loop.state_timeout_ns;
  expect.tick_on_state = ds.lockstep_trigger == "state";
  mppi::transport::Inbox inbox(expect);
  mppi::daemon::ControlLoop loop(initial, &clock, &tx, &inbox, ds.loop);
  loop.set_live_optimizer(&live);
  tx.start(&inbox);
  auto flush = [&] {
    const std::int64_t want = marks.load() + 1;
    lcm_in.lcm().publish("MPPID_REPLAY_MARK", "m", 1);
    while (marks.load() < want) std::this_thread::sleep_for(std::chrono::microseconds(50));
  };

  // ---- replay ------------------------------------------------------------------------------
  const auto& ls = ds.loop.latency;
  std::atomic<bool> stop{false};
  std::int64_t cycles = 0, compared = 0, last_tick_us = 0;
  std::size_t checked = 0;  // tx.out entries compared so far
  int rc = 0;
  auto publish = [&](const Event& e) { lcm_in.lcm().publish(e.channel, e.data.data(), static_cast<unsigned>(e.data.size())); };
  for (const Event& e : events) {
    const bool tick = e.channel == ch.clock || (expect.tick_on_state && e.channel == ch.state);
    if (e.channel != ch.state && e.channel != ch.reference && e.channel != ch.obstacles && !tick) continue;
    if (!tick) {
      publish(e);
      continue;
    }
    if (max_cycles >= 0 && cycles >= max_cycles) break;
    const std::int64_t cycle = loop.cycle_index();
    // Parameter updates that took effect (or were refused) at this cycle.
    if (auto it = params_at.find(cycle); it != params_at.end()) {
      for (std::int64_t seq : it->second)
        if (auto u = updates.find(seq); u != updates.end()) publish(*u->second);
    }
    // The expected latency this cycle used, from its command's lead.
    if (auto c = logged.find(cycle + 1); c != logged.end() && c->second.lead_us > 0) {
      std::int64_t now_us = 0;
      if (e.channel == ch.clock) {
        mppi_lcm::sim_clock_t t;
        if (decode(e, &t)) now_us = t.sim_utime;
      } else {
        mppi_lcm::vehicle_state_t s;
        if (decode(e, &s)) now_us = s.sample_utime;
      }
      if (auto s = sample_utime.find(c->second.state_seq); s != sample_utime.end() && now_us > 0) {
        const std::int64_t t_act = (s->second + c->second.lead_us) * mppi::rt::kNsPerUs;
        loop.set_expected_latency(t_act - now_us * mppi::rt::kNsPerUs - ls.transport_ns - ls.actuation_delay_ns);
      }
      last_tick_us = now_us;
    }
    publish(e);
    flush();
    if (inbox.ticks.empty()) continue;  // a state the inbox refused: no tick, no cycle
    if (loop.step_lockstep(stop)) ++cycles;
    // Compare what this step published (a cycle's command, or a repeated tick's resend).
    for (; checked < tx.out.size(); ++checked) {
      const Command& run = tx.out[checked];
      auto c = logged.find(run.seq);
      if (c == logged.end()) {
        std::printf("replay: cycle %" PRId64 " published command seq %" PRId64 ", which the log does not hold\n",
                    cycle, run.seq);
        rc = 1;
        break;
      }
      const std::string diff = compare(c->second, run);
      if (!diff.empty()) {
        std::printf("replay: first divergence at cycle %" PRId64 " (command seq %" PRId64 ", state seq %" PRId64
                    "): %s\n", cycle, run.seq, c->second.state_seq, diff.c_str());
        rc = 1;
        break;
      }
      ++compared;
    }
    if (rc != 0) break;
  }
  (void)last_tick_us;
  lcm_in.stop();
  if (rc == 0) {
    std::int64_t unreplayed = 0;
    for (const auto& [seq, c] : logged)
      if (seq > cycles) ++unreplayed;
    std::printf("replay: %" PRId64 " cycles, %" PRId64 " commands identical bit for bit (state_seq, mode, kind, u, "
                "age_us, lead_us) on %s; %" PRId64 " logged commands after the last replayed cycle%s\n",
                cycles, compared, loop.controller().backend(), unreplayed,
                max_cycles >= 0 ? " (--max-cycles)" : "");
    std::fflush(stdout);
    if (compared == 0) rc = 1;
  }
  return rc;
}
