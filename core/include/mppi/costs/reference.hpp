// Time-parameterised references for tracking: hold a point, a circle, or a figure-eight
// (lemniscate of Gerono) in a horizontal plane, at a given speed along the path.
#pragma once

#include "mppi/hd.hpp"

namespace mppi {

struct Reference {
  enum Kind : int { kHold = 0, kCircle = 1, kFigureEight = 2 };
  int kind = kHold;
  float center[3] = {0.0f, 0.0f, 1.0f};
  float radius = 0.0f;  // m
  float speed = 0.0f;   // m/s along the circle (nominal for the figure-eight)
  float yaw = 0.0f;     // rad, heading to hold

  // Position and velocity of the reference at time t (s).
  MPPI_HD void eval(float t, float* pos, float* vel) const {
    pos[0] = center[0];
    pos[1] = center[1];
    pos[2] = center[2];
    vel[0] = vel[1] = vel[2] = 0.0f;
    if (kind == kHold || radius <= 0.0f) return;
    const float w = speed / radius;
    const float a = w * t;
    const float s = fsin(a), c = fcos(a);
    if (kind == kCircle) {
      pos[0] += radius * c;
      pos[1] += radius * s;
      vel[0] = -radius * w * s;
      vel[1] = radius * w * c;
    } else {
      // x = R sin(a), y = R sin(a) cos(a) = R/2 sin(2a)
      const float c2 = fcos(2.0f * a);
      pos[0] += radius * s;
      pos[1] += 0.5f * radius * fsin(2.0f * a);
      vel[0] = radius * w * c;
      vel[1] = radius * w * c2;
    }
  }
};

}  // namespace mppi
