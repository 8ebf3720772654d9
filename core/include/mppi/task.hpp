// A task is a vehicle model, a cost, and a number of vehicles that share the cost (a team
// is M copies of one vehicle coupled only through the cost, Sec. IV.C). The rollout steps
// below are what both backends run for every sample; nothing here is backend-specific.
// They are templates on the number type V (hd.hpp) and the crash state C: a bit mask of
// crashed vehicles for one sample (std::uint32_t), or per vehicle a mask over a SIMD batch
// of samples (mppi/simd/lanes.hpp), with the two functions below.
#pragma once

#include <cstdint>
#include <type_traits>

#include "mppi/hd.hpp"

namespace mppi {

// Vehicle j of one sample has crashed.
MPPI_HD bool vehicle_crashed(std::uint32_t crashed, int j) { return ((crashed >> j) & 1u) != 0u; }
// Marks vehicle j crashed where `hit`.
MPPI_HD void mark_crashed(std::uint32_t* crashed, int j, bool hit) {
  if (hit) *crashed |= (1u << j);
}

template <class Cost, class = void>
struct CostUsesPath : std::false_type {};
template <class Cost>
struct CostUsesPath<Cost, std::enable_if_t<Cost::kUsesPath>> : std::true_type {};

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
  template <class V, class C>
  MPPI_HD static void advance(const Params& p, V* x, const V* u, float dt, int substeps, const C& crashed) {
    const float h = dt / static_cast<float>(substeps);
    for (int j = 0; j < M; ++j) {
      const auto frozen = vehicle_crashed(crashed, j);
      if (all_of(frozen)) continue;
      V* xj = x + j * kVehicleNx;
      if (any_of(frozen)) {  // some samples of a batch: step all, keep the crashed ones
        V keep[kVehicleNx];
        for (int n = 0; n < kVehicleNx; ++n) keep[n] = xj[n];
        for (int s = 0; s < substeps; ++s) Vehicle::step(p.vehicle, xj, u + j * kVehicleNu, h);
        for (int n = 0; n < kVehicleNx; ++n) xj[n] = select(frozen, keep[n], xj[n]);
      } else {
        for (int s = 0; s < substeps; ++s) Vehicle::step(p.vehicle, xj, u + j * kVehicleNu, h);
      }
    }
  }

  // State cost q(x) at time t (seconds from the plan's start), summed over vehicles and
  // vehicle pairs; sets the crash bit of each vehicle found in collision.
  template <class V, class C>
  MPPI_HD static V running(const Params& p, const V* x, float t, C* crashed) {
    return running_with(p, x, crashed, [&](int j, const V* xj, mask_t<V>* hit) {
      return Cost::vehicle(p.cost, j, xj, t, hit);
    });
  }

  // running() with the per-vehicle term computed by vehicle_cost(j, x_j, &hit): a backend
  // may evaluate Cost::vehicle its own way (same terms, same order of the sum). hit comes in
  // as the vehicle's crash state of the earlier steps and goes out or-ed with this step's.
  template <class V, class C, class VehicleCost>
  MPPI_HD static V running_with(const Params& p, const V* x, C* crashed, VehicleCost&& vehicle_cost) {
    V q = 0.0f;
    for (int j = 0; j < M; ++j) {
      // In: the vehicle crashed at an earlier step (a cost may keep charging for it); out:
      // crashed now or before.
      mask_t<V> hit = vehicle_crashed(*crashed, j);
      q += vehicle_cost(j, x + j * kVehicleNx, &hit);
      mark_crashed(crashed, j, hit);
    }
    for (int i = 0; i < M; ++i) {
      for (int j = i + 1; j < M; ++j) {
        mask_t<V> hit = false;
        q += Cost::pair(p.cost, x + i * kVehicleNx, x + j * kVehicleNx, &hit);
        mark_crashed(crashed, i, hit);
        mark_crashed(crashed, j, hit);
      }
    }
    return q;
  }

  template <class V>
  MPPI_HD static V terminal(const Params& p, const V* x) {
    V phi = 0.0f;
    for (int j = 0; j < M; ++j) phi += Cost::terminal(p.cost, j, x + j * kVehicleNx);
    return phi;
  }

  // Once per cycle, before the rollouts (host): lets the cost prepare for this cycle from
  // the plan's noise-free path (the forest cost indexes its obstacles near it). `path_xy`
  // holds (horizon + 1) * M xy pairs of scratch.
  static constexpr bool kUsesPath = CostUsesPath<Cost>::value;
  static void prepare(Params& p, const float* x0, const float* plan, int horizon, float dt, int substeps,
                      float* path_xy) {
    if constexpr (kUsesPath) {
      plan_path(p, x0, plan, horizon, dt, substeps, path_xy);
      Cost::prepare(p.cost, path_xy, (horizon + 1) * M, static_cast<float>(horizon) * dt);
    } else {
      (void)p, (void)x0, (void)plan, (void)horizon, (void)dt, (void)substeps, (void)path_xy;
    }
  }

  // The plan's noise-free path from x0: each vehicle's xy at steps 0..horizon, step-major
  // ((horizon + 1) * M pairs), with the rollouts' own Euler steps.
  static void plan_path(const Params& p, const float* x0, const float* plan, int horizon, float dt, int substeps,
                        float* path_xy) {
    float x[kNx];
    for (int n = 0; n < kNx; ++n) x[n] = x0[n];
    auto put = [&](int i) {
      for (int j = 0; j < M; ++j) {
        float pos[3];
        Vehicle::position(x + j * kVehicleNx, pos);
        path_xy[2 * (i * M + j)] = pos[0];
        path_xy[2 * (i * M + j) + 1] = pos[1];
      }
    };
    put(0);
    for (int i = 0; i < horizon; ++i) {
      advance(p, x, plan + i * kNu, dt, substeps, std::uint32_t{0});
      put(i + 1);
    }
  }
};

}  // namespace mppi
