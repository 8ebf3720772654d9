"""The fits (docs/sysid.md).

Body rates, per axis: w' = (K u(t - d) - w) / tau. The command is piecewise constant, so on a
1 ms grid the forced response y' = (u(t - d) - y) / tau is one recursive filter (exact for a
held input), and from a measured rate w_k at t_k the model predicts

    w(t_k + D) = e^(-D/tau) w_k + K (y(t_k + D) - e^(-D/tau) y(t_k))

exactly: linear in K (least squares in closed form), one-dimensional in tau (a bounded
scalar minimisation), and d on a grid (1 ms, then 0.1 ms around the best). The error is
summed over D = 1..5 state periods: an output error over 0.1 s, so noise on w_k, which biases
a one-step equation error towards a faster response, weighs little.

Thrust and drag: the velocity change between two states is

    dv = (1/m) int T(t - d) b dt - g z dt - (drag/m) int v dt + a dt

linear in (1/m, drag/m, a_x, a_y), a a constant horizontal external acceleration (wind, a
trim error), on the same delay grid. A vertical one is not fitted: at hover it cannot be
told from a thrust-map error, which is what 1/m is for (the thrust steps of the manoeuvre
pin the slope; with a_z free, a flight of the manoeuvre gave the mass 1.3 % off). 1/m is what
a newton of command buys: the mass the model must fly with, or, through the bridge, the
hover throttle (docs/sysid.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from .logs import FlightData
from .model import command_index

GRID_H = 0.001      # s, the fine grid of the input
MIN_EXCITATION = 0.05   # rad/s: the commanded rate's standard deviation below which an axis keeps the prior
HORIZONS = (1, 2, 3, 4, 5)
DELAY_MAX = 0.1     # s


@dataclass
class AxisFit:
    gain: float
    tau: float
    delay: float
    rmse: float      # rad/s, over the horizons fitted
    samples: int


@dataclass
class ThrustFit:
    mass: float      # kg per (N of command per m/s^2): 1 / (what a newton buys)
    drag: float      # N s/m at that mass
    accel: list[float]  # m/s^2, constant external acceleration (x, y; z is 0)
    delay: float
    rmse: float      # m/s^2
    samples: int


class Grid:
    """The commands as the plant sees them, delayed: their exact running integral, and their
    average over each cell of a fine grid (a command switching inside a cell counts for the
    part of the cell it acts in, so the fitted delay is not rounded to the grid)."""

    def __init__(self, data: FlightData):
        self.t0 = min(data.t[0], data.tc[0]) - 0.2
        self.n = int(np.ceil((data.t[-1] - self.t0) / GRID_H)) + 2
        self.t = self.t0 + GRID_H * np.arange(self.n)
        self.data = data

    def integral(self, channel: int, delay: float, t: np.ndarray) -> np.ndarray:
        """int u(s - delay) ds from the first command's switch to t (held before it)."""
        switch = self.data.tc + delay
        u = self.data.u[:, channel]
        before = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(switch))])
        k = np.clip(np.searchsorted(switch, t, side="right") - 1, 0, len(switch) - 1)
        return before[k] + u[k] * (t - switch[k])

    def input(self, channel: int, delay: float) -> np.ndarray:
        """The average of u(t - delay) over each cell [t_n, t_n + h)."""
        f = self.integral(channel, delay, np.append(self.t, self.t[-1] + GRID_H))
        return np.diff(f) / GRID_H

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid index at or before t, and the time past it."""
        i = np.clip(((t - self.t0) / GRID_H).astype(np.int64), 0, self.n - 2)
        return i, t - self.t[i]


def _rate_cost(grid: Grid, data: FlightData, axis: int, delay: float, tau: float, pairs, gain: float | None = None,
               u: np.ndarray | None = None):
    """The axis's mean squared error at (delay, tau) and its least-squares gain (or `gain`'s
    error); `u`: grid.input at this delay, when the caller already has it (a search over tau)."""
    if u is None:
        u = grid.input(Q.RATE_X + axis, delay)
    a = np.exp(-GRID_H / tau)
    y = lfilter([0.0, 1.0 - a], [1.0, -a], u)
    i, f = grid.at(data.t)
    yt = np.exp(-f / tau) * y[i] + (1.0 - np.exp(-f / tau)) * u[i]   # exact between grid points
    w = data.x[:, Q.WX + axis]
    num = den = 0.0
    parts = []
    for k0, k1 in pairs:
        decay = np.exp(-(data.t[k1] - data.t[k0]) / tau)
        z = yt[k1] - decay * yt[k0]
        r = w[k1] - decay * w[k0]
        parts.append((z, r))
        num += float(z @ r)
        den += float(z @ z)
    if gain is None:
        gain = num / den if den > 0 else 1.0
    sse = sum(float(np.sum((r - gain * z) ** 2)) for z, r in parts)
    n = sum(len(z) for z, _ in parts)
    return sse / max(n, 1), gain


def _pairs(data: FlightData):
    """(start, end) index pairs D states apart, for each horizon D, whose gap is regular."""
    out = []
    dt = np.diff(data.t)
    period = float(np.median(dt))
    for d in HORIZONS:
        k0 = np.arange(len(data.t) - d)
        k1 = k0 + d
        ok = np.abs((data.t[k1] - data.t[k0]) - d * period) < 0.5 * period
        out.append((k0[ok], k1[ok]))
    return out


def fit_rate_axis(data: FlightData, axis: int, grid: Grid | None = None, delay: float | None = None) -> AxisFit:
    grid = grid or Grid(data)
    pairs = _pairs(data)

    def best_tau(d):
        u = grid.input(Q.RATE_X + axis, d)  # the same for every tau tried
        r = minimize_scalar(lambda lt: _rate_cost(grid, data, axis, d, float(np.exp(lt)), pairs, u=u)[0],
                            bounds=(np.log(0.005), np.log(2.0)), method="bounded", options={"xatol": 1e-4})
        return float(np.exp(r.x)), float(r.fun)

    if delay is None:
        coarse = [(best_tau(d)[1], d) for d in np.arange(0.0, DELAY_MAX + 1e-9, 0.002)]
        d0 = min(coarse)[1]
        fine = [(best_tau(d)[1], d) for d in np.arange(max(0.0, d0 - 0.002), d0 + 0.002 + 1e-9, 0.0002)]
        delay = float(min(fine)[1])
    tau, mse = best_tau(delay)
    _, gain = _rate_cost(grid, data, axis, delay, tau, pairs)
    return AxisFit(gain, tau, delay, float(np.sqrt(mse)), int(sum(len(k) for k, _ in pairs)))


def excited_axes(data: FlightData, threshold: float = MIN_EXCITATION) -> list[int]:
    """The body axes whose commanded rate varies (standard deviation at least `threshold`)."""
    return [a for a in range(3) if float(np.std(data.u[:, Q.RATE_X + a])) >= threshold]


def fixed_axis(data: FlightData, axis: int, gain: float, tau: float, delay: float, grid: Grid | None = None) -> AxisFit:
    """An axis held at the given gain and tau (the prior's), with its error at the delay."""
    pairs = _pairs(data)
    mse, _ = _rate_cost(grid or Grid(data), data, axis, delay, tau, pairs, gain)
    return AxisFit(gain, tau, delay, float(np.sqrt(mse)), int(sum(len(k) for k, _ in pairs)))


def fit_common_delay(data: FlightData, grid: Grid | None = None, scored=(0, 1, 2)) -> tuple[float, list[AxisFit]]:
    """One delay for the three axes (what the daemon's actuation delay can express): the one
    that minimises the summed error of the `scored` axes (all, unless some were not excited),
    each axis's error scaled by its own best."""
    grid = grid or Grid(data)
    scored = list(scored) or [0, 1, 2]
    own = [fit_rate_axis(data, a, grid) for a in scored]
    candidates = sorted({round(f.delay, 4) for f in own} |
                        {round(x, 4) for x in np.arange(min(f.delay for f in own), max(f.delay for f in own) + 1e-9, 0.0005)})
    best = None
    for d in candidates:
        fits = [fit_rate_axis(data, a, grid, delay=d) for a in range(3)]
        score = sum((fits[a].rmse / max(o.rmse, 1e-9)) ** 2 for a, o in zip(scored, own))
        if best is None or score < best[0]:
            best = (score, d, fits)
    return float(best[1]), best[2]


def fit_thrust(data: FlightData, grid: Grid | None = None, delay: float | None = None, gravity: float = 9.81) -> ThrustFit:
    grid = grid or Grid(data)
    t, x = data.t, data.x
    k0 = np.arange(len(t) - 1)
    k1 = k0 + 1
    dt = t[k1] - t[k0]
    period = float(np.median(dt))
    k0, k1, dt = (a[np.abs(dt - period) < 0.5 * period] for a in (k0, k1, dt))
    qm = 0.5 * (x[k0, Q.QUAT] + x[k1, Q.QUAT])
    qm /= np.linalg.norm(qm, axis=1, keepdims=True)
    qw, qx, qy, qz = qm.T
    b = np.stack([2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy)], axis=1)
    dv = x[k1, Q.VEL] - x[k0, Q.VEL]
    iv = 0.5 * (x[k0, Q.VEL] + x[k1, Q.VEL]) * dt[:, None]

    def solve(d):
        it = grid.integral(Q.THRUST, d, t[k1]) - grid.integral(Q.THRUST, d, t[k0])
        rows, rhs = [], []
        g = np.array([0.0, 0.0, gravity])
        for c in range(3):
            a = np.zeros((len(dt), 4))
            a[:, 0] = it * b[:, c]
            a[:, 1] = -iv[:, c]
            if c < 2:
                a[:, 2 + c] = dt
            rows.append(a)
            rhs.append(dv[:, c] + g[c] * dt)
        a, y = np.concatenate(rows), np.concatenate(rhs)
        sol, *_ = np.linalg.lstsq(a, y, rcond=None)
        res = y - a @ sol
        return float(np.mean((res / np.concatenate([dt, dt, dt])) ** 2)), sol

    if delay is None:
        coarse = [(solve(d)[0], d) for d in np.arange(0.0, DELAY_MAX + 1e-9, 0.002)]
        d0 = min(coarse)[1]
        delay = float(min((solve(d)[0], d) for d in np.arange(max(0.0, d0 - 0.002), d0 + 0.002 + 1e-9, 0.0002))[1])
    mse, sol = solve(delay)
    mass = 1.0 / sol[0]
    return ThrustFit(float(mass), float(sol[1] * mass), [float(sol[2]), float(sol[3]), 0.0], delay, float(np.sqrt(mse)),
                     len(dt))
