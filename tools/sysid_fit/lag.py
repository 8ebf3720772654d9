"""How far the autopilot's position estimate trails the vehicle: the vehicle file's
`estimate_lag`, from a flight with an outside reference (docs/sysid.md).

The reference is a truth log: SITL's simulated truth as tools/sitl's referee writes it
(truth.jsonl: "x" the true ENU position, "v" its velocity, "boot_us" the autopilot's clock,
"wall_us" this host's), or motion capture / RTK written in the same form. The estimate is what
mppid flies on, the states the bridge published (MPPI_STATE in the flight's LCM log, stamped
with the autopilot's sample time on this host's clock), so everything between the autopilot's
estimator and mppid counts: the estimator's own lag, and any the bridge adds (before
2026-11-26 it paired each ArduPilot attitude with the previous burst's position: 20 ms).

The lag is the time shift tau that brings the estimate onto the truth,

    tau = argmin_tau  mean | p_est(t) - p_true(t - tau) |^2   over the samples moving faster than
                                                             `min_speed` (at rest a shift shows nothing),

on a 0.5 ms grid over [-50, 150] ms, the truth interpolated linearly; its time is the
autopilot's clock mapped onto this host's by the least receipt delay (as the harness scores).
Also reported: the along-track error at tau = 0 and at tau (a lag shows as a mean along-track
error of -speed * tau), and, when the truth log pairs each truth with the estimate of the
same burst ("paired", tools/sitl_harness/ap_truth.py), the estimator's own lag from those pairs.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import logs

GRID_S = np.arange(-0.050, 0.1505, 0.0005)


class LagError(ValueError):
    pass


def read_truth(path: Path) -> dict:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = [r for r in rows if "x" in r and r.get("boot_us", 0) > 0]
    if len(rows) < 50:
        raise LagError(f"{path}: {len(rows)} truth samples with the autopilot's time: too few")
    boot = np.array([r["boot_us"] for r in rows], float)
    wall = np.array([r["wall_us"] for r in rows], float)
    paired = np.array([bool(r.get("paired")) and r.get("est") is not None for r in rows])
    est = np.array([r["est"] if r.get("est") is not None else [np.nan] * 3 for r in rows], float)
    return {"t_wall_s": (boot + np.min(wall - boot)) * 1e-6, "t_boot_s": boot * 1e-6,
            "x": np.array([r["x"] for r in rows], float), "v": np.array([r["v"] for r in rows], float),
            "est": est, "paired": paired}


def read_states(log: Path) -> tuple[np.ndarray, np.ndarray]:
    """(sample times [s] on this host's clock, ENU positions) of the states mppid flew on."""
    m = logs._lcm_messages(log)
    seqs = sorted(m["states"])
    if len(seqs) < 50:
        raise LagError(f"{log}: {len(seqs)} states: too few")
    t = np.array([m["states"][s][0] for s in seqs], float) * 1e-6
    p = np.array([m["states"][s][1][0:3] for s in seqs], float)
    order = np.argsort(t, kind="stable")
    return t[order], p[order]


def along_track(err: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The component of each error along the horizontal velocity (positive: ahead)."""
    u = v[:, :2] / np.linalg.norm(v[:, :2], axis=1, keepdims=True)
    return np.sum(err[:, :2] * u, axis=1)


def best_shift(t_est, p_est, t_true, x_true, v_true, min_speed) -> dict:
    """The shift of the truth that the estimate matches best, over the moving samples."""
    fast = np.linalg.norm(v_true[:, :2], axis=1) > min_speed
    if fast.sum() < 50:
        raise LagError(f"{int(fast.sum())} truth samples faster than {min_speed:g} m/s: a lag needs motion")
    t = t_true[fast]
    inside = (t >= t_est[0]) & (t <= t_est[-1])
    t, x, v = t[inside], x_true[fast][inside], v_true[fast][inside]
    p = np.stack([np.interp(t, t_est, p_est[:, i]) for i in range(3)], 1)

    def cost(tau):  # the truth at t - tau, against the estimate at t
        xs = np.stack([np.interp(t - tau, t_true, x_true[:, i]) for i in range(3)], 1)
        return float(np.mean(np.sum((p - xs) ** 2, axis=1)))

    costs = np.array([cost(tau) for tau in GRID_S])
    tau = float(GRID_S[int(np.argmin(costs))])
    xs = np.stack([np.interp(t - tau, t_true, x_true[:, i]) for i in range(3)], 1)
    return {"lag_s": tau, "samples": int(len(t)), "speed_m_s": float(np.mean(np.linalg.norm(v[:, :2], axis=1))),
            "rms_at_0_m": float(np.sqrt(cost(0.0))), "rms_at_lag_m": float(np.sqrt(costs.min())),
            "along_at_0_m": float(np.mean(along_track(p - x, v))),
            "along_at_lag_m": float(np.mean(along_track(p - xs, v))),
            "at_bound": bool(tau in (GRID_S[0], GRID_S[-1]))}


def estimate_lag(flight: Path, min_speed: float = 1.0) -> dict:
    """From a flight folder (flight.lcmlog, truth.jsonl), or a truth log alone."""
    truth_path = flight / "truth.jsonl" if flight.is_dir() else flight
    truth = read_truth(truth_path)
    out = {"truth": str(truth_path), "min_speed_m_s": min_speed}
    log = flight / "flight.lcmlog" if flight.is_dir() else None
    if log is not None and log.exists():
        t_est, p_est = read_states(log)
        out["mppid_state"] = best_shift(t_est, p_est, truth["t_wall_s"], truth["x"], truth["v"], min_speed)
    k = truth["paired"]
    if k.sum() >= 50:  # the estimator alone: each truth with its burst's estimate, on the autopilot's clock
        out["estimator"] = best_shift(truth["t_boot_s"][k], truth["est"][k], truth["t_boot_s"], truth["x"], truth["v"],
                                      min_speed)
    if "mppid_state" not in out and "estimator" not in out:
        raise LagError(f"{flight}: neither the states mppid flew on (flight.lcmlog) nor paired estimates in the truth")
    return out
