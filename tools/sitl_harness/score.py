"""The score of a flight, from the simulator's truth (not the controller's view) and the
controller's own status messages.

success: the scenario's criterion (success.type in the scenario file) and no collision and
a controller that answered to the end:
  goal      every vehicle reached its goal (sim outcome "goal")
  tracking  full duration, position RMSE after `settle` s <= max_rmse
  swingup   full duration, over the last `hold` s the pole within angle_tol of upright and
            |theta_dot| < rate_tol
  laps      full duration, >= min_laps laps of the ellipse, mean speed >= min_mean_speed
tracking_rmse means, per type: the position error to the reference (tracking), the angle
error to upright over the hold window (swingup), the ellipse residual d (laps); null for goal.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from mppi_mavlink.layout import Cartpole, QuadrotorRate as Q, Racecar

from . import logs, paths, sensing, timing

QUAD_MODELS = ("quadrotor", "quadrotor_rate", "quadrotor_rate_body")


def reference_eval(ref: dict, t: np.ndarray):
    """core's Reference::eval, vectorised (the mission tool's mirror of it): positions
    (len(t), 3)."""
    from mppi_mission import reference
    return reference.evaluate({"center": [0, 0, 2], **ref}, t)[0]


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _controller_stats(status, commands=()):
    """From the controller_status_t messages: misses, cycles, and the timing figures of
    timing.py (compute_ms_p99 over the flight's cycles; *_worst_window: the worst window)."""
    msgs = [m for _, m in status]
    if not msgs:
        # No status in the log (a lock-step flight can end within one status period): the
        # per-cycle figures still come from the commands.
        return _timing_figures([], commands)
    last = msgs[-1]
    res = {
        "backend": last.backend,
        "rollouts": last.rollouts,
        "horizon": last.horizon,
        "cycles": int(max(m.cycles for m in msgs)),
        "deadline_misses": int(max(m.misses for m in msgs)),
        # Misses whose cycle's own work fit in a period: the loop woke late (the machine).
        "deadline_misses_late_start": int(max(m.late_start_misses for m in msgs)),
        "status_messages": len(msgs),
        "rejected": int(last.rejected_nan + last.rejected_stale + last.rejected_out_of_order + last.rejected_undecodable),
    }
    res.update(_timing_figures(msgs, commands))
    return res


def _timing_figures(msgs, commands) -> dict:
    """timing.py's figures of the flight, without the samples they come from."""
    t = timing.flight_timing(msgs, [m for _, m in commands])
    t.pop("compute_samples_ms", None)
    t.pop("state_to_command_samples_ms", None)
    return t


def score_flight(out: Path, spec, info: dict) -> dict:
    out = Path(out)
    scen = yaml.safe_load(paths.scenario_path(spec.scenario).read_text())
    world = logs.read_json(out / "world.json") or {}
    summary = logs.read_json(out / "sim_summary.json") or {}
    ticks, _events = logs.read_truth(out)
    lcm = logs.read_lcm_log(out / "flight.lcmlog", {"MPPI_COMMAND", "MPPI_STATUS", "MPPI_PARAM_RESULT"})
    res = _flight_record(spec, info, world, summary, lcm)
    res.update(_controller_stats(lcm.get("MPPI_STATUS", []), lcm.get("MPPI_COMMAND", [])))
    res.update(_log_figures(spec, ticks, lcm))
    X = None
    if ticks:
        t = np.array([tk["t"] for tk in ticks])
        X = np.array([[np.nan if v is None else v for v in tk["x"]] for tk in ticks], float)
        if scen["plant"]["model"] in QUAD_MODELS:
            res.update(_quad_speeds(world, X))
        else:
            res["mean_speed"] = _mean_speed(scen["plant"]["model"], X)
    if scen["plant"]["model"] in QUAD_MODELS:
        res.update(sensing.sensing_figures(out, world, t if ticks else None, X))
    res["reason"] = _not_the_vehicles_failure(info, summary, res["collisions"])
    if res["reason"] is not None or not ticks:
        res["reason"] = res["reason"] or "no truth log"
        return res
    crit = scen.get("success", {"type": "goal"})
    kind = crit.get("type", "goal")
    judge = CRITERIA.get(kind)
    if judge is None:
        res["reason"] = f"unknown success.type {kind}"
        return res
    duration = float(world.get("duration", 0))
    full = summary.get("outcome") == "duration" and abs(t[-1] - duration) < 0.05
    judge(res, crit, Flown(out=out, world=world, outcome=summary.get("outcome"), t=t, X=X, full=full,
                           duration=duration))
    return res


def _flight_record(spec, info: dict, world: dict, summary: dict, lcm: dict) -> dict:
    """What the flight was and what the simulator said of it, before any judgement."""
    res = {
        "scenario": paths.scenario_label(spec.scenario),
        "seed": spec.seed,
        "backend": spec.backend,
        "clock": "realtime" if spec.realtime else "lockstep",
        # Lock-step: what the simulator charged each command ("measured", "ideal", seconds).
        "latency_charge": world.get("latency_charge"),
        "controller": spec.controller,
        "success": False,
        "reason": None,
        "sim_outcome": summary.get("outcome"),
        "harness_outcome": info.get("harness_outcome"),
        "time_to_goal": summary.get("time_to_goal"),
        "sim_time": summary.get("t_end"),
        "wall_s": info.get("wall_s"),
        "min_clearance": summary.get("min_clearance"),
        "min_separation": summary.get("min_separation"),
        "collisions": summary.get("collisions", []),
        "tracking_rmse": None,
        "mean_speed": None,
        "commands": len(lcm.get("MPPI_COMMAND", [])),
    }
    if not spec.realtime and summary.get("ignored_commands") is not None:
        # Lock-step is deterministic only while every answer comes within 0.5 s of wall time:
        # after that the simulator republishes the state and its clock tick, the controller
        # runs an extra cycle on the copy (its answer is ignored and counted here) and its
        # noise and plan move one cycle ahead: the flight is no longer reproducible.
        res["lockstep_republished"] = int(summary["ignored_commands"])
    if summary.get("commands") is not None:
        # Commands the simulator received but the logger did not record (should be 0).
        res["log_commands_missing"] = max(0, int(summary["commands"]) - res["commands"])
    return res


def _log_figures(spec, ticks, lcm: dict) -> dict:
    """From the truth's answer times and the log: answer and command period p99, the answers
    to parameter updates, the commands by mode."""
    res = {}
    lat = [tk["lat_ms"] for tk in ticks if tk.get("lat_ms") is not None]
    if lat:
        res["answer_ms_p99"] = float(np.percentile(lat, 99))  # state published -> command received (lock-step)
    cmd_t = np.array([t for t, _ in lcm.get("MPPI_COMMAND", [])], float) / 1e6
    if len(cmd_t) > 2:
        res["command_period_ms_p99"] = float(np.percentile(np.diff(cmd_t) * 1e3, 99))
    if lcm.get("MPPI_PARAM_RESULT") or getattr(spec, "params", None):
        # The controller's answers to parameter updates (tools/sitl run --param).
        res["param_results"] = [{"update_seq": r.update_seq, "key": r.key, "value": r.value,
                                 "applied": r.status == 0, "cycle": r.cycle, "reason": r.reason}
                                for _, r in lcm.get("MPPI_PARAM_RESULT", [])]
    modes = [m.mode for _, m in lcm.get("MPPI_COMMAND", [])]
    if modes:
        res["commands_hold"] = int(sum(1 for m in modes if m == 1))
        res["commands_failsafe"] = int(sum(1 for m in modes if m == 2))
    return res


def _mean_speed(model: str, X: np.ndarray) -> float:
    """The cart's or the race car's mean speed (a quadrotor's: _quad_speeds)."""
    if model == "cartpole":
        return float(np.nanmean(np.abs(X[:, Cartpole.XDOT])))
    return float(np.nanmean(np.hypot(X[:, Racecar.VX], X[:, Racecar.VY])))


def _quad_speeds(world: dict, X: np.ndarray) -> dict:
    """mean_speed over every vehicle's samples; peak_speed: the fastest any vehicle flew;
    forest_speed: the mean speed while inside the obstacles' x extent (the trees, not the
    run-up and the stop at the goal), None without. The speeds are computed once for all three.
    Both quadrotor models put position and velocity first (layout.Quadrotor, QuadrotorRate)."""
    nx, m = int(world.get("nx", X.shape[1])), int(world.get("vehicles", 1))
    speeds = np.stack([np.linalg.norm(X[:, v * nx + Q.VX:v * nx + Q.VZ + 1], axis=1) for v in range(m)])
    obstacles = np.asarray(world.get("obstacles") or [], float).reshape(-1, 5)
    finite = np.isfinite(speeds).any()
    out = {"mean_speed": float(np.nanmean(speeds)) if finite else float("nan"),
           "peak_speed": float(np.nanmax(speeds)) if finite else None, "forest_speed": None}
    if len(obstacles):
        lo, hi = (obstacles[:, 0] - obstacles[:, 2]).min(), (obstacles[:, 0] + obstacles[:, 2]).max()
        px = np.stack([X[:, v * nx] for v in range(m)])
        inside = (px >= lo) & (px <= hi) & np.isfinite(speeds)
        out["forest_speed"] = float(speeds[inside].mean()) if inside.any() else None
    return out


def _not_the_vehicles_failure(info: dict, summary: dict, collisions: list) -> str | None:
    """Failures that are not the vehicle's (and collisions), else None."""
    ho = info.get("harness_outcome")
    so = summary.get("outcome")
    if info.get("error"):
        return "harness error: " + info["error"]
    if ho is not None:
        return ho
    if so is None:
        return "no simulator summary"
    if summary.get("rejected_commands"):
        return f"{summary['rejected_commands']} malformed commands (wrong size, kind or not finite)"
    if so == "controller_timeout":
        return "controller stopped answering (lock-step timeout)"
    if so in ("interrupted", "error"):
        return "simulator " + so
    if collisions:
        c = collisions[0]
        return f"collision with {c['with']} (vehicle {c['vehicle']}) at t={c['t']:.2f} s"
    return None


@dataclass
class Flown:
    """What the success criteria judge: the truth (t, X) and how the simulation ended."""
    out: Path
    world: dict
    outcome: str | None
    t: np.ndarray
    X: np.ndarray
    full: bool          # flown to the scenario's full duration
    duration: float


def _goal(res: dict, crit: dict, f: Flown) -> None:
    res["success"] = f.outcome == "goal"
    res["reason"] = "goal reached" if res["success"] else f"goal not reached in {f.duration:g} s"


def _tracking(res: dict, crit: dict, f: Flown) -> None:
    ref = f.world.get("reference", {})
    sel = f.t >= float(crit.get("settle", 0.0))
    err = np.linalg.norm(f.X[sel, Q.POS] - reference_eval(ref, f.t[sel]), axis=1)
    res["tracking_rmse"] = float(np.sqrt(np.mean(err ** 2))) if err.size else None
    ok = res["tracking_rmse"] is not None and res["tracking_rmse"] <= float(crit.get("max_rmse", 0.5))
    res["success"] = bool(f.full and ok)
    res["reason"] = "tracked" if res["success"] else f"tracking RMSE {res['tracking_rmse']:.3f} m > {crit.get('max_rmse', 0.5)}"


def _mission(res: dict, crit: dict, f: Flown) -> None:
    # The mission tool flew it (the scenario's `mission`): done, and its paths tracked.
    ms = logs.read_json(f.out / "mission_summary.json") or {}
    rms = [leg["rmse"] for leg in ms.get("legs", []) if "rmse" in leg and leg["kind"] != "hold"]
    res["tracking_rmse"] = max(rms) if rms else None
    ok = ms.get("outcome") == "done" and (res["tracking_rmse"] or 0.0) <= float(crit.get("max_rmse", 0.5))
    res["success"] = bool(ok)
    res["reason"] = "mission done" if ok else f"mission {ms.get('outcome')}, path RMSE {res['tracking_rmse']}"


def _swingup(res: dict, crit: dict, f: Flown) -> None:
    t, X = f.t, f.X
    th, w = X[:, Cartpole.THETA], X[:, Cartpole.THETADOT]
    err = np.abs(_wrap(th - np.pi))
    upright = (err < float(crit.get("angle_tol", 0.3))) & (np.abs(w) < float(crit.get("rate_tol", 2.0)))
    hold = t >= t[-1] - float(crit.get("hold", 2.0))
    res["tracking_rmse"] = float(np.sqrt(np.mean(err[hold] ** 2)))
    # Time to goal: from when the pole stays upright to the end.
    idx = np.where(~upright)[0]
    first_stay = (idx[-1] + 1) if idx.size else 0
    res["time_to_goal"] = float(t[first_stay]) if first_stay < len(t) else None
    res["success"] = bool(f.full and upright[hold].all())
    res["reason"] = "swung up and held" if res["success"] else "pole not held upright over the last %.1f s" % float(crit.get("hold", 2.0))


def _laps(res: dict, crit: dict, f: Flown) -> None:
    X = f.X
    x, y = X[:, Racecar.X], X[:, Racecar.Y]
    d = (x / 13.0) ** 2 + (y / 6.0) ** 2 - 1.0
    ang = np.unwrap(np.arctan2(y / 6.0, x / 13.0))
    laps = abs(ang[-1] - ang[0]) / (2 * np.pi)
    res["laps"] = float(laps)
    res["tracking_rmse"] = float(np.sqrt(np.mean(d ** 2)))
    ok = laps >= float(crit.get("min_laps", 1)) and res["mean_speed"] >= float(crit.get("min_mean_speed", 0))
    res["success"] = bool(f.full and ok)
    res["reason"] = "lapped" if res["success"] else f"{laps:.2f} laps at {res['mean_speed']:.2f} m/s mean"


# success.type -> its judge (the scenario file's criterion, module docstring).
CRITERIA = {"goal": _goal, "tracking": _tracking, "mission": _mission, "swingup": _swingup, "laps": _laps}
