// What the daemon's fuzz targets share: one small controller per task, built the way mppid
// builds it (the task's settings file through load_config and parse_daemon_settings, with
// 16 rollouts, 8 steps and one thread so an input runs in well under a millisecond), its
// inbox and lock-step control loop, the LCM decoder, and a transport that checks every
// command the loop publishes: nu values, finite, inside the task's limits. A command that
// is not is a crash (__builtin_trap), as is anything the sanitizers see.
//
// A fresh rig per input: nothing carries over from one input to the next, so a crash
// replays from its input alone.
#pragma once

#include <spdlog/spdlog.h>

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/daemon/control_loop.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/tasks.hpp"
#include "mppi/transport/lcm_decode.hpp"

namespace mppi::fuzz {

// A clock that stands still: lock-step cycles take their time from the ticks.
class StillClock final : public rt::Clock {
 public:
  std::int64_t now_ns() override { return 1'000'000'000; }
  void sleep_until(std::int64_t) override {}
};

class CheckingTransport final : public transport::Transport {
 public:
  CheckingTransport(int nu, std::vector<float> u_min, std::vector<float> u_max)
      : nu_(nu), lo_(std::move(u_min)), hi_(std::move(u_max)) {}
  std::string self_test() override { return {}; }
  void start(transport::Inbox*) override {}
  void stop() override {}
  bool publish_command(const transport::Command& c) override {
    if (c.n != nu_) __builtin_trap();
    for (int i = 0; i < c.n; ++i) {
      const auto j = static_cast<std::size_t>(i);
      if (!std::isfinite(c.u[i]) || c.u[i] < lo_[j] || c.u[i] > hi_[j]) __builtin_trap();
    }
    ++commands;
    return true;
  }
  bool publish_status(const transport::StatusReport&) override { return true; }
  bool publish_plan(const transport::PlanView& p) override {
    for (std::int32_t i = 0; i < p.horizon * p.nu; ++i)
      if (!std::isfinite(p.u[i])) __builtin_trap();
    return true;
  }
  int commands = 0;

 private:
  int nu_;
  std::vector<float> lo_, hi_;
};

// A task's settings, read once (they are immutable; every input builds its own controller).
struct TaskConfig {
  app::AppConfig cfg;
  daemon::DaemonSettings ds;
};
inline const TaskConfig& task_config(const std::string& task) {
  static std::map<std::string, TaskConfig> cache;
  auto it = cache.find(task);
  if (it == cache.end()) {
    TaskConfig t;
    t.cfg = app::load_config(app::default_config_path(task),
                             {"mppi.rollouts=16", "mppi.horizon=8", "mppi.threads=1", "backend=cpu"});
    t.ds = daemon::parse_daemon_settings(t.cfg.root["daemon"], t.cfg.task, static_cast<int>(t.cfg.mppi.u_init.size()));
    it = cache.emplace(task, std::move(t)).first;
  }
  return it->second;
}

struct Rig {
  explicit Rig(const std::string& task, bool tick_on_state = true) {
    const app::AppConfig& cfg = task_config(task).cfg;
    const daemon::DaemonSettings& ds = task_config(task).ds;
    controller = app::make_controller(cfg);
    transport::Inbox::Expect e;
    e.vehicles = controller->vehicles();
    e.nx = controller->nx() / controller->vehicles();
    e.model = ds.expect_model;
    e.restart_after_ns = ds.loop.state_timeout_ns;
    e.tick_on_state = tick_on_state;
    inbox = std::make_unique<transport::Inbox>(e);
    tx = std::make_unique<CheckingTransport>(controller->nu(), cfg.mppi.u_min, cfg.mppi.u_max);
    daemon::LoopSettings ls = ds.loop;
    ls.lockstep = true;
    ls.deadline_guard = false;
    loop = std::make_unique<daemon::ControlLoop>(controller.get(), &clock, tx.get(), inbox.get(), ls);
  }

  // A valid state for this task (hover-ish: every value 0.5, quaternions from it) at
  // sample time `utime`, through the decoder like any other.
  void valid_state(std::int64_t seq, std::int64_t utime) {
    mppi_lcm::vehicle_state_t m;
    m.utime = utime;
    m.seq = seq;
    m.sample_utime = utime;
    m.model = inbox->expect().model;
    m.vehicle_count = static_cast<std::int16_t>(inbox->expect().vehicles);
    m.nx = static_cast<std::int16_t>(inbox->expect().nx);
    m.n = m.nx * m.vehicle_count;
    m.x.assign(static_cast<std::size_t>(m.n), 0.5f);
    std::vector<std::uint8_t> buf(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(buf.data(), 0, static_cast<int>(buf.size()));
    decoder.state(buf.data(), buf.size(), inbox.get());
  }

  // Runs the cycles for the ticks queued so far.
  void run_cycles() {
    std::atomic<bool> stop{true};  // step_lockstep returns at once when no tick is queued
    while (loop->step_lockstep(stop)) {
    }
  }

  StillClock clock;
  transport::LcmDecoder decoder{&clock};
  std::unique_ptr<Controller> controller;
  std::unique_ptr<transport::Inbox> inbox;
  std::unique_ptr<CheckingTransport> tx;
  std::unique_ptr<daemon::ControlLoop> loop;
};

inline const std::vector<std::string>& tasks() {
  static const std::vector<std::string> t = task_names();
  return t;
}

// Quiet logs (the loop logs every rejected parameter and mode change).
inline void quiet() { spdlog::set_level(spdlog::level::off); }

// One input of a daemon target, what its LLVMFuzzerTestOneInput returns: the message's bytes,
// then one byte picking the task. A fresh rig for that task (tick_on_state as Rig's), then
// feed(rig, message, length) offers the message and the valid states around it, then the
// cycles for the ticks queued so far run.
template <class Feed>
int run_input(const std::uint8_t* data, std::size_t size, Feed feed, bool tick_on_state = true) {
  [[maybe_unused]] static const bool quieted = (quiet(), true);  // before the first rig logs
  if (size < 1) return 0;
  const std::vector<std::string>& names = tasks();
  Rig rig(names[data[size - 1] % names.size()], tick_on_state);
  feed(rig, data, size - 1);
  rig.run_cycles();
  return 0;
}

// The target of one decoder method (LcmDecoder::obstacles, ::param, ...): the message through
// it, then valid states 1, 2, ... sampled at `state_utimes`.
using Decode = void (transport::LcmDecoder::*)(const void*, std::size_t, transport::Inbox*);
inline int decode_then_states(const std::uint8_t* data, std::size_t size, Decode decode,
                              std::initializer_list<std::int64_t> state_utimes) {
  return run_input(data, size, [&](Rig& rig, const std::uint8_t* msg, std::size_t n) {
    (rig.decoder.*decode)(msg, n, rig.inbox.get());
    std::int64_t seq = 0;
    for (const std::int64_t utime : state_utimes) rig.valid_state(++seq, utime);
  });
}

}  // namespace mppi::fuzz
