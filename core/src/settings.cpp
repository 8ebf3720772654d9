#include "mppi/settings.hpp"

#include "mppi/simd.hpp"

#include <cmath>
#include <string>
#include <tuple>

namespace mppi {
namespace {

std::string check_vector(const char* field, const std::vector<float>& v, int nu, bool allow_empty) {
  if (allow_empty && v.empty()) return {};
  if (static_cast<int>(v.size()) != nu)
    return std::string(field) + ": expected " + std::to_string(nu) + " values, got " + std::to_string(v.size());
  for (float x : v)
    if (!std::isfinite(x)) return std::string(field) + ": values must be finite";
  return {};
}

}  // namespace

std::string validate(const MppiSettings& s, int nu) {
  if (s.rollouts < 1) return "rollouts: must be >= 1";
  if (s.horizon < 2) return "horizon: must be >= 2";
  if (!(s.dt > 0.0f) || !std::isfinite(s.dt)) return "dt: must be > 0";
  if (s.substeps < 1) return "substeps: must be >= 1";
  if (!(s.lambda > 0.0f) || !std::isfinite(s.lambda)) return "lambda: must be > 0";
  if (!(s.nu >= 1.0f) || !std::isfinite(s.nu)) return "nu: must be >= 1";
  if (!(s.control_cost_scale >= 0.0f) || !std::isfinite(s.control_cost_scale))
    return "control_cost_scale: must be >= 0";
  if (s.smoothing_window < 1 || s.smoothing_window % 2 == 0) return "smoothing_window: must be odd and >= 1";
  if (s.noise_groups < 1 || s.noise_groups > nu || nu % s.noise_groups != 0)
    return "noise_groups: must be >= 1 and divide the " + std::to_string(nu) + " control channels";
  if (s.threads < 0) return "threads: must be >= 0";
  if (!simd::parse_setting(s.simd, nullptr))
    return "simd: must be auto, off or a target (" + simd::target_names() + ")";
  if (s.chunk_rollouts < 0 || s.chunk_rollouts > s.rollouts) return "chunk_rollouts: must lie in [0, rollouts]";
  if (s.min_rollouts < 0 || s.min_rollouts > s.rollouts) return "min_rollouts: must lie in [0, rollouts]";
  for (auto [name, vec, empty_ok] : {std::tuple<const char*, const std::vector<float>*, bool>{"sigma", &s.sigma, false},
                                     {"u_min", &s.u_min, false},
                                     {"u_max", &s.u_max, false},
                                     {"u_init", &s.u_init, false},
                                     {"u_nominal", &s.u_nominal, true}}) {
    std::string err = check_vector(name, *vec, nu, empty_ok);
    if (!err.empty()) return err;
  }
  for (int j = 0; j < nu; ++j) {
    if (!(s.sigma[j] > 0.0f)) return "sigma: every value must be > 0";
    if (!(s.u_min[j] <= s.u_max[j])) return "u_min: must not exceed u_max";
    if (s.u_init[j] < s.u_min[j] || s.u_init[j] > s.u_max[j]) return "u_init: must lie inside [u_min, u_max]";
  }
  return {};
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
