// Plain, fixed-size messages between a transport and the control loop. The loop never
// sees an LCM type; a transport decodes into these on its own thread and encodes from
// them. Fixed capacities keep the hot path free of allocation.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include "mppi/costs/distance_field.hpp"
#include "mppi/costs/obstacles.hpp"

namespace mppi::transport {

constexpr int kMaxStates = 16 * 32;   // 16 states x 32 vehicles
constexpr int kMaxControls = 4 * 32;  // 4 controls x 32 vehicles
constexpr int kMaxPlanPositions = 4096;  // predicted positions in one plan_t
constexpr int kMaxVehicles = 32;
constexpr int kMaxObstaclesIn = 1024;  // accepted per message; the nearest ObstacleSet::kCapacity (256) are kept

// Command modes, equal to mppi_lcm::command_t::MODE_*.
enum class Mode : std::int8_t { kNormal = 0, kHoldPlan = 1, kFailsafe = 2 };
const char* to_string(Mode m);

struct StateSample {
  std::int64_t utime = 0;         // publisher's publish time, us
  std::int64_t seq = -1;
  std::int64_t sample_utime = 0;  // publisher's sample time, us
  std::int64_t recv_ns = 0;       // our CLOCK_MONOTONIC at receipt
  std::int64_t recv_utime = 0;    // our wall clock at receipt, us (0: unknown); with
                                  // sample_utime on the same host clock it gives the
                                  // state's age on arrival
  std::int8_t model = 0;
  std::int16_t vehicle_count = 0;
  std::int16_t nx = 0;
  std::int32_t n = 0;
  float x[kMaxStates] = {};
};

struct Command {
  std::int64_t utime = 0;
  std::int64_t seq = 0;
  std::int64_t state_seq = -1;
  Mode mode = Mode::kFailsafe;
  std::int8_t kind = 3;  // command_t::KIND_*
  std::int32_t age_us = 0, compute_us = 0, lead_us = 0;  // see command_t
  std::int32_t rollouts = 0;  // the update's rollout count (command_t.rollouts)
  std::int32_t n = 0;
  float u[kMaxControls] = {};
};

struct ReferenceInput {
  std::int64_t seq = -1;
  std::int8_t kind = 0;  // reference_t::KIND_*
  float center[3] = {0.0f, 0.0f, 1.0f};
  float radius = 0.0f, speed = 0.0f, yaw = 0.0f;
  float ramp_s = 0.0f, phase = 0.0f, end_s = 0.0f;
  std::int64_t t0_utime = 0;
  std::int16_t vehicle_count = 0;
  float goals[kMaxVehicles][3] = {};
};

struct ObstacleInput {
  std::int64_t seq = -1;
  std::int64_t utime = 0;
  std::int32_t count = 0;
  Cylinder items[kMaxObstaclesIn];
};

// A local map (local_map_t): the distance field's cells at their fixed capacity (2 MiB:
// allocate once, never on the stack; the inbox holds three, Inbox::Expect::local_map).
struct LocalMapInput {
  std::int64_t utime = 0;  // newest sensor data in it [us, the states' clock]
  std::int64_t seq = -1;
  std::int64_t recv_ns = 0;  // our CLOCK_MONOTONIC at receipt
  DistanceFieldGrid grid;
};

struct ParamUpdate {
  std::int64_t seq = 0;
  char key[64] = {};
  double value = 0.0;
  std::int64_t apply_utime = 0;  // the sample time of the first state it applies at; 0: at once
};

// The answer to one ParamUpdate (mppi_lcm::param_result_t).
struct ParamResult {
  std::int64_t update_seq = 0;
  char key[64] = {};
  double value = 0.0;
  bool applied = false;
  std::int64_t cycle = 0;  // the loop cycle from which it is in effect, or at which it was refused
  char reason[192] = {};   // "" when applied; "field: reason"
};

// The answer to update p: its key and value, applied or refused with `why` (cut to fit).
inline ParamResult answer_to(const ParamUpdate& p, bool applied, const std::string& why, std::int64_t cycle = 0) {
  ParamResult r;
  r.update_seq = p.seq;
  std::memcpy(r.key, p.key, sizeof(r.key));
  r.key[sizeof(r.key) - 1] = '\0';
  r.value = p.value;
  r.applied = applied;
  r.cycle = cycle;
  const std::size_t n = std::min(why.size(), sizeof(r.reason) - 1);
  std::memcpy(r.reason, why.data(), n);
  r.reason[n] = '\0';
  return r;
}

struct ClockTick {
  std::int64_t seq = 0;
  std::int64_t sim_utime = 0;
  std::int64_t step = 0;
};

// Mirrors mppi_lcm::controller_status_t.
struct StatusReport {
  std::int64_t utime = 0;
  std::int64_t seq = 0;
  Mode mode = Mode::kFailsafe;
  const char* backend = "";
  const char* task = "";
  std::int32_t rollouts = 0, horizon = 0;
  std::int32_t rollouts_active = 0;     // the work sized to the computer (<= rollouts)
  std::int64_t work_size_changes = 0;
  float compute_ms_last = 0, compute_ms_min = 0, compute_ms_mean = 0, compute_ms_max = 0, compute_ms_p99 = 0;
  float period_ms_min = 0, period_ms_mean = 0, period_ms_max = 0, period_ms_p99 = 0;
  float jitter_ms_p99 = 0;
  std::int64_t cycles = 0, misses = 0, late_start_misses = 0, consecutive_misses = 0;
  float state_to_command_ms_p99 = 0, state_age_ms_p99 = 0, latency_expected_ms = 0, lead_ms_mean = 0,
        lead_ms_p99 = 0;
  float disturbance_accel[3] = {0, 0, 0};
  float model_mass = 0.0f;  // kg, the mass the model flies with (the estimate, when on)
  float actuation_delay_ms = 0.0f;  // the delay predicted over (the estimate, when on)
  std::int64_t partial_updates = 0, anytime_holds = 0;
  float ess = 0, min_cost = 0;
  std::int64_t rejected_nan = 0, rejected_stale = 0, rejected_out_of_order = 0, rejected_undecodable = 0,
               rejected_params = 0, rejected_future = 0;
  // The local map (controller_status_t): taken, rejected (any reason), the age of the one
  // flown [ms] (-1: none), cycles flown with one older than daemon.map.timeout_ms.
  std::int64_t maps_accepted = 0, maps_rejected = 0, map_stale_cycles = 0;
  float map_age_ms = -1.0f;
  bool healthy = false;
};

// A view of the plan for display; the pointed-to data lives in the loop.
struct PlanView {
  std::int64_t utime = 0;
  std::int64_t seq = 0;
  std::int64_t state_seq = -1;
  std::int32_t horizon = 0;
  std::int32_t nu = 0;
  float dt = 0;
  const float* u = nullptr;  // horizon * nu, step-major
  std::int32_t npos = 0;
  const float* pos = nullptr;  // npos x 3, vehicle-major predicted positions
};

// A view of a display sample of one cycle's rollouts (core's RolloutFan); the pointed-to
// data lives in the loop.
struct RolloutsView {
  std::int64_t utime = 0;
  std::int64_t seq = 0;
  std::int64_t state_seq = -1;
  std::int64_t cycle = 0;
  std::int32_t total = 0, vehicles = 0, steps = 0;
  float dt = 0, lambda = 0;
  std::int32_t count = 0, top = 0;
  const int* index = nullptr;             // count each
  const float* cost = nullptr;
  const float* weight = nullptr;
  const unsigned char* crashed = nullptr;
  const float* xyz = nullptr;             // count x vehicles x steps x 3
};

}  // namespace mppi::transport
