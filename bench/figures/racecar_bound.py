#!/usr/bin/env python3
"""Upper bounds on the race car's mean speed for candidate lines (config/tasks/racecar_ellipse.yaml).

A point mass on a fixed line with at most mu g across the path and the drive's 80 N / 21 kg
along it, both at once on an ellipse of those semi-axes (the drive brakes too: the front
wheel has no brake in the model), starting at 3 m/s, over the scenario's 20 s
(the harness's mean_speed is distance / time over the flight). The usual forward-backward
pass: v(s) <= sqrt(mu g / kappa), then forward with the acceleration the friction circle
leaves, then backward for braking. It ignores the bicycle's yaw and the paper's model's
decoupled lateral velocity, so it bounds a car that drives the line, not the simulator.

    .venv/bin/python bench/figures/racecar_bound.py
"""
import numpy as np

MU_G = 0.55 * 9.81   # m/s^2
A_DRIVE = 80.0 / 21.0  # m/s^2, u_max of the drive / the car's mass
V0, DURATION = 3.0, 20.0


def mean_speed(x, y, laps=4):
    """Distance over DURATION / DURATION on the closed line (x, y), started at its first point."""
    X, Y = np.tile(x, laps), np.tile(y, laps)
    ds = np.hypot(np.diff(X), np.diff(Y))
    dx, dy = np.gradient(X), np.gradient(Y)
    ddx, ddy = np.gradient(dx), np.gradient(dy)
    kappa = np.abs(dx * ddy - dy * ddx) / np.maximum((dx * dx + dy * dy) ** 1.5, 1e-12)
    v = np.minimum(np.sqrt(MU_G / np.maximum(kappa, 1e-6)), 30.0)
    v[0] = min(V0, v[0])

    def along(vi, ki):  # the friction ellipse: the drive's A_DRIVE along, mu g across
        return A_DRIVE * np.sqrt(max(0.0, 1.0 - (vi * vi * ki / MU_G) ** 2))

    for i in range(len(ds)):
        v[i + 1] = min(v[i + 1], np.sqrt(v[i] ** 2 + 2.0 * along(v[i], kappa[i]) * ds[i]))
    for i in range(len(ds) - 1, -1, -1):
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2.0 * along(v[i + 1], kappa[i + 1]) * ds[i]))
    t = np.concatenate([[0.0], np.cumsum(ds / np.maximum(0.5 * (v[1:] + v[:-1]), 1e-3))])
    s = np.concatenate([[0.0], np.cumsum(ds)])
    lap_time = t[len(x)]
    return s[np.searchsorted(t, DURATION)] / DURATION, lap_time


def ellipse_line(c, n=4000):
    """The ellipse d = c of the track's family, from (0, -6 sqrt(1 + c)) counter-clockwise."""
    th = np.linspace(-np.pi / 2, 1.5 * np.pi, n, endpoint=False)
    f = np.sqrt(1.0 + c)
    return 13.0 * f * np.cos(th), 6.0 * f * np.sin(th)


def stadium_line(half, radius, n=4000):
    """Half circles of `radius` about (+-half, 0) joined by straights, from (0, -radius)."""
    length = 2 * np.pi * radius + 4 * half
    pts = []
    for s in np.linspace(0.0, length, n, endpoint=False):
        if s < half:
            pts.append((s, -radius))
        elif s < half + np.pi * radius:
            a = (s - half) / radius - np.pi / 2
            pts.append((half + radius * np.cos(a), radius * np.sin(a)))
        elif s < 3 * half + np.pi * radius:
            pts.append((half - (s - half - np.pi * radius), radius))
        elif s < 3 * half + 2 * np.pi * radius:
            a = (s - 3 * half - np.pi * radius) / radius + np.pi / 2
            pts.append((-half + radius * np.cos(a), radius * np.sin(a)))
        else:
            pts.append((-half + (s - 3 * half - 2 * np.pi * radius), -radius))
    p = np.array(pts)
    return p[:, 0], p[:, 1]


def max_d(x, y):
    d = (x / 13.0) ** 2 + (y / 6.0) ** 2 - 1.0
    return float(np.abs(d).max())


def main():
    print("line                        max|d|  mean speed over 20 s  lap time")
    for c in (0.0, 0.2, 0.3, 0.4, 0.45, 0.48, 0.5, 0.52):
        x, y = ellipse_line(c)
        v, lap = mean_speed(x, y)
        print(f"ellipse d = {c:<4}             {max_d(x, y):5.2f}  {v:6.2f} m/s          {lap:5.2f} s")
    for half, radius in ((3.0, 7.05), (2.0, 7.25), (5.0, 6.7)):
        x, y = stadium_line(half, radius)
        v, lap = mean_speed(x, y)
        print(f"stadium R {radius:4.2f} m, half {half:3.1f} m  {max_d(x, y):5.2f}  {v:6.2f} m/s          {lap:5.2f} s")


if __name__ == "__main__":
    main()
