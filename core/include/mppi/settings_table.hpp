// The optimizer's settings table (`mppi.*` of a settings file): key, type, range and
// whether a live update may change it, one row per field of MppiSettings (settings.hpp).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mppi/settings.hpp"

namespace mppi {

// As visit_fields is for the models and costs: one row per key, in the order validate()
// checks them. The settings-file reader (mppi/app/config.hpp), validate() and the daemon's
// live updates (mppi/daemon/live_optimizer.hpp) all read it, and their error messages come
// from it.

// What a live update (a parameter update while mppid runs) may do with a setting.
enum class LiveBound {
  kFixed,        // nothing: fixed for a run (restart with --set)
  kAny,          // any value validate() accepts
  kConstant,     // a whole number up to SettingSpec::live_hi
  kMaxRollouts,  // a whole number up to daemon.live.max_rollouts
  kMaxHorizon,   // a whole number up to daemon.live.max_horizon
  kCpus,         // a whole number up to the CPUs the process may use (daemon.live.max_threads)
};

// A rule of a row beyond its lower bound (validate()).
enum class SettingRule {
  kNone,
  kOdd,            // an odd number
  kDividesNu,      // divides the control channels
  kSimd,           // auto, off or a SIMD target
  kUpToRollouts,   // at most `rollouts`
  kPerChannel,     // a list of one value per control channel (may be empty unless required)
};

struct SettingSpec {
  const char* name;       // the key under `mppi.`
  bool required;          // a settings file must give it
  double lo;              // a number's lowest value (-inf: none)
  bool lo_open;           // lo itself is out of range ("> 0")
  SettingRule rule;
  LiveBound live;
  double live_hi;         // kConstant: the highest value a live update may set
};

// SettingSpec::lo of a row without a lower bound.
inline constexpr double kNoLowerBound = -1e300;

// A visitor is called as v(const SettingSpec&, field&), field being an int, float,
// std::uint64_t, std::string, Weighting or std::vector<float> of `s` (MppiSettings or const).
template <class S, class V>
void visit_settings(S& s, V&& v) {
  constexpr double kNoLo = kNoLowerBound;
  using B = LiveBound;
  using R = SettingRule;
  v(SettingSpec{"rollouts", true, 1, false, R::kNone, B::kMaxRollouts, 0}, s.rollouts);
  v(SettingSpec{"horizon", true, 2, false, R::kNone, B::kMaxHorizon, 0}, s.horizon);
  v(SettingSpec{"dt", true, 0, true, R::kNone, B::kAny, 0}, s.dt);
  v(SettingSpec{"substeps", false, 1, false, R::kNone, B::kConstant, 1000}, s.substeps);
  v(SettingSpec{"lambda", true, 0, true, R::kNone, B::kAny, 0}, s.lambda);
  v(SettingSpec{"nu", true, 1, false, R::kNone, B::kAny, 0}, s.nu);
  v(SettingSpec{"control_cost_scale", false, 0, false, R::kNone, B::kAny, 0}, s.control_cost_scale);
  v(SettingSpec{"smoothing_window", false, 1, false, R::kOdd, B::kConstant, 1001}, s.smoothing_window);
  v(SettingSpec{"noise_groups", false, 1, false, R::kDividesNu, B::kFixed, 0}, s.noise_groups);
  v(SettingSpec{"threads", false, 0, false, R::kNone, B::kCpus, 0}, s.threads);
  v(SettingSpec{"simd", false, kNoLo, false, R::kSimd, B::kFixed, 0}, s.simd);
  v(SettingSpec{"chunk_rollouts", false, 0, false, R::kUpToRollouts, B::kMaxRollouts, 0}, s.chunk_rollouts);
  v(SettingSpec{"min_rollouts", false, 0, false, R::kUpToRollouts, B::kMaxRollouts, 0}, s.min_rollouts);
  // A live `sigma` sets every channel; `sigma[j]` one channel.
  v(SettingSpec{"sigma", true, 0, true, R::kPerChannel, B::kAny, 0}, s.sigma);
  v(SettingSpec{"u_min", true, kNoLo, false, R::kPerChannel, B::kFixed, 0}, s.u_min);
  v(SettingSpec{"u_max", true, kNoLo, false, R::kPerChannel, B::kFixed, 0}, s.u_max);
  v(SettingSpec{"u_init", true, kNoLo, false, R::kPerChannel, B::kFixed, 0}, s.u_init);
  v(SettingSpec{"u_nominal", false, kNoLo, false, R::kPerChannel, B::kFixed, 0}, s.u_nominal);
  v(SettingSpec{"weighting", false, kNoLo, false, R::kNone, B::kFixed, 0}, s.weighting);
  v(SettingSpec{"seed", false, 0, false, R::kNone, B::kConstant, 9007199254740992.0}, s.seed);
}

// The keys a live update may change, from the table: "rollouts, horizon, ..., sigma, sigma[j], seed".
std::string live_setting_names();

}  // namespace mppi
