// A task is a vehicle model, a cost, and a number of vehicles that share the cost (a team
// is M copies of one vehicle coupled only through the cost, Sec. IV.C). The rollout steps
// below are what both backends run for every sample; nothing here is backend-specific.
#pragma once

#include <cstdint>

#include "mppi/hd.hpp"

namespace mppi {

template <class VehicleT, class CostT, int M = 1>
struct Task {
  using Vehicle = VehicleT;
  using Cost = CostT;
  static constexpr int kVehicles = M;
  static constexpr int kVehicleNx = Vehicle::kNx;
  static constexpr int kVehicleNu = Vehicle::kNu;
  static constexpr int kNx = M * Vehicle::kNx;
  static constexpr int kNu = M * Vehicle::kNu;
  static_assert(M >= 1 && M <= 32, "the crash mask holds 32 vehicles");

  struct Params {
    typename Vehicle::Params vehicle;
    typename Cost::Params cost;
  };

  // Advance every vehicle that has not crashed by one control step of `substeps` Euler
  // steps. A crashed vehicle stays where it is for the rest of the horizon (Sec. VI.C).
  MPPI_HD static void advance(const Params& p, float* x, const float* u, float dt, int substeps,
                              std::uint32_t crashed) {
    const float h = dt / static_cast<float>(substeps);
    for (int j = 0; j < M; ++j) {
      if ((crashed >> j) & 1u) continue;
      for (int s = 0; s < substeps; ++s) Vehicle::step(p.vehicle, x + j * kVehicleNx, u + j * kVehicleNu, h);
    }
  }

  // State cost q(x) at time t (seconds from the plan's start), summed over vehicles and
  // vehicle pairs; sets the crash bit of each vehicle found in collision.
  MPPI_HD static float running(const Params& p, const float* x, float t, std::uint32_t* crashed) {
    return running_with(p, x, crashed, [&](int j, const float* xj, bool* hit) {
      return Cost::vehicle(p.cost, j, xj, t, hit);
    });
  }

  // running() with the per-vehicle term computed by vehicle_cost(j, x_j, &hit): a backend
  // may evaluate Cost::vehicle its own way (same terms, same order of the sum).
  template <class VehicleCost>
  MPPI_HD static float running_with(const Params& p, const float* x, std::uint32_t* crashed,
                                    VehicleCost&& vehicle_cost) {
    float q = 0.0f;
    for (int j = 0; j < M; ++j) {
      bool hit = false;
      q += vehicle_cost(j, x + j * kVehicleNx, &hit);
      if (hit) *crashed |= (1u << j);
    }
    for (int i = 0; i < M; ++i) {
      for (int j = i + 1; j < M; ++j) {
        bool hit = false;
        q += Cost::pair(p.cost, x + i * kVehicleNx, x + j * kVehicleNx, &hit);
        if (hit) *crashed |= (1u << i) | (1u << j);
      }
    }
    return q;
  }

  MPPI_HD static float terminal(const Params& p, const float* x) {
    float phi = 0.0f;
    for (int j = 0; j < M; ++j) phi += Cost::terminal(p.cost, j, x + j * kVehicleNx);
    return phi;
  }
};

}  // namespace mppi
