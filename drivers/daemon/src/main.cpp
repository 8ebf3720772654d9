// mppid: settings -> controller -> transport self-test -> warm-up -> READY -> loop.
// The main thread owns signals (blocked everywhere else, taken with sigtimedwait), the
// systemd watchdog and STATUS= line; the loop thread owns the controller and publishes.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <spdlog/async.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <thread>
#include <type_traits>

#include "mppi/app/config.hpp"
#include "mppi/tasks.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/daemon/live_optimizer.hpp"
#include "mppi/daemon/lcm_url_check.hpp"
#include "mppi/daemon/notifier.hpp"
#include "mppi/daemon/stats_report.hpp"
#include "mppi/rt/clock.hpp"
#include "mppi/rt/realtime.hpp"
#include "mppi/transport/lcm_transport.hpp"

namespace {

using mppi::daemon::ControlLoop;
using mppi::daemon::DaemonSettings;

constexpr int kExitConfig = 2;
constexpr int kExitRuntime = 1;

struct Options {
  std::string config_path, vehicle_path, backend, controller_kind, lcm_url, log_level = "info";
  std::vector<std::string> sets;
  bool lockstep = false, realtime = false, require_realtime = false, stats = false, self_test = false;
  double duration_s = 0.0;
};

// The options, or the exit code (--help, a bad option).
std::optional<int> parse_options(int argc, char** argv, Options* o) {
  CLI::App app{"mppid: deterministic fixed-rate MPPI controller daemon"};
  app.add_option("--config", o->config_path, "Settings file (YAML)")->required();
  app.add_option("--set", o->sets, "Override a setting: key.path=value (repeatable)");
  app.add_option("--vehicle", o->vehicle_path, "Vehicle file (config/vehicles/*.yaml; overrides the settings' vehicle:)");
  app.add_option("--backend", o->backend, "cpu | cuda | auto");
  app.add_option("--controller", o->controller_kind,
                 "mppi (default) | ddp: the MPC-DDP baseline (iLQR, the settings file's ddp: section)")
      ->check(CLI::IsMember({"mppi", "ddp"}));
  app.add_option("--lcm-url", o->lcm_url, "LCM URL (overrides daemon.lcm_url)");
  app.add_flag("--lockstep", o->lockstep, "Run one cycle per sim_clock_t tick instead of the wall clock");
  app.add_flag("--realtime", o->realtime, "SCHED_FIFO, mlockall, CPU affinity (runs on if refused)");
  app.add_flag("--require-realtime", o->require_realtime, "Like --realtime, but exit non-zero if refused");
  app.add_flag("--stats", o->stats, "Print a timing and counter summary on exit");
  app.add_option("--duration", o->duration_s, "Stop after this many seconds (0 = until a signal)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--log-level", o->log_level, "trace | debug | info | warn | error");
  app.add_flag("--self-test", o->self_test,
               "Load the settings, build the controller, run a few cycles from rest, check the command is "
               "finite and print the compute time; exit 0 if so (no LCM, no real time)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  o->realtime = o->realtime || o->require_realtime;
  return std::nullopt;
}

// Asynchronous and non-blocking: the loop thread only enqueues (mode changes, parameter
// results); a slow stderr/journal never stalls a cycle (the oldest line is dropped).
void start_logging(const std::string& level) {
  spdlog::init_thread_pool(4096, 1);
  auto logger = std::make_shared<spdlog::async_logger>("mppid", std::make_shared<spdlog::sinks::stderr_color_sink_mt>(),
                                                       spdlog::thread_pool(), spdlog::async_overflow_policy::overrun_oldest);
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e %^%l%$ mppid: %v");
}

// The settings file with the command line's overrides, and the daemon section of the
// backend that will fly (a `cuda:` or `cpu_targets:` section may set its own; every
// variant's is checked whatever the machine, like the rest of the file).
void load_settings(const Options& o, mppi::app::AppConfig* cfg, DaemonSettings* ds) {
  std::vector<std::string> overrides = o.sets;
  if (!o.backend.empty()) overrides.push_back("backend=" + o.backend);
  if (!o.controller_kind.empty()) overrides.push_back("controller=" + o.controller_kind);
  // Relative to where mppid was started (a `vehicle:` in the file is relative to the file).
  if (!o.vehicle_path.empty()) overrides.push_back("vehicle=" + std::filesystem::absolute(o.vehicle_path).string());
  *cfg = mppi::app::load_config(o.config_path, overrides);
  const int nu = static_cast<int>(cfg->mppi.u_init.size());
  const auto check_daemon = [&](const mppi::app::AppConfig& v, const std::string& name) {
    try {
      mppi::daemon::parse_daemon_settings(v.root["daemon"], cfg->task, nu);
    } catch (const mppi::app::ConfigError& e) {
      throw mppi::app::ConfigError(name + ": " + e.what());
    }
  };
  if (cfg->cuda) check_daemon(*cfg->cuda, "cuda");
  for (const auto& [target, v] : cfg->cpu_targets) check_daemon(*v, "cpu_targets." + target);
  std::string section;
  const mppi::app::AppConfig* variant = cfg->variant(mppi::app::resolve_backend(cfg->backend), &section);
  const auto& flying = variant != nullptr ? *variant : *cfg;
  if (variant != nullptr) spdlog::info("settings: the file's {} section applies on this machine", section);
  if (cfg->vehicle) spdlog::info("vehicle {} from {}", cfg->vehicle->name, cfg->vehicle->path);
  *ds = mppi::daemon::parse_daemon_settings(flying.root["daemon"], cfg->task, nu);
}

// What the command line changes in the daemon section.
void apply_options(const Options& o, DaemonSettings* ds) {
  if (!o.lcm_url.empty()) ds->lcm_url = o.lcm_url;
  if (const std::string why = mppi::daemon::lcm_url_leaves_host(ds->lcm_url); !why.empty())
    spdlog::warn("lcm_url {}: {}", ds->lcm_url, why);  // legal, but the bus would leave this machine
  if (o.lockstep) ds->loop.lockstep = true;
  if (ds->local_map) {
    ds->lcm_url = mppi::daemon::with_map_receive_buffer(ds->lcm_url);
    long rmem_max = 0;
    std::ifstream("/proc/sys/net/core/rmem_max") >> rmem_max;
    if (const std::string why = mppi::daemon::map_receive_buffer_warning(ds->lcm_url, rmem_max); !why.empty())
      spdlog::warn("lcm_url {}: {}", ds->lcm_url, why);
  }
  // The deadline guard must preempt a stalled optimizer (and its OpenMP workers).
  if (o.realtime && ds->realtime.fifo_priority > 0)
    ds->loop.guard_fifo_priority = std::min(99, ds->realtime.fifo_priority + 2);
}

void log_controller(const mppi::Controller& c, const mppi::app::AppConfig& cfg, const DaemonSettings& ds) {
  const char* lockstep = ds.loop.lockstep ? ", lock-step" : "";
  if (cfg.controller == "ddp")
    spdlog::info("task {}: MPC-DDP (iLQR, at most {} iterations per cycle) T={} dt={}, {} Hz{}", c.task(),
                 cfg.ddp.max_iterations, c.settings().horizon, c.settings().dt, ds.loop.rate_hz, lockstep);
  else
    spdlog::info("task {} on {} backend: K={} T={} dt={} lambda={} nu={}, {} Hz{}", c.task(), c.backend(),
                 c.settings().rollouts, c.settings().horizon, c.settings().dt, c.settings().lambda, c.settings().nu,
                 ds.loop.rate_hz, lockstep);
  if (const auto& w = ds.loop.work; w.enabled && cfg.controller != "ddp")
    spdlog::info("work: rollouts sized to this computer, {} to {}, compute p99 under {:.0f} % of the period (daemon.work)",
                 std::min(w.floor, c.settings().rollouts), c.settings().rollouts, 100.0 * w.target);
}

// Settings (the command line's changes included), the memory lock of --realtime, the
// controller. 0, or the exit code.
int build_controller(const Options& opt, mppi::app::AppConfig* cfg, DaemonSettings* ds,
                     mppi::rt::RealtimeResult* rt_result, std::unique_ptr<mppi::Controller>* controller) {
  try {
    load_settings(opt, cfg, ds);
  } catch (const std::exception& e) {
    spdlog::error("invalid settings: {}", e.what());
    return kExitConfig;
  }
  apply_options(opt, ds);
  if (opt.realtime) mppi::rt::lock_memory(ds->realtime, rt_result);
  try {
    *controller = mppi::app::make_controller(*cfg);
  } catch (const mppi::app::ConfigError& e) {
    spdlog::error("invalid settings: {}", e.what());
    return kExitConfig;
  } catch (const std::exception& e) {
    spdlog::error("cannot build the controller: {}", e.what());
    return kExitRuntime;
  }
  const int nu = (*controller)->nu();
  if (!ds->loop.failsafe_u.empty() && static_cast<int>(ds->loop.failsafe_u.size()) != nu) {
    spdlog::error("invalid settings: daemon.failsafe_u: expected {} numbers", nu);
    return kExitConfig;
  }
  log_controller(**controller, *cfg, *ds);
  return 0;
}

// The LCM transport, self-tested. The plan message buffer is sized once, for the longest
// horizon a live update may set. 0, or the exit code.
int open_transport(const DaemonSettings& ds, const mppi::Controller& c, mppi::rt::Clock* clock,
                   std::unique_ptr<mppi::transport::LcmTransport>* tx) {
  const int max_plan_steps = ds.live.enabled ? std::max(c.horizon(), ds.live.max_horizon) : c.horizon();
  try {
    *tx = std::make_unique<mppi::transport::LcmTransport>(ds.lcm_url, ds.channels, clock, max_plan_steps * c.nu(),
                                                          ds.receive_timeout_ms);
    // Real time: maps on an LCM instance and thread of their own, so no state waits behind a
    // map's decode. Lock-step: on the states' thread, so the loop takes them in the bus's order
    // and a flight repeats and replays (tools/replay) as it did.
    if (ds.loop.lockstep) (*tx)->set_map_thread(mppi::transport::LcmTransport::MapThread::kStateThread);
    if (ds.local_map) (*tx)->open_map_receiver();
  } catch (const std::exception& e) {
    spdlog::error("invalid settings: daemon.{}", e.what());
    return kExitConfig;
  }
  if (const std::string why = (*tx)->self_test(); !why.empty()) {
    spdlog::error("transport self-test failed: {}", why);
    return kExitRuntime;
  }
  spdlog::info("transport self-test passed on {}", ds.lcm_url);
  if (const mppi::daemon::FanSettings& fan = ds.loop.rollouts; fan.hz > 0.0) {
    const int n = fan.top + fan.random;
    (*tx)->reserve_rollouts(n, n * c.vehicles() * (c.horizon() + 1) * 3);
    spdlog::info("rollouts: {} lowest-cost and {} random at {} Hz on {}", fan.top, fan.random, fan.hz,
                 ds.channels.rollouts);
  }
  return 0;
}

// Live optimizer updates: the builder thread makes controllers from the same settings with
// new mppi.* values; it owns the controller in service from here on. In lock-step the loop
// builds them itself at the next cycle (no deadline there), so the cycle an update takes
// effect at does not depend on how the builder thread was scheduled: a lock-step run with
// updates repeats, and a fast one cannot end before its updates were built.
std::unique_ptr<mppi::daemon::LiveOptimizer> make_live(std::unique_ptr<mppi::Controller> controller,
                                                       const mppi::app::AppConfig& cfg, const DaemonSettings& ds) {
  return std::make_unique<mppi::daemon::LiveOptimizer>(
      std::move(controller),
      [cfg](const mppi::MppiSettings& s) { return mppi::app::make_controller(cfg.with_mppi(s)); }, ds.live,
      ds.loop.lockstep ? mppi::daemon::LiveOptimizer::Mode::kSynchronous
                       : mppi::daemon::LiveOptimizer::Mode::kBuilderThread);
}

// OpenMP workers that spin after a parallel region under SCHED_FIFO hold off the receive
// and loop threads (measured in lock-step: ~8 ms between a tick and the cycle's start in
// one flight of ten with 2 threads; none with passive workers, at the same compute time).
// libgomp reads its wait policy when it loads, before main: re-execute once with
// OMP_WAIT_POLICY=PASSIVE unless the caller chose a policy.
void reexec_with_passive_omp_workers(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr) return;
  ::setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
  ::execv("/proc/self/exe", argv);  // returns only on failure: then run on as we are
}

// Signals go to the main thread only: blocked before any thread exists (the logger's
// thread pool included); the main thread takes them with sigtimedwait.
sigset_t block_stop_signals() {
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGINT);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);
  return sigs;
}

std::string status_line(const ControlLoop& loop, double rate_hz) {
  const auto s = loop.snapshot();
  char buf[200];
  std::snprintf(buf, sizeof(buf), "%s at %.1f Hz (nominal %.0f), cycles %lld, misses %lld (%lld in a row), mode %s",
                loop.settings().lockstep ? "lock-step" : "running", s.rate_hz, rate_hz,
                static_cast<long long>(s.cycles), static_cast<long long>(s.misses),
                static_cast<long long>(s.consecutive_misses), mppi::transport::to_string(loop.mode()));
  return buf;
}

// The loop thread: real-time set-up, warm-up, READY (ready = 1), then, once the main thread
// releases it (ready = 2), cycles until stop, and the final status.
struct LoopThread {
  LoopThread(ControlLoop* l, mppi::Controller* c, const DaemonSettings* d, bool rt, mppi::rt::RealtimeResult* r)
      : loop(l), controller(c), ds(d), realtime(rt), rt_result(r) {}
  ControlLoop* loop;
  mppi::Controller* controller;
  const DaemonSettings* ds;
  bool realtime;
  mppi::rt::RealtimeResult* rt_result;
  std::atomic<bool> stop{false};
  std::atomic<int> ready{0};  // 1 warmed up, -1 failed, 2 released
  std::string warmup_error;

  void main() {
    mppi::rt::RealtimeRequest req = ds->realtime;
    const int cpu = req.cpu;
    req.cpu = -1;
    if (realtime) mppi::rt::make_thread_realtime(req, rt_result);
    if (!warm_up()) return;
    if (realtime) pin(req.fifo_priority, cpu);
    loop->prepare();  // the deadline guard thread, before READY
    ready = 1;
    while (ready.load() == 1 && !stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (stop.load()) return;
    loop->run(stop);
    loop->publish_final_status();
  }

  // First-touch the backend's buffers and start its thread pool from this (real-time)
  // thread, so the worker threads inherit its policy.
  bool warm_up() {
    try {
      std::vector<float> x0(static_cast<std::size_t>(controller->nx()), 0.0f);
      std::vector<float> u(static_cast<std::size_t>(controller->nu()));
      for (int i = 0; i < ds->warmup_iterations; ++i) controller->iterate(x0.data(), u.data());
      controller->reset();
      return true;
    } catch (const std::exception& e) {
      warmup_error = e.what();
      ready = -1;
      return false;
    }
  }

  // The OpenMP workers keep the warm-up's priority; the loop thread goes one above them:
  // under SCHED_FIFO a worker still spinning after a parallel region on the loop's CPU
  // would otherwise hold the loop off until it sleeps (measured: ~8 ms between a lock-step
  // tick and the cycle's start with 2 threads).
  void pin(int fifo_priority, int cpu) {
    mppi::rt::RealtimeRequest p;
    p.lock_memory = false;
    p.fifo_priority = fifo_priority > 0 ? std::min(98, fifo_priority + 1) : 0;
    p.prefault_stack_bytes = 0;
    p.cpu = cpu;
    mppi::rt::make_thread_realtime(p, rt_result);
  }
};

// After the warm-up: the real-time outcome. False when --require-realtime was refused.
bool report_realtime(const mppi::rt::RealtimeResult& r, const DaemonSettings& ds, bool require) {
  for (const auto& why : r.refused) spdlog::warn("real-time refused: {}", why);
  if (!r.ok() && require) {
    spdlog::error("--require-realtime: the OS refused real-time operation; exiting");
    return false;
  }
  if (r.ok())
    spdlog::info("real-time: mlockall, SCHED_FIFO {}{}", ds.realtime.fifo_priority,
                 ds.realtime.cpu >= 0 ? ", pinned to CPU " + std::to_string(ds.realtime.cpu) : "");
  else
    spdlog::warn("running on without full real-time guarantees");
  return true;
}

// The main thread while the loop runs: signals, the watchdog (fed only while the loop itself
// is well: cycling, or in lock-step waiting on the simulator, and not stuck in misses or
// optimizer failures), the STATUS= line. Returns the signal that stopped it (0: duration).
int supervise(const ControlLoop& loop, const DaemonSettings& ds, mppi::daemon::Notifier& notify, const sigset_t& sigs,
              std::int64_t t_start, double duration_s) {
  const std::int64_t watchdog_every = notify.watchdog_ns() > 0 ? notify.watchdog_ns() / 4 : 0;
  const std::int64_t stale_heartbeat =
      std::max<std::int64_t>(std::llround(3e9 / ds.loop.rate_hz), 500 * mppi::rt::kNsPerMs);
  std::int64_t last_ping = 0, last_status = t_start;
  while (true) {
    const timespec wait{0, 20 * 1000 * 1000};
    const int sig = sigtimedwait(&sigs, nullptr, &wait);
    if (sig > 0) return sig;
    const std::int64_t now = mppi::rt::monotonic_ns();
    if (duration_s > 0.0 && static_cast<double>(now - t_start) * 1e-9 >= duration_s) return 0;
    const bool alive = ds.loop.lockstep || now - loop.heartbeat_ns() < stale_heartbeat;
    if (watchdog_every > 0 && now - last_ping >= watchdog_every && alive && loop.loop_healthy()) {
      notify.watchdog();
      last_ping = now;
    }
    if (now - last_status >= mppi::rt::kNsPerS) {
      notify.status(status_line(loop, ds.loop.rate_hz));
      last_status = now;
    }
  }
}

void log_stopped(const ControlLoop& loop, std::int64_t t_stop) {
  const auto total = loop.timing_total();
  spdlog::info(
      "final status published (status #{}); stopped after {} cycles, {} misses ({} late starts), {:.1f} ms after the "
      "stop request",
      loop.counters().status_published.load(), total.cycles, total.misses, total.late_start_misses,
      static_cast<double>(mppi::rt::monotonic_ns() - t_stop) * 1e-6);
}

void print_stats(const ControlLoop& loop, const DaemonSettings& ds, const mppi::transport::Inbox& inbox,
                 bool realtime_fifo, long rss_start_kb, double seconds) {
  mppi::daemon::RunFacts f;
  f.task = loop.controller().task();
  f.backend = loop.controller().backend();
  f.rollouts = loop.controller().settings().rollouts;
  f.horizon = loop.controller().horizon();
  f.rate_hz = ds.loop.rate_hz;
  f.seconds = seconds;
  f.lockstep = ds.loop.lockstep;
  f.realtime = realtime_fifo;
  f.rss_start_kb = rss_start_kb;
  f.rss_end_kb = mppi::rt::resident_kb();
  std::cout << mppi::daemon::format_stats(f, loop, inbox.counters) << std::flush;
}

// The loop thread's real-time set-up and warm-up done (else it is joined, and false), and
// the real-time report given (where it was required and refused, the thread is stopped).
bool await_warm_up(LoopThread* lt, std::thread* loop_thread, const Options& opt,
                   const mppi::rt::RealtimeResult& rt_result, const DaemonSettings& ds) {
  while (lt->ready.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (lt->ready.load() < 0) {
    loop_thread->join();
    spdlog::error("backend warm-up failed: {}", lt->warmup_error);
    return false;
  }
  if (opt.realtime && !report_realtime(rt_result, ds, opt.require_realtime)) {
    lt->stop = true;
    loop_thread->join();
    return false;
  }
  return true;
}

// --self-test: a resting state (zeros, the identity attitude where the model has a
// quaternion), kSelfTestCycles cycles from it after the warm-up; the command must be finite
// and inside the limits. Prints the compute time against the loop's period, so a board
// shows before its first flight whether the settings fit it.
constexpr int kSelfTestCycles = 20;

std::vector<float> rest_state(const mppi::Controller& c) {
  std::vector<float> x(static_cast<std::size_t>(c.nx()), 0.0f);
  mppi::visit_task(c.task(), [&](auto tag) {
    using Vehicle = typename decltype(tag)::type::Vehicle;
    if constexpr (std::is_same_v<Vehicle, mppi::QuadrotorRate>)
      for (int v = 0; v < c.vehicles(); ++v) x[static_cast<std::size_t>(v * Vehicle::kNx + Vehicle::QW)] = 1.0f;
  });
  return x;
}

int run_self_test(mppi::Controller& c, const DaemonSettings& ds) {
  const std::vector<float> x0 = rest_state(c);
  std::vector<float> u(static_cast<std::size_t>(c.nu()));
  for (int i = 0; i < ds.warmup_iterations; ++i) c.iterate(x0.data(), u.data());
  std::vector<double> ms;
  for (int i = 0; i < kSelfTestCycles; ++i) {
    const std::int64_t t0 = mppi::rt::monotonic_ns();
    const mppi::UpdateStats& st = c.iterate(x0.data(), u.data());
    ms.push_back(static_cast<double>(mppi::rt::monotonic_ns() - t0) * 1e-6);
    const bool finite = std::all_of(u.begin(), u.end(), [](float v) { return std::isfinite(v); });
    if (!st.finite || !finite) {
      spdlog::error("self-test FAILED: cycle {} gave a non-finite {}", i + 1, finite ? "update" : "command");
      return kExitRuntime;
    }
  }
  std::sort(ms.begin(), ms.end());
  const double period_ms = 1e3 / ds.loop.rate_hz;
  spdlog::info("self-test passed: task {} on {}, K={} T={}: {} cycles from rest, command finite; compute median "
               "{:.2f} ms, max {:.2f} ms of the {:.1f} ms period",
               c.task(), c.backend(), c.settings().rollouts, c.horizon(), kSelfTestCycles, ms[ms.size() / 2],
               ms.back(), period_ms);
  if (ms[ms.size() / 2] > 0.5 * period_ms)
    spdlog::warn("compute takes over half the period on this machine: fewer rollouts (mppi.rollouts) leave room "
                 "for the bridge and the recorder (docs/first-flight.md, latency budget)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  reexec_with_passive_omp_workers(argv);
  Options opt;
  if (const auto exit_code = parse_options(argc, argv, &opt)) return *exit_code;
  const sigset_t sigs = block_stop_signals();
  start_logging(opt.log_level);
  struct FlushAtExit {
    ~FlushAtExit() { spdlog::shutdown(); }
  } flush_at_exit;

  // ---- settings, controller, transport ------------------------------------------------------
  mppi::app::AppConfig cfg;
  DaemonSettings ds;
  mppi::rt::RealtimeResult rt_result;
  std::unique_ptr<mppi::Controller> controller;
  if (const int rc = build_controller(opt, &cfg, &ds, &rt_result, &controller); rc != 0) return rc;
  if (opt.self_test) return run_self_test(*controller, ds);
  mppi::rt::MonotonicClock clock(ds.spin && !ds.loop.lockstep);
  std::unique_ptr<mppi::transport::LcmTransport> tx;
  if (const int rc = open_transport(ds, *controller, &clock, &tx); rc != 0) return rc;
  auto inbox = std::make_unique<mppi::transport::Inbox>(mppi::daemon::inbox_expects(ds, *controller));
  mppi::Controller* const initial = controller.get();
  std::unique_ptr<mppi::daemon::LiveOptimizer> live;
  if (ds.live.enabled) live = make_live(std::move(controller), cfg, ds);
  ControlLoop loop(initial, &clock, tx.get(), inbox.get(), ds.loop);
  loop.set_live_optimizer(live.get());

  // ---- loop thread: real-time set-up, warm-up, then cycles -------------------------------
  LoopThread lt(&loop, initial, &ds, opt.realtime, &rt_result);
  std::thread loop_thread([&lt] { lt.main(); });
  if (!await_warm_up(&lt, &loop_thread, opt, rt_result, ds)) return kExitRuntime;

  // ---- run ---------------------------------------------------------------------------------
  // States and ticks must be taken in while the optimizer fills the cores.
  if (opt.realtime && ds.realtime.fifo_priority > 0) tx->set_receive_fifo_priority(std::min(99, ds.realtime.fifo_priority + 2));
  tx->set_receive_spin(ds.spin && !ds.loop.lockstep);
  tx->start(inbox.get());
  const long rss_start = mppi::rt::resident_kb();
  const std::int64_t t_start = mppi::rt::monotonic_ns();
  lt.ready = 2;  // release the loop
  mppi::daemon::Notifier notify;
  notify.ready(status_line(loop, ds.loop.rate_hz));
  spdlog::info("ready: {} Hz, state on {}, command on {}", ds.loop.rate_hz, ds.channels.state, ds.channels.command);
  const int signal_number = supervise(loop, ds, notify, sigs, t_start, opt.duration_s);

  // ---- stop --------------------------------------------------------------------------------
  if (signal_number) spdlog::info("{}: stopping", signal_number == SIGTERM ? "SIGTERM" : "SIGINT");
  const std::int64_t t_stop = mppi::rt::monotonic_ns();
  notify.stopping();
  lt.stop = true;
  loop_thread.join();  // publishes the final status
  tx->stop();
  const double seconds = static_cast<double>(mppi::rt::monotonic_ns() - t_start) * 1e-9;
  log_stopped(loop, t_stop);
  if (opt.stats) print_stats(loop, ds, *inbox, opt.realtime && rt_result.fifo, rss_start, seconds);
  return 0;
}
