// The identification manoeuvre (tools/sysid, docs/sysid.md): rate doublets on each body axis
// and thrust steps, added to the rate-controlled tasks' commands while the controller holds
// the vehicle where the manoeuvre started, so that a flight log holds the response of the
// autopilot's rate loop and thrust to known inputs. Requested explicitly (the parameter
// `daemon.identify` = 1 on MPPI_PARAMS: `mppid-mavlink-bridge identify`, or
// `tools/sitl run --param T:daemon.identify=1`); 0 stops it. Inside a safe box only: when
// the vehicle is further than box_m from where it started (any axis) or tilted past
// max_tilt_deg, the excitation pauses (the controller flies it back) and resumes inside half
// the box. What goes out is clamped into the task's limits, and the command history (latency
// prediction) and the log see the command as sent.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace mppi::daemon {

struct IdentificationSettings {
  double rate_amplitude = 1.2;   // rad/s, roll and pitch doublets
  double yaw_amplitude = 0.8;    // rad/s, yaw doublets
  double thrust_step = 0.15;     // fraction of the thrust the controller commands
  double pulse_s = 0.25;         // each half of a doublet, and each thrust step
  double gap_s = 0.8;            // between excitations: the controller settles the vehicle
  double box_m = 1.5;            // half-size of the safe box around the starting point
  double max_tilt_deg = 40.0;
  int repeats = 3;               // the sequence (roll, pitch, yaw, thrust), amplitudes x 0.6, 1, 1.4
};

class IdentificationManoeuvre {
 public:
  // limits: the task's u_min / u_max (one vehicle, thrust then body rates).
  IdentificationManoeuvre(const IdentificationSettings& s, std::vector<float> u_min, std::vector<float> u_max);

  // Start (on the next excite()) or stop. Only on a rate-controlled task (the caller checks).
  void request(bool on);
  bool active() const { return on_; }
  // The excitation added to u (thrust, p, q, r; in place, inside the limits) at t_ns, from the
  // state x (13-state rate model: position, velocity, quaternion w x y z, rates). Returns
  // whether u changed. Finishes (inactive) after the last pulse.
  bool excite(const float* x, std::int64_t t_ns, float* u);
  // Seconds of excitation the sequence holds (what the paused time does not count).
  double duration_s() const;
  std::int64_t pauses() const { return pauses_; }

 private:
  struct Pulse {
    int channel;     // 0 thrust (relative), 1..3 body rate
    double value;    // rad/s, or a fraction of the thrust
    double start_s;  // on the manoeuvre's own clock (paused time excluded)
    double end_s;
  };
  bool inside(const float* x, bool resume) const;

  IdentificationSettings s_;
  std::vector<float> u_min_, u_max_;
  std::vector<Pulse> pulses_;
  bool on_ = false, started_ = false, paused_ = false;
  float origin_[3] = {0.0f, 0.0f, 0.0f};
  std::int64_t last_ns_ = 0;
  double clock_s_ = 0.0;
  std::int64_t pauses_ = 0;
};

}  // namespace mppi::daemon
