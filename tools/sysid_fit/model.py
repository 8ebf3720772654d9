"""The rate model (core/include/mppi/models/quadrotor_rate.hpp) in numpy, for fitting and for
predicting held-out flight: the same equations, vectorised over many starting points.

    v' = T / m  b(q) - g z - (drag / m) v          b: the body z axis in the world
    q' = 1/2 q (x) (0, w)
    w' = (gain u_rate - w) / tau                    per body axis

Commands are piecewise constant and act `delay` seconds after their time (FlightData.tc):
the daemon's latency compensation with daemon.latency.actuation_delay_ms is the same delay.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q


@dataclass
class RateModel:
    mass: float = 1.0
    gravity: float = 9.81
    drag: float = 0.0
    tau: list[float] = field(default_factory=lambda: [0.05, 0.05, 0.05])
    gain: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    delay: float = 0.0

    @staticmethod
    def from_vehicle(v: dict) -> "RateModel":
        rr = v["rate_response"]
        return RateModel(v["mass"], v["gravity"], v["drag"], list(rr["tau"]), list(rr["gain"]), rr["delay"])


def command_index(tc: np.ndarray, t: np.ndarray, delay: float) -> np.ndarray:
    """Index of the command acting at each time t (the latest with tc + delay <= t; 0 before)."""
    return np.clip(np.searchsorted(tc + delay, t, side="right") - 1, 0, len(tc) - 1)


def derivative(m: RateModel, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    qw, qx, qy, qz = x[:, Q.QW], x[:, Q.QX], x[:, Q.QY], x[:, Q.QZ]
    wx, wy, wz = x[:, Q.WX], x[:, Q.WY], x[:, Q.WZ]
    b = np.stack([2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy)], axis=1)
    dx = np.empty_like(x)
    dx[:, Q.POS] = x[:, Q.VEL]
    dx[:, Q.VEL] = (u[:, Q.THRUST:Q.THRUST + 1] / m.mass) * b - (m.drag / m.mass) * x[:, Q.VEL]
    dx[:, Q.VZ] -= m.gravity
    dx[:, Q.QW] = 0.5 * (-qx * wx - qy * wy - qz * wz)
    dx[:, Q.QX] = 0.5 * (qw * wx + qy * wz - qz * wy)
    dx[:, Q.QY] = 0.5 * (qw * wy - qx * wz + qz * wx)
    dx[:, Q.QZ] = 0.5 * (qw * wz + qx * wy - qy * wx)
    for a in range(3):
        dx[:, Q.WX + a] = (m.gain[a] * u[:, Q.RATE_X + a] - x[:, Q.WX + a]) / m.tau[a]
    return dx


def predict(m: RateModel, x0: np.ndarray, t0: np.ndarray, horizon: float, tc: np.ndarray, u: np.ndarray,
            h: float = 0.002) -> np.ndarray:
    """Each row of x0 (at its time t0) advanced `horizon` seconds under the logged commands
    (RK4, steps of h, the command held over each step as at its start)."""
    x = x0.copy()
    steps = int(round(horizon / h))
    for n in range(steps):
        t = t0 + n * h
        uc = u[command_index(tc, t, m.delay)]
        k1 = derivative(m, x, uc)
        k2 = derivative(m, x + 0.5 * h * k1, uc)
        k3 = derivative(m, x + 0.5 * h * k2, uc)
        k4 = derivative(m, x + h * k3, uc)
        x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        x[:, Q.QUAT] /= np.linalg.norm(x[:, Q.QUAT], axis=1, keepdims=True)
    return x


def attitude_error(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Rotation angle [rad] between unit quaternions, row by row."""
    d = np.abs(np.sum(qa * qb, axis=1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))
