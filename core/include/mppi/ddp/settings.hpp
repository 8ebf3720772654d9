// Settings of the DDP (iLQR) baseline controller: the `ddp:` section of a task's settings
// file. Horizon, step, control limits and the warm start come from the task's `mppi:`
// section, so both controllers plan over the same horizon with the same limits.
#pragma once

#include <string>
#include <vector>

namespace mppi {

struct DdpSettings {
  int max_iterations = 3;        // iLQR iterations per control cycle (a fixed cap: the budget)
  int line_search_steps = 6;     // step sizes tried per iteration: 1, 1/2, 1/4, ...
  double mu_init = 1e-6;         // Levenberg-Marquardt regularisation of Q_uu (scaled controls)
  double mu_min = 1e-9;
  double mu_max = 1e10;
  double mu_factor = 4.0;        // multiplies mu after a failed backward pass or line search
  double fd_step = 1e-5;         // relative finite-difference step of the Jacobians (central)
  double fd_hessian_step = 1e-4; // relative step of the state-cost Hessian
  // Replace each step's state-cost Hessian by its nearest positive semi-definite matrix
  // (the Gauss-Newton spirit: a repulsive obstacle term curves the wrong way around the
  // obstacle, and an indefinite Q_uu only buys regularisation). Off where the task needs
  // its negative curvature (the cart-pole's swing-up from the bottom).
  bool convexify = false;
  // Control cost 1/2 (u - u_ref)^T diag(r) (u - u_ref); empty: MPPI's R = scale lambda / sigma^2
  // about mppi.u_nominal (or zero), i.e. the task's own control term.
  std::vector<float> r;
  // The plan the controller starts from (per channel; empty: mppi.u_init). A local method
  // started exactly at an equilibrium with a symmetric guess has a zero gradient (the
  // cart-pole hanging down): a small push breaks the symmetry.
  std::vector<float> initial_plan;
  // Smooth obstacle penalty (forest tasks), summed over the cylinders:
  //   obstacle_weight * exp(-(c - obstacle_margin) / obstacle_softness)
  // with c = surface distance - vehicle radius (the clearance), the exponent capped at
  // exp_cap. The crash term of the MPPI cost (discontinuous) is off for DDP.
  double obstacle_weight = 0.0;
  double obstacle_margin = 0.3;     // m
  double obstacle_softness = 0.15;  // m
  // Smooth ground penalty: ground_weight * exp(-(z - ground_z - ground_margin) / ground_softness).
  double ground_weight = 0.0;
  double ground_margin = 0.5;       // m
  double ground_softness = 0.2;     // m
  // Speed penalty (forest tasks): speed_weight * max(0, |v| - speed_limit)^2. A greedy local
  // optimizer with the paper's weights accelerates until it cannot turn in time.
  double speed_weight = 0.0;
  double speed_limit = 6.0;         // m/s
  double exp_cap = 30.0;
  // Obstacles further than this from the plan's path (m, beyond their surface) are left out
  // of the penalty for the cycle (their term is below weight * exp(-(reach - margin)/softness)).
  double obstacle_reach = 4.0;
};

// Empty when valid, else "ddp.field: reason" for the first bad field; nu is the number of
// control channels of the task.
std::string validate(const DdpSettings& s, int nu);

}  // namespace mppi
