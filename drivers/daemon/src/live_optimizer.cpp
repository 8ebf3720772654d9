#include "mppi/daemon/live_optimizer.hpp"

#include <cstdint>
#include <omp.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <stdexcept>
#include <thread>
#include <type_traits>

#include "mppi/settings_table.hpp"

namespace mppi::daemon {

namespace {

constexpr std::int64_t kBuilderPollNs = 100'000'000;

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

// An integer setting: the value must be integral and inside [lo, hi].
std::string integer(const std::string& key, double v, double lo, double hi, const std::string& why_hi, int* out) {
  if (v != std::floor(v)) return key + ": must be an integer, got " + num(v);
  if (v < lo) return key + ": must be >= " + num(lo) + ", got " + num(v);
  if (v > hi) return key + ": must be <= " + num(hi) + why_hi + ", got " + num(v);
  *out = static_cast<int>(v);
  return {};
}

// What bounds a live update: daemon.live's limits, the CPUs and the control size.
struct LiveLimits {
  int max_rollouts, max_horizon, max_threads, nu;
};

// The highest value a live update may give a row's whole number, and what sets it.
double live_hi(const SettingSpec& r, const LiveLimits& l, std::string* why) {
  switch (r.live) {
    case LiveBound::kMaxRollouts:
      *why = " (daemon.live.max_rollouts)";
      return l.max_rollouts;
    case LiveBound::kMaxHorizon:
      *why = " (daemon.live.max_horizon)";
      return l.max_horizon;
    case LiveBound::kCpus:
      *why = " (the CPUs this process may use)";
      return l.max_threads;
    default:
      return r.live_hi;
  }
}

std::string unknown_field(const std::string& key) {
  return key + ": unknown field (tunable at run time: " + live_setting_names() + ")";
}

// A row of the optimizer's table (mppi/settings.hpp) set by a live update: a whole number
// in [lo, the row's live bound]; a float as given (validate() checks the snapshot
// afterwards); a list: every channel, or channel j (`sigma[j]`).
struct LiveSet {
  const std::string& key;
  double v;
  const LiveLimits& l;

  std::string operator()(const SettingSpec& r, int& field) const {
    std::string why;
    return integer(key, v, r.lo, live_hi(r, l, &why), why, &field);
  }
  std::string operator()(const SettingSpec& r, std::uint64_t& field) const {
    std::string why;
    const double hi = live_hi(r, l, &why);
    if (v != std::floor(v) || v < r.lo || v > hi) return key + ": must be an integer in [" + num(r.lo) + ", " + num(hi) + "]";
    field = static_cast<std::uint64_t>(v);
    return {};
  }
  std::string operator()(const SettingSpec&, float& field) const {
    field = static_cast<float>(v);
    return {};
  }
  std::string operator()(const SettingSpec&, std::vector<float>& field) const {
    const std::size_t open = key.find('[');
    if (open == std::string::npos) {
      std::fill(field.begin(), field.end(), static_cast<float>(v));
      return {};
    }
    if (key.back() != ']') return unknown_field(key);
    const std::string index = key.substr(open + 1, key.size() - open - 2);
    char* end = nullptr;
    const long j = std::strtol(index.c_str(), &end, 10);
    if (index.empty() || *end != '\0' || j < 0 || j >= l.nu)
      return key + ": the channel index must be in [0, " + std::to_string(l.nu - 1) + "]";
    field[static_cast<std::size_t>(j)] = static_cast<float>(v);
    return {};
  }
  template <class T>
  std::string operator()(const SettingSpec&, T&) const {  // text and choices: fixed for a run
    return key + ": not tunable at run time";
  }
};

// Sets `name` (the key without "mppi.": "rollouts", "sigma[2]") of `n` through the table.
std::string set_live(MppiSettings* n, const std::string& name, const std::string& key, double v, const LiveLimits& l) {
  bool found = false;
  std::string err;
  visit_settings(*n, [&](const SettingSpec& r, auto& field) {
    using T = std::decay_t<decltype(field)>;
    const std::size_t len = std::strlen(r.name);
    const bool channel = std::is_same_v<T, std::vector<float>> && name.size() > len &&
                         name.compare(0, len, r.name) == 0 && name[len] == '[';
    if (found || (name != r.name && !channel)) return;
    found = true;
    if (r.live == LiveBound::kFixed)
      err = key + ": not tunable at run time (the command limits, the failsafe and the backend are fixed for a "
                  "run; restart with --set)";
    else
      err = LiveSet{key, v, l}(r, field);
  });
  return found ? err : unknown_field(key);
}

thread_local bool t_builder = false;

int resolved_threads(const MppiSettings& s) { return s.threads > 0 ? s.threads : omp_get_max_threads(); }

}  // namespace

std::string apply_live_update(MppiSettings* s, const std::string& key, double v, int nu, const LiveSettings& lim) {
  if (!std::isfinite(v)) return key + ": must be finite";
  MppiSettings n = *s;
  const std::string name = key.rfind("mppi.", 0) == 0 ? key.substr(5) : key;
  const LiveLimits limits{lim.max_rollouts, lim.max_horizon, lim.max_threads > 0 ? lim.max_threads : omp_get_num_procs(),
                          nu};
  const std::string err = set_live(&n, name, key, v, limits);
  if (!err.empty()) return err;
  const std::string invalid = validate(n, nu);
  if (!invalid.empty()) {
    // validate() names the field it checks ("sigma: every value must be > 0"): say which
    // update made the snapshot invalid when it is not that field itself.
    if (invalid.rfind(name + ":", 0) == 0) return "mppi." + invalid;
    return key + ": makes the settings invalid: mppi." + invalid;
  }
  *s = std::move(n);
  return {};
}

void resample_plan(const float* in, int t_in, double dt_in, float* out, int t_out, double dt_out, int nu,
                   const float* fill) {
  const bool same = dt_in == dt_out;
  for (int i = 0; i < t_out; ++i) {
    // A midpoint on an old step boundary (dt_out a multiple of dt_in) takes the later step,
    // whatever the rounding of the quotient.
    const long k = same ? i : static_cast<long>(std::floor((i + 0.5) * dt_out / dt_in + 1e-6));
    const float* src = (k >= 0 && k < t_in) ? in + k * nu : fill;
    std::copy_n(src, nu, out + static_cast<std::ptrdiff_t>(i) * nu);
  }
}

void resize_worker_team(int threads) {
  int policy = 0;
  sched_param master{};
  pthread_getschedparam(pthread_self(), &policy, &master);
#pragma omp parallel num_threads(threads)
  {
    // A worker started now would inherit the loop thread's priority; the warm-up leaves the
    // workers one below it (main.cpp says why).
    if (omp_get_thread_num() != 0 && policy == SCHED_FIFO && master.sched_priority > 1) {
      sched_param sp{};
      sp.sched_priority = master.sched_priority - 1;
      pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    }
  }
}

LiveOptimizer::LiveOptimizer(std::unique_ptr<Controller> initial, Factory factory, LiveSettings limits, Mode mode)
    : current_(std::move(initial)), factory_(std::move(factory)), limits_(limits), mode_(mode) {
  nu_ = current_->nu();
  task_ = current_->task();
  base_ = current_->settings();
  current_threads_ = resolved_threads(base_);
  if (limits_.max_threads <= 0) limits_.max_threads = omp_get_num_procs();
  pending_.reserve(256);
  if (mode_ == Mode::kBuilderThread) thread_ = std::thread([this] { builder_main(); });
}

LiveOptimizer::~LiveOptimizer() {
  quit_.store(true);
  wake_.post();
  if (thread_.joinable()) thread_.join();
  delete ready_.exchange(nullptr);
  delete retired_.exchange(nullptr);
}

bool LiveOptimizer::request(const transport::ParamUpdate& p) {
  if (!requests_.push(p)) return false;
  requested_.fetch_add(1, std::memory_order_release);
  wake_.post();
  return true;
}

OptimizerBundle* LiveOptimizer::take_ready() {
  if (mode_ == Mode::kSynchronous) {
    collect_retired();
    transport::ParamUpdate p;
    while (requests_.pop(&p)) pending_.push_back(p);
    if (!pending_.empty() && ready_.load(std::memory_order_relaxed) == nullptr) {
      OptimizerBundle* b = build(&pending_);
      if (b != nullptr) ready_.store(b, std::memory_order_release);
    }
  }
  // One retired slot: the builder empties it before the next swap may take place.
  if (retired_.load(std::memory_order_acquire) != nullptr) return nullptr;
  return ready_.exchange(nullptr, std::memory_order_acq_rel);
}

void LiveOptimizer::swap_current(OptimizerBundle* b) {
  current_.swap(b->controller);
  std::swap(current_threads_, b->threads);
}

void LiveOptimizer::retire(OptimizerBundle* b) {
  retired_.store(b, std::memory_order_release);
  wake_.post();
}

bool LiveOptimizer::pop_refusal(transport::ParamResult* out) { return refusals_.pop(out); }

void LiveOptimizer::wait_idle() const {
  while (handled_.load(std::memory_order_acquire) < requested_.load(std::memory_order_acquire) &&
         ready_.load(std::memory_order_acquire) == nullptr)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

void LiveOptimizer::collect_retired() { delete retired_.exchange(nullptr, std::memory_order_acq_rel); }

void LiveOptimizer::refuse(const transport::ParamUpdate& p, const std::string& why) {
  if (!refusals_.push(transport::answer_to(p, false, why))) refusals_dropped_.fetch_add(1, std::memory_order_relaxed);
}

OptimizerBundle* LiveOptimizer::build(std::vector<transport::ParamUpdate>* pending) {
  auto b = std::make_unique<OptimizerBundle>();
  MppiSettings next = base_;
  const std::size_t take = std::min<std::size_t>(pending->size(), OptimizerBundle::kMaxUpdates);
  std::int64_t refused = 0;
  for (std::size_t i = 0; i < take; ++i) {
    const transport::ParamUpdate& p = (*pending)[i];
    const std::string key(p.key, ::strnlen(p.key, sizeof(p.key)));
    const std::string err = apply_live_update(&next, key, p.value, nu_, limits_);
    if (err.empty()) {
      b->updates[b->count++] = p;
    } else {
      refuse(p, err);
      ++refused;
    }
  }
  pending->erase(pending->begin(), pending->begin() + static_cast<std::ptrdiff_t>(take));
  if (b->count == 0) {
    handled_.fetch_add(refused, std::memory_order_release);
    return nullptr;
  }
  try {
    b->controller = factory_(next);
    if (!b->controller || b->controller->task() != task_ || b->controller->nu() != nu_)
      throw std::runtime_error("the factory built another task");
    const std::size_t floats = static_cast<std::size_t>(next.horizon) * static_cast<std::size_t>(nu_);
    b->held.assign(floats, 0.0f);
    b->guard.assign(floats, 0.0f);
    b->threads = resolved_threads(next);
  } catch (const std::exception& e) {
    build_failures_.fetch_add(1, std::memory_order_relaxed);
    for (int i = 0; i < b->count; ++i) refuse(b->updates[i], std::string("mppi: cannot build the optimizer: ") + e.what());
    handled_.fetch_add(refused + b->count, std::memory_order_release);
    return nullptr;
  }
  base_ = std::move(next);
  builds_.fetch_add(1, std::memory_order_relaxed);
  OptimizerBundle* out = b.release();
  // Counted as handled once the loop can take it (wait_idle() then finds it ready).
  if (mode_ == Mode::kSynchronous) {
    handled_.fetch_add(refused + out->count, std::memory_order_release);
  } else {
    ready_.store(out, std::memory_order_release);
    handled_.fetch_add(refused + out->count, std::memory_order_release);
  }
  return out;
}

bool LiveOptimizer::on_builder_thread() { return t_builder; }

void LiveOptimizer::builder_main() {
  t_builder = true;
  // The builder shares the CPUs with the loop: it runs at the normal policy (the loop and
  // its workers, SCHED_FIFO, preempt it), niced, so a build never delays a cycle.
  sched_param sp{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
  ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), 10);
  while (!quit_.load(std::memory_order_relaxed)) {
    wake_.wait_for(kBuilderPollNs);
    collect_retired();
    transport::ParamUpdate p;
    while (requests_.pop(&p)) pending_.push_back(p);
    while (!pending_.empty() && ready_.load(std::memory_order_acquire) == nullptr &&
           !quit_.load(std::memory_order_relaxed)) {
      build(&pending_);  // publishes into ready_ itself
    }
  }
}

}  // namespace mppi::daemon
