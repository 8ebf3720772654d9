// Per-sample pieces of one MPPI iteration (Sec. II-III of the notes), shared by the CPU and
// CUDA backends: the perturbed, limited control and the importance-sampled control cost.
// Templates on the number type V (hd.hpp) and the sample index type S (rng.hpp): the plan
// is shared by every sample of a step, so it stays float.
#pragma once

#include <cstdint>

#include "mppi/hd.hpp"
#include "mppi/rng.hpp"

namespace mppi {

// Per-channel constants of the sampler, precomputed once from the settings.
template <int NU>
struct SamplerConstants {
  float noise_std[NU];  // sqrt(nu) * sigma
  float r[NU];          // R = lambda / sigma^2, times control_cost_scale
  float u_min[NU];
  float u_max[NU];
  float u_nominal[NU];
  float inv_nu_term;    // 1/2 (1 - 1/nu)
  int groups = 1;          // noise groups (MppiSettings::noise_groups); <= 1: off
  int group_channels = NU; // channels per group
};

// u = clamp(plan + noise); du = u - plan is the variation actually applied (the limits
// are part of the sampling, so the update stays inside them).
//
// Noise groups (c.groups > 1): the channels split into c.groups consecutive groups of
// c.group_channels, and sample k perturbs only group k mod c.groups: the other channels
// get u = plan, du = 0 (the noise is still drawn, so a channel's noise does not depend on
// the grouping). For a team with one group per vehicle, a sample moves one vehicle and the
// others fly the plan, so a sample's cost differs from its group's others by what that
// vehicle's variation did (its own terms and its pair terms): the weights no longer mix the
// other vehicles' noise into each vehicle's update (docs/sitl.md "Teams"). Every channel is then
// perturbed by a 1/groups share of the samples, and the update, a weighted average over all
// of them, moves a group by its share of the total weight.
template <int NU, class S, class V>
MPPI_HD void perturb(const SamplerConstants<NU>& c, const NoiseKey& key, S sample, std::uint32_t step,
                     const float* plan_u, V* u, V* du) {
  V n[NU];
  gaussian<NU>(key, sample, step, n);
  if (c.groups > 1) {
    const V group = V(sample_group(sample, static_cast<std::uint32_t>(c.groups)));
    for (int j = 0; j < NU; ++j) {
      const auto on = group == V(static_cast<float>(j / c.group_channels));
      u[j] = select(on, fclamp(plan_u[j] + c.noise_std[j] * n[j], V(c.u_min[j]), V(c.u_max[j])), V(plan_u[j]));
      du[j] = u[j] - plan_u[j];
    }
    return;
  }
  for (int j = 0; j < NU; ++j) {
    u[j] = fclamp(plan_u[j] + c.noise_std[j] * n[j], V(c.u_min[j]), V(c.u_max[j]));
    du[j] = u[j] - plan_u[j];
  }
}

// Control terms of q~ (Eq. 33): 1/2 (1 - 1/nu) du'R du + u'R du + 1/2 u'R u, with u measured
// from the nominal control.
template <int NU, class V>
MPPI_HD V control_cost(const SamplerConstants<NU>& c, const float* plan_u, const V* du) {
  V q = 0.0f;
  for (int j = 0; j < NU; ++j) {
    const float u = plan_u[j] - c.u_nominal[j];
    q += c.r[j] * (c.inv_nu_term * du[j] * du[j] + u * du[j] + 0.5f * u * u);
  }
  return q;
}

}  // namespace mppi
