#include "mppi/settings.hpp"
#include "mppi/settings_table.hpp"

#include "mppi/simd.hpp"

#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>

namespace mppi {
namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

// "must be >= 1" / "must be > 0" for a row's lower bound.
std::string lower_bound(const SettingSpec& r) { return std::string(r.lo_open ? "> " : ">= ") + num(r.lo); }

bool below(const SettingSpec& r, double v) { return r.lo_open ? !(v > r.lo) : !(v >= r.lo); }

std::string check_vector(const SettingSpec& r, const std::vector<float>& v, int nu) {
  if (!r.required && v.empty()) return {};
  if (static_cast<int>(v.size()) != nu)
    return std::string(r.name) + ": expected " + std::to_string(nu) + " values, got " + std::to_string(v.size());
  for (float x : v)
    if (!std::isfinite(x)) return std::string(r.name) + ": values must be finite";
  return {};
}

// The row's own rule for a number (a float must also be finite).
template <class T>
std::string check_number(const SettingSpec& r, T v, const MppiSettings& s, int nu) {
  const std::string name = std::string(r.name) + ": ";
  const bool bad = below(r, static_cast<double>(v)) || !std::isfinite(static_cast<double>(v));
  switch (r.rule) {
    case SettingRule::kOdd:
      if (bad || static_cast<long long>(v) % 2 == 0) return name + "must be odd and " + lower_bound(r);
      return {};
    case SettingRule::kDividesNu:
      if (bad || static_cast<double>(v) > nu || nu % static_cast<int>(v) != 0)
        return name + "must be " + lower_bound(r) + " and divide the " + std::to_string(nu) + " control channels";
      return {};
    case SettingRule::kUpToRollouts:
      if (bad || static_cast<double>(v) > s.rollouts) return name + "must lie in [" + num(r.lo) + ", rollouts]";
      return {};
    default:
      return bad ? name + "must be " + lower_bound(r) : std::string();
  }
}

// The checks of one row of the table against `s`.
struct RowCheck {
  const MppiSettings& s;
  int nu;
  std::string* err;

  template <class T>
  void operator()(const SettingSpec& r, const T& v) const {
    if (!err->empty()) return;
    if constexpr (std::is_same_v<T, std::vector<float>>) {
      *err = check_vector(r, v, nu);
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (r.rule == SettingRule::kSimd && !simd::parse_setting(v, nullptr))
        *err = std::string(r.name) + ": must be auto, off or a target (" + simd::target_names() + ")";
    } else if constexpr (std::is_arithmetic_v<T>) {
      if (r.lo > kNoLowerBound || r.rule != SettingRule::kNone) *err = check_number(r, v, s, nu);
    }
  }
};

// A lower bound on a list's values ("sigma: every value must be > 0"), once every list has its size.
struct ListBound {
  std::string* err;
  template <class T>
  void operator()(const SettingSpec& r, const T& v) const {
    if constexpr (std::is_same_v<T, std::vector<float>>) {
      if (!err->empty() || r.lo <= kNoLowerBound) return;
      for (float x : v)
        if (below(r, x)) {
          *err = std::string(r.name) + ": every value must be " + lower_bound(r);
          return;
        }
    }
  }
};

}  // namespace

std::string validate(const MppiSettings& s, int nu) {
  std::string err;
  visit_settings(s, RowCheck{s, nu, &err});
  visit_settings(s, ListBound{&err});
  if (!err.empty()) return err;
  for (int j = 0; j < nu; ++j) {
    if (!(s.u_min[j] <= s.u_max[j])) return "u_min: must not exceed u_max";
    if (s.u_init[j] < s.u_min[j] || s.u_init[j] > s.u_max[j]) return "u_init: must lie inside [u_min, u_max]";
  }
  return {};
}

std::string live_setting_names() {
  static const MppiSettings kDefaults;
  std::string out;
  visit_settings(kDefaults, [&](const SettingSpec& r, const auto& v) {
    if (r.live == LiveBound::kFixed) return;
    out += (out.empty() ? "" : ", ") + std::string(r.name);
    if constexpr (std::is_same_v<std::decay_t<decltype(v)>, std::vector<float>>) out += ", " + std::string(r.name) + "[j]";
  });
  return out;
}

int resolved_chunk_rollouts(const MppiSettings& s) {
  if (s.chunk_rollouts > 0) return s.chunk_rollouts;
  const int eighth = (s.rollouts + 7) / 8;
  return (eighth + 15) / 16 * 16;
}

int resolved_min_rollouts(const MppiSettings& s) {
  if (s.min_rollouts > 0) return s.min_rollouts;
  return (s.rollouts + 3) / 4;
}

const char* to_string(Weighting w) { return w == Weighting::kTrajectory ? "trajectory" : "cost_to_go"; }

bool parse_weighting(const std::string& text, Weighting* out) {
  if (text == "cost_to_go") *out = Weighting::kCostToGo;
  else if (text == "trajectory") *out = Weighting::kTrajectory;
  else return false;
  return true;
}

}  // namespace mppi
