// Settings files as input: whatever the YAML holds, a bad file ends in a ConfigError that
// names where (mppid exits 2 with it), never in a yaml-cpp error that names nothing.
// fuzz_settings found a list or map used as a key (YAML's "? ...") escaping as
// YAML::TypedBadConversion: test/fuzz/regressions/fuzz_settings.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "mppi/app/config.hpp"
#include "mppi/daemon/daemon_settings.hpp"
#include "mppi/settings.hpp"
#include "mppi/settings_table.hpp"
#include "mppi/simd.hpp"
#include "source_dir.hpp"

using namespace mppi;

namespace {

// The ConfigError's message, or a failure saying what escaped instead.
std::string config_error(const std::string& yaml) {
  try {
    const app::AppConfig c = app::parse_config(YAML::Load(yaml));
    daemon::parse_daemon_settings(c.root["daemon"], c.task, static_cast<int>(c.mppi.u_init.size()));
  } catch (const app::ConfigError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not a ConfigError: " << e.what();
    return {};
  }
  ADD_FAILURE() << "accepted:\n" << yaml;
  return {};
}

const char* kGood = R"(task: cartpole_swingup
mppi: {rollouts: 8, horizon: 5, dt: 0.02, lambda: 1, nu: 1, sigma: [1], u_min: [-1], u_max: [1], u_init: [0]}
)";

}  // namespace

TEST(SettingsInput, TheBaseFileIsValid) {
  const app::AppConfig c = app::parse_config(YAML::Load(kGood));
  EXPECT_EQ(c.task, "cartpole_swingup");
}

TEST(SettingsInput, AListOrMapAsAKeyNamesItsSection) {
  const std::string found = mppi::testing::source_dir() + "/test/fuzz/regressions/fuzz_settings/top_level_key_is_a_map.yaml";
  try {
    app::parse_config(YAML::LoadFile(found));
    ADD_FAILURE() << "accepted " << found;
  } catch (const app::ConfigError& e) {
    EXPECT_EQ(std::string(e.what()), "(file): keys must be plain names (line 14 is a map)");
  }
  EXPECT_EQ(config_error(std::string(kGood) + "? [a, b]\n: 1\n"), "(file): keys must be plain names (line 3 is a list)");
  EXPECT_EQ(config_error("task: cartpole_swingup\nmppi: {? [a]: 1}\n"), "mppi: keys must be plain names (line 2 is a list)");
  EXPECT_EQ(config_error(std::string(kGood) + "model: {? [a]: 1}\n"), "model: keys must be plain names (line 3 is a list)");
  EXPECT_EQ(config_error(std::string(kGood) + "daemon: {? [a]: 1}\n"), "daemon: keys must be plain names (line 3)");
  EXPECT_EQ(config_error(std::string(kGood) + "daemon: {realtime: {? {x: 1}: 1}}\n"),
            "daemon.realtime: keys must be plain names (line 3)");
}

TEST(SettingsInput, TheTriggerIsClockOrStateAndItsFractionsAreBounded) {
  EXPECT_EQ(config_error(std::string(kGood) + "daemon: {trigger: states}\n"), "daemon.trigger: must be clock or state");
  EXPECT_NE(config_error(std::string(kGood) + "daemon: {trigger: state, state_trigger: {min_gap: 0}}\n")
                .find("daemon.state_trigger.min_gap: must be in"),
            std::string::npos);
  EXPECT_NE(config_error(std::string(kGood) + "daemon: {state_trigger: {grace: 0.5, slack: 1}}\n").find("slack"),
            std::string::npos);
  const app::AppConfig c = app::parse_config(YAML::Load(std::string(kGood) +
                                                         "daemon: {trigger: state, state_trigger: {min_gap: 0.5, grace: 1}}\n"));
  const auto d = daemon::parse_daemon_settings(c.root["daemon"], c.task, 1);
  EXPECT_EQ(d.loop.trigger, daemon::Trigger::kState);
  EXPECT_DOUBLE_EQ(d.loop.state_trigger_min_gap, 0.5);
  EXPECT_DOUBLE_EQ(d.loop.state_trigger_grace, 1.0);
}

// daemon.latency.estimate_lag_ms (the vehicle file's estimate_lag): bounded, 0 by default, and
// only for the quadrotor models, whose position and velocity come first in the state.
TEST(SettingsInput, TheEstimateLagIsBoundedAndOnlyForQuadrotors) {
  const auto none = daemon::parse_daemon_settings(YAML::Load("rate_hz: 50"), "quadrotor_rate_track", 4);
  EXPECT_EQ(none.loop.latency.estimate_lag_ns, 0);
  const auto lag = daemon::parse_daemon_settings(YAML::Load("latency: {estimate_lag_ms: 25}"), "quadrotor_rate_track", 4);
  EXPECT_EQ(lag.loop.latency.estimate_lag_ns, 25'000'000);
  EXPECT_THROW(daemon::parse_daemon_settings(YAML::Load("latency: {estimate_lag_ms: 600}"), "quadrotor_rate_track", 4),
               app::ConfigError);
  try {
    daemon::parse_daemon_settings(YAML::Load("latency: {estimate_lag_ms: 5}"), "cartpole_swingup", 1);
    FAIL() << "a lag for the cart-pole";
  } catch (const app::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("only for the quadrotor models"), std::string::npos) << e.what();
  }
}

// daemon.spin (the loop and receive threads poll instead of sleeping): a boolean, off by default.
TEST(SettingsInput, SpinIsABooleanOffByDefault) {
  const auto off = daemon::parse_daemon_settings(YAML::Load("rate_hz: 50"), "cartpole_swingup", 1);
  EXPECT_FALSE(off.spin);
  const auto on = daemon::parse_daemon_settings(YAML::Load("spin: true"), "cartpole_swingup", 1);
  EXPECT_TRUE(on.spin);
  EXPECT_THROW(daemon::parse_daemon_settings(YAML::Load("spin: fast"), "cartpole_swingup", 1), app::ConfigError);
}

// The loop rate as a dial (tools/gpu/rate_dial.py: one plan step a period, the horizon the same
// in seconds): every task file takes 50 to 400 Hz, in each of its sections (mppid checks them
// all, whatever the machine), and the default anytime margin (3 ms) stays within a quarter of
// the period.
TEST(SettingsInput, EveryTaskFileTakesEveryLoopRateOfTheDial) {
  int files = 0;
  for (const char* task : {"cartpole_swingup", "quadrotor_forest", "quadrotor_rate_forest", "quadrotor_rate_track",
                           "quadrotor_track", "racecar_ellipse", "team3_forest", "team9_forest"}) {
    for (const double rate : {50.0, 100.0, 200.0, 400.0}) {
      const app::AppConfig file = app::load_config(app::default_config_path(task), {"daemon.rate_hz=" + std::to_string(rate)});
      const int nu = static_cast<int>(file.mppi.u_init.size());
      std::vector<std::pair<std::string, const app::AppConfig*>> sections = {{"file", &file}};
      if (file.cuda) sections.emplace_back("cuda", file.cuda.get());
      for (const auto& [target, v] : file.cpu_targets) sections.emplace_back("cpu_targets." + target, v.get());
      for (const auto& [name, c] : sections) {
        try {
          const auto d = daemon::parse_daemon_settings(c->root["daemon"], c->task, nu);
          EXPECT_LE(static_cast<double>(d.loop.anytime_margin_ns), 0.25e9 / rate + 1.0) << task << " " << name;
        } catch (const app::ConfigError& e) {
          ADD_FAILURE() << task << " " << name << " at " << rate << " Hz: " << e.what();
        }
      }
    }
    ++files;
  }
  EXPECT_EQ(files, 8);
}

// The rollout fan for tools/view: off unless asked; its fields bounded and named.
TEST(SettingsInput, TheRolloutFanIsOffByDefaultAndBounded) {
  const app::AppConfig base = app::parse_config(YAML::Load(std::string(kGood)));
  EXPECT_EQ(daemon::parse_daemon_settings(base.root["daemon"], base.task, 1).loop.rollouts.hz, 0.0);
  EXPECT_EQ(config_error(std::string(kGood) + "daemon: {rollouts: {top: 200, random: 100, hz: 5}}\n"),
            "daemon.rollouts.random: top + random must be at most 256");
  EXPECT_NE(config_error(std::string(kGood) + "daemon: {rollouts: {hz: -1}}\n").find("daemon.rollouts.hz: must be in"),
            std::string::npos);
  EXPECT_NE(config_error(std::string(kGood) + "daemon: {rollouts: {every: 3}}\n").find("every"), std::string::npos);
  const app::AppConfig c = app::parse_config(YAML::Load(std::string(kGood) + "daemon: {rollouts: {hz: 5, top: 8}}\n"));
  const auto d = daemon::parse_daemon_settings(c.root["daemon"], c.task, 1);
  EXPECT_DOUBLE_EQ(d.loop.rollouts.hz, 5.0);
  EXPECT_EQ(d.loop.rollouts.top, 8);
  EXPECT_EQ(d.loop.rollouts.random, 16);
}

// A `cuda:` section may carry daemon settings (the GPU's state trigger): merged key by key
// into the file's daemon section, the rest of which stays.
TEST(SettingsInput, TheCudaSectionMayCarryDaemonSettings) {
  const app::AppConfig c = app::parse_config(
      YAML::Load(std::string(kGood) + "daemon: {rate_hz: 40, trigger: clock}\ncuda: {daemon: {trigger: state}}\n"));
  ASSERT_TRUE(c.cuda);
  const auto cpu = daemon::parse_daemon_settings(c.for_backend("cpu").root["daemon"], c.task, 1);
  const auto gpu = daemon::parse_daemon_settings(c.for_backend("cuda").root["daemon"], c.task, 1);
  EXPECT_EQ(cpu.loop.trigger, daemon::Trigger::kClock);
  EXPECT_EQ(gpu.loop.trigger, daemon::Trigger::kState);
  EXPECT_DOUBLE_EQ(gpu.loop.rate_hz, 40.0);
  // A file section that is not a map cannot take the cuda section's keys (fuzz_settings found
  // `daemon: 1` escaping as YAML::BadSubscript: test/fuzz/regressions/fuzz_settings).
  EXPECT_EQ(config_error(std::string(kGood) + "daemon: 1\ncuda: {daemon: {trigger: state}}\n"),
            "cuda.daemon: expected a map");
}

// `cpu_targets:` (issue 10, item 4): what the CPU backend flies with on each SIMD target. The
// entry of the target mppi.simd resolves to here applies; every entry is validated at load,
// whatever the machine, and a bad one names itself.
TEST(SettingsInput, TheCpuTargetOfThisMachineTakesItsEntry) {
  const std::string file = std::string(kGood) +
                           "daemon: {rate_hz: 40}\n"
                           "cpu_targets: {scalar: {mppi: {rollouts: 4}, daemon: {rate_hz: 25}}, sse4: {mppi: {rollouts: 6}}}\n";
  const app::AppConfig c = app::parse_config(YAML::Load(file), {"mppi.simd=off"});
  ASSERT_EQ(c.cpu_targets.size(), 2u);
  EXPECT_EQ(c.variant_for("cpu"), "cpu_targets.scalar");
  EXPECT_EQ(c.for_backend("cpu").mppi.rollouts, 4);
  EXPECT_EQ(c.mppi.rollouts, 8);  // the file's own settings stay
  EXPECT_DOUBLE_EQ(daemon::parse_daemon_settings(c.for_backend("cpu").root["daemon"], c.task, 1).loop.rate_hz, 25.0);
  // A command-line --set wins over the entry; --set cpu_targets.scalar... changes the entry.
  const app::AppConfig d = app::parse_config(YAML::Load(file), {"mppi.simd=off", "mppi.rollouts=16"});
  EXPECT_EQ(d.for_backend("cpu").mppi.rollouts, 16);
  const app::AppConfig e = app::parse_config(YAML::Load(file), {"mppi.simd=off", "cpu_targets.scalar.mppi.rollouts=12"});
  EXPECT_EQ(e.for_backend("cpu").mppi.rollouts, 12);
  // A target with no entry flies the file's settings; so does the CUDA backend.
  EXPECT_EQ(c.variant_for("cuda"), "");
  EXPECT_EQ(c.for_backend("cuda").mppi.rollouts, 8);
  if (simd::supported(simd::Target::kAvx2)) {
    const app::AppConfig f = app::parse_config(YAML::Load(file), {"mppi.simd=avx2"});
    EXPECT_EQ(f.variant_for("cpu"), "");
    EXPECT_EQ(f.for_backend("cpu").mppi.rollouts, 8);
  }
  // A live update (with_mppi) reaches the entry.
  MppiSettings s = c.for_backend("cpu").mppi;
  s.rollouts = 2;
  EXPECT_EQ(c.with_mppi(s).for_backend("cpu").mppi.rollouts, 2);
}

TEST(SettingsInput, ABadCpuTargetEntryNamesItself) {
  EXPECT_EQ(config_error(std::string(kGood) + "cpu_targets: {avx9: {mppi: {rollouts: 4}}}\n"),
            "cpu_targets.avx9: not a SIMD target (scalar, " + simd::target_names() + ")");
  EXPECT_EQ(config_error(std::string(kGood) + "cpu_targets: {sse4: {mppi: {rollouts: 0}}}\n"),
            "cpu_targets.sse4: mppi.rollouts: must be >= 1");
  EXPECT_EQ(config_error(std::string(kGood) + "cpu_targets: {sse4: {planner: {x: 1}}}\n"),
            "cpu_targets.sse4.planner: unknown section (mppi, model, cost, daemon)");
  EXPECT_EQ(config_error(std::string(kGood) + "cpu_targets: [1, 2]\n"),
            "cpu_targets: expected a map of SIMD target: {mppi/model/cost/daemon overrides}");
  EXPECT_EQ(config_error(std::string(kGood) + "cpu_targets: {scalar: {mppi: {rollouts: 4}}, off: {}}\n"),
            "cpu_targets.off: not a SIMD target (scalar, " + simd::target_names() + ")");
}

// The shipped task files: each entry is valid and has fewer rollouts than the AVX-512 default.
TEST(SettingsInput, ShippedCpuTargetsFlyFewerRolloutsOnNarrowerLanes) {
  for (const char* task : {"quadrotor_forest", "quadrotor_rate_forest", "quadrotor_track", "quadrotor_rate_track",
                           "racecar_ellipse", "team3_forest"}) {
    const app::AppConfig c = app::load_config(app::default_config_path(task));
    ASSERT_FALSE(c.cpu_targets.empty()) << task;
    for (const auto& [target, v] : c.cpu_targets) {
      EXPECT_LT(v->mppi.rollouts, c.mppi.rollouts) << task << " " << target;
      EXPECT_NO_THROW(daemon::parse_daemon_settings(v->root["daemon"], c.task, static_cast<int>(c.mppi.u_init.size())));
    }
  }
}

namespace {

const char* kQuad = R"(task: quadrotor_track
mppi: {rollouts: 8, horizon: 5, dt: 0.02, lambda: 1, nu: 1, sigma: [1, 1, 1, 1], u_min: [-1, -1, -1, -1],
       u_max: [1, 1, 1, 1], u_init: [0, 0, 0, 0]}
)";

// A valid value for row `r` of the optimizer's table that the base file (kQuad) does not
// give, as YAML text.
template <class T>
std::string optimizer_value(const SettingSpec& r, const T&) {
  if constexpr (std::is_same_v<T, std::vector<float>>) {
    const std::string name = r.name;
    const char* v = name == "sigma" ? "0.5" : name == "u_min" ? "-0.5" : name == "u_max" ? "0.5"
                  : name == "u_init" ? "0.25" : name == "u_nominal" ? "0.125" : nullptr;
    if (v == nullptr) ADD_FAILURE() << "no test value for the list " << name;
    const std::string one = v != nullptr ? v : "0";
    return "[" + one + ", " + one + ", " + one + ", " + one + "]";
  } else if constexpr (std::is_same_v<T, std::string>) {
    return "off";
  } else if constexpr (std::is_same_v<T, Weighting>) {
    return "trajectory";
  } else if constexpr (std::is_same_v<T, std::uint64_t>) {
    return "12345";
  } else if constexpr (std::is_integral_v<T>) {
    switch (r.rule) {
      case SettingRule::kOdd: return std::to_string(static_cast<int>(r.lo) + 2);
      case SettingRule::kDividesNu: return "2";
      default: return std::to_string(static_cast<int>(r.lo) + 1);
    }
  } else {
    return std::to_string(r.lo + 0.5);
  }
}

}  // namespace

// Every row of the optimizer's table (mppi/settings.hpp) is read from the file into its
// field, and a missing required row is named.
TEST(SettingsInput, EveryOptimizerKeyRoundTripsFromYaml) {
  const MppiSettings defaults;
  int rows = 0;
  visit_settings(defaults, [&](const SettingSpec& r, const auto& def) {
    using T = std::decay_t<decltype(def)>;
    ++rows;
    const std::string text = optimizer_value(r, def);
    YAML::Node root = YAML::Load(kQuad);
    root["mppi"][r.name] = YAML::Load(text);
    const app::AppConfig c = app::parse_config(root);
    bool seen = false;
    visit_settings(c.mppi, [&](const SettingSpec& got, const auto& field) {
      if (std::string(got.name) != r.name) return;
      seen = true;
      if constexpr (std::is_same_v<std::decay_t<decltype(field)>, Weighting>) {
        EXPECT_EQ(to_string(field), text);
      } else if constexpr (std::is_same_v<std::decay_t<decltype(field)>, T>) {
        EXPECT_EQ(field, YAML::Load(text).as<T>()) << r.name << " = " << text;
      }
    });
    EXPECT_TRUE(seen) << r.name;
    if (r.required) {
      YAML::Node missing = YAML::Load(kQuad);
      missing["mppi"].remove(r.name);
      EXPECT_EQ(config_error(YAML::Dump(missing)), std::string("mppi.") + r.name + ": missing");
    }
  });
  EXPECT_EQ(rows, 20);
}

namespace {

// The file text of `daemon.<path>: value` ("daemon: {latency: {window: 3}}").
std::string daemon_yaml(const std::string& path, const std::string& value) {
  std::string out = "daemon: ", close;
  std::size_t start = 0;
  for (auto dot = path.find('.'); dot != std::string::npos; dot = path.find('.', start = dot + 1) ) {
    out += "{" + path.substr(start, dot - start) + ": ";
    close += "}";
  }
  return out + "{" + path.substr(start) + ": " + value + "}" + close + "\n";
}

// A value inside row k's range (1 % of the way up: the rows' rules between each other hold
// with the others' defaults), as YAML text, and what the field then holds.
struct DaemonValue {
  const daemon::DaemonKey& k;
  double hi;

  template <class T>
  std::pair<std::string, T> operator()(const T& def) const {
    if constexpr (std::is_same_v<T, bool>) {
      if (k.choices != nullptr) return {def ? "receive" : "sample", !def};  // state_time: true = sample
      return {def ? "false" : "true", !def};
    } else if constexpr (std::is_same_v<T, daemon::Trigger>) {
      return {"state", daemon::Trigger::kState};
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (k.choices != nullptr) return {"state", "state"};
      return {"TEST_TEXT", "TEST_TEXT"};
    } else if constexpr (std::is_same_v<T, std::vector<float>>) {
      return {"[1, 2, 3, 4]", {1, 2, 3, 4}};
    } else {
      double v = k.lo + 0.01 * (hi - k.lo);
      // work.target must stay above work.grow_below x work.grow (their defaults): its top end.
      if (std::string(k.path) == "work.target") v = hi - 0.01 * (hi - k.lo);
      if constexpr (std::is_same_v<T, int>) v = std::ceil(v);  // an integer row takes whole numbers
      const std::string text = std::to_string(v);
      const double read = std::stod(text);
      if constexpr (std::is_same_v<T, std::int64_t>) return {text, std::llround(read * k.scale)};
      return {text, static_cast<T>(read)};
    }
  }
};

}  // namespace

// Every row of the daemon's table (daemon_settings.hpp) is read from the file into its
// field; every section refuses a key it does not hold, naming it.
TEST(SettingsInput, EveryDaemonKeyRoundTripsFromYaml) {
  const daemon::DaemonSettings defaults = daemon::parse_daemon_settings(YAML::Node(), "quadrotor_track", 4);
  int rows = 0;
  std::set<std::string> sections{""};
  daemon::visit_daemon_settings(defaults, [&](const daemon::DaemonKey& k, const auto& def) {
    using T = std::decay_t<decltype(def)>;
    if constexpr (!std::is_same_v<T, daemon::DaemonCommand>) {
      ++rows;
      const std::string path = k.path;
      if (path.find('.') != std::string::npos) sections.insert(path.substr(0, path.rfind('.')) + ".");
      const double hi = k.hi_is == daemon::DaemonHi::kRateHz     ? defaults.loop.rate_hz
                        : k.hi_is == daemon::DaemonHi::kPeriodMs ? 1000.0 / defaults.loop.rate_hz
                        : k.hi_is == daemon::DaemonHi::kDelayMaxMs ? defaults.loop.latency.delay_estimate.max_ms
                                                                    : k.hi;
      const auto value = DaemonValue{k, hi}(def);
      const T& want = value.second;
      const std::string yaml = daemon_yaml(path, value.first);
      daemon::DaemonSettings d;
      try {
        d = daemon::parse_daemon_settings(YAML::Load(yaml)["daemon"], "quadrotor_track", 4);
      } catch (const app::ConfigError& e) {
        ADD_FAILURE() << yaml << e.what();
        return;
      }
      daemon::visit_daemon_settings(d, [&](const daemon::DaemonKey& got, const auto& field) {
        if constexpr (std::is_same_v<std::decay_t<decltype(field)>, T>) {
          if (std::string(got.path) == path) {
            EXPECT_EQ(field, want) << yaml;
          }
        }
      });
    }
  });
  EXPECT_EQ(rows, 80);
  for (const std::string& section : sections) {
    const std::string path = section + "bogus";
    try {
      daemon::parse_daemon_settings(YAML::Load(daemon_yaml(path, "1"))["daemon"], "quadrotor_track", 4);
      ADD_FAILURE() << path << " accepted";
    } catch (const app::ConfigError& e) {
      EXPECT_EQ(std::string(e.what()), "daemon." + path + ": unknown field");
    }
  }
  EXPECT_EQ(sections.size(), 13u);
}
