#include "mppi/ddp/settings.hpp"

#include <cmath>

namespace mppi {
namespace {

bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }
bool finite_nonnegative(double v) { return std::isfinite(v) && v >= 0.0; }

std::string check_list(const std::vector<float>& v, int nu, const char* name, bool positive) {
  if (v.empty()) return {};
  if (static_cast<int>(v.size()) != nu)
    return std::string("ddp.") + name + ": expected " + std::to_string(nu) + " numbers, got " + std::to_string(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i]) || (positive && !(v[i] >= 0.0f)))
      return std::string("ddp.") + name + "[" + std::to_string(i) + "]: must be finite" + (positive ? " and >= 0" : "");
  }
  return {};
}

}  // namespace

std::string validate(const DdpSettings& s, int nu) {
  if (s.max_iterations < 1 || s.max_iterations > 1000) return "ddp.max_iterations: must be in [1, 1000]";
  if (s.line_search_steps < 1 || s.line_search_steps > 30) return "ddp.line_search_steps: must be in [1, 30]";
  if (!finite_nonnegative(s.mu_min)) return "ddp.mu_min: must be finite and >= 0";
  if (!finite_positive(s.mu_max) || s.mu_max <= s.mu_min) return "ddp.mu_max: must be finite and > mu_min";
  if (!std::isfinite(s.mu_init) || s.mu_init < s.mu_min || s.mu_init > s.mu_max)
    return "ddp.mu_init: must lie in [mu_min, mu_max]";
  if (!std::isfinite(s.mu_factor) || s.mu_factor <= 1.0) return "ddp.mu_factor: must be > 1";
  if (!finite_positive(s.fd_step) || s.fd_step > 0.1) return "ddp.fd_step: must be in (0, 0.1]";
  if (!finite_positive(s.fd_hessian_step) || s.fd_hessian_step > 0.1) return "ddp.fd_hessian_step: must be in (0, 0.1]";
  if (std::string e = check_list(s.r, nu, "r", true); !e.empty()) return e;
  if (std::string e = check_list(s.initial_plan, nu, "initial_plan", false); !e.empty()) return e;
  if (!finite_nonnegative(s.obstacle_weight)) return "ddp.obstacle_weight: must be finite and >= 0";
  if (!std::isfinite(s.obstacle_margin)) return "ddp.obstacle_margin: must be finite";
  if (!finite_positive(s.obstacle_softness)) return "ddp.obstacle_softness: must be finite and > 0";
  if (!finite_nonnegative(s.ground_weight)) return "ddp.ground_weight: must be finite and >= 0";
  if (!std::isfinite(s.ground_margin)) return "ddp.ground_margin: must be finite";
  if (!finite_positive(s.ground_softness)) return "ddp.ground_softness: must be finite and > 0";
  if (!finite_nonnegative(s.speed_weight)) return "ddp.speed_weight: must be finite and >= 0";
  if (!finite_nonnegative(s.speed_limit)) return "ddp.speed_limit: must be finite and >= 0";
  if (!finite_positive(s.exp_cap) || s.exp_cap > 80.0) return "ddp.exp_cap: must be in (0, 80]";
  if (!finite_nonnegative(s.obstacle_reach)) return "ddp.obstacle_reach: must be finite and >= 0";
  return {};
}

}  // namespace mppi
