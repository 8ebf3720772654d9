// Time-parameterised references for tracking: hold a point, a circle, a figure-eight
// (lemniscate of Gerono) in a horizontal plane, or a straight line, at a given speed along
// the path. A reference can start at rest: its speed rises linearly from 0 over `ramp`
// seconds (and a line also slows to a stop at its end), so a vehicle hovering at the start
// point is not asked for full speed at once; `phase` places t = 0 on a curve (a circle's
// start angle), so the path can begin where the vehicle is.
#pragma once

#include "mppi/hd.hpp"

namespace mppi {

struct Reference {
  enum Kind : int { kHold = 0, kCircle = 1, kFigureEight = 2, kLine = 3 };
  int kind = kHold;
  float center[3] = {0.0f, 0.0f, 1.0f};  // hold point, curve centre, or a line's start
  float radius = 0.0f;  // m
  float speed = 0.0f;   // m/s along the circle and the line (nominal for the figure-eight)
  float yaw = 0.0f;     // rad, heading to hold
  float ramp = 0.0f;    // s: the speed rises from 0 over this long, and falls to 0 over the end's
  float phase = 0.0f;   // rad: the curve's parameter at t = 0 (circle: the angle from +x)
  float end_s = 0.0f;   // s: a curve comes to rest here (0: it runs on); a line at its end
  float end[3] = {0.0f, 0.0f, 1.0f};  // kLine: where the line ends

  // Position and velocity of the reference at time t (s).
  MPPI_HD void eval(float t, float* pos, float* vel) const {
    pos[0] = center[0];
    pos[1] = center[1];
    pos[2] = center[2];
    vel[0] = vel[1] = vel[2] = 0.0f;
    if (kind == kLine) return eval_line(t, pos, vel);
    if (kind == kHold || radius <= 0.0f) return;
    float a, da;  // the curve's parameter and its rate
    along(t, speed / radius, end_s, &a, &da);
    a += phase;
    const float s = fsin(a), c = fcos(a);
    if (kind == kCircle) {
      pos[0] += radius * c;
      pos[1] += radius * s;
      vel[0] = -radius * da * s;
      vel[1] = radius * da * c;
    } else {
      // x = R sin(a), y = R sin(a) cos(a) = R/2 sin(2a)
      const float c2 = fcos(2.0f * a);
      pos[0] += radius * s;
      pos[1] += 0.5f * radius * fsin(2.0f * a);
      vel[0] = radius * da * c;
      vel[1] = radius * da * c2;
    }
  }

  // How far along (distance or angle) at rate v by time t, and the rate: from rest at t = 0
  // up a linear ramp of `ramp` s, cruising, then down a mirrored ramp to rest at t_end (0:
  // never). Without a ramp: v t at any t (the path runs before its epoch too, as it always
  // has) until t_end.
  MPPI_HD void along(float t, float v, float t_end, float* s, float* ds) const {
    if (t_end > 0.0f && t >= t_end) t = t_end;
    if (ramp <= 0.0f) {
      *s = v * t;
      *ds = (t_end > 0.0f && t >= t_end) ? 0.0f : v;
    } else if (t <= 0.0f) {
      *s = *ds = 0.0f;
    } else if (t_end > 0.0f && t > t_end - ramp) {
      const float r = t_end - t;  // the ramp down mirrors the ramp up
      *ds = v * r / ramp;
      *s = v * (t_end - ramp) - 0.5f * *ds * r;
    } else if (t < ramp) {
      *ds = v * t / ramp;
      *s = 0.5f * *ds * t;
    } else {
      *ds = v;
      *s = v * (t - 0.5f * ramp);
    }
  }

  // center -> end at `speed`, ramping up and down over `ramp` s (a line too short for full
  // speed peaks lower, at length / ramp), then holding at the end.
  MPPI_HD void eval_line(float t, float* pos, float* vel) const {
    const float d[3] = {end[0] - center[0], end[1] - center[1], end[2] - center[2]};
    const float len = fsqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (len <= 0.0f || speed <= 0.0f || t <= 0.0f) return;  // at rest at the start until t0
    const float v = (ramp > 0.0f && len < speed * ramp) ? len / ramp : speed;
    float s, ds;
    along(t, v, len / v + ramp, &s, &ds);  // trapezoid: ramp/2 lost at each end
    for (int i = 0; i < 3; ++i) {
      pos[i] += d[i] / len * s;
      vel[i] = d[i] / len * ds;
    }
  }
};

}  // namespace mppi
