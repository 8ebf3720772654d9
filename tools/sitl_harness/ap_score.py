"""The score of a flight through ArduCopter SITL (ardupilot.py), from the SITL's simulated
truth (ap_truth.py's truth.jsonl), the mission tool's record of what it asked for
(mission.jsonl: each step's reference and epoch) and, for mppid, its commands in the LCM log.

Per leg of the mission: the RMS and largest distance between the true position and the
reference while the path is at speed (from `score.settle` s after its ramp; hold legs from
`settle` s after they start: the hover error) and the same from the autopilot's own estimate
(what the controller saw). Over the flight: crashes (the truth below 5 cm while flying or
tilted past 80 degrees, or the SITL's "crash" text), the largest tilt, the clearance to the
virtual trees (truth), whether the mission was done. success: the mission done, no crash,
no tree hit.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from mppi_mavlink.layout import QuadrotorRate as Q

from . import paths, survey
from .logs import read_jsonl

CRASH_TILT_DEG = 80.0
GROUND_Z = 0.05


# The controllers that are the autopilot's own (no mppid, no LCM log to time).
AUTOPILOT_CONTROLLERS = ("guided", "px4", "auto", "loiter", "position")


def score_flight(out: Path, spec, info: dict, autopilot: str = "ardupilot") -> dict:
    out = Path(out)
    truth = [r for r in read_jsonl(out / "truth.jsonl") if "x" in r]
    events = [r for r in read_jsonl(out / "truth.jsonl") if "event" in r]
    mission = read_jsonl(out / "mission.jsonl")
    summary = json.loads((out / "mission_summary.json").read_text()) if (out / "mission_summary.json").is_file() else {}
    res = {"scenario": paths.scenario_label(spec.scenario), "seed": spec.seed, "autopilot": autopilot,
           "controller": spec.controller, "success": False, "reason": None,
           "harness_outcome": info.get("harness_outcome"), "mission_outcome": summary.get("outcome"),
           "wall_s": info.get("wall_s")}
    if not truth or not mission:
        res["reason"] = info.get("error") or "no truth or mission record"
        return res
    head = next((m for m in mission if m.get("event") == "mission"), {})
    world = survey.load_world(out)  # a survey uploaded to the autopilot: the world's trees
    if world:
        head = {**head, "trees": world["trees"], "vehicle_radius": world["vehicle_radius"]}
    clock = head.get("clock", "state")
    t_truth = _truth_clock(truth, clock)
    X = np.array([r["x"] for r in truth])
    est = np.array([r["est"] if r.get("est") else [np.nan] * 3 for r in truth])
    flying = np.array([r.get("armed", False) for r in truth])
    res.update(_legs(mission, t_truth, X, est, settle=float(head.get("settle", 3.0))))
    if world:
        res.update(survey.figures(world, t_truth * 1e-6, X[:, Q.PX:Q.PZ + 1], np.array([r["v"] for r in truth])))
    res.update(_safety(truth, events, X, flying, head, res.get("last_item_index")))
    res.update(_push(mission, truth, X, head))
    res.update(_timing(out) if spec.controller not in AUTOPILOT_CONTROLLERS else {})
    res.update(_sensing(out, head, t_truth, X))
    done = summary.get("outcome") == "done" and res.get("waypoints_reached") == res.get("waypoints")
    res["success"] = bool(done and not res["crashes"] and (res.get("min_clearance") is None or res["min_clearance"] > 0))
    res["reason"] = ("mission done" if res["success"] else
                     res["crashes"][0] if res["crashes"] else
                     "hit a tree" if done else f"mission {summary.get('outcome') or 'not finished'}"
                     + (f" (harness: {info.get('harness_outcome')})" if info.get("harness_outcome") else ""))
    return res


def _truth_clock(truth, clock: str) -> np.ndarray:
    """The truth's times on the mission's clock: the autopilot's boot time (the GUIDED
    baseline's), or this host's wall clock as the bridge maps boot times onto it (mppid's
    states): boot time + the smallest receipt delay, one offset for the flight. ArduCopter
    SITL's clock keeps pace with this host's; an autopilot whose clock drifts (PX4 SIH) needs
    the drift followed, as the bridge does (mppi_mavlink/clock_sync.py): its truth lines carry
    their time on the mission's clock already (`mission_us`, px4_score.py)."""
    if all("mission_us" in r for r in truth):
        return np.array([r["mission_us"] for r in truth], float)
    boot = np.array([r["boot_us"] for r in truth], float)
    if clock == "boot":
        return boot
    wall = np.array([r["wall_us"] for r in truth], float)
    ok = boot > 0
    return boot + (np.min(wall[ok] - boot[ok]) if ok.any() else 0.0)


def _legs(mission, t_truth, X, est, settle) -> dict:
    from mppi_mission import reference
    steps = [m for m in mission if m.get("event") == "step" and m["leg"] >= 0]
    legs = {}
    for i, s in enumerate(steps):
        t_end = steps[i + 1]["t0_us"] if i + 1 < len(steps) else t_truth[-1]
        t = (t_truth - s["t0_us"]) * 1e-6
        start = settle + (float(s["ref"].get("ramp", 0.0)) if s["kind"] != "hold" else 0.0)
        sel = (t >= start) & (t_truth < t_end)
        if s["duration"] is not None:
            sel &= t <= s["duration"]
        if s.get("transit") or s["kind"] == "goal" or not sel.any():
            continue
        ref = reference.evaluate(s["ref"], t[sel])[0]
        e_true = np.linalg.norm(X[sel] - ref, axis=1)
        e_est = np.linalg.norm(est[sel] - ref, axis=1)
        key = f"leg{s['leg']}_{s['kind']}"
        legs[key] = {"rmse": float(np.sqrt(np.mean(e_true ** 2))), "max": float(np.max(e_true)),
                     "rmse_estimate": float(np.sqrt(np.nanmean(e_est ** 2))), "samples": int(sel.sum()),
                     "speed": s["ref"].get("speed")}
    out = {"legs": legs}
    paths_ = [v for k, v in legs.items() if not k.endswith("_hold")]
    holds = [v for k, v in legs.items() if k.endswith("_hold")]
    if paths_:
        out["tracking_rmse"] = float(np.sqrt(np.mean([v["rmse"] ** 2 for v in paths_])))
        out["tracking_max"] = max(v["max"] for v in paths_)
    if holds:
        out["hover_rmse"] = float(np.sqrt(np.mean([v["rmse"] ** 2 for v in holds])))
        out["hover_max"] = max(v["max"] for v in holds)
    return out


def _safety(truth, events, X, flying, head, end: int | None = None) -> dict:
    """Crashes between the first take-off and the landing: the mode LAND, or `end` (a survey's
    last waypoint: its NAV_LAND lands in AUTO)."""
    crashes = []
    tilt = np.array([r.get("tilt_deg", 0.0) for r in truth])
    airborne = np.flatnonzero(X[:, Q.PZ] > 0.5)
    if airborne.size:
        # After the first take-off and before the last landing began (the mode left GUIDED).
        lo = airborne[0]
        land = [i for i, r in enumerate(truth) if i > lo and r.get("mode") == "LAND"]
        hi = min(land[0] if land else len(truth), len(truth) if end is None else end + 1)
        low = np.flatnonzero((X[lo:hi, Q.PZ] < GROUND_Z) & flying[lo:hi])
        if low.size:
            crashes.append(f"ground contact while flying, {X[lo + low[0], Q.PX:Q.PY + 1].round(2).tolist()}")
        over = np.flatnonzero(tilt[lo:hi] > CRASH_TILT_DEG)
        if over.size:
            crashes.append(f"tilted past {CRASH_TILT_DEG:g} degrees")
    for e in events:
        if e.get("event") == "statustext" and "crash" in e.get("text", "").lower():
            crashes.append(f"autopilot: {e['text']}")
    res = {"crashes": crashes, "max_tilt_deg": float(tilt.max()) if tilt.size else None,
           "max_speed": float(np.max(np.linalg.norm([r["v"] for r in truth], axis=1)))}
    trees = head.get("trees") or []
    if trees:
        vr = float(head.get("vehicle_radius", 0.2))
        air = X[:, Q.PZ] > 0.3
        d = [min(math.hypot(p[0] - x, p[1] - y) - r - vr for x, y, r in trees) for p in X[air]]
        res["min_clearance"] = float(min(d)) if d else None
    return res


PUSH_AFTER_S = 3.0     # the push's figures run on this long after the stick's release
STOPPED_SPEED = 0.3    # m/s: slower than this at the release, the vehicle had stopped


def _push(mission, truth, X, head) -> dict:
    """A flight that pushes the stick towards the trees (--controller loiter, position: the
    ground station's `push` and `released` events): "push", from the push to PUSH_AFTER_S after
    the release, the closest the vehicle came to a tree (surface, less the vehicle's radius, as
    min_clearance), its clearance, horizontal speed and place at the release, whether it had
    stopped there, and its largest horizontal speed while pushed."""
    ev = {m["event"]: m["wall_us"] for m in mission if m.get("event") in ("push", "released")}
    trees = head.get("trees") or []
    if {"push", "released"} - set(ev) or not trees:
        return {}
    wall = np.array([r["wall_us"] for r in truth], float)
    pushed = (wall >= ev["push"]) & (wall <= ev["released"])
    window = (wall >= ev["push"]) & (wall <= ev["released"] + PUSH_AFTER_S * 1e6)
    if not pushed.any():
        return {}
    vr = float(head.get("vehicle_radius", 0.2))
    clear = np.array([min(math.hypot(p[0] - x, p[1] - y) - r - vr for x, y, r in trees) for p in X[:, :2]])
    speed = np.array([math.hypot(r["v"][0], r["v"][1]) for r in truth])
    i = int(np.flatnonzero(pushed)[-1])
    return {"push": {"seconds": round((ev["released"] - ev["push"]) * 1e-6, 2),
                     "closest_m": round(float(clear[window].min()), 3), "at_release_m": round(float(clear[i]), 3),
                     "speed_at_release": round(float(speed[i]), 3), "max_speed": round(float(speed[pushed].max()), 3),
                     "at_release_xy": [round(float(c), 2) for c in X[i, :2]],
                     "start_xy": [round(float(c), 2) for c in X[np.flatnonzero(pushed)[0], :2]],
                     "stopped": bool(speed[i] < STOPPED_SPEED)}}


def _sensing(out: Path, head: dict, t_truth: np.ndarray, X: np.ndarray) -> dict:
    """A sensed mission's (flights/sensed.py) "sensing": each tree passed, when it first entered
    mppid's map and how far off it then was (sensing.py, on the mapper's clock: seconds since
    its first frame), and the sensor node's truths taken and refused and its frames."""
    from . import logs, sensing
    records = logs.read_jsonl(out / "sensed.jsonl") if (out / "sensed.jsonl").is_file() else []
    if not records:
        return {}
    first_us = records[0]["utime"] - 1e6 * records[0]["t"]
    res = sensing.sensing_figures(out, {"obstacles": head.get("trees") or []}, (t_truth - first_us) * 1e-6, X)
    node = logs.read_json(out / "sensors_stats.json") or {}
    if res and node:
        res["sensing"].update(sensors=node.get("sensors", {}), truth=node.get("truth", {}))
    return res


def _timing(out: Path) -> dict:
    """mppid's per-cycle timing from its commands in the LCM log (timing.py's definitions)."""
    from . import logs, timing
    log = out / "flight.lcmlog"
    if not log.is_file():
        return {}
    msgs = logs.read_lcm_log(log, {"MPPI_COMMAND", "MPPI_STATUS"})
    commands = [m for _, m in msgs.get("MPPI_COMMAND", [])]
    status = [m for _, m in msgs.get("MPPI_STATUS", [])]
    t = timing.flight_timing(status, commands)
    t.pop("compute_samples_ms", None)
    if status:
        t["deadline_misses"] = int(max(m.misses for m in status))
    return t
