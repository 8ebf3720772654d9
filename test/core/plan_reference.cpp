// Plans of one machine against another's (docs/aarch64.md): `--write FILE` records, on this
// machine, the scalar backend's updates of every named task (seed 1: the task file's noise
// seed and the offline scenario's start), and the C library's single-precision functions on
// fixed inputs; `--check FILE` computes the same here and compares:
//  - the C library: how many results differ, by how many ulp (reported; the premise below);
//  - the scalar backend, task by task: bit for bit where the task's models and costs call
//    only functions that gave the same bits on both machines (IEEE +, -, *, /, sqrt and
//    sinf, cosf, expf, logf), otherwise within the SIMD tests' tolerances (tolerances.hpp);
//  - every SIMD target this machine runs (Highway's transcendentals): within those
//    tolerances of the recorded scalar update, from the recorded start plan, as
//    test_simd.cpp holds this machine's own targets to its own scalar backend.
// CI writes the reference natively on x86-64 and checks it on aarch64 under qemu-user
// (test/core/CMakeLists.txt, tools/aarch64.sh).
//
//   plan_reference --write FILE
//   plan_reference --check FILE [--task NAME]
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "mppi/cpu_backend.hpp"
#include "simd_probe.hpp"
#include "task_cases.hpp"
#include "tolerances.hpp"

namespace mppi {
namespace {

using testing::rel_error;
using testing::same_bits;

constexpr int kCycles = 3;
constexpr int kHorizon = 50;
constexpr int kLibmInputs = 20000;

// ---------------------------------------------------------------------------------------
// The file: whitespace-separated words, floats as their 32 bits in hex.
// ---------------------------------------------------------------------------------------

struct Record {
  std::vector<std::uint32_t> words;
};
using Reference = std::map<std::string, Record>;  // "libm/sinf", "task/NAME/cycle/C/start", ...

std::uint32_t bits_of(float f) {
  std::uint32_t u = 0;
  std::memcpy(&u, &f, sizeof u);
  return u;
}

float float_of(std::uint32_t u) {
  float f = 0.0f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

std::vector<float> floats_of(const Record& r) {
  std::vector<float> out;
  for (std::uint32_t w : r.words) out.push_back(float_of(w));
  return out;
}

void put(std::ostream& out, const std::string& key, const std::vector<float>& values) {
  out << key << " " << values.size();
  char word[16];
  for (float v : values) {
    std::snprintf(word, sizeof word, " %08x", bits_of(v));
    out << word;
  }
  out << "\n";
}

Reference read_reference(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  Reference ref;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key, part;
    std::size_t n = 0;
    words >> key >> n;
    Record r;
    for (std::size_t i = 0; i < n; ++i) {
      words >> part;
      r.words.push_back(static_cast<std::uint32_t>(std::stoul(part, nullptr, 16)));
    }
    if (!words) throw std::runtime_error(path + ": truncated record '" + key + "'");
    ref[key] = r;
  }
  return ref;
}

// ---------------------------------------------------------------------------------------
// The C library on fixed inputs
// ---------------------------------------------------------------------------------------

struct LibmFunction {
  const char* name;
  std::function<float(float, float)> f;
};

const std::vector<LibmFunction>& libm_functions() {
  static const std::vector<LibmFunction> fs = {
      {"sinf", [](float x, float) { return ::sinf(x); }},
      {"cosf", [](float x, float) { return ::cosf(x); }},
      {"expf", [](float x, float) { return ::expf(x); }},
      {"logf", [](float x, float) { return ::logf(std::fabs(x) + 1e-3f); }},
      {"sqrtf", [](float x, float) { return ::sqrtf(std::fabs(x)); }},
      {"atanf", [](float x, float) { return ::atanf(x); }},
      {"atan2f", [](float x, float y) { return ::atan2f(y, x); }},
      {"tanf", [](float x, float) { return ::tanf(0.05f * x); }},
  };
  return fs;
}

// Results on x in [-20, 20), y in [-5, 5), from a fixed linear congruential sequence.
std::vector<float> libm_results(const LibmFunction& fn) {
  std::vector<float> out;
  std::uint32_t s = 12345u;
  for (int i = 0; i < kLibmInputs; ++i) {
    s = s * 1664525u + 1013904223u;
    const float x = (static_cast<float>(s >> 8) / 16777216.0f - 0.5f) * 40.0f;
    const float y = (static_cast<float>(s & 0xffffu) / 65536.0f - 0.5f) * 10.0f;
    out.push_back(fn.f(x, y));
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// Updates
// ---------------------------------------------------------------------------------------

// The functions beyond IEEE arithmetic each task's models and costs call (core/include/mppi:
// models/, costs/, rng.hpp, the update's expf).
template <class T>
std::vector<std::string> libm_used() {
  if constexpr (std::is_same_v<typename T::Vehicle, Racecar>) return {"sinf", "cosf", "expf", "logf", "atanf", "tanf"};
  else if constexpr (std::is_same_v<typename T::Vehicle, QuadrotorRate>) return {"sinf", "cosf", "expf", "logf", "atan2f"};
  else return {"sinf", "cosf", "expf", "logf"};
}

template <class T>
int rollouts() {
  return T::kVehicles > 1 ? 1024 : 256;  // as test_simd.cpp's whole updates
}

std::string cycle_key(const char* task, int cycle, const std::string& what) {
  return std::string("task/") + task + "/cycle/" + std::to_string(cycle) + "/" + what;
}

// The SIMD targets whose lanes fuse a * b + c (Highway's MulAdd where the ISA has FMA): they
// run the same IEEE operations in the same order, so each agrees with the others bit for bit;
// SSE4's lanes round the product first and agree with SSE4 only; the scalar code with itself.
std::string arithmetic_of(const std::string& backend) {
  if (backend == "avx2" || backend == "avx3" || backend == "neon") return "fused lanes";
  return backend;
}

// Each cycle's updated plan and rollout costs, from the start plans of the recorded scalar run.
struct Updates {
  std::vector<std::vector<float>> plans, costs;
};

template <class T>
Updates updates_from(const std::vector<std::vector<float>>& starts, TaskController<T>& c,
                     const std::vector<float>& x0) {
  Updates out;
  std::vector<float> u(static_cast<std::size_t>(T::kNu));
  for (const auto& start : starts) {
    c.set_plan(start.data());
    c.iterate(x0.data(), u.data());
    out.plans.push_back(c.plan());
    out.costs.push_back(c.rollout_costs());
  }
  return out;
}

// The backends of this machine: the scalar code and every SIMD target it runs.
template <class T, class F>
void for_each_backend(const testing::TaskSetup& s, F&& f) {
  auto scalar = testing::controller<T>(s, std::make_unique<CpuBackend<T>>(s.cfg.mppi));
  f(std::string("scalar"), *scalar);
  testing::for_each_simd_target([&](auto target) {
    MppiSettings lanes = s.cfg.mppi;
    lanes.simd = simd::name(target.value);
    auto vector = testing::controller<T>(s, std::make_unique<CpuBackend<T>>(lanes));
    f(std::string(simd::name(target.value)), *vector);
  });
}

template <class T>
void write_task(std::ostream& out, const char* name) {
  const testing::TaskSetup s = testing::setup(name, rollouts<T>(), kHorizon);
  auto scalar = testing::controller<T>(s, std::make_unique<CpuBackend<T>>(s.cfg.mppi));
  std::vector<std::vector<float>> starts;
  std::vector<float> u(static_cast<std::size_t>(T::kNu));
  for (int c = 0; c < kCycles; ++c) {
    starts.push_back(scalar->plan());
    put(out, cycle_key(name, c, "start"), starts.back());
    scalar->iterate(s.scenario.x0.data(), u.data());
  }
  for_each_backend<T>(s, [&](const std::string& backend, TaskController<T>& c) {
    const Updates updates = updates_from(starts, c, s.scenario.x0);
    for (int cycle = 0; cycle < kCycles; ++cycle) {
      put(out, cycle_key(name, cycle, backend + "/plan"), updates.plans[static_cast<std::size_t>(cycle)]);
      put(out, cycle_key(name, cycle, backend + "/costs"), updates.costs[static_cast<std::size_t>(cycle)]);
    }
  });
}

struct Tally {
  int failures = 0;
  void fail(const std::string& what) {
    ++failures;
    std::printf("  FAIL %s\n", what.c_str());
  }
};

// This machine's updates against one recorded backend's: bit for bit, or within the SIMD
// tests' tolerances (all but a fraction of the rollouts' costs, every plan entry).
template <class T>
void compare(const Reference& ref, const char* name, const std::string& here_backend, const Updates& here,
             const std::string& there_backend, bool exact, Tally& tally) {
  double worst_plan = 0.0;
  int worst_over = 0, differing_bits = 0, entries = 0;
  for (int cycle = 0; cycle < kCycles; ++cycle) {
    const auto plan = floats_of(ref.at(cycle_key(name, cycle, there_backend + "/plan")));
    const auto costs = floats_of(ref.at(cycle_key(name, cycle, there_backend + "/costs")));
    const auto& my_plan = here.plans[static_cast<std::size_t>(cycle)];
    const auto& my_costs = here.costs[static_cast<std::size_t>(cycle)];
    if (plan.size() != my_plan.size() || costs.size() != my_costs.size()) {
      tally.fail(std::string(name) + ": the reference was written with other sizes");
      return;
    }
    int over = 0;
    for (std::size_t k = 0; k < costs.size(); ++k) {
      over += rel_error(my_costs[k], costs[k]) > testing::kCostTolerance;
      differing_bits += !same_bits(my_costs[k], costs[k]);
    }
    for (std::size_t n = 0; n < plan.size(); ++n) {
      worst_plan = std::max(worst_plan, rel_error(my_plan[n], plan[n]));
      differing_bits += !same_bits(my_plan[n], plan[n]);
    }
    entries += static_cast<int>(costs.size() + plan.size());
    worst_over = std::max(worst_over, over);
  }
  const int allowed = static_cast<int>(testing::divergent_fraction<T>() * rollouts<T>());
  const std::string pair = std::string(name) + " " + here_backend + " vs " + there_backend;
  std::printf("  %-40s %5d of %5d numbers differ in any bit%s; plan error %.1e (bound %.0e); "
              "rollout costs beyond %.0e: %d (bound %d)\n",
              pair.c_str(), differing_bits, entries, exact ? " (must be 0)" : "", worst_plan,
              testing::plan_tolerance<T>(), testing::kCostTolerance, worst_over, allowed);
  if (exact && differing_bits > 0) tally.fail(pair + ": not bit for bit");
  if (worst_plan >= testing::plan_tolerance<T>()) tally.fail(pair + ": plan beyond the tolerance");
  if (worst_over > allowed) tally.fail(pair + ": too many rollout costs beyond the tolerance");
}

// Every backend here against the recorded scalar code (the scalar code bit for bit where the
// C library agreed on every function the task calls) and against each recorded backend of
// the same arithmetic (bit for bit).
template <class T>
void check_task(const Reference& ref, const char* name, const std::vector<std::string>& libm_same, Tally& tally) {
  bool libm_agrees = true;
  for (const auto& f : libm_used<T>())
    libm_agrees = libm_agrees && std::find(libm_same.begin(), libm_same.end(), f) != libm_same.end();
  const testing::TaskSetup s = testing::setup(name, rollouts<T>(), kHorizon);
  std::vector<std::vector<float>> starts;
  for (int cycle = 0; cycle < kCycles; ++cycle) starts.push_back(floats_of(ref.at(cycle_key(name, cycle, "start"))));
  for_each_backend<T>(s, [&](const std::string& backend, TaskController<T>& c) {
    if (starts.front().size() != c.plan().size()) {
      tally.fail(std::string(name) + ": the reference was written with another horizon");
      return;
    }
    const Updates here = updates_from(starts, c, s.scenario.x0);
    compare<T>(ref, name, backend, here, "scalar", backend == "scalar" && libm_agrees, tally);
    for (const char* there : {"sse4", "avx2", "avx3", "neon"}) {
      if (backend != "scalar" && arithmetic_of(backend) == arithmetic_of(there) &&
          ref.count(cycle_key(name, 0, std::string(there) + "/plan")) > 0)
        compare<T>(ref, name, backend, here, there, true, tally);
    }
  });
}

int write(const std::string& path) {
  std::ofstream out(path);
  out << "# plan_reference --write: key, count, the values' 32 bits in hex\n";
  for (const auto& fn : libm_functions()) put(out, std::string("libm/") + fn.name, libm_results(fn));
  testing::for_each_task([&](auto named) { write_task<typename decltype(named)::Task>(out, named.name); });
  out.close();
  if (!out) {
    std::fprintf(stderr, "plan_reference: cannot write %s\n", path.c_str());
    return 1;
  }
  std::printf("plan_reference: wrote %s\n", path.c_str());
  return 0;
}

int check(const std::string& path, const std::string& only) {
  const Reference ref = read_reference(path);
  Tally tally;
  std::vector<std::string> libm_same;
  std::printf("C library against %s (%d inputs each):\n", path.c_str(), kLibmInputs);
  for (const auto& fn : libm_functions()) {
    const auto there = floats_of(ref.at(std::string("libm/") + fn.name));
    const auto here = libm_results(fn);
    int differ = 0;
    long worst_ulp = 0;
    for (std::size_t i = 0; i < here.size(); ++i) {
      const long d = std::labs(static_cast<long>(static_cast<std::int32_t>(bits_of(here[i]))) -
                               static_cast<long>(static_cast<std::int32_t>(bits_of(there[i]))));
      differ += d != 0;
      worst_ulp = std::max(worst_ulp, d);
    }
    std::printf("  %-7s %5d differ, at most %ld ulp\n", fn.name, differ, worst_ulp);
    if (differ == 0) libm_same.emplace_back(fn.name);
  }
  std::printf("Updates (seed 1, T = %d, %d cycles from the recorded start plans) against the reference's:\n", kHorizon, kCycles);
  int passed = 0, failed = 0;
  testing::for_each_task([&](auto named) {
    if (!only.empty() && only != named.name) return;
    const int before = tally.failures;
    check_task<typename decltype(named)::Task>(ref, named.name, libm_same, tally);
    (tally.failures == before ? passed : failed) += 1;
  });
  if (passed + failed == 0) {
    tally.fail("no task named '" + only + "'");
    ++failed;
  }
  std::printf("tasks: %d passed, %d failed\n", passed, failed);
  return failed == 0 ? 0 : 1;
}

}  // namespace
}  // namespace mppi

int main(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  try {
    if (args.size() == 2 && args[0] == "--write") return mppi::write(args[1]);
    if (args.size() == 2 && args[0] == "--check") return mppi::check(args[1], "");
    if (args.size() == 4 && args[0] == "--check" && args[2] == "--task") return mppi::check(args[1], args[3]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "plan_reference: %s\n", e.what());
    return 1;
  }
  std::fprintf(stderr, "usage: plan_reference --write FILE | --check FILE [--task NAME]\n");
  return 2;
}
