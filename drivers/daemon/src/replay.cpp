// mppid-replay: reruns the controller on a recorded lock-step flight and checks every
// command against the log, bit for bit.
//
// The log (lcm-logger's, e.g. tools/sitl run's flight.lcmlog) holds what went into the
// daemon (states, clock ticks, obstacles, local maps, references, parameter updates) and what
// came out (commands, status, parameter answers). A lock-step cycle is a function of its inputs and
// of the daemon's state, with two exceptions that the log also records:
//   - the expected latency (the estimator's, from measured compute times unless pinned
//     with daemon.latency.floor_ms = ceiling_ms): command_t.lead_us gives it back exactly
//     (the daemon keeps it in whole microseconds), cycle by cycle;
//   - when a parameter update took effect (mppi.* ones after the builder thread): each
//     param_result_t names the cycle;
//   - the rollouts each update ran (daemon.work sizes them from measured compute times):
//     command_t.rollouts gives them back, cycle by cycle, and the replay runs those.
// The noise is keyed by (seed, cycle), the seed from the settings, the cycle counter
// starting after daemon.warmup_iterations as in the daemon. So the same settings, the same
// inputs in the same order (fed through the daemon's own LCM decoder, over memq://) and the
// same ControlLoop reproduce every command; the replay compares state_seq, mode, kind, u
// (bitwise), age_us, lead_us and rollouts, and stops at the first difference (cycle, field,
// values).
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
  if (log.rollouts != run.rollouts) return num("rollouts", log.rollouts, run.rollouts);
  return {};
}

struct Options {
  std::string log_path, config_path, backend;
  std::vector<std::string> sets;
  std::int64_t max_cycles = -1;
  bool verbose = false;
};

std::vector<Event> read_log(const std::string& path, bool* ok) {
  std::vector<Event> events;
  lcm::LogFile log(path, "r");
  *ok = log.good();
  if (!*ok) return events;
  while (const lcm::LogEvent* e = log.readNextEvent()) {
    const auto* p = static_cast<const std::uint8_t*>(e->data);
    events.push_back({e->channel, std::vector<std::uint8_t>(p, p + e->datalen)});
  }
  return events;
}

// What came out of the daemon: its commands by seq, its status (backend), its answers; and
// what the replay needs of its inputs (parameter updates by seq, sample times by state seq).
struct Recorded {
  std::map<std::int64_t, mppi_lcm::command_t> commands;
  std::map<std::int64_t, std::vector<std::int64_t>> params_at;  // cycle -> param_update seqs
  std::map<std::int64_t, const Event*> updates;                  // param_update seq -> event
  std::map<std::int64_t, std::int64_t> sample_utime;             // state seq -> sample time
  std::string backend;
};

Recorded index_log(const std::vector<Event>& events, const mppi::transport::LcmChannels& ch) {
  Recorded r;
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
      r.commands.emplace(c.seq, c);
    } else if (e.channel == ch.status && r.backend.empty()) {
      mppi_lcm::controller_status_t s;
      if (decode(e, &s)) r.backend = s.backend;
    } else if (e.channel == ch.param_result) {
      mppi_lcm::param_result_t p;
      if (decode(e, &p)) r.params_at[p.cycle].push_back(p.update_seq);
    } else if (e.channel == ch.params) {
      mppi_lcm::param_update_t p;
      if (decode(e, &p)) r.updates[p.seq] = &e;
    } else if (e.channel == ch.state) {
      mppi_lcm::vehicle_state_t s;
      if (decode(e, &s)) r.sample_utime[s.seq] = s.sample_utime;
    }
  }
  return r;
}

std::vector<std::string> overrides(const Options& o) {
  std::vector<std::string> v = o.sets;
  if (!o.backend.empty()) v.push_back("backend=" + o.backend);
  return v;
}

// The daemon's settings, for a lock-step run without the deadline guard. An error, or "".
std::string load_settings(const Options& o, mppi::app::AppConfig* cfg, mppi::daemon::DaemonSettings* ds) {
  try {
    *cfg = mppi::app::load_config(o.config_path, overrides(o));
    *ds = mppi::daemon::parse_daemon_settings(cfg->root["daemon"], cfg->task, static_cast<int>(cfg->mppi.u_init.size()));
  } catch (const std::exception& e) {
    return std::string("invalid settings: ") + e.what();
  }
  ds->loop.lockstep = true;
  ds->loop.deadline_guard = false;
  ds->loop.work.enabled = false;  // the recorded rollout counts instead (Replay::pin_work_size)
  return {};
}

// The same kernels as the flight: the SIMD target it ran (targets differ in the last ulp).
// An error, or "".
std::string pin_backend(const Options& o, const std::string& recorded, mppi::app::AppConfig* cfg) {
  if (recorded.rfind("cuda", 0) == 0)
    return "the flight ran on " + recorded + "; the replay runs the CPU backend, whose numbers differ";
  if (recorded.rfind("cpu-", 0) != 0 && recorded != "cpu") return {};
  std::vector<std::string> v = overrides(o);
  v.push_back(recorded == "cpu" ? "mppi.simd=off" : "mppi.simd=" + recorded.substr(4));
  v.push_back("backend=cpu");
  try {
    *cfg = mppi::app::load_config(o.config_path, v);
  } catch (const std::exception& e) {
    return "the flight's backend " + recorded + ": " + e.what();
  }
  return {};
}

// The controller, as the daemon built and warmed it up.
std::unique_ptr<mppi::Controller> warmed_controller(const mppi::app::AppConfig& cfg, int warmup_iterations) {
  std::unique_ptr<mppi::Controller> c = mppi::app::make_controller(cfg);
  std::vector<float> x0(static_cast<std::size_t>(c->nx()), 0.0f), u(static_cast<std::size_t>(c->nu()));
  for (int i = 0; i < warmup_iterations; ++i) c->iterate(x0.data(), u.data());
  c->reset();
  return c;
}

// The daemon's ControlLoop fed the log's inputs through the daemon's own LCM decoder on
// memq://, one lock-step tick at a time, its commands compared with the logged ones.
class Replay {
 public:
  Replay(const mppi::app::AppConfig& cfg, const mppi::daemon::DaemonSettings& ds, const Recorded& rec)
      : ds_(ds),
        rec_(rec),
        first_(warmed_controller(cfg, ds.warmup_iterations)),
        initial_(first_.get()),
        live_(std::move(first_), [cfg](const mppi::MppiSettings& s) { return mppi::app::make_controller(cfg.with_mppi(s)); },
              ds.live, mppi::daemon::LiveOptimizer::Mode::kSynchronous),
        lcm_in_("memq://", ds.channels, &clock_, 4096, 5),
        tx_(&lcm_in_),
        inbox_(mppi::daemon::inbox_expects(ds, *initial_)),
        loop_(initial_, &clock_, &tx_, &inbox_, ds.loop) {
    marker_.n = &marks_;
    lcm_in_.lcm().subscribe("MPPID_REPLAY_MARK", &Marker::on, &marker_);
    // Maps in the log's order among the states: one memq:// FIFO, handled by one thread.
    lcm_in_.set_map_thread(mppi::transport::LcmTransport::MapThread::kStateThread);
    loop_.set_live_optimizer(&live_);
    tx_.start(&inbox_);
  }
  ~Replay() { lcm_in_.stop(); }

  // Feeds one logged event; a tick runs a cycle and compares what it published. False at
  // the first divergence (printed).
  bool feed(const Event& e) {
    const auto& ch = ds_.channels;
    const bool tick = e.channel == ch.clock || (inbox_.expect().tick_on_state && e.channel == ch.state);
    if (e.channel != ch.state && e.channel != ch.reference && e.channel != ch.obstacles && e.channel != ch.local_map &&
        !tick)
      return true;
    if (!tick) {
      publish(e);
      return true;
    }
    const std::int64_t cycle = loop_.cycle_index();
    // Parameter updates that took effect (or were refused) at this cycle.
    if (auto it = rec_.params_at.find(cycle); it != rec_.params_at.end()) {
      for (std::int64_t seq : it->second)
        if (auto u = rec_.updates.find(seq); u != rec_.updates.end()) publish(*u->second);
    }
    pin_expected_latency(e, cycle);
    pin_work_size(cycle);
    publish(e);
    flush();
    if (inbox_.ticks.empty()) return true;  // a state the inbox refused: no tick, no cycle
    if (loop_.step_lockstep(stop_)) ++cycles_;
    return compare_published(cycle);
  }

  std::int64_t cycles() const { return cycles_; }
  bool log_ended() const { return log_ended_; }
  std::int64_t compared() const { return compared_; }
  const char* backend() const { return loop_.controller().backend(); }

 private:
  struct Marker {
    std::atomic<std::int64_t>* n = nullptr;
    void on(const lcm::ReceiveBuffer*, const std::string&) { n->fetch_add(1); }
  };

  void publish(const Event& e) {
    lcm_in_.lcm().publish(e.channel, e.data.data(), static_cast<unsigned>(e.data.size()));
  }
  // A marker on a channel of our own: once it is handled, everything published before it
  // has reached the inbox (memq:// is one FIFO, handled by one thread).
  void flush() {
    const std::int64_t want = marks_.load() + 1;
    lcm_in_.lcm().publish("MPPID_REPLAY_MARK", "m", 1);
    while (marks_.load() < want) std::this_thread::sleep_for(std::chrono::microseconds(50));
  }

  // The expected latency this cycle used, from its command's lead.
  void pin_expected_latency(const Event& tick, std::int64_t cycle) {
    const auto c = rec_.commands.find(cycle + 1);
    if (c == rec_.commands.end() || c->second.lead_us <= 0) return;
    std::int64_t now_us = 0;
    if (tick.channel == ds_.channels.clock) {
      mppi_lcm::sim_clock_t t;
      if (decode(tick, &t)) now_us = t.sim_utime;
    } else {
      mppi_lcm::vehicle_state_t s;
      if (decode(tick, &s)) now_us = s.sample_utime;
    }
    const auto s = rec_.sample_utime.find(c->second.state_seq);
    if (s == rec_.sample_utime.end() || now_us <= 0) return;
    const auto& ls = ds_.loop.latency;
    const std::int64_t t_act = (s->second + c->second.lead_us) * mppi::rt::kNsPerUs;
    loop_.set_expected_latency(t_act - now_us * mppi::rt::kNsPerUs - ls.transport_ns - ls.actuation_delay_ns);
  }

  // The rollouts this cycle ran, from its command.
  void pin_work_size(std::int64_t cycle) {
    const auto c = rec_.commands.find(cycle + 1);
    if (c != rec_.commands.end() && c->second.rollouts > 0) loop_.set_work_size(c->second.rollouts);
  }

  // What this step published (a cycle's command, or a repeated tick's resend).
  bool compare_published(std::int64_t cycle) {
    for (; checked_ < tx_.out.size(); ++checked_) {
      const Command& run = tx_.out[checked_];
      auto c = rec_.commands.find(run.seq);
      if (c == rec_.commands.end() && run.seq > rec_.commands.rbegin()->first) {
        // The recording stopped between this cycle's state and its command: the log ends here.
        std::printf("replay: the log ends before command seq %" PRId64 " (the recording stopped first)\n", run.seq);
        log_ended_ = true;
        return true;
      }
      if (c == rec_.commands.end()) {
        std::printf("replay: cycle %" PRId64 " published command seq %" PRId64 ", which the log does not hold\n",
                    cycle, run.seq);
        return false;
      }
      const std::string diff = compare(c->second, run);
      if (!diff.empty()) {
        std::printf("replay: first divergence at cycle %" PRId64 " (command seq %" PRId64 ", state seq %" PRId64
                    "): %s\n", cycle, run.seq, c->second.state_seq, diff.c_str());
        return false;
      }
      ++compared_;
    }
    return true;
  }

  const mppi::daemon::DaemonSettings& ds_;
  const Recorded& rec_;
  std::unique_ptr<mppi::Controller> first_;
  mppi::Controller* initial_;
  mppi::daemon::LiveOptimizer live_;
  mppi::rt::MonotonicClock clock_;
  mppi::transport::LcmTransport lcm_in_;
  ReplayTransport tx_;
  mppi::transport::Inbox inbox_;
  mppi::daemon::ControlLoop loop_;
  std::atomic<std::int64_t> marks_{0};
  Marker marker_;
  std::atomic<bool> stop_{false};
  std::int64_t cycles_ = 0, compared_ = 0;
  std::size_t checked_ = 0;  // tx_.out entries compared so far
  bool log_ended_ = false;   // a cycle past the log's last command: the recording stopped first
};

// The flight's events, the daemon's settings, the log's index (which points into `events`)
// and the backend it was flown with; "" or why not.
std::string load_flight(const Options& o, std::vector<Event>* events, mppi::app::AppConfig* cfg,
                        mppi::daemon::DaemonSettings* ds, Recorded* rec) {
  bool readable = false;
  *events = read_log(o.log_path, &readable);
  if (!readable) return "cannot read " + o.log_path;
  if (std::string err = load_settings(o, cfg, ds); !err.empty()) return err;
  *rec = index_log(*events, ds->channels);
  if (rec->commands.empty()) return "no commands on " + ds->channels.command + " in " + o.log_path;
  return pin_backend(o, rec->backend, cfg);
}

// The log's events through the replay, to the end, --max-cycles or the first divergence;
// the exit code (0: every command compared was identical, and there was one).
int replay_flight(const Options& o, const std::vector<Event>& events, const Recorded& rec, Replay& replay) {
  for (const Event& e : events) {
    if (o.max_cycles >= 0 && replay.cycles() >= o.max_cycles) break;
    if (!replay.feed(e)) return 1;
    if (replay.log_ended()) break;
  }
  std::int64_t unreplayed = 0;
  for (const auto& [seq, c] : rec.commands)
    if (seq > replay.cycles()) ++unreplayed;
  std::printf("replay: %" PRId64 " cycles, %" PRId64 " commands identical bit for bit (state_seq, mode, kind, u, "
              "age_us, lead_us, rollouts) on %s; %" PRId64 " logged commands after the last replayed cycle%s\n",
              replay.cycles(), replay.compared(), replay.backend(), unreplayed,
              o.max_cycles >= 0 ? " (--max-cycles)" : "");
  std::fflush(stdout);
  return replay.compared() == 0 ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mppid-replay: rerun the controller on a recorded lock-step flight, compare every command bit for bit"};
  Options o;
  app.add_option("log", o.log_path, "LCM log of the flight (flight.lcmlog)")->required()->check(CLI::ExistingFile);
  app.add_option("--config", o.config_path, "the daemon's settings file")->required();
  app.add_option("--set", o.sets, "the daemon's overrides, key.path=value (repeatable), in its order");
  app.add_option("--backend", o.backend, "cpu (the replay runs the CPU backend)");
  app.add_option("--max-cycles", o.max_cycles, "stop after this many cycles (default: all)");
  app.add_flag("--verbose", o.verbose, "log the daemon's messages");
  CLI11_PARSE(app, argc, argv);
  spdlog::set_level(o.verbose ? spdlog::level::info : spdlog::level::err);

  std::vector<Event> events;
  mppi::app::AppConfig cfg;
  mppi::daemon::DaemonSettings ds;
  Recorded rec;
  if (const std::string err = load_flight(o, &events, &cfg, &ds, &rec); !err.empty()) {
    std::fprintf(stderr, "replay: %s\n", err.c_str());
    return 2;
  }
  std::unique_ptr<Replay> replay;
  try {
    replay = std::make_unique<Replay>(cfg, ds, rec);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "replay: cannot build the controller: %s\n", e.what());
    return 2;
  }
  return replay_flight(o, events, rec, *replay);
}
