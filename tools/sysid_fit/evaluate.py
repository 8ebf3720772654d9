"""How well a model predicts flight it was not fitted on: from each state of the held-out part,
the model flies the logged commands for `horizon` seconds (0.5 s), and its state is compared
with the logged one then. RMSE over the starting points of position, velocity, attitude
(angle) and body-rate errors."""
from __future__ import annotations

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q

from .logs import FlightData
from .model import RateModel, attitude_error, predict


def prediction_errors(m: RateModel, data: FlightData, horizon: float = 0.5, stride: int = 2) -> dict:
    t = data.t
    period = float(np.median(np.diff(t)))
    steps = int(round(horizon / period))
    k0 = np.arange(0, len(t) - steps, stride)
    # The state nearest `horizon` later (uneven streams: a PX4's states come at two rates).
    hi = np.clip(np.searchsorted(t, t[k0] + horizon), 1, len(t) - 1)
    k1 = np.where(np.abs(t[hi] - t[k0] - horizon) <= np.abs(t[hi - 1] - t[k0] - horizon), hi, hi - 1)
    ok = np.abs(t[k1] - t[k0] - horizon) < 0.5 * period
    k0, k1 = k0[ok], k1[ok]
    if len(k0) < 5:
        raise ValueError(f"held-out part too short for {horizon} s predictions ({len(k0)} starting points)")
    xp = predict(m, data.x[k0], t[k0], horizon, data.tc, data.u)
    xt = data.x[k1]
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    return {
        "horizon_s": horizon,
        "starts": int(len(k0)),
        "position_m": rms(np.linalg.norm(xp[:, Q.POS] - xt[:, Q.POS], axis=1)),
        "velocity_m_s": rms(np.linalg.norm(xp[:, Q.VEL] - xt[:, Q.VEL], axis=1)),
        "attitude_deg": float(np.degrees(rms(attitude_error(xp[:, Q.QUAT], xt[:, Q.QUAT])))),
        "rate_rad_s": rms(np.linalg.norm(xp[:, Q.RATES] - xt[:, Q.RATES], axis=1)),
    }
