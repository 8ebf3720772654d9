// Optimizer settings: one validated, immutable snapshot per controller. Loading from a
// file lives outside core (config/); validate() names the first bad field.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace mppi {

enum class Weighting {
  kCostToGo,    // the paper's: step i weighted by the cost-to-go from i
  kTrajectory,  // every step weighted by the whole-trajectory cost
};

struct MppiSettings {
  int rollouts = 1024;          // K
  int horizon = 100;            // T, control steps
  float dt = 0.02f;             // s per control step
  int substeps = 1;             // Euler steps per control step inside a rollout
  float lambda = 1.0f;          // temperature
  float nu = 1.0f;              // exploration variance (>= 1)
  std::vector<float> sigma;     // per-channel natural std deviation; R = lambda / sigma^2
  std::vector<float> u_min;     // per-channel limits, applied before costing
  std::vector<float> u_max;
  std::vector<float> u_init;    // appended by the shift (warm start)
  std::vector<float> u_nominal; // control cost is on (u - u_nominal); zero if empty
  float control_cost_scale = 1.0f;  // multiplies the control terms of q~ (paper: 1)
  Weighting weighting = Weighting::kCostToGo;
  int smoothing_window = 1;     // moving average over the plan, odd; 1 = off
  // Noise groups: the NU channels split into this many equal consecutive groups (a team:
  // one per vehicle), and sample k perturbs only group k mod noise_groups (the others fly
  // the plan). 1: every sample perturbs every channel (the paper's). See sampling.hpp.
  int noise_groups = 1;
  std::uint64_t seed = 1;
  int threads = 0;              // CPU backend: 0 = all cores (OpenMP default)
  // CPU backend: samples in SIMD lanes. "auto" (the best target this CPU runs), "off" (one
  // sample at a time, the scalar reference), or a target: sse4, avx2, avx3 (x86), neon (Arm).
  std::string simd = "auto";
  // Anytime cycle (CPU backend, when given a stop flag): rollouts run in chunks of
  // chunk_rollouts (0: K/8, rounded up to 16), and an update stopped early uses the chunks
  // done if at least min_rollouts finished (0: K/4), else leaves the plan as it was.
  int chunk_rollouts = 0;
  int min_rollouts = 0;
};

// The chunk size and minimum of the anytime cycle, the defaults resolved.
int resolved_chunk_rollouts(const MppiSettings& s);
int resolved_min_rollouts(const MppiSettings& s);

// Empty when valid, else "field: reason" for the first bad field. nu is the control
// dimension the settings must match.
std::string validate(const MppiSettings& s, int nu);

const char* to_string(Weighting w);
bool parse_weighting(const std::string& text, Weighting* out);

}  // namespace mppi
