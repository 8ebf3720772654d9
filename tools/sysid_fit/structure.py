"""Does the rate model's structure express the autopilot? The first-order fit (fit.py) is
compared with a second-order response per axis,

    w'' = wn^2 (K u(t - d) - w) - 2 zeta wn w'

(a rate loop through motor lag, or an input-shaped one), fitted the same way: from each
measured rate, 0.1 s ahead (w' at the start from the difference of the two states before
it). When the second-order fit leaves markedly less error, the first-order model is the
limit, not its parameters (docs/sysid.md reports what mppid-sim's rigid-body plant gives).
A diagnostic: mppid's model stays first-order.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q
from scipy.optimize import least_squares

from .fit import GRID_H, Grid
from .logs import FlightData

STEPS = 5  # states ahead


@dataclass
class SecondOrderFit:
    gain: float
    wn: float      # rad/s
    zeta: float
    delay: float
    rmse: float    # rad/s, over 1..STEPS states ahead


def _predict(grid: Grid, data: FlightData, axis: int, starts: np.ndarray, gain, wn, zeta, delay) -> np.ndarray:
    u = grid.input(Q.RATE_X + axis, delay)
    w = data.x[starts, Q.WX + axis].copy()
    wd = (data.x[starts, Q.WX + axis] - data.x[starts - 1, Q.WX + axis]) / (data.t[starts] - data.t[starts - 1])
    t = data.t[starts].copy()
    out = []
    for n in range(1, STEPS + 1):
        end = data.t[starts + n]
        while np.any(t < end - 1e-9):
            h = np.minimum(GRID_H, np.maximum(end - t, 0.0))
            i, _ = grid.at(t)
            acc = wn * wn * (gain * u[i] - w) - 2.0 * zeta * wn * wd
            wd = wd + h * acc
            w = w + h * wd
            t = t + h
        out.append(w.copy())
    return np.stack(out, axis=1)


def fit_second_order(data: FlightData, axis: int, grid: Grid | None = None, stride: int = 2) -> SecondOrderFit:
    grid = grid or Grid(data)
    starts = np.arange(2, len(data.t) - STEPS - 1, stride)
    truth = np.stack([data.x[starts + n, Q.WX + axis] for n in range(1, STEPS + 1)], axis=1)
    best = None
    for delay in np.arange(0.0, 0.05 + 1e-9, 0.005):
        r = least_squares(lambda p: (_predict(grid, data, axis, starts, p[0], p[1], p[2], delay) - truth).ravel(),
                          [1.0, 25.0, 0.7], bounds=([0.2, 2.0, 0.05], [5.0, 300.0, 5.0]), x_scale=[1.0, 20.0, 1.0])
        rmse = float(np.sqrt(np.mean(r.fun ** 2)))
        if best is None or rmse < best.rmse:
            best = SecondOrderFit(float(r.x[0]), float(r.x[1]), float(r.x[2]), float(delay), rmse)
    return best
