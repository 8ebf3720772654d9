"""core's Reference (core/include/mppi/costs/reference.hpp) in Python, vectorised over time:
what mppid tracks, so the mission tool can show progress, the harness can score against it,
and ArduCopter's own position controller (the baseline) can be sent the same path.

A reference is a dict with the fields of reference_t: kind (hold, circle, figure_eight,
line), center [x, y, z], radius, speed, yaw, ramp (s), phase (rad), end_s (s: a curve comes
to rest then; 0 or absent: it runs on) and, for a line, end [x, y, z].
"""
from __future__ import annotations

import numpy as np

KINDS = ("hold", "circle", "figure_eight", "line")


def along(t, v, ramp, t_end=0.0):
    """How far along (distance or angle) at rate v by times t, its rate and acceleration:
    from rest at t = 0 up a linear ramp, cruising, down a mirrored ramp to rest at t_end (0:
    never). Without a ramp: v t at any t, until t_end."""
    t = np.asarray(t, float)
    if t_end > 0:
        t = np.minimum(t, t_end)
    stopped = (t >= t_end) if t_end > 0 else np.zeros(t.shape, bool)
    if ramp <= 0:
        return v * t, np.where(stopped, 0.0, v), np.zeros_like(t)
    down = (t > t_end - ramp) if t_end > 0 else np.zeros(t.shape, bool)
    up = (t > 0) & (t < ramp) & ~down
    r = t_end - t
    s = np.where(t <= 0, 0.0, np.where(down, v * (t_end - ramp) - 0.5 * v * r * r / ramp,
                                       np.where(up, 0.5 * v * t * t / ramp, v * (t - 0.5 * ramp))))
    ds = np.where(t <= 0, 0.0, np.where(down, v * r / ramp, np.where(up, v * t / ramp, v)))
    dds = np.where(t <= 0, 0.0, np.where(down & ~stopped, -v / ramp, np.where(up, v / ramp, 0.0)))
    return s, ds, dds


def evaluate(ref: dict, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration (len(t), 3) of the reference at times t [s]."""
    t = np.atleast_1d(np.asarray(t, float))
    c = np.asarray(ref.get("center", [0.0, 0.0, 1.0]), float)
    pos = np.tile(c, (len(t), 1))
    vel = np.zeros_like(pos)
    acc = np.zeros_like(pos)
    kind = ref.get("kind", "hold")
    r, v = float(ref.get("radius", 0.0)), float(ref.get("speed", 0.0))
    ramp, phase = float(ref.get("ramp", 0.0)), float(ref.get("phase", 0.0))
    if kind == "line":
        return _line(ref, t, pos, vel, acc, v, ramp)
    if kind not in ("circle", "figure_eight") or r <= 0:
        return pos, vel, acc
    a, da, dda = along(t, v / r, ramp, float(ref.get("end_s", 0.0)))
    a = a + phase
    s, co = np.sin(a), np.cos(a)
    if kind == "circle":
        pos[:, 0] += r * co
        pos[:, 1] += r * s
        vel[:, 0], vel[:, 1] = -r * da * s, r * da * co
        acc[:, 0] = -r * (dda * s + da * da * co)
        acc[:, 1] = r * (dda * co - da * da * s)
    else:
        s2, c2 = np.sin(2 * a), np.cos(2 * a)
        pos[:, 0] += r * s
        pos[:, 1] += 0.5 * r * s2
        vel[:, 0], vel[:, 1] = r * da * co, r * da * c2
        acc[:, 0] = r * (dda * co - da * da * s)
        acc[:, 1] = r * (dda * c2 - 2 * da * da * s2)
    return pos, vel, acc


def line_speed(length: float, v: float, ramp: float) -> float:
    """The speed a path of this length cruises at: a short one peaks at length / ramp."""
    return length / ramp if ramp > 0 and length < v * ramp else v


def _line(ref, t, pos, vel, acc, v, ramp):
    d = np.asarray(ref["end"], float) - pos[0]
    length = float(np.linalg.norm(d))
    if length <= 0 or v <= 0:
        return pos, vel, acc
    u = d / length
    v = line_speed(length, v, ramp)
    s, ds, dds = along(t, v, ramp, length / v + ramp)
    rest = t <= 0  # at the start until t0
    s, ds, dds = np.where(rest, 0.0, s), np.where(rest, 0.0, ds), np.where(rest, 0.0, dds)
    return pos + np.outer(s, u), np.outer(ds, u), np.outer(dds, u)


def duration(ref: dict, laps: float = 1.0) -> float:
    """Seconds from t0 until the path comes to rest: a line's end, or `laps` laps of a curve
    (a figure-eight's lap is one period of its parameter), the ramps up and down included."""
    kind, v, ramp = ref.get("kind", "hold"), float(ref.get("speed", 0.0)), float(ref.get("ramp", 0.0))
    if kind == "line":
        length = float(np.linalg.norm(np.asarray(ref["end"], float) - np.asarray(ref["center"], float)))
        v = line_speed(length, v, ramp)
        return length / v + ramp if v > 0 else 0.0
    if kind in ("circle", "figure_eight") and v > 0:
        return laps * 2 * np.pi * float(ref["radius"]) / v + ramp
    return 0.0
