// mppid: settings -> controller -> transport self-test -> warm-up -> READY -> loop.
// The main thread owns signals (blocked everywhere else, taken with sigtimedwait), the
// systemd watchdog and STATUS= line; the loop thread owns the controller and publishes.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <spdlog/async.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <thread>

#include "mppi/app/config.hpp"
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

constexpr int kExitConfig = 2;
constexpr int kExitRuntime = 1;

std::string status_line(const mppi::daemon::ControlLoop& loop, double rate_hz) {
  const auto s = loop.snapshot();
  char buf[200];
  std::snprintf(buf, sizeof(buf), "%s at %.1f Hz (nominal %.0f), cycles %lld, misses %lld (%lld in a row), mode %s",
                loop.settings().lockstep ? "lock-step" : "running", s.rate_hz, rate_hz,
                static_cast<long long>(s.cycles), static_cast<long long>(s.misses),
                static_cast<long long>(s.consecutive_misses), mppi::transport::to_string(loop.mode()));
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  // OpenMP workers that spin after a parallel region under SCHED_FIFO hold off the
  // receive and loop threads (measured in lock-step: ~8 ms between a tick and the cycle's
  // start in one flight of ten with 2 threads; none with passive workers, at the same
  // compute time). libgomp reads its wait policy when it loads, before main: re-execute
  // once with OMP_WAIT_POLICY=PASSIVE unless the caller chose a policy.
  if (std::getenv("OMP_WAIT_POLICY") == nullptr) {
    ::setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
    ::execv("/proc/self/exe", argv);  // returns only on failure: then run on as we are
  }
  CLI::App app{"mppid: deterministic fixed-rate MPPI controller daemon"};
  std::string config_path, vehicle_path, backend, controller_kind, lcm_url, log_level = "info";
  std::vector<std::string> sets;
  bool lockstep = false, realtime = false, require_realtime = false, stats = false;
  double duration_s = 0.0;
  app.add_option("--config", config_path, "Settings file (YAML)")->required();
  app.add_option("--set", sets, "Override a setting: key.path=value (repeatable)");
  app.add_option("--vehicle", vehicle_path, "Vehicle file (config/vehicles/*.yaml; overrides the settings' vehicle:)");
  app.add_option("--backend", backend, "cpu | cuda | auto");
  app.add_option("--controller", controller_kind,
                 "mppi (default) | ddp: the MPC-DDP baseline (iLQR, the settings file's ddp: section)")
      ->check(CLI::IsMember({"mppi", "ddp"}));
  app.add_option("--lcm-url", lcm_url, "LCM URL (overrides daemon.lcm_url)");
  app.add_flag("--lockstep", lockstep, "Run one cycle per sim_clock_t tick instead of the wall clock");
  app.add_flag("--realtime", realtime, "SCHED_FIFO, mlockall, CPU affinity (runs on if refused)");
  app.add_flag("--require-realtime", require_realtime, "Like --realtime, but exit non-zero if refused");
  app.add_flag("--stats", stats, "Print a timing and counter summary on exit");
  app.add_option("--duration", duration_s, "Stop after this many seconds (0 = until a signal)")->check(CLI::NonNegativeNumber);
  app.add_option("--log-level", log_level, "trace | debug | info | warn | error");
  CLI11_PARSE(app, argc, argv);
  realtime = realtime || require_realtime;

  // Signals go to the main thread only: block them before any thread exists (the logger's
  // thread pool included); the main thread takes them with sigtimedwait.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGINT);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  // Asynchronous and non-blocking: the loop thread only enqueues (mode changes, parameter
  // results); a slow stderr/journal never stalls a cycle (the oldest line is dropped).
  spdlog::init_thread_pool(4096, 1);
  auto logger = std::make_shared<spdlog::async_logger>("mppid", std::make_shared<spdlog::sinks::stderr_color_sink_mt>(),
                                                       spdlog::thread_pool(), spdlog::async_overflow_policy::overrun_oldest);
  spdlog::set_default_logger(logger);
  struct FlushAtExit {
    ~FlushAtExit() { spdlog::shutdown(); }
  } flush_at_exit;
  spdlog::set_level(spdlog::level::from_str(log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e %^%l%$ mppid: %v");

  // ---- settings -------------------------------------------------------------------
  std::vector<std::string> overrides = sets;
  if (!backend.empty()) overrides.push_back("backend=" + backend);
  if (!controller_kind.empty()) overrides.push_back("controller=" + controller_kind);
  // Relative to where mppid was started (a `vehicle:` in the file is relative to the file).
  if (!vehicle_path.empty()) overrides.push_back("vehicle=" + std::filesystem::absolute(vehicle_path).string());
  mppi::app::AppConfig cfg;
  mppi::daemon::DaemonSettings ds;
  try {
    cfg = mppi::app::load_config(config_path, overrides);
    // The daemon section of the backend that will fly (a `cuda:` section may set its own).
    const int nu = static_cast<int>(cfg.mppi.u_init.size());
    // Every variant's daemon section is checked whatever the machine, like the rest of it.
    const auto check_daemon = [&](const mppi::app::AppConfig& v, const std::string& name) {
      try {
        mppi::daemon::parse_daemon_settings(v.root["daemon"], cfg.task, nu);
      } catch (const mppi::app::ConfigError& e) {
        throw mppi::app::ConfigError(name + ": " + e.what());
      }
    };
    if (cfg.cuda) check_daemon(*cfg.cuda, "cuda");
    for (const auto& [target, v] : cfg.cpu_targets) check_daemon(*v, "cpu_targets." + target);
    std::string section;
    const mppi::app::AppConfig* variant = cfg.variant(mppi::app::resolve_backend(cfg.backend), &section);
    const auto& flying = variant != nullptr ? *variant : cfg;
    if (variant != nullptr) spdlog::info("settings: the file's {} section applies on this machine", section);
    if (cfg.vehicle) spdlog::info("vehicle {} from {}", cfg.vehicle->name, cfg.vehicle->path);
    ds = mppi::daemon::parse_daemon_settings(flying.root["daemon"], cfg.task, nu);
  } catch (const std::exception& e) {
    spdlog::error("invalid settings: {}", e.what());
    return kExitConfig;
  }
  if (!lcm_url.empty()) ds.lcm_url = lcm_url;
  if (const std::string why = mppi::daemon::lcm_url_leaves_host(ds.lcm_url); !why.empty())
    spdlog::warn("lcm_url {}: {}", ds.lcm_url, why);  // legal, but the bus would leave this machine
  if (lockstep) ds.loop.lockstep = true;
  // The deadline guard must preempt a stalled optimizer (and its OpenMP workers).
  if (realtime && ds.realtime.fifo_priority > 0) ds.loop.guard_fifo_priority = std::min(99, ds.realtime.fifo_priority + 2);

  mppi::rt::RealtimeResult rt_result;
  if (realtime) mppi::rt::lock_memory(ds.realtime, &rt_result);

  std::unique_ptr<mppi::Controller> controller;
  try {
    controller = mppi::app::make_controller(cfg);
  } catch (const mppi::app::ConfigError& e) {
    spdlog::error("invalid settings: {}", e.what());
    return kExitConfig;
  } catch (const std::exception& e) {
    spdlog::error("cannot build the controller: {}", e.what());
    return kExitRuntime;
  }
  const int nu = controller->nu();
  if (!ds.loop.failsafe_u.empty() && static_cast<int>(ds.loop.failsafe_u.size()) != nu) {
    spdlog::error("invalid settings: daemon.failsafe_u: expected {} numbers", nu);
    return kExitConfig;
  }
  if (cfg.controller == "ddp")
    spdlog::info("task {}: MPC-DDP (iLQR, at most {} iterations per cycle) T={} dt={}, {} Hz{}", controller->task(),
                 cfg.ddp.max_iterations, controller->settings().horizon, controller->settings().dt, ds.loop.rate_hz,
                 ds.loop.lockstep ? ", lock-step" : "");
  else
    spdlog::info("task {} on {} backend: K={} T={} dt={} lambda={} nu={}, {} Hz{}", controller->task(),
                 controller->backend(), controller->settings().rollouts, controller->settings().horizon,
                 controller->settings().dt, controller->settings().lambda, controller->settings().nu,
                 ds.loop.rate_hz, ds.loop.lockstep ? ", lock-step" : "");

  // ---- transport --------------------------------------------------------------------
  // The plan message buffer is sized once, for the longest horizon a live update may set.
  const int max_plan_steps = ds.live.enabled ? std::max(controller->horizon(), ds.live.max_horizon) : controller->horizon();
  mppi::rt::MonotonicClock clock;
  std::unique_ptr<mppi::transport::LcmTransport> tx;
  try {
    tx = std::make_unique<mppi::transport::LcmTransport>(ds.lcm_url, ds.channels, &clock,
                                                         max_plan_steps * nu, ds.receive_timeout_ms);
  } catch (const std::exception& e) {
    spdlog::error("invalid settings: daemon.{}", e.what());
    return kExitConfig;
  }
  if (const std::string why = tx->self_test(); !why.empty()) {
    spdlog::error("transport self-test failed: {}", why);
    return kExitRuntime;
  }
  spdlog::info("transport self-test passed on {}", ds.lcm_url);

  mppi::transport::Inbox::Expect expect;
  expect.vehicles = controller->vehicles();
  expect.nx = controller->nx() / controller->vehicles();
  expect.model = ds.expect_model;
  expect.restart_after_ns = ds.loop.state_timeout_ns;
  expect.tick_on_state = ds.loop.lockstep && ds.lockstep_trigger == "state";
  expect.wake_on_state = !ds.loop.lockstep && ds.loop.trigger == mppi::daemon::Trigger::kState;
  auto inbox = std::make_unique<mppi::transport::Inbox>(expect);
  // Live optimizer updates: the builder thread makes controllers from the same settings
  // with new mppi.* values; it owns the controller in service from here on. In lock-step the
  // loop builds them itself at the next cycle (no deadline there), so the cycle an update
  // takes effect at does not depend on how the builder thread was scheduled: a lock-step run
  // with updates repeats, and a fast one cannot end before its updates were built.
  std::unique_ptr<mppi::daemon::LiveOptimizer> live;
  mppi::Controller* const initial = controller.get();
  if (ds.live.enabled) {
    live = std::make_unique<mppi::daemon::LiveOptimizer>(
        std::move(controller),
        [cfg](const mppi::MppiSettings& s) {
          return mppi::app::make_controller(cfg.with_mppi(s));
        },
        ds.live,
        ds.loop.lockstep ? mppi::daemon::LiveOptimizer::Mode::kSynchronous
                         : mppi::daemon::LiveOptimizer::Mode::kBuilderThread);
  }
  mppi::daemon::ControlLoop loop(initial, &clock, tx.get(), inbox.get(), ds.loop);
  loop.set_live_optimizer(live.get());

  // ---- loop thread: real-time set-up, warm-up, then cycles --------------------------
  std::atomic<bool> stop{false};
  std::atomic<int> ready{0};  // 1 warmed up, -1 failed
  std::string warmup_error;
  std::thread loop_thread([&] {
    mppi::rt::RealtimeRequest req = ds.realtime;
    const int cpu = req.cpu;
    req.cpu = -1;
    if (realtime) mppi::rt::make_thread_realtime(req, &rt_result);
    try {
      // Warm-up: first-touch the backend's buffers and start its thread pool from this
      // (real-time) thread, so the worker threads inherit its policy.
      std::vector<float> x0(static_cast<std::size_t>(initial->nx()), 0.0f), u(static_cast<std::size_t>(nu));
      for (int i = 0; i < ds.warmup_iterations; ++i) initial->iterate(x0.data(), u.data());
      initial->reset();
    } catch (const std::exception& e) {
      warmup_error = e.what();
      ready = -1;
      return;
    }
    if (realtime) {
      // The OpenMP workers keep the warm-up's priority; the loop thread goes one above
      // them: under SCHED_FIFO a worker still spinning after a parallel region on the
      // loop's CPU would otherwise hold the loop off until it sleeps (measured: ~8 ms
      // between a lock-step tick and the cycle's start with 2 threads).
      mppi::rt::RealtimeRequest pin;
      pin.lock_memory = false;
      pin.fifo_priority = req.fifo_priority > 0 ? std::min(98, req.fifo_priority + 1) : 0;
      pin.prefault_stack_bytes = 0;
      pin.cpu = cpu;
      mppi::rt::make_thread_realtime(pin, &rt_result);
    }
    loop.prepare();  // the deadline guard thread, before READY
    ready = 1;
    while (ready.load() == 1 && !stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (stop.load()) return;
    loop.run(stop);
    loop.publish_final_status();
  });
  while (ready.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (ready.load() < 0) {
    loop_thread.join();
    spdlog::error("backend warm-up failed: {}", warmup_error);
    return kExitRuntime;
  }
  if (realtime) {
    for (const auto& r : rt_result.refused) spdlog::warn("real-time refused: {}", r);
    if (!rt_result.ok() && require_realtime) {
      spdlog::error("--require-realtime: the OS refused real-time operation; exiting");
      stop = true;
      loop_thread.join();
      return kExitRuntime;
    }
    if (rt_result.ok()) spdlog::info("real-time: mlockall, SCHED_FIFO {}{}", ds.realtime.fifo_priority,
                                     ds.realtime.cpu >= 0 ? ", pinned to CPU " + std::to_string(ds.realtime.cpu) : "");
    else spdlog::warn("running on without full real-time guarantees");
  }

  // ---- run ---------------------------------------------------------------------------
  // States and ticks must be taken in while the optimizer fills the cores.
  if (realtime && ds.realtime.fifo_priority > 0) tx->set_receive_fifo_priority(std::min(99, ds.realtime.fifo_priority + 2));
  tx->start(inbox.get());
  const long rss_start = mppi::rt::resident_kb();
  const std::int64_t t_start = mppi::rt::monotonic_ns();
  ready = 2;  // release the loop
  mppi::daemon::Notifier notify;
  notify.ready(status_line(loop, ds.loop.rate_hz));
  spdlog::info("ready: {} Hz, state on {}, command on {}", ds.loop.rate_hz, ds.channels.state, ds.channels.command);

  const std::int64_t watchdog_every = notify.watchdog_ns() > 0 ? notify.watchdog_ns() / 4 : 0;
  const std::int64_t stale_heartbeat = std::max<std::int64_t>(
      std::llround(3e9 / ds.loop.rate_hz), 500 * mppi::rt::kNsPerMs);
  std::int64_t last_ping = 0, last_status = t_start;
  int signal_number = 0;
  while (true) {
    const timespec wait{0, 20 * 1000 * 1000};
    const int sig = sigtimedwait(&sigs, nullptr, &wait);
    if (sig > 0) {
      signal_number = sig;
      break;
    }
    const std::int64_t now = mppi::rt::monotonic_ns();
    if (duration_s > 0.0 && static_cast<double>(now - t_start) * 1e-9 >= duration_s) break;
    // The watchdog is fed only while the loop itself is well: cycling (or, in lock-step,
    // waiting on the simulator) and not stuck in misses or optimizer failures.
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

  // ---- stop --------------------------------------------------------------------------
  if (signal_number) spdlog::info("{}: stopping", signal_number == SIGTERM ? "SIGTERM" : "SIGINT");
  const std::int64_t t_stop = mppi::rt::monotonic_ns();
  notify.stopping();
  stop = true;
  loop_thread.join();  // publishes the final status
  tx->stop();
  const double seconds = static_cast<double>(mppi::rt::monotonic_ns() - t_start) * 1e-9;
  const auto total = loop.timing_total();
  spdlog::info(
      "final status published (status #{}); stopped after {} cycles, {} misses ({} late starts), {:.1f} ms after the "
      "stop request",
      loop.counters().status_published.load(), total.cycles, total.misses, total.late_start_misses,
      static_cast<double>(mppi::rt::monotonic_ns() - t_stop) * 1e-6);
  if (stats) {
    mppi::daemon::RunFacts f;
    f.task = loop.controller().task();
    f.backend = loop.controller().backend();
    f.rollouts = loop.controller().settings().rollouts;
    f.horizon = loop.controller().horizon();
    f.rate_hz = ds.loop.rate_hz;
    f.seconds = seconds;
    f.lockstep = ds.loop.lockstep;
    f.realtime = realtime && rt_result.fifo;
    f.rss_start_kb = rss_start;
    f.rss_end_kb = mppi::rt::resident_kb();
    std::cout << mppi::daemon::format_stats(f, loop, inbox->counters) << std::flush;
  }
  return 0;
}
