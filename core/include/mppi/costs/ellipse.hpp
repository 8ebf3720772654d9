// Race car on the elliptical track (Sec. VI.B): q = 100 d^2 + (vx - 7)^2 with
// d = (x / 13)^2 + (y / 6)^2 - 1.
//
// The track term may pull to another ellipse of the family, d = line (0: the paper's); a
// line near the outer edge is longer and its ends are wider, so a car on it is faster.
//
// Racing-line term, off by default: the centre line's ends have a radius of 6^2/13 = 2.8 m
// (3.9 m/s at mu g), and the track (|d| <= 0.6, 4 to 8 m wide) holds a far rounder line.
// A stadium (two half circles of radius line_radius about (+-line_half, 0), joined by
// straights) fits it with a radius near 7 m; its term is
//   w_line * (rho - line_radius)^2,  rho = |(max(0, |x| - line_half), y)|
// (rho is the distance to the stadium's spine, so rho - line_radius is the distance to it).
//
// Track-limit terms, off by default (the paper's cost), on in the task file: the paper's
// cost knows nothing of where the track ends, so a car asked to go faster than the
// friction limit on the line allows simply leaves it. A rollout with |d| > track_limit
// counts as crashed (it stops and pays w_crash at every remaining step, as the quadrotor's
// crashes do), and
//   w_edge * max(0, |d| - edge)^2
// pushes it back before that.
//
// Drift term, off by default: the paper's model integrates the lateral velocity vy (which
// moves the car) apart from the sideslip beta (which its tires see), so a sideways slide
// costs the tires nothing. Without a cost on it, MPPI asked for speed finds "laps" slid
// sideways at vy = -9 m/s with vx = 3 (a 70 degree crab, 8 m/s over the ground; seen in
// tuning). This term keeps the ground velocity's slip under a drift angle:
//   w_drift * max(0, |vy| - drift * |vx|)^2      (drift = tan of the angle)
#pragma once

#include "mppi/hd.hpp"
#include "mppi/models/racecar.hpp"

namespace mppi {

struct EllipseCost {
  struct Params {
    float semi_x = 13.0f;  // m
    float semi_y = 6.0f;   // m
    float w_track = 100.0f;
    float line = 0.0f;          // the d the track term pulls to (0: the ellipse itself)
    float target_speed = 7.0f;  // m/s
    float w_speed = 1.0f;
    float w_slip = 0.0f;        // optional sideslip penalty
    float track_limit = 1e9f;   // |d| beyond this is a crash (off the track)
    float w_crash = 0.0f;
    float edge = 1e9f;          // |d| where the soft edge term starts
    float w_edge = 0.0f;
    float w_line = 0.0f;        // racing-line (stadium) term
    float line_radius = 7.0f;   // m
    float line_half = 2.5f;     // m, half the length of the stadium's straights
    float drift = 1e9f;         // tan of the slip angle atan(vy / vx) where the drift term starts
    float w_drift = 0.0f;
  };
  template <class V>
  MPPI_HD static V vehicle(const Params& p, int, const V* x, float, mask_t<V>* crash) {
    const V d = fsq(x[Racecar::X] / p.semi_x) + fsq(x[Racecar::Y] / p.semi_y) - 1.0f;
    const V ad = fabs_(d);
    const V out = fmax_(ad - p.edge, V(0.0f));
    const V ex = fmax_(fabs_(x[Racecar::X]) - p.line_half, V(0.0f));
    const V off_line = fsqrt(ex * ex + fsq(x[Racecar::Y])) - p.line_radius;
    const V slide = fmax_(fabs_(x[Racecar::VY]) - p.drift * fabs_(x[Racecar::VX]), V(0.0f));
    const V q = p.w_track * fsq(d - p.line) + p.w_speed * fsq(x[Racecar::VX] - p.target_speed) +
                p.w_slip * fsq(x[Racecar::BETA]) + p.w_edge * out * out + p.w_drift * slide * slide + p.w_line * off_line * off_line;
    const mask_t<V> off = ad > p.track_limit;
    *crash = mask_or(*crash, off);
    return select(off, q + p.w_crash, q);
  }
  template <class V>
  MPPI_HD static V pair(const Params&, const V*, const V*, mask_t<V>*) { return V(0.0f); }
  template <class V>
  MPPI_HD static V terminal(const Params&, int, const V*) { return V(0.0f); }
};

}  // namespace mppi
